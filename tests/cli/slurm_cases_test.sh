#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# scripts/slurm_cases.sh against a stand-in sbatch that records each submission and answers a job id as
# `sbatch --parsable` does: a case whose flow follows a session gets its stages, the session and the flow as one
# chain of jobs, each depending on the one before, each running the stage's Makefile.cases target (or the scene);
# without --scene for it, the case is refused (exit 2) and nothing is submitted.
# usage: slurm_cases_test.sh PREP WORKDIR
set -euo pipefail
prep=$1 w=$2
root=$(cd "$(dirname "$0")/../.." && pwd)
rm -rf "$w" && mkdir -p "$w/cases" "$w/bin"
cat > "$w/bin/sbatch" <<SB
#!/usr/bin/env bash
n=\$(( \$(wc -l < "$w/submitted" 2>/dev/null || echo 0) + 101 ))
printf '%s\n' "\$*" >> "$w/submitted"
echo "\$n;cluster"
SB
chmod +x "$w/bin/sbatch"
printf '[run]\nsource = "%s"\n[flow]\nseries = "%s"\n' "$root/sample_data/real/aneurisk_C0096_basilar_tip.vtk" "$w/out/c96/scene_series.h5" > "$w/cases/c96.toml"
fail() { echo "slurm_cases_test: $*" >&2; exit 1; }
# Without --scene: refused, nothing submitted.
set +e
msg=$(PREP=$prep CASES_DIR=$w/cases OUT=$w/out SBATCH=$w/bin/sbatch bash "$root/scripts/slurm_cases.sh" 2>&1)
rc=$?
set -e
[ $rc = 2 ] || fail "without --scene: exit $rc, expected 2 ($msg)"
grep -q "case c96: its \[flow\] follows a session .*give --scene c96=SCENE.json" <<< "$msg" || fail "without --scene: message '$msg'"
[ ! -e "$w/submitted" ] || fail "without --scene: something was submitted"
# With it: seven jobs in one chain.
out=$(PREP=$prep CASES_DIR=$w/cases OUT=$w/out SBATCH=$w/bin/sbatch bash "$root/scripts/slurm_cases.sh" --scene c96=$w/scene.json -- --partition=short)
grep -q "case c96: 7 jobs, the last 107" <<< "$out" || fail "summary '$out'"
expect=(surface:surface.h5 wall:wall.h5 tetmesh:volume.h5 assemble:fem.h5 condense:case.h5 session: flow:flow.h5)
mapfile -t lines < "$w/submitted"
[ ${#lines[@]} = 7 ] || fail "${#lines[@]} submissions, expected 7"
for i in "${!expect[@]}"; do
  stage=${expect[$i]%%:*} file=${expect[$i]#*:} line=${lines[$i]}
  grep -q -- "--job-name aneu-c96-$stage " <<< "$line" || fail "job $i: '$line' is not $stage"
  grep -q -- "--partition=short" <<< "$line" || fail "job $i: the sbatch options are missing: '$line'"
  if [ $i = 0 ]; then
    ! grep -q -- "--dependency" <<< "$line" || fail "the first job depends on something: '$line'"
  else
    grep -q -- "--dependency afterok:$((100 + i)) " <<< "$line" || fail "job $i does not wait for job $((100 + i)): '$line'"
  fi
  if [ "$stage" = session ]; then
    grep -q -- "--wrap .*aneusim run $w/scene.json --deterministic" <<< "$line" || fail "the session job: '$line'"
  else
    grep -q -- "--wrap make -f Makefile.cases .* $w/out/c96/$file\$" <<< "$line" || fail "job $i does not make $file: '$line'"
  fi
done
grep -q "^$w/out/c96/flow.h5: $w/out/c96/case.h5 $w/out/c96/scene_series.h5 " "$w/out/c96/rules.mk" || fail "the flow's make rule does not depend on the case bundle and the series"
echo "slurm_cases_test: 7 chained jobs (5 stages, the session, the flow); refused without --scene"
