# SPDX-License-Identifier: MIT
# How far a held spring clip is from closing the neck line it holds between its jaws, and the torque that would take:
# from a patch run's end lumen (ANEU_LUMEN_OBJ: `# neck LOOP X Y Z GAP` lines), its scene, its report and its trace
# (ANEU_PATCH_TRACE: the spring balance's `balance t=... k K ...` lines, K = dR/dθ of R = τ − M).
#   python3 bench/closing_torque_needed.py LUMEN.obj SCENE.json REPORT.json TRACE.txt
# Per neck-line point between the jaws (|across| ≤ half their width, 0 ≤ r ≤ reach; r from where the blades turn) whose
# gap across the lumen exceeds the scene's neck gap tolerance, the jaws must close Δθ_i = (gap_i − tol) / r_i further
# (the blades' separation at r is 2 r sin(θ/2): d/dθ = r cos(θ/2) ≈ r). The largest Δθ closes them all. The tissue's
# moment grows by |dM/dθ| Δθ on the way, |dM/dθ| = K − k_spring at the held state: a LOWER bound on what closing needs,
# since the squeezed tissue stiffens. The spring there gives τ(θ − Δθ). Their ratio is the factor the spring falls
# short by (for a neo-Hookean wall the same as the factor the walls' E would have to fall by: the equilibrium is
# unchanged when forces and moduli are scaled together). Points beside the jaws (squeezed out) are counted apart: no
# torque closes them. Points with no opposite wall within reach (gap +inf: a fold's apex, or open across) are counted
# apart too.
import json, math, os, sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from neck_line_in_jaws import neck_line_in_jaws  # noqa: E402

obj, scene_path, report_path, trace_path = sys.argv[1:5]
scene = json.load(open(scene_path))
report = json.load(open(report_path))
rows, model, reach = neck_line_in_jaws(obj, scene)
if model.get("jaw_curve_radius_mm", 0.0) != 0:
    sys.exit("closing_torque_needed.py: a straight clip only (this one has jaw_curve_radius_mm)")
half = 0.5 * model["jaw_width_mm"]
tol = report.get("neck_gap_mm", 0.05)
between, beside, nowall, closed = [], [], [], 0
for r, a, _, gap in rows:
    if gap <= tol:
        closed += 1
    elif math.isinf(gap):
        nowall.append((r, a))  # no opposite wall within reach: a fold's apex, or the lumen open across
    elif 0 <= r <= reach and abs(a) <= half:
        between.append((r, gap))
    else:
        beside.append((r, a, gap))
# The spring as the simulator makes it (sim/scene.cpp): the label force at 1 mm opening at the label arm, the open
# force at the largest opening, linear in θ between.
spring = model.get("spring")
if not spring:
    sys.exit("closing_torque_needed.py: the clip has no spring")
arm = model.get("fulcrum_mm", 0.0) + 2.0 * model["jaw_length_mm"] / 3.0
th1 = 2.0 * math.asin(0.5 * (1.0 - model.get("closed_gap_mm", 0.0)) / arm)
th2 = math.radians(model["max_opening_deg"])
k_spring = (spring["open_force_n"] - spring["label_force_n"]) * arm / (th2 - th1)
tau = lambda th: spring["label_force_n"] * arm + k_spring * (th - th1)
clip = report["clips"][0]
theta = math.radians(clip["opening_deg"])
moment = clip.get("tissue_moment_nmm", float("nan"))
k_balance = float("nan")
for line in open(trace_path):
    if line.startswith("balance t="):
        f = line.split()
        k_balance = float(f[f.index("k") + 1])
slope = k_balance - k_spring  # |dM/dθ| of the tissue
n = closed + len(between) + len(beside) + len(nowall)
print("neck line: %d points, %d closed (gap <= %.3g mm), %d open between the jaws, %d open beside or past them, %d with no opposite wall "
      "(a fold's apex, or the lumen open across)" % (n, closed, tol, len(between), len(beside), len(nowall)))
print("clip held at %.3f deg; spring %.2f N mm (k %.1f N mm/rad), tissue moment %.2f N mm, balance secant %.1f N mm/rad -> tissue |dM/dtheta| %.1f N mm/rad"
      % (math.degrees(theta), tau(theta), k_spring, moment, k_balance, slope))
if between:
    dth = max((g - tol) / r for r, g in between)
    r_w, g_w = max(between, key=lambda rg: (rg[1] - tol) / rg[0])
    need = moment + slope * dth
    give = tau(theta - dth)
    print("to close the open points between the jaws: %.3f deg more (the widest, gap %.3f mm at r = %.2f mm from the fulcrum)" % (math.degrees(dth), g_w, r_w))
    print("tissue moment then >= %.1f N mm (linear in theta: a lower bound), the spring there %.1f N mm: short by a factor >= %.2f" % (need, give, need / give))
else:
    print("no open point between the jaws: what stays open was squeezed out beside them")
if nowall:
    inside = sum(1 for r, a in nowall if 0 <= r <= reach and abs(a) <= half)
    print("with no opposite wall: %d between the jaws, %d beside or past them" % (inside, len(nowall) - inside))
sideways = [abs(a) - half for r, a, g in beside if 0 <= r <= reach]
if sideways:
    print("open beside the jaws: up to %.3f mm beyond their edge" % max(sideways))
elif beside:
    print("open only past the jaws' tips or heel")
