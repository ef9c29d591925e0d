#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_real_corpus.sh PREP CASE_CONFIG WORKDIR [RESULTS_TSV [SIM]]
# One case of the real-data corpus (configs/real/*.toml, data in sample_data/real/) through `aneuprep run` with
# the corpus settings and no per-case tuning, then its standards, read from the stages' QA in the bundle:
#   - every stage ran (exit 0) and the bundle exists;
#   - surface: an aneurysm sac was labelled (area > 0) when the source is an aneurysm model (AneuRisk), and where the
#     case has its AneuRisk neck polygon (sample_data/real/necks/), the label is at that neck (real_sac_check.py);
#   - wall: closed, manifold, free of self-intersections (the stage checks these and stops otherwise; the
#     QA's self_intersections must be 0), thickness medians within ±10 % of the targets per region;
#   - tetmesh: no dihedral angle below 5°;
#   - with SIM (aneusim) and a labelled sac: `aneusim plan` plans a clip, or refuses with an input error (exit 2) a
#     neck no straight clip of its set spans or whose only clear ways cover under a quarter of its border; the
#     planned scene runs with the linear model (--deterministic, no series), and where the plan's header says the
#     open blades come in clear of the vessel (0 vertices within 0.2 mm along the approach), the run has no contact
#     node before the applier starts closing. The plan (clip, tilt, share of the neck's border the jaws' width
#     covers, vertices in the way) and the run's figures go to RESULTS_TSV: a clear approach is not found on every
#     real case yet (bench/results/study/plan_corpus.md);
# and prints the time per stage. The bundle (hundreds of MB) is removed afterwards; the QA line is appended
# to RESULTS_TSV when given.
set -u
prep=$1 config=$2 work=$3 results=${4:-} sim=${5:-}
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
python3 - "$out/case.json" "$id" "$results" "$root/tests/cli" <<'EOF'
import json, sys
sys.path.insert(0, sys.argv[4])
from corpus_report import finish
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
finish(cid, line, fails, results)
EOF
rc=$?
# The sac against the AneuRisk neck polygon (ground truth), where the case has one.
cid=$(echo "$id" | cut -d_ -f1)
neck=$root/sample_data/real/necks/${cid}_automatedneck.vtk
if [ -f "$neck" ]; then
  "$prep" export "$out/surface.h5" --format vtp --surface lumen -o "$out/lumen.vtp" -q &&
    python3 "$root/tests/cli/real_sac_check.py" "$out/lumen.vtp" "$neck" || rc=1
fi
# The planned clip (aneurysm models only): a clear approach, and no contact until the jaws close.
if [ -n "$sim" ] && [ "${id#C0}" != "$id" ]; then
  "$sim" plan "$out/case.h5" -o "$out/planned.json" 2>"$out/plan.err"
  prc=$?
  if [ $prc -eq 2 ] && grep -q "does not span it\|without cutting into the vessel on the way in" "$out/plan.err"; then
    line="$id	plan: refused, $(tail -1 "$out/plan.err" | sed 's/.*error: //')"
    echo "$line"
    [ -n "$results" ] && echo "$line" >> "$results"
  elif [ $prc -ne 0 ]; then
    echo "FAIL $id: aneusim plan (exit $prc): $(tail -1 "$out/plan.err")"
    rc=1
  else
    python3 - "$out/planned.json" <<'EOF'
import json, sys
p = sys.argv[1]
t = open(p).read()
j = json.loads(t[t.index("{"):])
j["outputs"] = {"log": "planned_log.csv", "report": "planned_report.json"}
open(p, "w").write(t[:t.index("{")] + json.dumps(j, indent=1))
EOF
    if ! OMP_THREAD_LIMIT=1 "$sim" run "$out/planned.json" --deterministic >"$out/planned.out" 2>&1; then
      echo "FAIL $id: aneusim run planned.json: $(tail -1 "$out/planned.out")"
      rc=1
    else
      python3 - "$out" "$id" "$results" "$root/tests/cli" <<'EOF' || rc=1
import json, re, sys
sys.path.insert(0, sys.argv[4])
from corpus_report import finish
out, cid, results = sys.argv[1], sys.argv[2], sys.argv[3]
text = open(out + "/planned.json").read()
head = " ".join(l[2:].strip() for l in text.splitlines() if l.startswith("//"))
m = re.search(r"turned (-?\d+) deg from its long axis and tilted (\d+) deg \(the hinge up\), where they cover (\d+) % of the neck line(?: \(its border\))?; (\d+) outer-surface vertices", head)
fails = []
if not m:
    fails.append("planned scene header without the jaws' placement: " + head[:300])
    yaw, tilt, cover, hits = 0, -1, -1, -1
else:
    yaw, tilt, cover, hits = int(m.group(1)), int(m.group(2)), int(m.group(3)), int(m.group(4))
j = json.loads(text[text.index("{"):])
t_close = j["instruments"][0]["keyframes"][1]["t"]
early = 0
rows = open(out + "/planned_log.csv").read().splitlines()
assert rows[0].startswith("t_s,contact_nodes,"), rows[0]
for r in rows[1:]:
    f = r.split(",")
    if float(f[0]) < t_close - 1e-9 and int(f[1]) > 0:
        early += 1
if early and hits == 0:
    fails.append("the plan says the approach is clear, but %d frames have contact before the jaws close (t < %g s)" % (early, t_close))
rep = json.load(open(out + "/planned_report.json"))
clip = list(j["clip_models"])[0]
opening = j["instruments"][0]["keyframes"][0]["opening_deg"]
line = "%s\tplan: %s open %g deg, yaw %d deg, tilt %d deg, neck line covered %d %%, approach hits %d, early contact frames %d, linear run: neck between jaws %.0f %%, closed %.0f %%, peak %.2f N" % (
    cid, clip, opening, yaw, tilt, cover, hits, early, 100 * rep["neck_between_jaws_fraction"], 100 * rep["neck_closed_fraction"], rep["peak_vessel_force_n"])
finish(cid, line, fails, results)
EOF
    fi
  fi
fi
rm -f "$out/case.h5" "$out/fem.h5"
exit $rc

