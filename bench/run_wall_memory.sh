#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Wall stage: time and peak memory on the same real vessel at two sizes (the AneuRisk C0043 lumen as
# published, and scaled by 2: 4x the surface area, 8x the bounding box). The narrow-band field's memory
# should follow the area, not the box. Writes bench/results/real/wall_memory.md.
# usage: bash bench/run_wall_memory.sh   (build first: bash scripts/build.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
prep=build/tools/aneuprep
w=build/bench_wall_memory
rm -rf "$w" && mkdir -p "$w"
out=bench/results/real/wall_memory.md
src=sample_data/real/aneurisk_C0043_basilar_sidewall.vtp
{
  echo "# Wall stage memory against surface size ($(date -u +%F), $(nproc) cores)"
  echo
  echo "Same vessel (AneuRisk C0043, $src) at scale 1 and 2; surface stage with default options, then \`aneuprep wall\`."
  echo
  echo "| scale | lumen area (mm²) | virtual box (voxels) | band samples | distance queries | wall time (s) | wall peak RSS (MB) | a dense box grid would need (MB) |"
  echo "|---|---|---|---|---|---|---|---|"
} > "$out"
for s in 1 2; do
  "$prep" surface "$src" -o "$w/surf$s.h5" --input-scale "$s" -q
  /usr/bin/time -f "%M %e" -o "$w/time$s" "$prep" wall "$w/surf$s.h5" -o "$w/wall$s.h5" -q
  read -r kb secs < "$w/time$s"
  "$prep" inspect --json "$w/wall$s.h5" > "$w/wall$s.json"
  python3 - "$w/wall$s.json" "$s" "$kb" "$secs" >> "$out" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
st = {r["stage"]: r for r in d["provenance"]}
q, sq = st["wall"]["qa"], st["surface"]["qa"]
area = sq["area_artery_mm2"] + sq["area_aneurysm_mm2"]
print("| %s | %.0f | %.3g | %.3g | %.3g | %s | %.0f | %.0f |" % (sys.argv[2], area, q["grid_voxels"], q["band_samples"], q["distance_queries"],
      sys.argv[4], int(sys.argv[3]) / 1024, q["grid_voxels"] * 6 / 1e6))
PY
done
echo >> "$out"
echo "The dense grid column is a float field and two byte masks per voxel of the box at the same spacing, which the previous wall stage allocated before any surface work (at a third of this spacing: 27 times more)." >> "$out"
cat "$out"
