#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The speed/accuracy study (issue #6), part 1: a tube with a sac of known dimensions (the demo's, configs/tube_wall.toml:
# lumen radius 1.7 mm, wall 0.3 mm, 12 mm long, sac lumen radius 2.5 mm with a 0.1 mm wall, neck radius 1.5 mm),
# built at several target edge lengths and both element orders; for each, W condensed in float32 and float64 when
# it fits, and an indenter pushing the sac's apex 0.2 mm (aneu_bench_study) measured against a reference model
# (the finest, quadratic, by the full FEM); the same for the sample phantom case (CT -> every stage); and a clip
# closing across the sac's neck, linear model vs a neo-Hookean reference (aneu_bench_closure).
# Writes bench/results/study/{study,study_phantom,closure}.jsonl, study.md and PNG plots.
#
#   bash bench/run_study.sh            # default sweep: h 0.6 0.5 0.4 0.3, reference h 0.25 quadratic (~25 min)
#   bash bench/run_study.sh --quick    # h 0.6 0.5, reference h 0.4 quadratic, closures to 0.3 (a few minutes;
#                                      # writes bench/results/study_quick/)
# (Coarser than 0.6 mm the 0.1 mm sac wall of this generator self-intersects at the neck and tetmesh refuses it.)
#
# Build first (bash scripts/build.sh). Plots need python3-matplotlib (installed here if missing and root/sudo).
set -euo pipefail
cd "$(dirname "$0")/.."
prep=build/tools/aneuprep
probe=build/bench/aneu_bench_study
closure=build/bench/aneu_bench_closure
py=python3
[ -x /usr/bin/python3 ] && py=/usr/bin/python3   # Debian's, where python3-matplotlib lives (not a pyenv's)
quick=0
[ "${1:-}" = "--quick" ] && quick=1
if [ $quick = 1 ]; then hs="0.6 0.5"; href=0.4; else hs="0.6 0.5 0.4 0.3"; href=0.25; fi
max_w_dofs=${MAX_W_DOFS:-25000}   # condense only models whose W fits comfortably in memory (float64: 2.5 GB)
out=bench/results/study
[ $quick = 1 ] && out=bench/results/study_quick   # the committed default results stay
work=build/study
mkdir -p "$out" "$work"
for t in "$prep" "$probe" "$closure"; do [ -x "$t" ] || { echo "run_study.sh: $t missing: build first (bash scripts/build.sh)" >&2; exit 2; }; done
if ! $py -c "import matplotlib" 2>/dev/null; then
  if [ "$(id -u)" -eq 0 ]; then apt-get install -y -q --no-install-recommends python3-matplotlib >/dev/null || true
  elif command -v sudo >/dev/null; then sudo apt-get install -y -q --no-install-recommends python3-matplotlib >/dev/null || true; fi
fi

