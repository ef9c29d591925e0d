# SPDX-License-Identifier: MIT
# Which curved blade holds a neck line best: the line at rest in a planned clip's jaw frame (bench/neck_line_in_jaws.py's
# table: r along the jaws from where they turn, across their width), against blades that curve from the heel
# (fulcrum_mm from the pose) on a circle of radius R (fem::ClipBlades::face_coords: the offset across the centre
# line), the clip turned by psi about its opening direction and moved delta across: per R, the turn that leaves
# the line the narrowest band across the blade (its spread), and the delta that centres it.
#   python3 bench/fit_curved_blade.py NECK_LINE.tsv FULCRUM_MM BLADE_MM [R ...]
import math, sys

rows = [l.split("\t") for l in open(sys.argv[1]) if l[0].isdigit() or l[0] == "-"]
pts = [(float(r[0]), float(r[1])) for r in rows]
r0, blade = float(sys.argv[2]), float(sys.argv[3])
radii = [float(x) for x in sys.argv[4:]] or [0, 30, 20, 15, 12, 10, 8, 7]


def across(R, r, a):
    """fem::ClipBlades::face_coords: (s, offset across the centre line) of a blade curved at R (signed) from r0."""
    if R == 0 or r <= r0:
        return r, a
    g, Rm = (1.0 if R > 0 else -1.0), abs(R)
    dr, da = r - r0, Rm - g * a
    return r0 + Rm * math.atan2(dr, da), g * (Rm - math.hypot(dr, da))


width = 1.0  # the planner's blade width (sim/plan.cpp JAW_W): the share of the line within it, centred
print("R_mm\tturn_deg\tspread_mm\tshift_mm\ts_min_mm\ts_max_mm\tin_1mm")
for R in radii:
    if R != 0 and (r0 + blade - r0) / abs(R) > 0.5 * math.pi + 1e-12:
        continue
    best = None
    for sign in ([1, -1] if R else [1]):
        for k in range(-300, 301):
            psi = math.radians(0.1 * k)
            c, s = math.cos(psi), math.sin(psi)
            # the clip moved delta across (before its blades bend: the curve moves with the clip), delta found by
            # centring the band a few times over
            delta = 0.0
            for _ in range(6):
                q = [across(sign * R, r * c + a * s, -r * s + a * c - delta) for r, a in pts]
                lo, hi = min(x[1] for x in q), max(x[1] for x in q)
                delta += 0.5 * (hi + lo)
            q = [across(sign * R, r * c + a * s, -r * s + a * c - delta) for r, a in pts]
            lo, hi = min(x[1] for x in q), max(x[1] for x in q)
            mid = 0.5 * (hi + lo)
            inside = sum(1 for x in q if abs(x[1] - mid) <= 0.5 * width and r0 <= x[0] <= r0 + blade) / len(q)
            cand = (hi - lo, 0.1 * k, delta, min(x[0] for x in q), max(x[0] for x in q), sign * R, inside)
            if best is None or cand[0] < best[0]:
                best = cand
    print("%g\t%.1f\t%.3f\t%+.3f\t%.2f\t%.2f\t%.0f%%" % (best[5], best[1], best[0], best[2], best[3], best[4], 100 * best[6]))
