# SPDX-License-Identifier: MIT
# Where a run's deformed neck line lies in its clip's jaw frame: per neck-line point (as ANEU_LUMEN_OBJ writes them,
# `# neck LOOP X Y Z GAP`), r from the hinge along the jaws, across their width (along axis x up; the jaws span
# +-width/2; a curved clip's along and across its centre line), up (the opening direction) and the gap across the
# lumen there, sorted by r. Shows whether an open part
# of the neck line lies between the jaws (the clip held open) or beside them (squeezed out sideways).
#   python3 bench/neck_line_in_jaws.py LUMEN.obj SCENE.json > neck_line.tsv
#   (or, from another script: `from neck_line_in_jaws import neck_line_in_jaws`)
import json, math, sys


def neck_line_in_jaws(obj, scene, applier=0, keep_order=False):
    """The neck line's points of LUMEN.obj `obj` in the jaws' frame of `scene` (a parsed scene): (rows, model, reach),
    rows (r, across, up, gap) sorted by r, `model` the scene's clip model, `reach` fulcrum_mm + jaw_length_mm.
    `applier`: which of the scene's clip appliers (tandem clips: 0 the first, 1 the second)."""
    app = [i for i in scene["instruments"] if i["kind"] == "clip_applier"][applier]
    keys = app["keyframes"]
    axis, up = keys[0]["axis"], keys[0]["up"]
    closing = keys[0]
    for k in keys:  # the pose where the applier asks for the smallest opening
        axis, up = k.get("axis", axis), k.get("up", up)
        if k.get("opening_deg", 1e9) < closing.get("opening_deg", 1e9):
            closing = dict(k, axis=axis, up=up)
    model = scene["clip_models"][keys[0]["load"]]
    dot = lambda a, b: sum(x * y for x, y in zip(a, b))
    unit = lambda a: [x / math.sqrt(dot(a, a)) for x in a]
    ax, upv = unit(closing["axis"]), unit(closing["up"])
    w = unit([ax[1] * upv[2] - ax[2] * upv[1], ax[2] * upv[0] - ax[0] * upv[2], ax[0] * upv[1] - ax[1] * upv[0]])
    hinge = closing["position"]
    rows = []
    for line in open(obj):
        if line.startswith("# neck "):
            p = line.split()
            d = [float(p[3 + i]) - hinge[i] for i in range(3)]
            rows.append((dot(d, ax), dot(d, w), dot(d, upv), float(p[6])))
    # r from where the blades turn: with a fulcrum (fulcrum_mm) the arms behind the heel close as blade, as the
    # simulator and its assessment take them (docs/scene_format.md)
    reach = model.get("fulcrum_mm", 0.0) + model["jaw_length_mm"]
    # A curved clip (jaw_curve_radius_mm, from the heel): r along its centre line and across it, as
    # fem::ClipBlades::face_coords measures them.
    R, r0 = model.get("jaw_curve_radius_mm", 0.0), model.get("fulcrum_mm", 0.0)
    if R != 0:
        g, Rm = (1.0 if R > 0 else -1.0), abs(R)
        bent = lambda r, a: (r, a) if r <= r0 else (r0 + Rm * math.atan2(r - r0, Rm - g * a), g * (Rm - math.hypot(r - r0, Rm - g * a)))
        rows = [bent(r, a) + (u, gp) for r, a, u, gp in rows]
    if not keep_order:  # (keep_order: in the OBJ's order, to match the same point in another applier's frame)
        rows.sort()
    return rows, model, reach


if __name__ == "__main__":
    # Tandem clips (several clip appliers): the rows in the first's frame; a point between the first clip's jaws is
    # "in the jaws", one between a further clip's "in clip K's jaws" (K from 2), else beside or past them.
    sc = json.load(open(sys.argv[2]))
    n_app = sum(1 for i in sc["instruments"] if i["kind"] == "clip_applier")
    rows, model, reach = neck_line_in_jaws(sys.argv[1], sc, 0, keep_order=True)
    more = [neck_line_in_jaws(sys.argv[1], sc, k, keep_order=True) for k in range(1, n_app)]
    half = 0.5 * model["jaw_width_mm"]
    # the faces begin at the heel (fulcrum_mm out) unless the model's arms clamp too (arms_press)
    heel = 0.0 if model.get("arms_press", False) else model.get("fulcrum_mm", 0.0)
    print("r_mm\tacross_mm\tup_mm\tgap_mm\twhere")
    out = []
    for i, (r, a, u, g) in enumerate(rows):
        where = "past the jaws" if r < heel or r > reach else ("in the jaws" if abs(a) <= half else "beside the jaws")
        if where != "in the jaws":
            for k, (rk, mk, reach_k) in enumerate(more):
                rr, aa = rk[i][0], rk[i][1]
                heel_k = 0.0 if mk.get("arms_press", False) else mk.get("fulcrum_mm", 0.0)
                if heel_k <= rr <= reach_k and abs(aa) <= 0.5 * mk["jaw_width_mm"]:
                    where = "in clip %d's jaws" % (k + 2)
                    break
        out.append((r, a, u, g, where))
    for r, a, u, g, where in sorted(out):
        print("%.3f\t%+.3f\t%+.3f\t%s\t%s" % (r, a, u, "inf" if math.isinf(g) else "%.4f" % g, where))
