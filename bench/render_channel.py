# The deformed lumen at a run's end coloured by its width (the diameter of the largest ball inside the lumen touching
# the wall at each face: green where the walls touch, red from 0.5 mm), the narrowest place of the widest channel still
# joining the sac to the parent (black), and the closed clip's blades (blue: the hinge line and the jaws' two edges),
# seen along the clip's closing and down its jaws. The OBJ is what `ANEU_LUMEN_OBJ=F aneusim run ...` writes (widths
# and channel as comments). System python3 with python3-vtk9 (bench only):
#   bash scripts/xvfb.sh /usr/bin/python3 bench/render_channel.py LUMEN.obj OUT.png "TITLE" HINGE AXIS CLOSING LENGTH_MM OPENING_DEG [FROM_MM [WIDTH_MM]]
# FROM_MM: draw the blades from this distance from the hinge (a hinge set far back: patch_scene.py --hinge-back-mm);
# WIDTH_MM: the jaws' width (their edge lines' spacing) [1]; CURVE_MM: a curved clip's radius [0]. patch_case_summary.py --render-args gives all of them.
# HINGE, AXIS (along the jaws) and CLOSING (the scene's "up": the direction the jaws close across) as x,y,z.
import math, sys, vtk
obj, out, title = sys.argv[1], sys.argv[2], sys.argv[3]
hinge = [float(x) for x in sys.argv[4].split(",")]; axis = [float(x) for x in sys.argv[5].split(",")]; up = [float(x) for x in sys.argv[6].split(",")]
length, theta_deg = float(sys.argv[7]), float(sys.argv[8])
start = float(sys.argv[9]) if len(sys.argv) > 9 else 0.0  # the blades drawn from this far from the hinge (a hinge set far back)
jaw_w = float(sys.argv[10]) if len(sys.argv) > 10 else 1.0  # the jaws' width: their edges drawn that far apart
curve = float(sys.argv[11]) if len(sys.argv) > 11 else 0.0  # a curved clip's radius (jaw_curve_radius_mm), bent from `start`
widths = obj
r = vtk.vtkOBJReader(); r.SetFileName(obj); r.Update()
pd = r.GetOutput()
W = vtk.vtkDoubleArray(); W.SetName("width")
chan = None
for line in open(widths):
    if line.startswith("# channel"):
        f = line.split(); chan = (float(f[2]), [float(f[3]), float(f[4]), float(f[5])])
    elif line.startswith("# width"):
        W.InsertNextValue(min(float(line.split()[3]), 0.5))
