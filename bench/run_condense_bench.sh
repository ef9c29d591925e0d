#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Condensation benchmark (FEM issue): both routes, double and float32 storage, 1 and 2 threads, on the
# 11,128-node / 33,072-tet tube wall with 16,380 kept DOFs; then the whole `aneuprep condense` command on
# the TetGen mesh of the same wall, bundle written. Writes bench/results/condense.md (and .jsonl).
# Usage: bash bench/run_condense_bench.sh [--quick]   (build first: bash scripts/build.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
B=build/bench/aneu_bench_condense
P=build/tools/aneuprep
out=bench/results
mkdir -p "$out"
jsonl=$out/condense.jsonl
: >"$jsonl"
configs=("sparse float64 1" "sparse float64 2" "sparse float32 1" "sparse float32 2" "dense float64 2" "dense float64 1")
[ "${1:-}" = "--quick" ] && configs=("sparse float64 2" "sparse float32 2")
for c in "${configs[@]}"; do
  set -- $c
  echo "bench: $1 $2, $3 thread(s)" >&2
  "$B" --method "$1" --precision "$2" --threads "$3" >>"$jsonl"
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$P" tubewall -o "$tmp/wall.h5" --inner-radius-mm 1.7 --thickness-mm 0.3 --length-mm 25.6 --n-theta 52 --n-z 106 -q
"$P" tetmesh "$tmp/wall.h5" -o "$tmp/vol.h5" -q
"$P" assemble "$tmp/vol.h5" -o "$tmp/fem.h5" -q
cmd_rows=""
for pr in float64 float32; do
  /usr/bin/time -f "%e %M" -o "$tmp/t" "$P" condense "$tmp/fem.h5" -o "$tmp/case.h5" --precision "$pr" -q
  read -r secs kb <"$tmp/t"
  size=$(stat -c %s "$tmp/case.h5")
  load=$(build/tools/aneusim "$tmp/case.h5" -q | awk '/load_seconds/ {print $2}')
  cmd_rows+="| $pr | $secs | $(awk "BEGIN{printf \"%.2f\", $kb/1048576}") | $(awk "BEGIN{printf \"%.0f\", $size/1048576}") | $load |"$'\n'
done
python3 - "$jsonl" "$cmd_rows" >"$out/condense.md" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
r0 = rows[0]
print("# Condensation benchmark\n")
print(f"Mesh: tube wall, {r0['nodes']} nodes, {r0['tets']} linear tets, nnz(K) = {r0['nnz_K']}; "
      f"{int(r0['n_kept_dofs'])} kept outer DOFs of {int(r0['n_free_dofs'])} free. BLAS kernels: {r0['blas_kernels']}.\n")
print("From the assembled K to W in memory (`bench/run_condense_bench.sh`, one process per row):\n")
print("| route | W storage | threads | factor [s] | W [s] | total [s] | W flops | GFLOP/s | dgemm peak [GFLOP/s] | fraction of peak | peak RSS [GB] | predicted [GB] | residual |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for r in rows:
    print(f"| {r['method']} | {r['precision']} | {r['threads']} | {r['factor_s']:.2f} | {r['w_s']:.2f} | {r['total_s']:.2f} | "
          f"{r['w_flops']/1e12:.3f} T | {r['w_gflops_per_s']:.0f} | {r['dgemm_peak_gflops']:.0f} | "
          f"{r['w_gflops_per_s']/r['dgemm_peak_gflops']:.0%} | {r['peak_rss_bytes']/1e9:.2f} | {r['predicted_peak_bytes']/1e9:.2f} | {r['residual_max_rel']:.1e} |")
print("\nfloat32 rows: the factor and Y are double, the YᵀY accumulation is SSYRK/SGEMM, whose peak is about twice "
      "dgemm's, so the fraction is against the wrong peak there (above 100 %). Residual: max relative 2-norm error of "
      "sample columns of W against independent CHOLMOD solves of K x = e_j.")
print("\nWhole `aneuprep condense` command on the TetGen mesh of the same wall (11,128 nodes, 33,072 tets), "
      "reading the assembled bundle and writing the case bundle; then `aneusim` loading all of W:\n")
print("| W storage | command wall time [s] | max RSS [GB] | bundle [MiB] | aneusim load, all columns [s] |")
print("|---|---|---|---|---|")
print(sys.argv[2], end="")
PY
cat "$out/condense.md"
