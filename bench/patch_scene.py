#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""A planned scene (`aneusim plan` output, // comments allowed) made into a scene run with the nonlinear patch
(model.wall = "patch", 40 Newton iterations a frame), for bench/run_patch_case.sh and bench/run_patch_realtime.sh.

usage: patch_scene.py PLAN.json SCENE.json BUNDLE [--log L --report R] [--spring-scale S] [--slow DURATION_S]
                      [--solver newton|compliance] [--refresh-frames N] [--compliance-reuse N] [--friction-cell MM] [--duration S]
  --spring-scale S  multiplies the planned clip's two spring forces (an experiment; its source says so)
  --solver          model.patch_solver: the Newton frames [newton] or contact on the patch's compliance
  --refresh-frames  model.refresh_frames for the compliance frames [0: linearised once, where the patch starts]
  --compliance-reuse N  model.compliance_reuse: linearisations that borrow the last one's W, at most N in a row [0]
  --friction-cell   model.friction_cell_mm for the compliance frames [0: two friction rows a pressed node]
  --duration S      the scene's duration_s (1.40: the sample's planned clip held, before its release at 1.5 s)
  --shift-mm D      moves the applier's path D mm along the neck's normal (the plan's header; towards the sac
                    positive): an experiment on where the jaws' width sits on the neck line
  --jaw-width-mm W  the planned clip's jaws W mm wide (an experiment: how much of a saddle-shaped neck line
                    a wider blade keeps between its jaws as they close)
  --jaw-length-mm L  the planned clip's blades L mm long, the hinge where it was (an experiment: tips that stop
                    before the thick tissue past the neck's far fold, against the planner's shortest blade passing it)
  --hinge-back-mm H  the clip model's fulcrum H mm behind its blades' heel (fulcrum_mm; the applier's pose moved H mm
                    back to it), so that the blades, where the plan put them, close nearly parallel; the opening scaled
                    so that the gap at the blades' middle is the plan's, the spring so that its force there is the
                    plan's (an experiment: the planner does not plan for a fulcrum yet)
  --blade-friction M  model.blade_friction (the blades' Coulomb friction on the tissue; the default is 0.3): an
                    experiment on how much of the neck line the grip holds between the jaws
  --hold            the applier holds the clip closed to the scene's end (the keyframes after the one that closes it
                    dropped: no release): a real-time run whose patch is made long after the planned release
  --tandem-mm D     a second applier beside the first (tandem clips: the same clip model, the same timeline), its path
                    D mm across the blades (along axis x up; the sign picks the side: the plan's header's neck normal
                    is printed with the side it lands on); an experiment until `aneusim plan` plans tandem clips
                    (a plan made with `aneusim plan --tandem` has its second applier already; --shift-mm, --hinge-back-mm,
                    --turn-deg, --across-mm, --hold and --slow move or retime the first applier only)
  --slow D          the applier approaches as planned, then closes 60 -> 30 deg by 30 s and on towards 0 deg at
                    600 s; the scene lasts D s (a real-time run that covers the patch's build and first frames)
"""
import argparse
import json

ap = argparse.ArgumentParser()
ap.add_argument("plan")
ap.add_argument("scene")
ap.add_argument("bundle")
ap.add_argument("--log", default="scene_log.csv")
ap.add_argument("--report", default="scene_report.json")
ap.add_argument("--spring-scale", type=float, default=1.0)
ap.add_argument("--slow", type=float, default=0.0)
ap.add_argument("--solver", choices=["newton", "compliance"], default="newton")
ap.add_argument("--refresh-frames", type=int, default=0)
ap.add_argument("--compliance-reuse", type=int, default=0)
ap.add_argument("--friction-cell", type=float, default=0.0)
ap.add_argument("--duration", type=float, default=0.0)
ap.add_argument("--shift-mm", type=float, default=0.0)
ap.add_argument("--jaw-width-mm", type=float, default=0.0)
ap.add_argument("--jaw-length-mm", type=float, default=0.0)
ap.add_argument("--hinge-back-mm", type=float, default=0.0)
ap.add_argument("--blade-friction", type=float, default=-1.0)
ap.add_argument("--hold", action="store_true")
# a curved clip (the model's jaw_curve_radius_mm, from the heel), the clip turned by --turn-deg about its opening
# direction at the closing pose (the fulcrum) and moved --across-mm along its width: bench/fit_curved_blade.py's fit
ap.add_argument("--curve-radius-mm", type=float, default=0.0)
ap.add_argument("--turn-deg", type=float, default=0.0)
ap.add_argument("--across-mm", type=float, default=0.0)
ap.add_argument("--tandem-mm", type=float, default=0.0)
a = ap.parse_args()
raw = open(a.plan).read()
text = "\n".join(l for l in raw.splitlines() if not l.lstrip().startswith("//"))
s = json.loads(text)
s["bundle"] = a.bundle
s["model"] = {"wall": "patch", "newton_per_frame": 40}
if a.solver == "compliance":
    s["model"].update(patch_solver="compliance", refresh_frames=a.refresh_frames)
    if a.compliance_reuse > 0:
        s["model"]["compliance_reuse"] = a.compliance_reuse
    if a.friction_cell > 0:
        s["model"]["friction_cell_mm"] = a.friction_cell
if a.blade_friction >= 0:
    s["model"]["blade_friction"] = a.blade_friction
s["outputs"] = {"log": a.log, "report": a.report}
if a.duration > 0:
    s["duration_s"] = a.duration
if a.spring_scale != 1:
    for m in s["clip_models"].values():
        sp = m["spring"]
        sp["label_force_n"] *= a.spring_scale
        sp["open_force_n"] *= a.spring_scale
        sp["source"] = "experiment: %g x the planned clip's spring (%s)" % (a.spring_scale, sp.get("source", ""))
if a.jaw_width_mm > 0:
    for m in s["clip_models"].values():
        m["jaw_width_mm"] = a.jaw_width_mm
if a.jaw_length_mm > 0:
    for m in s["clip_models"].values():
        m["jaw_length_mm"] = a.jaw_length_mm
if a.hinge_back_mm > 0:
    import math
    H = a.hinge_back_mm
    k0 = s["instruments"][0]["keyframes"][0]
    ax = k0["axis"]
    nrm = math.sqrt(sum(v * v for v in ax))
    ax = [v / nrm for v in ax]
    for m in s["clip_models"].values():
        L = m["jaw_length_mm"]
        rm_old, rm_new = L / 2, H + L / 2  # the blade's middle from the heel and from the fulcrum
        m["fulcrum_mm"] = H  # the clip model's fulcrum behind the heel (docs/scene_format.md); the pose is the fulcrum's
        # the opening whose gap at the blade's middle is the planned opening's there
        scale_open = lambda deg: math.degrees(2 * math.asin(min(1.0, rm_old * math.sin(math.radians(deg) / 2) / rm_new)))
        sp = m["spring"]
        # F = tau / r: the label point moves from 2/3 L to H + 2/3 L from where the blades turn; the torque that gives
        # the plan's force at the blade's middle is tau_old * rm_new / rm_old, read at the new label point
        f = (rm_new / rm_old) * (2 * L / 3) / (H + 2 * L / 3)
        sp["label_force_n"] = round(sp["label_force_n"] * f, 4)
        sp["open_force_n"] = round(sp["open_force_n"] * f, 4)
        sp["source"] = "experiment: hinge %g mm further back, the forces at the planned blades' middle kept (%s)" % (H, sp.get("source", ""))
    for k in s["instruments"][0]["keyframes"]:
        if "position" in k:
            k["position"] = [round(p - H * q, 4) for p, q in zip(k["position"], ax)]
        if "opening_deg" in k:
            k["opening_deg"] = round(scale_open(k["opening_deg"]), 4)
if a.shift_mm != 0:
    import re
    m = re.search(r"normal towards the sac \(([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+)\)", raw)
    if not m:
        raise SystemExit(a.plan + ": no 'normal towards the sac (x, y, z)' in the plan's header (expected `aneusim plan` output)")
    n = [float(v) for v in m.groups()]
    for k in s["instruments"][0]["keyframes"]:
        if "position" in k:
            k["position"] = [round(p + a.shift_mm * q, 4) for p, q in zip(k["position"], n)]
if a.curve_radius_mm != 0:
    for m in s["clip_models"].values():
        m["jaw_curve_radius_mm"] = a.curve_radius_mm
if a.turn_deg != 0 or a.across_mm != 0:
    import math
    keys = s["instruments"][0]["keyframes"]
    closing = min((k for k in keys if "position" in k and "opening_deg" in k), key=lambda k: k["opening_deg"])
    c0 = closing["position"]
    up = closing.get("up", keys[0]["up"])
    dot = lambda u, v: sum(x * y for x, y in zip(u, v))
    cross = lambda u, v: [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    nu = math.sqrt(dot(up, up))
    up = [x / nu for x in up]
    c, sn = math.cos(math.radians(a.turn_deg)), math.sin(math.radians(a.turn_deg))
    # Rodrigues about up: v -> c v + s (up x v) + (1 - c)(up.v) up; a turn by +psi takes the axis towards +w (= axis x up):
    # up x axis = -w, so the turn is by -psi about up
    def turn(v):
        k = cross(up, v)
        return [c * x - sn * y + (1 - c) * dot(up, v) * z for x, y, z in zip(v, k, up)]
    axis = None
    for k in keys:
        if "axis" in k:
            k["axis"] = [round(x, 6) for x in turn(k["axis"])]
        if "up" in k:
            k["up"] = [round(x, 6) for x in turn(k["up"])]
        if "position" in k:
            k["position"] = [round(q + x, 4) for q, x in zip(c0, turn([p - q for p, q in zip(k["position"], c0)]))]
    ax = next(k["axis"] for k in keys if "axis" in k)
    w = cross(ax, up)
    nw = math.sqrt(dot(w, w))
    for k in keys:
        if "position" in k:
            k["position"] = [round(p + a.across_mm * x / nw, 4) for p, x in zip(k["position"], w)]
if a.hold:
    k = s["instruments"][0]["keyframes"]
    closing = next(i for i, x in enumerate(k) if x.get("opening_deg") == 0)
    s["instruments"][0]["keyframes"] = k[:closing + 1]
if a.slow > 0:
    k = s["instruments"][0]["keyframes"]
    at = dict(k[1])  # at the neck, open (the planned approach's end)
    mid = dict(at)
    mid.update(t=30.0, opening_deg=30.0)
    end = dict(at)
    end.update(t=600.0, opening_deg=0.0)
    s["instruments"][0]["keyframes"] = [k[0], at, mid, end]
    s["duration_s"] = a.slow
if a.tandem_mm != 0:
    import copy
    import math
    import re
    first = next(i for i in s["instruments"] if i["kind"] == "clip_applier")
    keys = first["keyframes"]
    ax = next(k["axis"] for k in keys if "axis" in k)
    up = next(k["up"] for k in keys if "up" in k)
    w = [ax[1] * up[2] - ax[2] * up[1], ax[2] * up[0] - ax[0] * up[2], ax[0] * up[1] - ax[1] * up[0]]
    nw = math.sqrt(sum(x * x for x in w))
    w = [x / nw for x in w]
    second = copy.deepcopy(first)
    second["name"] = first["name"] + " 2"
    for k in second["keyframes"]:
        if "position" in k:
            k["position"] = [round(p + a.tandem_mm * x, 4) for p, x in zip(k["position"], w)]
    s["instruments"].insert(s["instruments"].index(first) + 1, second)
    m = re.search(r"normal towards the sac \(([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+)\)", raw)
    if m:
        n = [float(v) for v in m.groups()]
        along = a.tandem_mm * sum(x * y for x, y in zip(w, n))
        print("tandem: the second clip %+.3f mm along the neck's normal (%s side)" % (along, "sac" if along > 0 else "parent"))
json.dump(s, open(a.scene, "w"), indent=1)
