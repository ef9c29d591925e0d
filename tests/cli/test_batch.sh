#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_batch.sh REPO_ROOT PREP WORKDIR
# Makefile.cases on the shipped case configs (copied, so edits stay here): builds both from scratch, a second
# call runs nothing, a changed sac thickness reruns exactly wall, tetmesh, assemble and condense of that case,
# a batch killed in the middle of a stage resumes to valid bundles with nothing half-written under a final
# name, with -k a failing case does not stop the others and is listed at the end, and the sample's QA report
# renders in headless Chromium with all its pictures.
set -u
root=$1 prep=$2 w=$3
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$w"; mkdir -p "$w/cases"
cp "$root"/configs/cases/*.toml "$w/cases/"
cases=$(ls "$w/cases" | sed 's/\.toml$//' | sort | tr '\n' ' ')
mk() { make -C "$root" -f Makefile.cases PREP="$prep" CASES_DIR="$w/cases" OUT="$w/out" "$@"; }
ran() { grep -Eo '^[a-z_0-9]+ [a-z]+: ran in' "$1" | sed 's/: ran in//' | sort | tr '\n' ';'; }
valid_bundles() {
  for c in $cases; do
    "$prep" inspect "$w/out/$c/case.h5" >/dev/null 2>&1 || fail "$c: case.h5 is not a valid bundle"
  done
}

echo "== 1. both cases from scratch: $cases"
mk -j2 >"$w/log1" 2>&1 || { tail -30 "$w/log1"; fail "first build failed"; }
valid_bundles
n=$(grep -c ': ran in' "$w/log1")
[ "$n" = 14 ] || { cat "$w/log1"; fail "expected 14 stage runs (2 cases x 7 stages), got $n"; }

echo "== 2. a second call runs nothing"
before=$(stat -c %Y "$w"/out/*/case.h5 | tr '\n' ' ')
mk -j2 >"$w/log2" 2>&1 || fail "second call failed"
grep -q 'aneuprep\|ran in\|up to date' "$w/log2" && { cat "$w/log2"; fail "second call ran something"; }
[ "$before" = "$(stat -c %Y "$w"/out/*/case.h5 | tr '\n' ' ')" ] || fail "second call changed a bundle"

echo "== 3. sac thickness changed in sample: wall and what follows rerun, for that case only"
printf '\n[wall]\naneurysm-thickness-mm = 0.15\n' >>"$w/cases/sample.toml"
mk -j2 >"$w/log3" 2>&1 || { cat "$w/log3"; fail "rebuild failed"; }
got=$(ran "$w/log3")
want="sample assemble;sample condense;sample tetmesh;sample wall;"
[ "$got" = "$want" ] || { cat "$w/log3"; fail "stages run: '$got', expected '$want'"; }
"$prep" inspect "$w/out/sample/wall.h5" | grep -q 'aneurysm_thickness_mm=0.15' || fail "wall provenance lacks the new thickness"

echo "== 4. the batch killed in the middle of the wall stage, then resumed"
sed -i 's/aneurysm-thickness-mm = 0.15/aneurysm-thickness-mm = 0.12/' "$w/cases/sample.toml"
setsid make -C "$root" -f Makefile.cases PREP="$prep" CASES_DIR="$w/cases" OUT="$w/out" -j2 >"$w/log4" 2>&1 &
pid=$!
for _ in $(seq 600); do  # until the wall stage has started writing or computing (up to 60 s)
  pgrep -f -- "--stage wall" >/dev/null && break
  sleep 0.1
done
pgrep -f -- "--stage wall" >/dev/null || { cat "$w/log4"; fail "the wall stage never started"; }
sleep 1   # the sample's wall stage computes for ~5 s on the 2-core machine: the kill lands inside it
pgrep -f -- "--stage wall" >/dev/null || { cat "$w/log4"; fail "the wall stage ended before the kill (too fast a machine for this test's wait)"; }
kill -KILL -- -"$pid"
wait "$pid" 2>/dev/null
"$prep" inspect "$w/out/sample/wall.h5" | grep -q 'aneurysm_thickness_mm=0.15' || fail "killed run left a changed wall.h5"
valid_bundles
mk -j2 >"$w/log5" 2>&1 || { cat "$w/log5"; fail "resumed batch failed"; }
got=$(ran "$w/log5")
[ "$got" = "$want" ] || { cat "$w/log5"; fail "resumed run: '$got', expected '$want'"; }
"$prep" inspect "$w/out/sample/case.h5" | grep -q 'aneurysm_thickness_mm=0.12' || fail "resumed bundle lacks the new thickness"
valid_bundles
left=$(find "$w/out" -name '*.part-*' | wc -l)
[ "$left" = 0 ] || fail "$left unfinished files left after the resumed run"

echo "== 5. -k: a failing case is listed and does not stop the others"
cp "$w/cases/sample.toml" "$w/cases/zz_bad.toml"
printf '\n[segment]\nthreshold-hu = 5000\n' >>"$w/cases/zz_bad.toml"
mk -k -j2 >"$w/log6" 2>&1 && { cat "$w/log6"; fail "a failing case gave exit code 0"; }
grep -q 'Makefile.cases: failed (case stage):' "$w/log6" || { cat "$w/log6"; fail "no failure list"; }
grep -q '^  zz_bad segment$' "$w/log6" || { cat "$w/log6"; fail "the failure list does not name zz_bad segment"; }
grep -q 'aneuprep segment: error: .*threshold' "$w/log6" || { cat "$w/log6"; fail "no error line from the failing stage"; }
for s in surface wall tetmesh assemble condense; do  # the stages of the failed case that follow did not run
  [ -e "$w/out/zz_bad/$s.h5" ] && fail "zz_bad/$s.h5 exists after its segment stage failed"
done
valid_bundles

echo "== 6. the QA report of the sample case renders in headless Chromium with every picture"
report() { bash "$root/scripts/xvfb.sh" "$prep" report "$w/cases/sample.toml" --out-dir "$w/out/sample" -q; }
report >"$w/log7" 2>&1 || { cat "$w/log7"; fail "aneuprep report failed"; }
html="$w/out/sample/report.html"
grep -q 'Dice of the lumen against the phantom' "$html" || fail "report: no Dice figure"
grep -q 'thickness_aneurysm_median_mm' "$html" || fail "report: no thickness per region"
grep -q '<svg' "$html" || fail "report: no quality histograms"
grep -q 'kept DOFs' "$html" || fail "report: no condensation diagnostics"
grep -q 'http://\|https://\|src="/\|src="file' <(grep -o 'src="[^"]\{0,12\}' "$html") && fail "report: refers to an outside resource"
command -v chromium >/dev/null || fail "chromium not found (scripts/install_deps.sh installs it)"
dom=$(chromium --headless --no-sandbox --disable-gpu --dump-dom "file://$html" 2>/dev/null)
check=$(echo "$dom" | grep -o 'id="picture-check" data-ok="[a-z]*">[^<]*')
echo "   chromium: $check"
echo "$check" | grep -q 'data-ok="yes">5 of 5 pictures shown' || fail "chromium: not every picture shown ($check)"
chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1200,2400 --screenshot="$w/report.png" "file://$html" >/dev/null 2>&1
[ -s "$w/report.png" ] || fail "chromium made no screenshot"
echo "OK"
rm -rf "$w"
