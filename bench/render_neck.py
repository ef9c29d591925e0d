# The deformed lumen at a run's end (aneusim with ANEU_LUMEN_OBJ=FILE) with its neck points coloured by gap.
#   bash scripts/xvfb.sh /usr/bin/python3 bench/render_neck.py lumen_end.obj OUT.png TITLE GAP_TOL_MM AXIS(x,y,z) UP(x,y,z)
import sys, vtk
obj, out, title, tol = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
axis = [float(x) for x in sys.argv[5].split(",")]; up = [float(x) for x in sys.argv[6].split(",")]
r = vtk.vtkOBJReader(); r.SetFileName(obj); r.Update()
pts = []
for line in open(obj):
    if line.startswith("# neck"):
        f = line.split(); pts.append(([float(f[3]), float(f[4]), float(f[5])], float(f[6])))
cx = [sum(p[0][i] for p in pts) / len(pts) for i in range(3)]
closed = sum(1 for p in pts if p[1] <= tol)
rw = vtk.vtkRenderWindow(); rw.SetOffScreenRendering(1); rw.SetSize(1400, 700)
for vi, (d, vu) in enumerate([(up, axis), ([-a for a in axis], up)]):
    ren = vtk.vtkRenderer(); ren.SetViewport(0.5 * vi, 0, 0.5 * vi + 0.5, 1); ren.SetBackground(1, 1, 1)
    m = vtk.vtkPolyDataMapper(); m.SetInputConnection(r.GetOutputPort())
    a = vtk.vtkActor(); a.SetMapper(m); a.GetProperty().SetColor(0.8, 0.8, 0.8); a.GetProperty().SetOpacity(0.35)
    ren.AddActor(a)
    for p, g in pts:
        s = vtk.vtkSphereSource(); s.SetCenter(*p); s.SetRadius(0.12); s.SetThetaResolution(12); s.SetPhiResolution(12)
        sm = vtk.vtkPolyDataMapper(); sm.SetInputConnection(s.GetOutputPort())
        sa = vtk.vtkActor(); sa.SetMapper(sm); sa.GetProperty().SetColor((0.1, 0.7, 0.2) if g <= tol else (0.9, 0.1, 0.1))
        ren.AddActor(sa)
    cam = ren.GetActiveCamera(); cam.SetFocalPoint(*cx); cam.SetPosition(*[cx[i] + 30 * d[i] for i in range(3)]); cam.SetViewUp(*vu); cam.SetViewAngle(35)
    t = vtk.vtkTextActor(); t.SetInput("%s: %d of %d neck points closed (gap <= %g mm)%s" % (title, closed, len(pts), tol, " - along the closing" if vi == 0 else " - down the jaws"))
    t.GetTextProperty().SetColor(0, 0, 0); t.GetTextProperty().SetFontSize(14); ren.AddActor2D(t)
    rw.AddRenderer(ren)
rw.Render()
w = vtk.vtkWindowToImageFilter(); w.SetInput(rw); w.Update()
pw = vtk.vtkPNGWriter(); pw.SetFileName(out); pw.SetInputConnection(w.GetOutputPort()); pw.Write()