pd.GetCellData().SetScalars(W)
lut = vtk.vtkLookupTable(); lut.SetTableRange(0, 0.5); lut.SetHueRange(0.33, 0.0); lut.SetNumberOfTableValues(256); lut.Build()
lut.SetTableValue(0, 0.1, 0.7, 0.2, 1)
side = [axis[1]*up[2]-axis[2]*up[1], axis[2]*up[0]-axis[0]*up[2], axis[0]*up[1]-axis[1]*up[0]]
cx = chan[1]
rw = vtk.vtkRenderWindow(); rw.SetOffScreenRendering(1); rw.SetSize(1400, 700)
for vi, (d, vu) in enumerate([(up, axis), ([-a for a in axis], up)]):
    ren = vtk.vtkRenderer(); ren.SetViewport(0.5 * vi, 0, 0.5 * vi + 0.5, 1); ren.SetBackground(1, 1, 1)
    m = vtk.vtkPolyDataMapper(); m.SetInputData(pd); m.SetLookupTable(lut); m.SetScalarRange(0, 0.5); m.SetScalarModeToUseCellData()
    a = vtk.vtkActor(); a.SetMapper(m); a.GetProperty().SetOpacity(0.55)
    ren.AddActor(a)
    # the blades: two thin boxes from the hinge along the axis, turned ±θ/2 about the width direction
    for s in (1, -1):
        half = 0.5 * theta_deg * math.pi / 180
        t = [math.cos(half) * axis[i] + s * math.sin(half) * up[i] for i in range(3)]
        # the centre line and the two edges (a curved clip's bend from `start` on a circle of radius `curve`,
        # towards +side when positive: fem::ClipBlades::centre_line)
        def poly(e):
            pts = vtk.vtkPoints(); n = 40
            for k in range(n + 1):
                sl = start + (length - start) * k / n
                if curve == 0:
                    r, a, dr, da = sl, 0.0, 1.0, 0.0
                else:
                    g, R = (1.0 if curve > 0 else -1.0), abs(curve); phi = (sl - start) / R
                    r, a, dr, da = start + R * math.sin(phi), g * R * (1 - math.cos(phi)), math.cos(phi), g * math.sin(phi)
                pts.InsertNextPoint(*[hinge[i] + r * t[i] + a * side[i] + e * (-da * t[i] + dr * side[i]) for i in range(3)])
            src = vtk.vtkLineSource(); src.SetPoints(pts); return src
        line = poly(0.0)
        tube = vtk.vtkTubeFilter(); tube.SetInputConnection(line.GetOutputPort()); tube.SetRadius(0.06); tube.SetNumberOfSides(8)
        bm = vtk.vtkPolyDataMapper(); bm.SetInputConnection(tube.GetOutputPort())
        ba = vtk.vtkActor(); ba.SetMapper(bm); ba.GetProperty().SetColor(0.2, 0.2, 0.9); ren.AddActor(ba)
        for e in (0.5 * jaw_w, -0.5 * jaw_w):
            l2 = poly(e)
            m2 = vtk.vtkPolyDataMapper(); m2.SetInputConnection(l2.GetOutputPort())
            a2 = vtk.vtkActor(); a2.SetMapper(m2); a2.GetProperty().SetColor(0.2, 0.2, 0.9); a2.GetProperty().SetLineWidth(2); ren.AddActor(a2)
    sph = vtk.vtkSphereSource(); sph.SetCenter(*cx); sph.SetRadius(0.15); sm = vtk.vtkPolyDataMapper(); sm.SetInputConnection(sph.GetOutputPort())
    sa = vtk.vtkActor(); sa.SetMapper(sm); sa.GetProperty().SetColor(0.0, 0.0, 0.0); ren.AddActor(sa)
    cam = ren.GetActiveCamera(); cam.SetFocalPoint(*cx); cam.SetPosition(*[cx[i] + 30 * d[i] for i in range(3)]); cam.SetViewUp(*vu); cam.SetViewAngle(30)
    mid = start + 0.6 * (length - start)
    if vi == 0: cam.SetFocalPoint(*[hinge[i] + mid * axis[i] for i in range(3)]); cam.SetPosition(*[hinge[i] + mid * axis[i] + 30 * d[i] for i in range(3)])
    txt = vtk.vtkTextActor(); txt.SetInput("%s: widest sac-parent channel %.3f mm (black)%s" % (title, chan[0], " - along the closing" if vi == 0 else " - down the jaws"))
    txt.GetTextProperty().SetColor(0, 0, 0); txt.GetTextProperty().SetFontSize(14); ren.AddActor2D(txt)
    if vi == 1:
        bar = vtk.vtkScalarBarActor(); bar.SetLookupTable(lut); bar.SetTitle("lumen width mm"); bar.SetNumberOfLabels(6)
        bar.GetTitleTextProperty().SetColor(0, 0, 0); bar.GetLabelTextProperty().SetColor(0, 0, 0); bar.SetWidth(0.1); bar.SetHeight(0.5)
        ren.AddActor2D(bar)
    rw.AddRenderer(ren)
rw.Render()
w = vtk.vtkWindowToImageFilter(); w.SetInput(rw); w.Update()
pw = vtk.vtkPNGWriter(); pw.SetFileName(out); pw.SetInputConnection(w.GetOutputPort()); pw.Write()
