#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The residual blood flow after clipping (issue #17) on the sample case: the case built by `aneuprep run`, a scene
# planned by `aneusim plan` (a clip closing across the detected neck) and the same scene with the clip stopped half
# way along the neck (its hinge moved back until the closed jaws' tips stand at the neck's centre), each run deterministically; `aneuprep flow
# --series` on each session's last frame (pre-clip baseline and frame solved by the same reachable-domain method).
# Figures to bench/results/flow/clip.md, pictures (blood domain, wall shear stress) to bench/results/flow/pictures/.
# usage: bash bench/run_flow_clip_bench.sh   (build first: bash scripts/build.sh; about 5 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
P=$PWD/build/tools/aneuprep
S=$PWD/build/tools/aneusim
w=$PWD/build/flow_clip_bench
mkdir -p "$w"
[ -f "$w/case/case.h5" ] || "$P" run configs/cases/sample.toml --out-dir "$w/case" --quiet
"$S" plan "$w/case/case.h5" -o "$w/case/closing.json"
# The half clip: the same scene with the hinge moved back along the approach axis by half the neck's length.
python3 - "$w/case/closing.json" "$w/case/half.json" <<'PY'
import json, re, sys
src, dst = sys.argv[1], sys.argv[2]
text = open(src).read()
body = "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))
s = json.loads(body)
centre = [float(x) for x in re.search(r"neck centre \(([-0-9.]+), ([-0-9.]+), ([-0-9.]+)\)", text).groups()]
ap = next(i for i in s["instruments"] if i["kind"] == "clip_applier")
axis = ap["keyframes"][0]["axis"]
jaw = s["clip_models"][ap["keyframes"][0]["load"]]["jaw_length_mm"]
hinge = next(k for k in ap["keyframes"] if k.get("release"))["position"]  # where the clip is let go
# Back along the approach until the closed jaws' tips stand at the neck's centre: they cover half the neck's length.
shift = sum((h + jaw * a - c) * a for h, a, c in zip(hinge, axis, centre))
for k in ap["keyframes"][1:]:
    if "position" in k:  # the approach, the closing and the retreat alike
        k["position"] = [p - shift * a for p, a in zip(k["position"], axis)]
s["outputs"] = {k: v.replace("closing", "half") for k, v in s["outputs"].items()}
open(dst, "w").write("// bench/run_flow_clip_bench.sh: closing.json with the hinge %.2f mm further back: the %.0f mm jaws' tips at the neck's centre\n" % (shift, jaw) + json.dumps(s, indent=2) + "\n")
PY
for scene in closing half; do
  "$S" run "$w/case/$scene.json" --deterministic > "$w/$scene.sim.txt"
  /usr/bin/time -f "%e s %M KB" -o "$w/$scene.time" "$P" -q flow "$w/case/case.h5" --series "$w/case/${scene}_series.h5" -o "$w/$scene.flow.h5"
  "$P" inspect --json "$w/$scene.flow.h5" > "$w/$scene.flow.json"
done
mkdir -p bench/results/flow/pictures
for scene in closing half; do
  bash scripts/xvfb.sh "$P" snapshot "$w/$scene.flow.h5" --surface blood --color-by wall_shear_stress_pa -o "bench/results/flow/pictures/sample_${scene}_clip_wss.png" -q || true
  bash scripts/xvfb.sh "$P" snapshot "$w/$scene.flow.h5" --surface lumen_deformed -o "bench/results/flow/pictures/sample_${scene}_clip_lumen.png" -q || true
  bash scripts/xvfb.sh "$P" snapshot "$w/$scene.flow.h5" --streamlines -o "bench/results/flow/pictures/sample_${scene}_clip_streamlines.png" -q || true
done
bash scripts/xvfb.sh "$P" snapshot "$w/closing.flow.h5" --surface blood_pre_clip --color-by wall_shear_stress_pa -o "bench/results/flow/pictures/sample_pre_clip_wss.png" -q || true
python3 - "$w" <<'PY'
import json, sys
w = sys.argv[1]
def qa(name):
    return json.load(open("%s/%s.flow.json" % (w, name)))["provenance"][-1]["qa"]
def sim(name):
    return json.load(open("%s/case/%s_report.json" % (w, name)))
out = ["# Residual blood flow after clipping, sample case (bash bench/run_flow_clip_bench.sh, 2 cores)\n",
       "Scenes: `aneusim plan` (a clip closing across the detected neck) and the same with the hinge moved back until the jaws' tips stand at the neck's centre;",
       "each run `--deterministic`; `aneuprep flow CASE --series SCENE_series.h5` on the last frame. Inflow 30 cm/s, outlets p = 0, Newtonian blood;",
       "pre-clip and frame by the same reachable-domain method (grid of half a cell).\n",
       "| scene | neck closed (simulator) | neck between closed jaws (simulator) | largest push / wall | pre-clip sac inflow (mL/s) | residual sac inflow (mL/s) | residual / pre-clip (%) | sac volume reached (mm³; pre-clip) | ends closed off | cells (pre / frame) | wall time (s) | peak MB |",
       "|---|---|---|---|---|---|---|---|---|---|---|---|"]
for name in ("closing", "half"):
    q, s = qa(name), sim(name)
    t = open("%s/%s.time" % (w, name)).read().split()
    out.append("| %s | %.0f %% | %.0f %% | %.1f x | %.4f | %.4f | %.1f | %.1f (%.1f) | %d | %d / %d | %s | %.0f |" % (
        name, 100 * s["neck_closed_fraction"], 100 * s["neck_between_jaws_fraction"], s["max_displacement_to_thickness"], q["pre_clip_sac_inflow_ml_s"], q["sac_inflow_ml_s"],
        100 * q["residual_sac_inflow_ratio"], q["sac_volume_mm3"], q.get("pre_clip_sac_volume_mm3", float("nan")), q.get("ends_closed_off", 0),
        q["pre_clip_cells"], q["cells"], t[0], float(t[2]) / 1024))
out.append("\nPictures: pictures/sample_{closing,half}_clip_{wss,lumen,streamlines}.png, pictures/sample_pre_clip_wss.png.")
open("bench/results/flow/clip.md", "w").write("\n".join(out) + "\n")
print("\n".join(out))
PY
