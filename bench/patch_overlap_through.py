#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""How a patch's overlapping nodes got into the other tissue (aneusim's ANEU_PATCH_DUMP=F).

    python3 bench/patch_overlap_through.py F [--list N]

For the N deepest nodes lying more than 1 um inside an element not their own (the dump's depth column): how many
element rings lie between the node and the element holding it and how far apart they were at rest (a neighbour:
tangled elements; rings and a millimetre away: a fold), and the patch's boundary face (corner faces, off the
interface) the node now lies behind that it lay in front of at rest, with its surface: the boundary's components by
size, 'outer' the largest (the outer surface reaches round the whole patch), 'lumen' the next. Session 48 found
C0001's deepest behind outer-surface faces 0.6-1.5 mm away at rest: the outer surface folding into its own wall.
Pure Python (no numpy); seconds on a 14,000-node patch.
"""
import argparse
import math
import sys
from collections import defaultdict, deque

from patch_tissue_overlap import cross, dot, sub  # (run from anywhere: bench/ is the script's own directory)


def plane(p, a, b, c):
    """Signed distance of p from the plane of (a, b, c) (normal (b-a)x(c-a)) and whether p projects into the triangle."""
    n = cross(sub(b, a), sub(c, a))
    nn = math.sqrt(dot(n, n))
    if nn == 0:
        return 0.0, False
    n = (n[0] / nn, n[1] / nn, n[2] / nn)
    s = dot(sub(p, a), n)
    q = (p[0] - s * n[0], p[1] - s * n[1], p[2] - s * n[2])
    inside = all(dot(cross(sub(v, u), sub(q, u)), n) >= -1e-12 for u, v in ((a, b), (b, c), (c, a)))
    return s, inside


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dump")
    ap.add_argument("--list", type=int, default=30)
    args = ap.parse_args()
    X, x, iface, cand, held, depth, E = [], [], [], [], [], [], []
    with open(args.dump) as f:
        for line in f:
            t = line.split()
            if not t:
                continue
            if t[0] == "patch" and X:
                break  # the first patch only
            if t[0] == "n":
                X.append(tuple(map(float, t[1:4])))
                x.append(tuple(map(float, t[4:7])))
                iface.append(int(t[7]))
                cand.append(int(t[8]))
                held.append(int(t[9]))
                depth.append(float(t[10]) if len(t) > 10 else 0.0)
            elif t[0] == "e":
                E.append(tuple(map(int, t[1:])))
    if not E:
        sys.exit("%s: no patch in the dump" % args.dump)
    inc = defaultdict(list)
    for e, el in enumerate(E):
        for n in el:
            inc[n].append(e)
    # Boundary corner faces (one element's), off the interface, turned away from the element's fourth corner.
    faces = defaultdict(list)
    for e, el in enumerate(E):
        c = el[:4]
        for tri, opp in (((0, 1, 2), 3), ((0, 1, 3), 2), ((0, 2, 3), 1), ((1, 2, 3), 0)):
            f = tuple(c[i] for i in tri)
            faces[tuple(sorted(f))].append((f, c[opp]))
    boundary = []
    for v in faces.values():
        if len(v) != 1:
            continue
        f, opp = v[0]
        if all(iface[n] for n in f):
            continue
        a, b, c = (X[n] for n in f)
        if dot(cross(sub(b, a), sub(c, a)), sub(X[opp], a)) > 0:
            f = (f[0], f[2], f[1])
        boundary.append(f)
    parent = {}

    def find(a):
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for f in boundary:
        for i in range(3):
            parent[find(f[i])] = find(f[(i + 1) % 3])
    size = defaultdict(int)
    for f in boundary:
        size[find(f[0])] += 1
    order = sorted(size, key=lambda r: -size[r])
    name = {r: ("outer" if k == 0 else "lumen" if k == 1 else "other") for k, r in enumerate(order)}
    deep = sorted(((depth[i], i) for i in range(len(X)) if held[i] >= 0 and depth[i] > 1e-3 and not iface[i]), reverse=True)
    print("%d boundary faces: %s" % (len(boundary), ", ".join("%s %d" % (name[r], size[r]) for r in order[:3])))
    print("depth_mm node candidate rings rest_mm now_mm surface behind_mm in_front_at_rest_mm  (surface: the boundary face it lies behind)")
    for d, n in deep[: args.list]:
        h = held[n]
        target = set(E[h])
        seen = {n: 0}
        queue = deque([n])
        rings = None
        while queue:
            a = queue.popleft()
            if a in target:
                rings = seen[a]
                break
            if seen[a] > 8:
                continue
            for e in inc[a]:
                for b in E[e]:
                    if b not in seen:
                        seen[b] = seen[a] + 1
                        queue.append(b)
        rest = min(math.dist(X[n], X[b]) for b in E[h])
        now = min(math.dist(x[n], x[b]) for b in E[h])
        best = None
        for f in boundary:
            if n in f:
                continue
            a, b, c = (x[m] for m in f)
            if min(math.dist(x[n], a), math.dist(x[n], b), math.dist(x[n], c)) > 0.6:
                continue
            s, inside = plane(x[n], a, b, c)
            if inside and -0.3 < s < 0:
                s0, _ = plane(X[n], X[f[0]], X[f[1]], X[f[2]])
                if s0 > 0 and (best is None or s > best[0]):
                    best = (s, f, s0)
        through = ("%s %.4f %.3f" % (name[find(best[1][0])], -best[0], best[2])) if best else "none - -"
        print("%.4f %d %d %s %.3f %.3f %s" % (d, n, cand[n], rings if rings is not None else ">8", rest, now, through))


if __name__ == "__main__":
    main()
