#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# One case's planned clip closed with the nonlinear patch (issue #15's neck acceptance on the sample and the real
# corpus): the case bundle (built from a case config when given one), `aneusim plan`, the plan run with
# model.wall = "patch" (40 Newton iterations a frame, --deterministic, one core), the deformed lumen's widths and
# the sac-parent channel (ANEU_LUMEN_OBJ), a picture, and one summary line appended to OUT/../patch_cases.tsv.
# About an hour a case on one core (a patch frame is ~10-30 s).
# usage: bash bench/run_patch_case.sh CASE.toml|CASE_DIR OUT_DIR [SPRING_SCALE]
#   CASE.toml: built with `aneuprep run` into OUT_DIR; CASE_DIR: a directory holding case.h5 and fem.h5.
#   SPRING_SCALE: multiplies the planned clip's two spring forces (an experiment; the line says so) [1].
#   SOLVER=compliance [REFRESH=N] in the environment: the patch's frames on the compliance solver (model.patch_solver,
#   refresh_frames; minutes a case instead of an hour); REUSE=N: model.compliance_reuse (refreshes borrowing the last
#   W, 2-3x faster on the real cases, compliance.md session 56).
# Build first (bash scripts/build.sh); the picture needs Xvfb and the system python3 with python3-vtk9.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
src=$1 out=$2 scale=${3:-1}
mkdir -p "$out"
out=$(cd "$out" && pwd)
prep=$root/build/tools/aneuprep sim=$root/build/tools/aneusim
if [ -f "$src" ]; then
  [ -f "$out/case.h5" ] || (cd "$root" && OMP_THREAD_LIMIT=1 OPENBLAS_NUM_THREADS=1 "$prep" run "$src" --out-dir "$out" -q)
  case_dir=$out
else
  case_dir=$(cd "$src" && pwd)
fi
"$sim" plan "$case_dir/case.h5" -o "$out/plan.json" 2> "$out/plan.err"
python3 "$root/bench/patch_scene.py" "$out/plan.json" "$out/scene.json" "$case_dir/case.h5" --spring-scale "$scale" \
  --solver "${SOLVER:-newton}" --refresh-frames "${REFRESH:-0}" --compliance-reuse "${REUSE:-0}"
cp "$sim" "$out/aneusim"  # the run keeps its own binary: a rebuild during the hour does not change it
start=$(date +%s)
(cd "$out" && OMP_THREAD_LIMIT=1 OPENBLAS_NUM_THREADS=1 ANEU_PATCH_TRACE=1 ANEU_LUMEN_OBJ=lumen_end.obj \
  ./aneusim --log-file trace.log run --deterministic scene.json --report report.json > run.log 2>&1) || true
secs=$(( $(date +%s) - start ))
python3 "$root/bench/patch_case_summary.py" "$out" "$secs" "$scale" | tee -a "$out/../patch_cases.tsv"
if command -v Xvfb > /dev/null && [ -f "$out/lumen_end.obj" ]; then
  args=$(python3 "$root/bench/patch_case_summary.py" "$out" --render-args)
  eval "bash $root/scripts/xvfb.sh /usr/bin/python3 $root/bench/render_channel.py $out/lumen_end.obj $out/channel.png $args" || true
fi
