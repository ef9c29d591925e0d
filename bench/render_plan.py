# Renders a planned scene (aneusim plan) on the case's lumen: the closed clip's two jaws (blue, green) on the
# lumen (sac orange, vessel grey), along the closing and down the jaws (a tandem plan: both clips' jaws). System python3 with python3-vtk9 (apt-get install python3-vtk9; bench only):
#   aneuprep export CASE/surface.h5 --format vtp --surface lumen -o lumen.vtp
#   bash scripts/xvfb.sh /usr/bin/python3 bench/render_plan.py lumen.vtp SCENE.json OUT.png "TITLE"
import json, re, sys
class V(tuple):
    def __new__(c, x): return tuple.__new__(c, [float(a) for a in x])
    def __add__(a, b): return V([x + y for x, y in zip(a, b)])
    def __sub__(a, b): return V([x - y for x, y in zip(a, b)])
    def __mul__(a, s): return V([x * s for x in a])
    __rmul__ = __mul__
    def __neg__(a): return V([-x for x in a])
def cross(a, b): return V([a[1]*b[2]-a[2]*b[1], a[2]*b[0]-a[0]*b[2], a[0]*b[1]-a[1]*b[0]])
import vtk
vtp, plan, out, title = sys.argv[1:5]
t = open(plan).read()
head = " ".join(l[2:].strip() for l in t.splitlines() if l.startswith("//"))
j = json.loads(t[t.index("{"):])
nrm = V([float(x) for x in re.search(r"normal towards the sac \(([^)]*)\)", head).group(1).split(",")])
ctr = V([float(x) for x in re.search(r"neck centre \(([^)]*)\)", head).group(1).split(",")])
cm = list(j["clip_models"].values())[0]
# every clip applier's jaws (a tandem plan, aneusim plan --tandem: two), where it closes (its third keyframe)
appliers = [i for i in j["instruments"] if i["kind"] == "clip_applier"]
k = appliers[0]["keyframes"]
hinge = V(k[2]["position"]); axis = V(k[0]["axis"]); up = V(k[0]["up"])
hinges = [V(a["keyframes"][2]["position"]) for a in appliers]
side = cross(axis, up)
L, W, T = cm["jaw_length_mm"], cm["jaw_width_mm"], cm["jaw_thickness_mm"]
r = vtk.vtkXMLPolyDataReader(); r.SetFileName(vtp); r.Update()
poly = r.GetOutput()
reg = poly.GetCellData().GetArray("region")
cols = vtk.vtkUnsignedCharArray(); cols.SetNumberOfComponents(3); cols.SetName("c")
for i in range(poly.GetNumberOfCells()):
    cols.InsertNextTuple3(*((235, 150, 60) if reg.GetValue(i) == 1 else (200, 200, 200)))
poly.GetCellData().SetScalars(cols)
def blade(sgn, hinge=hinge):
    pts = vtk.vtkPoints()
    for a in (0, L):
        for b in (-W / 2, W / 2):
            for c in (0, sgn * T):
                pts.InsertNextPoint(*(hinge + a * axis + b * side + c * up))
    ug = vtk.vtkUnstructuredGrid(); ug.SetPoints(pts)
    hexa = vtk.vtkHexahedron()
    for i, v in enumerate([0, 2, 3, 1, 4, 6, 7, 5]):
        hexa.GetPointIds().SetId(i, v)
    ug.InsertNextCell(hexa.GetCellType(), hexa.GetPointIds())
    g = vtk.vtkDataSetSurfaceFilter(); g.SetInputData(ug); g.Update()
    m = vtk.vtkPolyDataMapper(); m.SetInputData(g.GetOutput())
    a = vtk.vtkActor(); a.SetMapper(m); a.GetProperty().SetColor((0.15, 0.3, 0.85) if sgn > 0 else (0.1, 0.6, 0.3))
    return a
rw = vtk.vtkRenderWindow(); rw.SetOffScreenRendering(1); rw.SetSize(1400, 700)
for vi, (dirn, vup) in enumerate([(up, nrm), (-axis, nrm)]):
    ren = vtk.vtkRenderer(); ren.SetViewport(0.5 * vi, 0, 0.5 * vi + 0.5, 1); ren.SetBackground(1, 1, 1)
    m = vtk.vtkPolyDataMapper(); m.SetInputData(poly); m.SetScalarModeToUseCellData()
    a = vtk.vtkActor(); a.SetMapper(m); a.GetProperty().SetOpacity(0.75)
    ren.AddActor(a)
    for h in hinges:
        ren.AddActor(blade(1, h)); ren.AddActor(blade(-1, h))
    cam = ren.GetActiveCamera(); focus = ctr
    cam.SetFocalPoint(*focus); cam.SetPosition(*(focus + 40 * dirn)); cam.SetViewUp(*vup); cam.SetViewAngle(30)
    txt = vtk.vtkTextActor(); txt.SetInput(title + (" - along the closing" if vi == 0 else " - down the jaws")); txt.GetTextProperty().SetColor(0, 0, 0); txt.GetTextProperty().SetFontSize(14)
    ren.AddActor2D(txt)
    rw.AddRenderer(ren)
rw.Render()
w = vtk.vtkWindowToImageFilter(); w.SetInput(rw); w.Update()
pw = vtk.vtkPNGWriter(); pw.SetFileName(out); pw.SetInputConnection(w.GetOutputPort()); pw.Write()
