#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The haptic loop while a nonlinear patch is made and solved, in the threaded real-time mode (issue #15's rate
# acceptance: haptics 1 kHz, period p99 <= 2 ms, with the patch active, on 2 cores). The sample's planned scene with
# model.wall = "patch", the applier slowed so that the run's DURATION (wall clock) covers the patch's build and its
# first frames: approach as planned (0.8 s), 60 -> 30 deg by 30 s, on towards 0 deg at 600 s. Nothing else should
# run beside it. Writes OUT/N/report.json and run.log for run N and prints a table row each; RUNS=3 runs it three times.
# PATCH_ARGS are passed to bench/patch_scene.py in place of the slowed applier, e.g. PATCH_ARGS="--solver compliance
# --refresh-frames 10 --duration 90": the compliance frames on the planned scene's own timing, held to 90 s, refreshed on
# their own thread; the row then also gives the patch frames' times and the refreshes taken and dropped.
# usage: bash bench/run_patch_realtime.sh [OUT_DIR] [DURATION_S]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-/tmp/patch_realtime} dur=${2:-240}
mkdir -p "$out"
out=$(cd "$out" && pwd)
case_dir=$root/build/demo/sample
sim=$root/build/tools/aneusim
[ -f "$case_dir/case.h5" ] || { echo "run_patch_realtime: $case_dir/case.h5 missing (bash scripts/build.sh builds the sample)" >&2; exit 2; }
"$sim" plan "$case_dir/case.h5" -o "$out/plan.json" 2> "$out/plan.err"
if [ -n "${PATCH_ARGS:-}" ]; then
  # shellcheck disable=SC2086
  python3 "$root/bench/patch_scene.py" "$out/plan.json" "$out/scene.json" "$case_dir/case.h5" --log log.csv --report report.json $PATCH_ARGS
else
  python3 "$root/bench/patch_scene.py" "$out/plan.json" "$out/scene.json" "$case_dir/case.h5" --log log.csv --report report.json --slow "$dur"
fi
printf '| run | haptic rate Hz | period p50 / p99 / max ms | step p99 ms | patch frames | frame p50 / p99 / max ms | refreshes taken / dropped / refused | end wait s |\n|---|---|---|---|---|---|---|---|\n'
for run in $(seq 1 "${RUNS:-1}"); do
  mkdir -p "$out/$run"
  start=$(date +%s.%N)
  (cd "$out/$run" && ANEU_PATCH_TRACE=1 "$sim" run ../scene.json --report report.json > run.log 2>&1) || true
  secs=$(python3 -c "print($(date +%s.%N) - $start)")
  python3 - "$out/$run" "$run" "$secs" "$dur" <<'PY'
import json, sys, re
d, run, secs, dur = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
r = json.load(open(d + "/report.json"))
h = r["haptic_loop"]
log = open(d + "/run.log").read()
frames = len(re.findall(r"^patch t=\S+ theta", log, re.M))  # the frames that finished (a cancelled one too)
ms = sorted(float(m) for m in re.findall(r"^patch t=\S+ theta .* pairs ([0-9.]+) ms", log, re.M))
q = lambda p: ms[min(len(ms) - 1, int(p * len(ms)))] if ms else float("nan")
taken, dropped, refused = (len(re.findall(w, log)) for w in ("made on another thread .* taken", "made on another thread .* dropped", "refused"))
print("| %s | %.0f | %.3f / %.3f / %.2f | %.3f | %d | %.0f / %.0f / %.0f | %d / %d / %d | %.1f |" % (run, h["rate_hz"], h["period_ms"]["p50"], h["period_ms"]["p99"],
      h["period_ms"]["max"], h["step_ms"]["p99"], frames, q(0.5), q(0.99), ms[-1] if ms else float("nan"), taken, dropped, refused,
      secs - dur - r.get("load_s", 0)))
PY
done
