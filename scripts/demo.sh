#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The main job on the shipped sample, from a fresh Debian 12 machine: install what is missing, build,
# run every stage that exists on the sample case, and inspect the result.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
out=build/demo
mkdir -p "$out"
prep=build/tools/aneuprep
case=configs/cases/sample.toml
echo "== aneuprep version"
"$prep" version
echo "== phantom: synthetic CTA of the sample case ($case) -> $out/phantom"
"$prep" --config "$case" phantom -o "$out/phantom"
if cmp -s "$out/phantom/ct.nrrd" sample_data/phantom/ct.nrrd; then
  echo "   regenerated CT is byte-identical to the shipped sample_data/phantom/ct.nrrd"
else
  echo "   note: regenerated CT differs from the shipped sample_data/phantom/ct.nrrd (other zlib or version?)"
fi
echo "== inspect $out/phantom/truth.h5"
"$prep" inspect "$out/phantom/truth.h5"
echo "== FEM stages on a synthetic tube wall with a sac (configs/tube_wall.toml; the geometry stages that turn"
echo "   the CT into a wall surface are not built yet)"
fem=configs/tube_wall.toml
"$prep" --config "$fem" tubewall -o "$out/tube_wall.h5"
xvfb-run -a "$prep" snapshot "$out/tube_wall.h5" --color-by region -o "$out/tube_wall_regions.png"
echo "   picture of the wall, artery/aneurysm regions: $out/tube_wall_regions.png"
"$prep" --config "$fem" tetmesh "$out/tube_wall.h5" -o "$out/tube_volume.h5"
"$prep" --config "$fem" assemble "$out/tube_volume.h5" -o "$out/tube_fem.h5"
"$prep" --config "$fem" condense "$out/tube_fem.h5" -o "$out/tube_case.h5"
echo "== inspect $out/tube_case.h5 (the case bundle)"
"$prep" inspect "$out/tube_case.h5"
echo "== aneusim loads the case bundle"
build/tools/aneusim load "$out/tube_case.h5"
echo "== aneusim runs the clipping scene configs/scenes/tube_clip.json (threads, real time): log, series, report"
build/tools/aneusim run configs/scenes/tube_clip.json
echo "   assessment: $out/sim_report.json.txt; deformed surface for ParaView: $out/sim_series.xdmf"
cat "$out/sim_report.json.txt"
echo "== done: outputs under $out/"
