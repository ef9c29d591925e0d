#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The memory-heavy stages of the largest corpus case (C0001: 446 k DOFs of 10-node tetrahedra, a 1.1 GB factor)
# with and without transparent huge pages for malloc (aneuprep sets glibc.malloc.hugetlb=1 itself; ANEU_HUGE_PAGES=0
# turns it off). Three runs each, alternating; writes bench/results/huge_pages.md.
# usage: bash bench/run_huge_pages.sh   (build first; needs build/bench_real/real/C0001_ica_sidewall/volume.h5
#        from bash bench/run_real_corpus.sh or ctest -L real, else it builds it)
set -euo pipefail
cd "$(dirname "$0")/.."
prep=$PWD/build/tools/aneuprep
w=$PWD/build/bench_huge_pages
mkdir -p "$w"
vol=$w/volume.h5
if [ ! -f "$vol" ]; then
  for st in surface wall tetmesh; do "$prep" -q run configs/real/C0001_ica_sidewall.toml --out-dir "$w/case" --stage $st; done
  cp "$w/case/volume.h5" "$vol"
fi
out=bench/results/huge_pages.md
tsv=$w/times.tsv
: > "$tsv"
for i in 1 2 3; do
  for hp in 1 0; do
    for stage in assemble condense; do
      in=$vol; [ $stage = condense ] && in=$w/fem.h5
      o=$w/fem.h5; [ $stage = condense ] && o=$w/case.h5
      t=$( { ANEU_HUGE_PAGES=$hp /usr/bin/time -f "%e %U %S %M" "$prep" -q $stage "$in" -o "$o" ; } 2>&1 | tail -1 )
      echo -e "$hp\t$stage\t$t" >> "$tsv"
    done
  done
done
python3 - "$tsv" "$out" <<'PY'
import sys, statistics as st
rows = [l.split("\t") for l in open(sys.argv[1]).read().splitlines()]
res = {}
for hp, stage, t in rows:
    e, u, s, m = t.split()
    res.setdefault((hp, stage), []).append((float(e), float(u), float(s), int(m) / 1024))
with open(sys.argv[2], "w") as f:
    f.write("# Transparent huge pages for malloc: C0001 assemble and condense (%d runs each, median)\n\n" % len(res[("1", "assemble")]))
    f.write("`bash bench/run_huge_pages.sh`. aneuprep re-executes itself once with GLIBC_TUNABLES=glibc.malloc.hugetlb=1 where the kernel's\n")
    f.write("THP mode is `madvise`; ANEU_HUGE_PAGES=0 turns it off. 2 cores, virtual machine.\n\n")
    f.write("| stage | huge pages | wall (s) | user (s) | system (s) | peak RSS (MB) |\n|---|---|---|---|---|---|\n")
    for stage in ("assemble", "condense"):
        for hp in ("0", "1"):
            r = res[(hp, stage)]
            med = lambda k: st.median(x[k] for x in r)
            f.write("| %s | %s | %.1f | %.1f | %.1f | %.0f |\n" % (stage, "on" if hp == "1" else "off", med(0), med(1), med(2), med(3)))
print(open(sys.argv[2]).read())
PY
