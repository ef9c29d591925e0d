#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Why the flow stage keeps a pinched lumen's reachable part by a flood fill (pipeline::reachable_distance) and not
# by CGAL's alpha wrapping or self-intersection removal: each method on the capped tube (radius 1 mm, 12 mm) pinched
# shut and pinched across half its width at x = 6 (the flow tests' pinch: walls pushed 1.4 R through each other).
# -> bench/results/flow/pinch_methods.md. usage: bash bench/flow/pinch_methods.sh (about a minute)
set -euo pipefail
cd "$(dirname "$0")/../.."
w=build/pinch_methods
mkdir -p "$w"
python3 - "$w" <<'PY'
import math, sys
w = sys.argv[1]
R, L, n, m = 1.0, 12.0, 96, 160
def pinch(x, y, z, half):
    c = 1.0 / (1.0 + math.exp(z / 0.05)) if half else 1.0
    return (x, y - 1.4 * math.exp(-((x - 6) / 0.8) ** 2) * math.tanh(y / 0.15) * c, z)
for half in (False, True):
    V = [pinch(L * j / m, R * math.cos(2 * math.pi * k / n), R * math.sin(2 * math.pi * k / n), half) for j in range(m + 1) for k in range(n)]
    idx = lambda j, k: j * n + (k % n)
    F = []
    for j in range(m):
        for k in range(n):
            F += [(idx(j, k), idx(j + 1, k + 1), idx(j + 1, k)), (idx(j, k), idx(j, k + 1), idx(j + 1, k + 1))]
    c0, c1 = len(V), len(V) + 1
    V += [(0, 0, 0), (L, 0, 0)]
    for k in range(n):
        F += [(c0, idx(0, k), idx(0, k + 1)), (c1, idx(m, k + 1), idx(m, k))]
    with open("%s/%s.off" % (w, "half" if half else "full"), "w") as f:
        f.write("OFF\n%d %d 0\n" % (len(V), len(F)))
        f.writelines("%.9f %.9f %.9f\n" % v for v in V)
        f.writelines("3 %d %d %d\n" % t for t in F)
PY
g++ -O2 -std=c++17 bench/flow/pinch_methods.cpp -o "$w/pinch_methods" -lgmp -lmpfr
{
  echo "# A pinched lumen: which method finds the blood domain (bash bench/flow/pinch_methods.sh)"
  echo
  echo "The capped tube (radius 1 mm, 12 mm long, volume 37.70 mm³) pinched at x = 6 mm with the walls pushed 1.4 R through each"
  echo "other, shut (full) and across half its width (half), as in \`Flow.APinchedTubeKeepsOnlyWhatBloodReaches\` and"
  echo "\`Flow.BloodPassesAHalfPinchedTubeOnlyWhereItStaysOpen\`. CGAL 5.5.1 (Debian 12) has no autorefine (5.6+)."
  echo
  echo '```'
  "$w/pinch_methods" "$w/full.off"
  "$w/pinch_methods" "$w/half.off"
  echo '```'
  echo
  echo "The flow stage's flood fill (pipeline::reachable_distance, grid 0.0625 mm): pinched shut, 15.43 mm³ reached, the tube up to"
  echo "x = 4.91 mm, (9,0,0) not reached, the stage refuses to solve (no outlet); half pinched, the section at the pinch reached"
  echo "where it is open (0.55 % of the open area more than a grid spacing from the walls missed, none where the walls crossed)."
} > bench/results/flow/pinch_methods.md
cat bench/results/flow/pinch_methods.md
