#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The main job on the shipped sample, from a fresh Debian 12 machine: install what is missing, build,
# build the sample case through every stage with its QA report and exports, and run the simulator.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh aneuprep aneusim   # the test command builds the rest with the same flags
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
echo "== the sample case, every stage (segment, surface, wall, tetmesh, assemble, condense): aneuprep run $case"
"$prep" run "$case" --out-dir "$out/sample"
echo "== QA report of the sample case (pictures by VTK off screen)"
bash scripts/xvfb.sh "$prep" report "$case" --out-dir "$out/sample" -q
echo "   open $out/sample/report.html in a browser (self-contained)"
echo "== export for ParaView (VTU) and CalculiX (.inp with 120 mmHg on the inner wall)"
"$prep" export "$out/sample/fem.h5" --format vtu -o "$out/sample/volume.vtu" -q
"$prep" export "$out/sample/fem.h5" --format inp --pressure-mpa 0.016 -o "$out/sample/model.inp" -q
echo "   $out/sample/volume.vtu, $out/sample/model.inp"
echo "== the simulator's demo scene runs on a bent tube with a sac of known dimensions (configs/tube_wall.toml)"
fem=configs/tube_wall.toml
"$prep" --config "$fem" tubewall -o "$out/tube_wall.h5"
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
echo "== aneusim plans a scene for the CT-derived sample case (a clip across its detected neck) and runs it;"
echo "   after the session, the residual blood flow into the sac (aneuprep flow, OpenFOAM: about a minute)"
build/tools/aneusim plan "$out/sample/case.h5" -o "$out/sample/planned_scene.json" --flow
head -3 "$out/sample/planned_scene.json"
build/tools/aneusim run "$out/sample/planned_scene.json"
cat "$out/sample/planned_scene_report.json.txt"
echo "== done: outputs under $out/"
