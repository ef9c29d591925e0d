#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Where a patch's tissue overlaps itself at the end of a run (aneusim's ANEU_PATCH_DUMP=F).

    python3 bench/patch_tissue_overlap.py F [--list N]

For each patch node that lies inside an element not its own (fem::nodes_inside_elements, the report's
patch_nodes_in_other_tissue): how deep (aneusim's depth, to the holding element's faces on the mesh's boundary; older
dumps: the least distance to the faces of the straight piece holding it, a lower bound), whether it is a blade candidate (outer surface by the jaws), whether the
element holding it or one of the node's own elements has a straight piece turned inside out (its signed volume against
the one at rest), and how far the node moved. Pure Python (no numpy).
"""
import argparse
import math
import sys

# The 10-node element's straight pieces (element.hpp's order): four at the corners, four round the diagonal 4-9.
QUAD = [(0, 4, 6, 7), (4, 1, 5, 8), (6, 5, 2, 9), (7, 8, 9, 3), (4, 9, 5, 8), (4, 9, 8, 7), (4, 9, 7, 6), (4, 9, 6, 5)]
LIN = [(0, 1, 2, 3)]


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def volume(p):
    return dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0]))) / 6.0


def depth_inside(q, p):
    """Least signed distance from q to the tetrahedron p's faces, inside positive."""
    best = math.inf
    for k in range(4):
        a, b, c = p[(k + 1) % 4], p[(k + 2) % 4], p[(k + 3) % 4]
        n = cross(sub(b, a), sub(c, a))
        ln = math.sqrt(dot(n, n))
        if ln == 0:
            return -math.inf
        s = 1.0 if dot(sub(p[k], a), n) > 0 else -1.0
        best = min(best, s * dot(sub(q, a), n) / ln)
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dump")
    ap.add_argument("--list", type=int, default=10, help="the deepest N nodes listed")
    args = ap.parse_args()
    patches = []
    with open(args.dump) as f:
        for line in f:
            t = line.split()
            if not t:
                continue
            if t[0] == "patch":
                patches.append({"X": [], "x": [], "iface": [], "cand": [], "in": [], "E": []})
            elif t[0] == "n":
                P = patches[-1]
                P["X"].append(tuple(map(float, t[1:4])))
                P["x"].append(tuple(map(float, t[4:7])))
                P["iface"].append(int(t[7]))
                P["cand"].append(int(t[8]))
                P["in"].append(int(t[9]))
                P.setdefault("depth", []).append(float(t[10]) if len(t) > 10 else None)
            elif t[0] == "e":
                patches[-1]["E"].append(tuple(map(int, t[1:])))
    if not patches:
        sys.exit("%s: no patch in the dump" % args.dump)
    for k, P in enumerate(patches):
        pieces = QUAD if len(P["E"][0]) == 10 else LIN
        X, x, E = P["X"], P["x"], P["E"]
        inverted = []  # per element: a straight piece whose signed volume changed sign from rest
        for e in E:
            bad = False
            for s in pieces:
                v0 = volume([X[e[i]] for i in s])
                v1 = volume([x[e[i]] for i in s])
                bad = bad or v0 * v1 <= 0
            inverted.append(bad)
        own = [[] for _ in X]
        for j, e in enumerate(E):
            for n in e:
                own[n].append(j)
        rows = []
        for n, e in enumerate(P["in"]):
            if e < 0:
                continue
            # aneusim's depth (to the holding element's faces on the boundary) where the dump has it, else the least
            # distance to the faces of the straight piece holding it (a lower bound)
            d = P["depth"][n] if P["depth"][n] is not None else max(depth_inside(x[n], [x[E[e][i]] for i in s]) for s in pieces)
            moved = math.sqrt(dot(sub(x[n], X[n]), sub(x[n], X[n])))
            rows.append((d, n, e, P["iface"][n], P["cand"][n], inverted[e], any(inverted[j] for j in own[n]), moved))
        nodes = len(X)
        print("patch %d: %d nodes, %d elements (%d with a straight piece turned inside out); %d nodes in an element not their own"
              % (k, nodes, len(E), sum(inverted), len(rows)))
        if not rows:
            continue
        rows.sort(reverse=True)
        deeper = sum(1 for r in rows if r[0] > 1e-3)
        print("  %d deeper than 1 um; deepest %.4f mm, median %.4f mm; %d on the interface, %d blade candidates; %d in an element turned inside out, "
              "%d with one of their own turned inside out"
              % (deeper, rows[0][0], rows[len(rows) // 2][0], sum(r[3] for r in rows), sum(r[4] for r in rows), sum(r[5] for r in rows),
                 sum(r[6] for r in rows)))
        print("  depth_mm node element interface candidate element_inverted own_inverted moved_mm")
        for r in rows[: args.list]:
            print("  %.2e %d %d %d %d %d %d %.3f" % (r[0], r[1], r[2], r[3], r[4], int(r[5]), int(r[6]), r[7]))


if __name__ == "__main__":
    main()
