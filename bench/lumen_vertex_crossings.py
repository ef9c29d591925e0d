# SPDX-License-Identifier: MIT
# Lumen vertices through the lumen's own faces: a run's end lumen as ANEU_LUMEN_OBJ writes it (faces oriented out of
# the lumen, `# neck LOOP X Y Z GAP` lines). A vertex counts as through a face when it lies 0.005-0.3 mm beyond the
# face's plane (out of the lumen, into the face's wall) with its projection inside the face, and the face is not
# within RINGS edges of it (the frames' wall rows leave out faces within 2 rings: fem::ContactParams::exclude_rings). By default the whole lumen is searched; with
# --near R only the vertices within R mm of the neck line's deepest point (the assessment's most negative gap).
# Session 44 asked whether C0054's negative gap is a vertex through a face beyond the rows' rings (none is); session 45
# counts the crossings the rings hide: the same scan with RINGS 1 against 2.
# Session 46: --rest REST.obj (the same lumen at rest, e.g. the scene run until just before the blades touch, with
# ANEU_LUMEN_OBJ): a vertex counts only if it lay on the lumen's side of the face's plane at rest, as
# fem::surface_crossings now counts (one behind it at rest lies beyond the wall: another lumen); --wall MM: no deeper
# than the wall's thickness (sim::lumen_crossing takes each face's own); --depth MM the search's depth (0.3).
#   python3 bench/lumen_vertex_crossings.py LUMEN.obj [--rings N (2)] [--near R_MM] [--list K (8)] [--rest REST.obj] [--wall MM] [--depth MM]
import sys, math

args = sys.argv[1:]
obj = args[0]
rest_obj = args[args.index('--rest') + 1] if '--rest' in args else None
depth = float(args[args.index('--depth') + 1]) if '--depth' in args else 0.3
if '--wall' in args: depth = min(depth, float(args[args.index('--wall') + 1]))
rings = int(args[args.index('--rings') + 1]) if '--rings' in args else 2
near_mm = float(args[args.index('--near') + 1]) if '--near' in args else None
show = int(args[args.index('--list') + 1]) if '--list' in args else 8
V = []; F = []; neck = []
for l in open(obj):
    if l.startswith('v '): V.append(tuple(map(float, l.split()[1:4])))
    elif l.startswith('f '): F.append(tuple(int(t.split('/')[0]) - 1 for t in l.split()[1:4]))
    elif l.startswith('# neck '):
        p = l.split(); neck.append((tuple(map(float, p[3:6])), float(p[6])))
R = None
if rest_obj:
    R = [tuple(map(float, l.split()[1:4])) for l in open(rest_obj) if l.startswith('v ')]
    if len(R) != len(V): sys.exit('lumen_vertex_crossings: the rest lumen has %d vertices, the lumen %d' % (len(R), len(V)))
sub = lambda a, b: (a[0] - b[0], a[1] - b[1], a[2] - b[2])
dot = lambda a, b: a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
cross = lambda a, b: (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
vs = range(len(V))
if near_mm is not None:
    worst = min(neck, key=lambda x: x[1]); c = worst[0]
    print('neck line deepest point', c, 'gap', worst[1])
    vs = [i for i, p in enumerate(V) if dot(sub(p, c), sub(p, c)) < near_mm * near_mm]
nb = {}
for f in F:
    for k in f: nb.setdefault(k, set()).update(f)
def ring(v, n):
    s = {v}
    for _ in range(n): s = set().union(*[nb[x] for x in s])
    return s
# faces by 0.5 mm cells of their bounding boxes (grown by the depth)
CELL = max(0.5, depth)
cells = {}
for j, f in enumerate(F):
    lo = [min(V[k][i] for k in f) - depth for i in range(3)]; hi = [max(V[k][i] for k in f) + depth for i in range(3)]
    for x in range(int(math.floor(lo[0] / CELL)), int(math.floor(hi[0] / CELL)) + 1):
        for y in range(int(math.floor(lo[1] / CELL)), int(math.floor(hi[1] / CELL)) + 1):
            for z in range(int(math.floor(lo[2] / CELL)), int(math.floor(hi[2] / CELL)) + 1):
                cells.setdefault((x, y, z), []).append(j)
out = []
for v in vs:
    p = V[v]
    r = None
    for j in cells.get(tuple(int(math.floor(p[i] / CELL)) for i in range(3)), ()):
        f = F[j]
        if v in f: continue
        a, b, cc = (V[k] for k in f); e1 = sub(b, a); e2 = sub(cc, a); n = cross(e1, e2); ln = math.sqrt(dot(n, n))
        if ln == 0: continue
        n = tuple(x / ln for x in n); w = sub(p, a); d = dot(w, n)  # through the face: out of the lumen, into its wall
        if d < 0.005 or d > depth: continue
        d11 = dot(e1, e1); d12 = dot(e1, e2); d22 = dot(e2, e2); w1 = dot(w, e1); w2 = dot(w, e2); den = d11 * d22 - d12 * d12
        b1 = (d22 * w1 - d12 * w2) / den; b2 = (d11 * w2 - d12 * w1) / den
        if min(1 - b1 - b2, b1, b2) < 0: continue
        if r is None: r = ring(v, rings)
        if any(k in r for k in f): continue
        if R is not None:
            ra, rb, rc = (R[k] for k in f)
            if dot(sub(R[v], ra), cross(sub(rb, ra), sub(rc, ra))) >= 0: continue  # not on the lumen's side at rest
        out.append((d, v, j))
out.sort(reverse=True)
where = 'within %.2f mm of it' % near_mm if near_mm is not None else 'on the whole lumen'
print('%d vertex-face crossings (0.005-%.3g mm through, projection inside, the face beyond %d rings%s) %s; %d vertices through a face' %
      (len(out), depth, rings, ', in front of its plane at rest' if R is not None else '', where, len({v for _, v, _ in out})))
for d, v, j in out[:show]:
    print('  vertex %d (%.3f %.3f %.3f) through face %d by %.4f mm' % (v, V[v][0], V[v][1], V[v][2], j, d))
