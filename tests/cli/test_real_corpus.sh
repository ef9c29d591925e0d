#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_real_corpus.sh PREP CASE_CONFIG WORKDIR [RESULTS_TSV]
# One case of the real-data corpus (configs/real/*.toml, data in sample_data/real/) through `aneuprep run` with
# the corpus settings and no per-case tuning, then its standards, read from the stages' QA in the bundle:
#   - every stage ran (exit 0) and the bundle exists;
#   - surface: an aneurysm sac was labelled (area > 0) when the source is an aneurysm model (AneuRisk), and where the
#     case has its AneuRisk neck polygon (sample_data/real/necks/), the label is at that neck (real_sac_check.py);
#   - wall: closed, manifold, free of self-intersections (the stage checks these and stops otherwise; the
#     QA's self_intersections must be 0), thickness medians within ±10 % of the targets per region;
#   - tetmesh: no dihedral angle below 5°;
# and prints the time per stage. The bundle (hundreds of MB) is removed afterwards; the QA line is appended
# to RESULTS_TSV when given.
set -u
prep=$1 config=$2 work=$3 results=${4:-}
root=$(cd "$(dirname "$0")/../.." && pwd)
id=$(basename "$config" .toml)
out=$work/real/$id
rm -rf "$out"
cd "$root"
if ! "$prep" run "$config" --out-dir "$out" -q; then
  echo "FAIL $id: aneuprep run failed"
  exit 1
fi
"$prep" inspect --json "$out/case.h5" > "$out/case.json" || { echo "FAIL $id: inspect"; exit 1; }
python3 - "$out/case.json" "$id" "$results" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
cid, results = sys.argv[2], sys.argv[3]
stages = {}
for rec in d["provenance"]:
    stages[rec.get("stage", rec.get("name", "?"))] = rec
def qa(stage, key):
    return stages[stage]["qa"].get(key)
fails = []
def need(cond, what):
    if not cond:
        fails.append(what)
aneurysm_model = cid.startswith("C0")
if aneurysm_model:
    need(qa("surface", "area_aneurysm_mm2") > 0, "no sac labelled")
need(qa("wall", "self_intersections") == 0, "wall self-intersections")
ta, ts = qa("wall", "thickness_artery_target_mm"), qa("wall", "thickness_aneurysm_target_mm")
ma, ms = qa("wall", "thickness_artery_median_mm"), qa("wall", "thickness_aneurysm_median_mm")
need(abs(ma - ta) <= 0.1 * ta, "artery thickness median %.4f vs %.4f" % (ma, ta))
if ms is not None:
    need(abs(ms - ts) <= 0.1 * ts, "sac thickness median %.4f vs %.4f" % (ms, ts))
quality = next(e.get("attributes", {}) for e in d["entries"] if e["path"] == "/volume/quality")
dmin = float(quality["min_dihedral_deg"])
need(dmin >= 5.0, "min dihedral %.2f deg < 5" % dmin)
times = {s: stages[s].get("wall_time_s", float("nan")) for s in stages}
line = "%s\tsac_mm2=%.1f\tthick_artery=%.4f\tthick_sac=%s\tmin_dihedral=%.2f\tends_moved=%d\tfallback=%d/%d\t%s" % (
    cid, qa("surface", "area_aneurysm_mm2"), ma, "-" if ms is None else "%.4f" % ms, dmin,
    qa("surface", "end_planes_moved") or 0, qa("surface", "remesher_fallback") or 0, qa("wall", "remesher_fallback") or 0,
    " ".join("%s=%.1fs" % (s, t) for s, t in times.items() if isinstance(t, (int, float))))
print(line)
if results:
    open(results, "a").write(line + ("\tFAIL: " + "; ".join(fails) if fails else "") + "\n")
if fails:
    print("FAIL %s: %s" % (cid, "; ".join(fails)))
    sys.exit(1)
EOF
rc=$?
# The sac against the AneuRisk neck polygon (ground truth), where the case has one.
cid=$(echo "$id" | cut -d_ -f1)
neck=$root/sample_data/real/necks/${cid}_automatedneck.vtk
if [ -f "$neck" ]; then
  "$prep" export "$out/surface.h5" --format vtp --surface lumen -o "$out/lumen.vtp" -q &&
    python3 "$root/tests/cli/real_sac_check.py" "$out/lumen.vtp" "$neck" || rc=1
fi
rm -f "$out/case.h5" "$out/fem.h5"
exit $rc
