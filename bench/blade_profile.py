# SPDX-License-Identifier: MIT
# Where a clip's blades press the tissue along them, from a run's report: the patch's `blade_profile_n` (the last
# frame's normal force on the blades per mm from where they turn, the mean of the two blades, the compliance frames'
# contact forces) per 1 mm of r, its share of the force and of the moment about the fulcrum, and what part of the
# clip that is (the arms before the heel, the blade) and whether the neck line (`# neck` rows of ANEU_LUMEN_OBJ,
# deformed) spans that mm; then the totals per part: arms, blade before the neck line, along it, past it.
#   python3 bench/blade_profile.py REPORT.json SCENE.json [LUMEN.obj] > profile.tsv
import json, math, os, sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from neck_line_in_jaws import neck_line_in_jaws  # noqa: E402


def main():
    rep, sc = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
    prof = next(p["blade_profile_n"] for p in rep["patches"] if p.get("blade_profile_n"))
    model = next(iter(sc["clip_models"].values()))
    heel = model.get("fulcrum_mm", 0.0)
    lo = hi = None
    if len(sys.argv) > 3:
        rows, _, _ = neck_line_in_jaws(sys.argv[3], sc)
        lo, hi = rows[0][0], rows[-1][0]
    f_tot = sum(prof) or 1.0
    m_tot = sum(f * (k + 0.5) for k, f in enumerate(prof)) or 1.0
    part = lambda r: "arms" if r < heel else ("blade" if lo is None else ("before the neck line" if r < lo else ("along the neck line" if r <= hi else "past the neck line")))
    print("r_mm\tforce_n\tforce_share\tmoment_share\tpart")
    sums = {}
    for k, f in enumerate(prof):
        r = k + 0.5
        p = part(r)
        s = sums.setdefault(p, [0.0, 0.0])
        s[0] += f
        s[1] += f * r
        print("%.1f\t%.4f\t%.3f\t%.3f\t%s" % (r, f, f / f_tot, f * r / m_tot, p))
    print("# total %.4f N, moment %.3f N mm%s" % (f_tot, m_tot, "" if lo is None else "; the neck line spans r %.2f-%.2f mm" % (lo, hi)))
    for p, (f, m) in sums.items():
        print("# %s: %.4f N (%.1f %%), moment %.1f %%" % (p, f, 100 * f / f_tot, 100 * m / m_tot))


if __name__ == "__main__":
    main()