geometry="--inner-radius-mm 1.7 --thickness-mm 0.3 --length-mm 12 --sac-radius-mm 2.5 --sac-thickness-mm 0.1 --neck-radius-mm 1.5"
jsonl="$out/study.jsonl"
: >"$jsonl"
point() {  # h order [reference]
  local h=$1 order=$2 ref=${3:-0}
  local d="$work/h${h}_p${order}"
  mkdir -p "$d"
  local nt nz
  nt=$($py -c "import math; print(max(8, round(2*math.pi*1.85/$h)))")
  nz=$($py -c "print(max(4, round(12/$h)))")
  echo "== h $h mm, order $order$([ "$ref" = 1 ] && echo ' (reference)')"
  "$prep" tubewall -o "$d/wall.h5" $geometry --n-theta "$nt" --n-z "$nz" --edge-mm "$h" -q
  "$prep" tetmesh "$d/wall.h5" -o "$d/vol.h5" -q
  "$prep" assemble "$d/vol.h5" -o "$d/fem.h5" --element-order "$order" -q
  local kept
  kept=$("$prep" inspect "$d/fem.h5" --json | $py -c "
import json,sys
for e in json.load(sys.stdin)['entries']:
    if e.get('path') == '/volume/node_sets/outer': print(3 * e['shape'][0])" 2>/dev/null || echo 0)
  if [ "$ref" = 1 ] || [ "${kept:-0}" -gt "$max_w_dofs" ] || [ "${kept:-0}" = 0 ]; then
    "$probe" "$d/fem.h5" $centre_arg | $py -c "import json,sys; j=json.loads(sys.stdin.read()); j.update(h=$h, reference=$ref); print(json.dumps(j))" >>"$jsonl"
    return
  fi
  for prec in float32 float64; do
    local t0 t1
    t0=$(date +%s.%N)
    "$prep" condense "$d/fem.h5" -o "$d/case_$prec.h5" --precision "$prec" --region-label all --nodes all -q
    t1=$(date +%s.%N)
    "$probe" "$d/fem.h5" --case "$d/case_$prec.h5" $centre_arg |
      $py -c "import json,sys; j=json.loads(sys.stdin.read()); j.update(h=$h, reference=0, condense_s=$t1-$t0); print(json.dumps(j))" >>"$jsonl"
    rm -f "$d/case_$prec.h5"
  done
}
centre_arg=""
point "$href" 2 1
# Every model is indented at the reference's sac apex (the same physical point).
centre_arg="--centre $($py -c "import json; print(','.join(str(x) for x in json.loads(open('$jsonl').readline())['centre']))")"
for h in $hs; do for order in 1 2; do point "$h" "$order"; done; done
# Condensed set: W on working regions of growing radius around the indenter (h 0.4 quadratic, float32) against
# all outer nodes (the point above): memory, precompute, load and update rate; the indenter's answer is the same
# as long as the region holds it (condensation is exact).
hr=0.4; [ $quick = 1 ] && hr=0.5
d="$work/h${hr}_p2"
if [ -f "$d/fem.h5" ]; then
  c=$($py -c "import json; print(','.join(str(x) for x in json.loads(open('$jsonl').readline())['centre']))")
  for R in 2.5 4 6; do
    echo "== region sphere $R mm, h $hr, order 2, float32"
    t0=$(date +%s.%N)
    "$prep" condense "$d/fem.h5" -o "$d/case_r$R.h5" --precision float32 --region-sphere "$c,$R" --nodes all -q
    t1=$(date +%s.%N)
    "$probe" "$d/fem.h5" --case "$d/case_r$R.h5" $centre_arg |
      $py -c "import json,sys; j=json.loads(sys.stdin.read()); j.update(h=$hr, reference=0, region_mm=$R, condense_s=$t1-$t0); print(json.dumps(j))" >>"$jsonl"
    rm -f "$d/case_r$R.h5"
  done
fi
# The sample phantom case (configs/cases/sample.toml: CT → segment → surface → wall → tetmesh → assemble → condense)
# at several surface edge lengths and both orders, W float32, indented at the sac's apex (truth: sac centre + (dome
# radius + sac wall) along the neck normal), against its finest quadratic model by the full FEM.
if [ $quick = 1 ]; then pes="0.6"; peref=0.45; else pes="0.6 0.45 0.35"; peref=0.3; fi
phantom_point() {  # edge order [reference]
  local e=$1 order=$2 ref=${3:-0}
  local d="$work/phantom_e${e}"
  echo "== phantom, edge $e mm, order $order$([ "$ref" = 1 ] && echo ' (reference)')"
  "$prep" run configs/cases/sample.toml --out-dir "$d" --set surface.edge-mm="$e" --set assemble.element-order="$order" \
    --stage phantom --quiet >/dev/null
  for st in segment surface wall tetmesh assemble; do
    "$prep" run configs/cases/sample.toml --out-dir "$d" --set surface.edge-mm="$e" --set assemble.element-order="$order" \
      --stage "$st" --quiet >/dev/null
  done
  local pc
  pc=$($py -c "
import json; t = json.load(open('$d/phantom/truth.json')); c = t['sac']['centre_mm']; n = t['neck']['normal']
r = t['sac']['radius_mm'] + 0.4 / 3
print(','.join(str(c[k] + r * n[k]) for k in range(3)))")
  local kept
  kept=$("$prep" inspect "$d/fem.h5" --json | $py -c "
import json,sys
for e in json.load(sys.stdin)['entries']:
    if e.get('path') == '/volume/node_sets/outer': print(3 * e['shape'][0])")
  if [ "$ref" = 1 ] || [ "${kept:-0}" -gt "$max_w_dofs" ]; then
    "$probe" "$d/fem.h5" --centre "$pc" |
      $py -c "import json,sys; j=json.loads(sys.stdin.read()); j.update(h=$e, reference=$ref, case_name='phantom'); print(json.dumps(j))" >>"$pjsonl"
  else
    local t0 t1
    t0=$(date +%s.%N)
    "$prep" condense "$d/fem.h5" -o "$d/case_f32.h5" --precision float32 --region-label all --nodes all -q
    t1=$(date +%s.%N)
    "$probe" "$d/fem.h5" --case "$d/case_f32.h5" --centre "$pc" |
      $py -c "import json,sys; j=json.loads(sys.stdin.read()); j.update(h=$e, reference=0, case_name='phantom', condense_s=$t1-$t0); print(json.dumps(j))" >>"$pjsonl"
    rm -f "$d/case_f32.h5"
  fi
}
pjsonl="$out/study_phantom.jsonl"
: >"$pjsonl"
phantom_point "$peref" 2 1
for e in $pes; do for order in 1 2; do phantom_point "$e" "$order"; done; done
# Linear vs large deformation: a clip closing across the sac's neck, linear model vs the neo-Hookean reference
# (bench/bench_closure.cpp), on the h 0.5 mm quadratic tube-with-sac. --quick stops at 30 % closure.
cjsonl="$out/closure.jsonl"
closures=""
[ $quick = 1 ] && closures="--closures 0.01,0.02,0.05,0.1,0.2,0.3"
echo "== clip closing on the sac: linear vs neo-Hookean (h 0.5, order 2)"
"$closure" "$work/h0.5_p2/fem.h5" $closures >"$cjsonl"
# The same clip across the parent artery (0.3 mm wall) beside the sac: squeezing the tube flat (full closure:
# gap = twice its wall). Shows how the linear model's range scales with the wall thickness.
cajsonl="$out/closure_artery.jsonl"
echo "== clip closing on the parent artery: linear vs neo-Hookean (h 0.5, order 2)"
"$closure" "$work/h0.5_p2/fem.h5" --label artery --centre 0,0,2 --blade-width-mm 4.4 --blade-length-mm 1 --full-gap-mm 0.6 \
  $closures >"$cajsonl"
# Stability at the extremes: the tests that assert each behaviour, run here for their figures (build/tests/).
ext="$out/extremes.txt"
: >"$ext"
echo "== stability at the extremes (the tests' figures)"
for spec in "fem:Lame.NearIncompressible*:Lame.VeryThin*" \
            "sim:*StiffnessRangeContrast*:*CrowdedContactSets*:*LongSessionOfFactorUpdates*:*TwoClipsReleased*" \
            "pipeline:Stages.AssembleNamesSliver*:Stages.NearDegenerateSurface*"; do
  exe="build/tests/aneu_${spec%%:*}_tests"
  if [ -x "$exe" ]; then
    "$exe" --gtest_filter="${spec#*:}" 2>&1 | grep -E '^\[ RUN|^\[       OK|^\[  FAILED|^[A-Za-z]' >>"$ext" || true
  else
    echo "missing $exe (build the tests)" >>"$ext"
  fi
done
$py bench/study_report.py "$jsonl" "$out" "$pjsonl" "$cjsonl,$cajsonl" "$ext"
echo "report: $out/study.md"
