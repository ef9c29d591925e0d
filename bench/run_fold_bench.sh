#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The fold of a flattened tube against the mesh (bench/bench_fold.cpp; issue #15: the channel a clipped neck keeps
# at its fold): a 1.5 mm tube with a 0.28 mm wall (the sample's neck) flattened by parallel blades to 0.9, 0.8, 0.7 and
# 0.6 × its two walls' thickness, with 1 or 2 element layers through the wall and 24 (the sample's 0.39 mm surface
# edges), 48, 72 or 96 cells round it; the walls' contact on the corner triangles (as the simulator before session
# 24) and on the quadratic surface (--p2-contact, as since). One core each; the finest take tens of minutes.
# Writes bench/results/study/fold_corner.jsonl and fold_quadratic.jsonl.
# usage: bash bench/run_fold_bench.sh [SPEC ...]   SPEC = layers:around[:q] (default: the series in patch_sim_notes.md)
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/results/study
specs=${*:-"1:24 1:48 2:24 2:48 1:72 1:96 1:24:q 1:48:q 1:72:q 1:96:q"}
for spec in $specs; do
  IFS=: read -r layers around q <<<"$spec"
  if [ "${q:-}" = q ]; then flag=--p2-contact; dst=$out/fold_quadratic.jsonl; else flag=; dst=$out/fold_corner.jsonl; fi
  OMP_THREAD_LIMIT=1 OPENBLAS_NUM_THREADS=1 build/bench/aneu_bench_fold $flag --layers "$layers" --around "$around" --along 16 \
    --gaps 0.9,0.8,0.7,0.6 >> "$dst"
done
