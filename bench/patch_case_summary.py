# SPDX-License-Identifier: MIT
# One line (tab-separated) summing up a planned patch run made by bench/run_patch_case.sh: the plan, where the clip
# stopped, the neck (closed share of its border, the widest sac-parent channel, sealed or not, the walls' deepest
# interpenetration), the parent's narrowing, the forces against the clip model's range, and the patch frames' cost.
#   python3 bench/patch_case_summary.py RUN_DIR SECONDS SPRING_SCALE     -> the line
#   python3 bench/patch_case_summary.py RUN_DIR --render-args            -> render_channel.py's arguments after OUT.png
#                                                                        (title, pose, length, opening, blades' start, width, curve)
import json, math, os, sys

run = sys.argv[1]
scene = json.load(open(os.path.join(run, "scene.json")))
report = json.load(open(os.path.join(run, "report.json"))) if os.path.exists(os.path.join(run, "report.json")) else {}
app = next(i for i in scene["instruments"] if i["kind"] == "clip_applier")
keys = app["keyframes"]
model_name = keys[0]["load"]
model = scene["clip_models"][model_name]
# the applier's pose where it closes the clip: the first keyframe asking for the smallest opening
axis, up = keys[0]["axis"], keys[0]["up"]
closing = keys[0]
for k in keys:
    axis, up = k.get("axis", axis), k.get("up", up)
    if k.get("opening_deg", 1e9) < closing.get("opening_deg", 1e9):
        closing = dict(k, axis=axis, up=up)
clip = (report.get("clips") or [{}])[0]
case = os.path.basename(os.path.dirname(os.path.abspath(scene["bundle"])))
if sys.argv[2] == "--render-args":
    f = lambda v: ",".join("%.5f" % x for x in v)
    title = "%s: %s, %.2f deg" % (case, model_name, clip.get("opening_deg", float("nan")))
    import re
    # bench/patch_scene.py --hinge-back-mm says so in the spring's source: the blades are drawn from there
    # (a clip model's fulcrum_mm: the blades from there; session 41's first scenes made the blades longer instead)
    back = re.search(r"hinge ([0-9.]+) mm further back", model.get("spring", {}).get("source", ""))
    start = model.get("fulcrum_mm", float(back.group(1)) if back else 0.0)
    length = model["jaw_length_mm"] + model.get("fulcrum_mm", 0.0)
    print("'%s' %s %s %s %g %.4f %g %g %g" % (title, f(closing["position"]), f(closing["axis"]), f(closing["up"]), length,
                                             clip.get("opening_deg", 0.0), start, model.get("jaw_width_mm", 1.0),
                                             model.get("jaw_curve_radius_mm", 0.0)))
    sys.exit(0)
secs, scale = int(sys.argv[2]), float(sys.argv[3])
header = [l for l in open(os.path.join(run, "plan.json")) if l.startswith("//")]
short = any("stop short" in l for l in header)
sp = model["spring"]
# the clip model's closing-force range: its label force (1 mm open) to its force fully open, ±10 %
lo, hi = 0.9 * sp["label_force_n"], 1.1 * sp["open_force_n"]
p = (report.get("patches") or [{}])[0]
# the clip's force as its range is stated (ISO 9713): the tissue's moment on a blade over the label point's arm, at its
# peak; beside it the blade's whole normal force (larger where the tissue presses nearer the fulcrum) and the haptic
# peak (what the hand feels). Reports before session 49 have no label-point figure: nan.
label = p.get("peak_label_force_n", report.get("peak_clip_label_force_n", float("nan")))
blade = p.get("peak_blade_force_n", report.get("peak_vessel_force_n", float("nan")))
fields = [
    case,
    "clip=%s open=%g tips_short=%s spring_x=%g%s" % (model_name, keys[0]["opening_deg"], "yes" if short else "no", scale,
                                                    " (placeholder)" if sp.get("placeholder") else ""),
    "state=%s held_deg=%.3f grip_n=%.3f" % (clip.get("state", "?"), clip.get("opening_deg", float("nan")), clip.get("grip_force_n", float("nan"))),
    "neck_closed=%.1f%% cut_off=%s channel_mm=%s sealed=%s interpenetration_mm=%.4f on=%s edge_mm=%s" % (
        100 * report.get("neck_closed_fraction", float("nan")),
        "%.1f%%" % (100 * report["neck_cut_off_fraction"]) if report.get("neck_cut_off_fraction") is not None else "-",
        "%.3f" % report["neck_channel_mm"] if report.get("neck_channel_mm") is not None else "-",
        report.get("neck_sealed", "-"), report.get("neck_interpenetration_mm", float("nan")),
        report.get("neck_measured_on", "corner triangles").replace(" ", "_"),
        "%.3f" % report["neck_channel_edge_mm"] if report.get("neck_channel_edge_mm") is not None else "-"),
    "lumen_crossing_mm=%s" % ("%.4f (%d vertices)" % (report["lumen_crossing_mm"], report.get("lumen_crossing_vertices", 0))
                              if report.get("lumen_crossing_mm") is not None else "-"),
    "beside_tissue_mm=%s" % ("%.4f (%d vertices)" % (report["lumen_beside_tissue_mm"], report.get("lumen_beside_tissue_vertices", 0))
                             if report.get("lumen_beside_tissue_mm") is not None else "-"),
    "nodes_in_other_tissue=%s (%s mm)" % (report.get("patch_nodes_in_other_tissue", "-"), report.get("patch_tissue_overlap_mm", "-")),
    "parent_narrowed=%s parent_mm=%s" % (
        "%.1f%%" % (100 * report["parent_narrowing"]) if report.get("parent_narrowing") is not None else "-",
        "%.2f/%.2f" % (report["parent_channel_mm"], report["parent_channel_rest_mm"]) if report.get("parent_narrowing") is not None else "-"),
    "peak_clip_force_at_label_n=%.3f range_n=%.2f-%.2f within=%s peak_blade_force_n=%.3f haptic_peak_n=%.3f" % (
        label, lo, hi, "yes" if lo <= label <= hi else "no", blade, report.get("peak_force_n", float("nan"))),
    "patch_frames=%s unconverged=%s restarts=%s builds=%s mean_solve_s=%.1f walls_min_mm=%s solver=%s%s" % (
        p.get("frames", "-"), p.get("unconverged_frames", "-"), p.get("restarts", "-"), p.get("builds", "-"), p.get("mean_solve_ms", float("nan")) / 1000,
        "%.4f" % p["min_wall_distance_mm"] if p.get("min_wall_distance_mm") is not None else "-", p.get("solver", "newton"),
        " linearisations=%s (%.0f s, %s refused, %s for the linear range, %s frames kept an earlier attempt)" % (
            p["linearisations"], p.get("linearise_s", 0), p.get("linearisations_failed", 0), p.get("range_refreshes", "-"),
            p.get("range_earlier_kept", "-")) if "linearisations" in p else ""),
    "max_lag_to_thickness=%s" % ("%.2f" % p["max_lag_to_thickness"] if p.get("max_lag_to_thickness") is not None else "-"),
    "scene_t=%.3f run_s=%d" % (report.get("total_time_s", float("nan")), secs),
]
# tandem clips: the further clips at the end (opening, grip, the force at the label point); the peaks above are the patch's,
# over all its clips
for c in (report.get("clips") or [])[1:]:
    fields.append("clip%d: state=%s held_deg=%.3f grip_n=%.3f label_n=%.3f" % (
        c.get("id", -1), c.get("state", "?"), c.get("opening_deg", float("nan")), c.get("grip_force_n", float("nan")), c.get("label_force_n", float("nan"))))
print("\t".join(fields))
