#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The real-data corpus (configs/real/*.toml) through `aneuprep run`, case by case: time per stage, peak memory,
# the standards (tests/cli/test_real_corpus.sh), and two pictures per case (the lumen coloured by the automatic
# artery/aneurysm label, the wall by region). Writes bench/results/real/corpus.md and pictures/.
# usage: bash bench/run_real_corpus.sh   (build first: bash scripts/build.sh; pictures need Xvfb)
set -uo pipefail
shopt -s nullglob
cd "$(dirname "$0")/.."
prep=$PWD/build/tools/aneuprep
w=$PWD/build/bench_real
res=bench/results/real
mkdir -p "$w" "$res/pictures"
tsv=$w/results.tsv
rm -f "$tsv"
md=$res/corpus.md
{
  echo "# Real-data corpus: every case from its source file to a case bundle ($(date -u +%F), $(nproc) cores)"
  echo
  echo "\`aneuprep run configs/real/<case>.toml\` with the corpus settings and no per-case tuning; sources and licences in"
  echo "sample_data/real/README.md. Standards: sac labelled (AneuRisk cases), wall closed, manifold and free of"
  echo "self-intersections, thickness medians within 10 % of 0.4 / 0.133 mm, min dihedral angle >= 5°."
  echo
  echo "| case | result | sac (mm²) | sac against the true neck | thickness artery / sac (mm) | min dihedral (°) | end planes moved | remesher fallback (surface/wall) | time per stage (s) | total (s) | peak memory (MB) |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
} > "$md"
for cfg in configs/real/*.toml configs/real/pending/*.toml; do
  id=$(basename "$cfg" .toml)
  start=$(date +%s.%N)
  /usr/bin/time -f "%M" -o "$w/$id.mem" bash tests/cli/test_real_corpus.sh "$prep" "$cfg" "$w" "$tsv" > "$w/$id.log" 2>&1
  rc=$?
  total=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  mem=$(( $(tail -1 "$w/$id.mem" | tr -cd '0-9') / 1024 ))
  line=$(grep "^$id" "$tsv" | tail -1)
  if [ -z "$line" ]; then
    echo "| $id | FAILED: $(grep -m1 -E 'aneuprep [a-z]+: error:|^FAIL' "$w/$id.log" | cut -c1-200 | tr '|' '/') | | | | | | | | $total | $mem |" >> "$md"
    continue
  fi
  neck=$(grep -m1 -oE "sac (NOT )?found: .*" "$w/$id.log" | sed 's/: labelled [0-9.]* mm², /: /' || true)
  python3 - "$line" "$rc" "$total" "$mem" "${neck:--}" >> "$md" <<'PY'
import sys
f = sys.argv[1].split("\t")
kv = dict(x.split("=", 1) for x in f[1:7])
times = f[7] if len(f) > 7 else ""
fail = f[8] if len(f) > 8 else ""
print("| %s | %s | %s | %s | %s / %s | %s | %s | %s | %s | %.0f | %s |" % (f[0], "ok" if sys.argv[2] == "0" else (fail or "FAIL").replace("|", "/"), kv["sac_mm2"],
      sys.argv[5], kv["thick_artery"], kv["thick_sac"], kv["min_dihedral"], kv["ends_moved"], kv["fallback"], times.replace("=", " "), float(sys.argv[3]), sys.argv[4]))
PY
  d=$w/real/$id
  if command -v Xvfb >/dev/null; then
    bash scripts/xvfb.sh "$prep" snapshot "$d/surface.h5" --surface lumen -o "$res/pictures/${id}_lumen.png" -q || true
    bash scripts/xvfb.sh "$prep" snapshot "$d/wall.h5" --color-by region -o "$res/pictures/${id}_wall.png" -q || true
  fi
done
echo >> "$md"
echo "Pictures: pictures/<case>_lumen.png (automatic label: artery red, aneurysm yellow) and pictures/<case>_wall.png (wall by region)." >> "$md"
cat "$md"
