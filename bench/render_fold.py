# SPDX-License-Identifier: MIT
# usage: ZCUT=3.0 bash scripts/xvfb.sh /usr/bin/python3 bench/render_fold.py OUT.png LUMEN_0.70.obj=TITLE [...]  (OBJs from aneu_bench_fold --obj)
# The fold of a flattened tube (aneu_bench_fold --obj): the mid cross-section z = 3 seen down the tube, zoomed on
# the channel's narrowest place, for several OBJs side by side.
import sys, vtk
out, objs = sys.argv[1], sys.argv[2:]
rw = vtk.vtkRenderWindow(); rw.SetOffScreenRendering(1); rw.SetSize(400 * len(objs), 420)
lut = vtk.vtkLookupTable(); lut.SetTableRange(0, 0.3); lut.SetHueRange(0.33, 0.0); lut.Build()
for i, spec in enumerate(objs):
    obj, title = spec.split("=")
    r = vtk.vtkOBJReader(); r.SetFileName(obj); r.Update(); pd = r.GetOutput()
    W = vtk.vtkDoubleArray()
    for line in open(obj):
        if line.startswith("# width"): W.InsertNextValue(min(float(line.split()[3]), 0.3))
        if line.startswith("# channel"): f = line.split(); ch = (float(f[2]), [float(f[3]), float(f[4]), float(f[5])])
    pd.GetCellData().SetScalars(W)
    cut = vtk.vtkCutter(); pl = vtk.vtkPlane(); pl.SetOrigin(0, 0, float(__import__("os").environ.get("ZCUT","3.0"))); pl.SetNormal(0, 0, 1); cut.SetCutFunction(pl); cut.SetInputData(pd)
    ren = vtk.vtkRenderer(); ren.SetViewport(i / len(objs), 0, (i + 1) / len(objs), 1); ren.SetBackground(1, 1, 1)
    m = vtk.vtkPolyDataMapper(); m.SetInputConnection(cut.GetOutputPort()); m.SetLookupTable(lut); m.SetScalarRange(0, 0.3); m.SetScalarModeToUseCellData()
    a = vtk.vtkActor(); a.SetMapper(m); a.GetProperty().SetLineWidth(3); ren.AddActor(a)
    x = float(__import__("os").environ.get("FOCUSX", ch[1][0])) if ch[0] == 0 or "FOCUSX_ALL" in __import__("os").environ else ch[1][0]
    cam = ren.GetActiveCamera(); cam.SetFocalPoint(x - 0.4 * (1 if x > 0 else -1), 0, 3); cam.SetPosition(x - 0.4 * (1 if x > 0 else -1), 0, 30); cam.SetViewUp(0, 1, 0)
    cam.ParallelProjectionOn(); cam.SetParallelScale(0.6)
    t = vtk.vtkTextActor(); t.SetInput("%s: channel %.3f mm" % (title, ch[0])); t.GetTextProperty().SetColor(0, 0, 0); t.GetTextProperty().SetFontSize(15); ren.AddActor2D(t)
    rw.AddRenderer(ren)
rw.Render(); w = vtk.vtkWindowToImageFilter(); w.SetInput(rw); w.Update()
p = vtk.vtkPNGWriter(); p.SetFileName(out); p.SetInputConnection(w.GetOutputPort()); p.Write()
