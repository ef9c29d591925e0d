#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Simulator speed (issue #5) on the demo case bundle (float32 W): load time and, per contact-set size, the
# deformation update rate with the W_CC factor reused / recomputed, on the rows a physics frame updates
# (within the update margin, 1.2 mm, of the contact) and on the whole working region, and its time split.
# Writes bench/results/sim.jsonl and bench/results/sim.md. Usage: bash bench/run_sim_bench.sh [BUNDLE]
# (make the bundle first: bash scripts/demo.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
bundle=${1:-build/demo/tube_case.h5}
out=bench/results
mkdir -p "$out"
{
  build/bench/aneu_bench_sim "$bundle" --reps 100
  build/bench/aneu_bench_sim "$bundle" --region 2,0,6,5 --reps 100
} >"$out/sim.jsonl"
python3 - "$out/sim.jsonl" >"$out/sim.md" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("# Simulator update rate\n")
for r in rows:
    if "bundle" in r:
        print(f"\n## {r['bundle']}: W {r['W_rows']} rows, {r['W_columns_loaded']} columns loaded ({r['precision']}), "
              f"{r['surface_vertices']} surface vertices, load {r['load_s']:.2f} s\n")
        print("| contact nodes | rows near contact | update, same set [Hz] | update, set changed by a node [Hz] | SMVM near [ms] | solve [ms] | factor update [ms] | factor from scratch [ms] | update, same set, whole region [Hz] | SMVM whole region [ms] | SMVM rest of surface [ms] |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        continue
    print(f"| {r['contact_nodes']} | {r['near_rows']} | {r['near_update_hz']:.0f} | {r['changed_update_hz']:.0f} | {r['near_smvm_ms']:.2f} | "
          f"{r['reuse_solve_ms']:.3f} | {r['factor_update_ms']:.2f} | {r['full_factor_ms']:.2f} | {r['reuse_update_hz']:.0f} | "
          f"{r['reuse_smvm_region_ms']:.2f} | {r['smvm_rest_of_surface_ms']:.2f} |")
PY
cat "$out/sim.md"
