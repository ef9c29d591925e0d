#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Writes the surface files of sample_data/real/ from the AneuRisk lumen models as published (legacy VTK ASCII
in grupomoccai/AneuSI, CC BY-NC 3.0), in the formats other tools write: legacy VTK as published, VTP with
zlib-compressed binary arrays (SimVascular/VMTK/ParaView), binary STL in metres with flat-fan caps on the
open ends (a CFD lumen mesh), binary STL in mm closed with rounded ends (a segmentation's surface), and ASCII OBJ. The geometry is not changed (coordinates are written as float32,
the published files have 6-7 significant digits); only the capped STL adds one vertex per end and the rounded one a dome per end.

usage: make_corpus.py SOURCE_DIR OUT_DIR
SOURCE_DIR holds CXXXX_model.vtk and CXXXX_test.vtk as in the repository (see README.md for the commit).
Standard library only."""
import base64, math, os, shutil, struct, sys, zlib


def read_vtk(path):
    toks = open(path, 'rb').read().split(b'\n', 3)[3].split()
    i, P, F = 0, [], []
    while i < len(toks):
        t = toks[i].upper()
        if t == b'POINTS':
            n = int(toks[i + 1])
            v = toks[i + 3:i + 3 + 3 * n]
            P = [tuple(float(x) for x in v[j:j + 3]) for j in range(0, 3 * n, 3)]
            i += 3 + 3 * n
        elif t == b'POLYGONS':
            n = int(toks[i + 1])
            i += 3
            if toks[i].upper() == b'OFFSETS':  # legacy 5.1
                nc = int(toks[i - 1])
                off = [int(x) for x in toks[i + 2:i + 2 + n]]
                i += 2 + n
                con = [int(x) for x in toks[i + 2:i + 2 + nc]]
                i += 2 + nc
                F += [con[a:b] for a, b in zip(off[:-1], off[1:])]
                continue
            for _ in range(n):
                k = int(toks[i])
                F.append([int(x) for x in toks[i + 1:i + 1 + k]])
                i += 1 + k
        else:
            i += 1
    return P, [f for f in F if len(f) == 3]


def b64_block(raw):
    comp = zlib.compress(raw, 6)
    header = struct.pack('<4Q', 1, len(raw), len(raw), len(comp))
    return base64.b64encode(header).decode() + base64.b64encode(comp).decode()


def write_vtp(path, P, F):
    pts = struct.pack('<%df' % (3 * len(P)), *[c for p in P for c in p])
    con = struct.pack('<%di' % (3 * len(F)), *[v for f in F for v in f])
    off = struct.pack('<%di' % len(F), *[3 * (k + 1) for k in range(len(F))])
    with open(path, 'w') as o:
        o.write('<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" '
                'header_type="UInt64" compressor="vtkZLibDataCompressor">\n<PolyData>\n'
                '<Piece NumberOfPoints="%d" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="%d">\n'
                % (len(P), len(F)))
        o.write('<Points><DataArray type="Float32" NumberOfComponents="3" format="binary">%s</DataArray></Points>\n' % b64_block(pts))
        o.write('<Polys><DataArray type="Int32" Name="connectivity" format="binary">%s</DataArray>\n' % b64_block(con))
        o.write('<DataArray type="Int32" Name="offsets" format="binary">%s</DataArray></Polys>\n' % b64_block(off))
        o.write('</Piece>\n</PolyData>\n</VTKFile>\n')


def boundary_loops(F):
    directed = set()
    for f in F:
        for k in range(3):
            directed.add((f[k], f[(k + 1) % 3]))
    nxt = {a: b for (a, b) in directed if (b, a) not in directed}
    loops, used = [], set()
    for a in sorted(nxt):
        if a in used:
            continue
        loop, v = [], a
        while v not in used:
            used.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(loop)
    return loops


def cap_fans(P, F):
    """One fan per open end from the loop's centroid: the flat caps a CFD tool puts on a lumen (as flat as the
    published cut ends are planar, a few hundredths of a mm)."""
    P, F = list(P), list(F)
    for loop in boundary_loops(F):
        c = tuple(sum(P[v][d] for v in loop) / len(loop) for d in range(3))
        P.append(c)
        ci = len(P) - 1
        for k in range(len(loop)):
            a, b = loop[k], loop[(k + 1) % len(loop)]
            F.append([b, a, ci])  # the wall face has a->b; the cap runs b->a
    return P, F


def round_ends(P, F, rings=6):
    """Closes each open end with a hemispherical dome of the loop's equal-area radius (rings of the loop scaled
    towards the apex): the rounded blind ends of a closed surface made from a segmentation, where the segmented
    vessel stopped. The published lumen is not moved; only the domes are added."""
    P, F = list(P), list(F)
    for loop in boundary_loops(F):
        n = len(loop)
        c = [sum(P[v][d] for v in loop) / n for d in range(3)]
        w = [0.0, 0.0, 0.0]
        for k in range(n):
            a = [P[loop[k]][d] - c[d] for d in range(3)]
            b = [P[loop[(k + 1) % n]][d] - c[d] for d in range(3)]
            w = [w[0] + a[1] * b[2] - a[2] * b[1], w[1] + a[2] * b[0] - a[0] * b[2], w[2] + a[0] * b[1] - a[1] * b[0]]
        lw = math.sqrt(sum(x * x for x in w))
        nrm = [-x / lw for x in w]  # out of the vessel (the wall's faces run along the loop)
        r = math.sqrt(0.5 * lw / math.pi)
        prev = list(loop)
        for k in range(1, rings):
            t = 0.5 * math.pi * k / rings
            ring = []
            for v in loop:
                P.append(tuple(c[d] + math.cos(t) * (P[v][d] - c[d]) + math.sin(t) * r * nrm[d] for d in range(3)))
                ring.append(len(P) - 1)
            for i in range(n):
                a0, b0, a1, b1 = prev[i], prev[(i + 1) % n], ring[i], ring[(i + 1) % n]
                F += [[b0, a0, a1], [b0, a1, b1]]
            prev = ring
        P.append(tuple(c[d] + r * nrm[d] for d in range(3)))
        apex = len(P) - 1
        for i in range(n):
            F.append([prev[(i + 1) % n], prev[i], apex])
    return P, F


def write_stl(path, P, F, scale, title=b'aneuclip corpus: AneuRisk lumen, capped, metres'):
    with open(path, 'wb') as o:
        o.write(title.ljust(80, b' '))
        o.write(struct.pack('<I', len(F)))
        for f in F:
            a, b, c = (tuple(x * scale for x in P[v]) for v in f)
            u = [b[d] - a[d] for d in range(3)]
            w = [c[d] - a[d] for d in range(3)]
            n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
            ln = math.sqrt(sum(x * x for x in n)) or 1.0
            o.write(struct.pack('<12fH', *[x / ln for x in n], *a, *b, *c, 0))


def write_obj(path, P, F):
    with open(path, 'w') as o:
        o.write('# aneuclip corpus: AneuRisk lumen (mm)\n')
        for p in P:
            o.write('v %.6g %.6g %.6g\n' % p)
        for f in F:
            o.write('f %d %d %d\n' % (f[0] + 1, f[1] + 1, f[2] + 1))


def main(src, out):
    os.makedirs(out, exist_ok=True)
    m = lambda c: os.path.join(src, '%s_model.vtk' % c)
    shutil.copyfile(m('C0096'), os.path.join(out, 'aneurisk_C0096_basilar_tip.vtk'))  # as published
    for c, name in [('C0043', 'basilar_sidewall'), ('C0093', 'mca_bifurcation'), ('C0024', 'ica_sidewall'),
                    ('C0001', 'ica_sidewall'), ('C0070', 'mca_bifurcation_small'), ('C0095', 'model'), ('C0054', 'model')]:
        write_vtp(os.path.join(out, 'aneurisk_%s_%s.vtp' % (c, name)), *read_vtk(m(c)))
    P, F = cap_fans(*read_vtk(m('C0061')))
    write_stl(os.path.join(out, 'aneurisk_C0061_aca_bifurcation_capped_m.stl'), P, F, 0.001)
    P, F = round_ends(*read_vtk(m('C0093')))
    write_stl(os.path.join(out, 'aneurisk_C0093_mca_bifurcation_rounded.stl'), P, F, 1.0,
              b'aneuclip corpus: AneuRisk lumen, rounded ends, mm')
    write_obj(os.path.join(out, 'aneurisk_C0096_dome_clipped.obj'), *read_vtk(os.path.join(src, 'C0096_test.vtk')))


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
