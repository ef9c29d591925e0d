# SPDX-License-Identifier: MIT
# The deformed lumen cut across the neck line at one of its points, seen along the line (parallel projection): whether
# the walls there touch, stand apart or cross. The OBJ is what `ANEU_LUMEN_OBJ=F aneusim run ...` writes (`# neck LOOP X
# Y Z GAP` lines); the point is the K-th neck point in the file (default: the one with the most negative gap), red; the
# line's other points green. Session 45: C0054's end crossing on its neck line is the slit's two walls crossed at its
# end fold (a figure-eight section). System python3 with python3-vtk9 (bench only):
# Or, with --at X Y Z --normal NX NY NZ, the cut through any point (session 46: C0001's walls crossed 2-6 mm past the
# tips, where no neck point is; the blades' axis as the normal).
#   bash scripts/xvfb.sh /usr/bin/python3 bench/lumen_section.py LUMEN.obj OUT.png [HALF_HEIGHT_MM (0.5)] [K]
#   bash scripts/xvfb.sh /usr/bin/python3 bench/lumen_section.py LUMEN.obj OUT.png HALF_HEIGHT_MM --at X Y Z --normal NX NY NZ
import math, sys, vtk

argv = sys.argv
at = normal = None
if '--at' in argv:
    i = argv.index('--at'); at = [float(x) for x in argv[i + 1:i + 4]]; del argv[i:i + 4]
if '--normal' in argv:
    i = argv.index('--normal'); normal = [float(x) for x in argv[i + 1:i + 4]]; del argv[i:i + 4]
if (at is None) != (normal is None): sys.exit('lumen_section: --at and --normal go together')
obj, out = argv[1], argv[2]
half = float(argv[3]) if len(argv) > 3 else 0.5
neck = []
for l in open(obj):
    if l.startswith('# neck '):
        p = l.split(); neck.append(([float(x) for x in p[3:6]], float(p[6]), int(p[2])))
if at is None:
    k = int(argv[4]) if len(argv) > 4 else min(range(len(neck)), key=lambda i: neck[i][1])
    p, g, loop = neck[k]
    same = [i for i in range(len(neck)) if neck[i][2] == loop]
    i = same.index(k)
    a, b = neck[same[(i - 1) % len(same)]][0], neck[same[(i + 1) % len(same)]][0]
    t = [b[j] - a[j] for j in range(3)]
else:
    p, t, k, g, same = at, normal, -1, float('nan'), []
tn = math.sqrt(sum(x * x for x in t)); t = [x / tn for x in t]
r = vtk.vtkOBJReader(); r.SetFileName(obj); r.Update()
plane = vtk.vtkPlane(); plane.SetOrigin(p); plane.SetNormal(t)
cut = vtk.vtkCutter(); cut.SetCutFunction(plane); cut.SetInputData(r.GetOutput()); cut.Update()
ren = vtk.vtkRenderer(); ren.SetBackground(1, 1, 1)
m = vtk.vtkPolyDataMapper(); m.SetInputData(cut.GetOutput())
ac = vtk.vtkActor(); ac.SetMapper(m); ac.GetProperty().SetColor(0, 0, 0); ac.GetProperty().SetLineWidth(2); ren.AddActor(ac)
for q, col in [(p, (1, 0, 0))] + [(neck[j][0], (0, 0.6, 0)) for j in same if j != k]:
    s = vtk.vtkSphereSource(); s.SetCenter(q); s.SetRadius(half / 80)
    sm = vtk.vtkPolyDataMapper(); sm.SetInputConnection(s.GetOutputPort())
    sa = vtk.vtkActor(); sa.SetMapper(sm); sa.GetProperty().SetColor(col); ren.AddActor(sa)
cam = ren.GetActiveCamera(); cam.SetFocalPoint(p); cam.SetPosition([p[j] + 10 * t[j] for j in range(3)])
cam.ParallelProjectionOn(); cam.SetParallelScale(half); ren.ResetCameraClippingRange()
tx = vtk.vtkTextActor(); tx.SetInput('neck point %d (red), gap %.4f mm; the lumen cut across the line; the view %.2f mm high' % (k, g, 2 * half) if at is None else
           'point (%.3f %.3f %.3f) (red); the lumen cut across (%.3f %.3f %.3f); the view %.2f mm high' % (*p, *t, 2 * half))
tx.GetTextProperty().SetColor(0, 0, 0); tx.GetTextProperty().SetFontSize(16); ren.AddActor2D(tx)
rw = vtk.vtkRenderWindow(); rw.SetOffScreenRendering(1); rw.SetSize(800, 800); rw.AddRenderer(ren); rw.Render()
w = vtk.vtkWindowToImageFilter(); w.SetInput(rw); w.Update()
wr = vtk.vtkPNGWriter(); wr.SetFileName(out); wr.SetInputConnection(w.GetOutputPort()); wr.Write()
