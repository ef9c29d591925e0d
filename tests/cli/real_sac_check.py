#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The automatic aneurysm label of a real case against the AneuRisk neck (ostium) polygon, the ground truth of
where the sac is: the labelled region must touch the neck (a labelled face within the neck's radius + 1 mm of its
centre) and lie around it (its area centroid within neck radius + the sac's equivalent radius + 2 mm).
usage: real_sac_check.py LUMEN.vtp NECK.vtk   (the VTP from `aneuprep export surface.h5 --format vtp --surface lumen`)
Prints one line; exit 1 when the label is elsewhere. Standard library only."""
import base64, math, re, struct, sys, zlib


def vtp(path):
    s = open(path).read()

    def arr(name, last=False):
        ms = list(re.finditer(r'<DataArray type="(\w+)" Name="%s"[^>]*>(.*?)</DataArray>' % name, s, re.S))
        m = ms[-1] if last else ms[0]
        t, data = m.group(1), ''.join(m.group(2).split())
        nb = struct.unpack('<I', base64.b64decode(data[:8])[:4])[0]
        hl = (3 + nb) * 4
        hc = 4 * ((hl + 2) // 3)
        hdr = struct.unpack('<%dI' % (3 + nb), base64.b64decode(data[:hc])[:hl])
        body, raw, off = base64.b64decode(data[hc:]), b'', 0
        for c in hdr[3:]:
            raw += zlib.decompress(body[off:off + c])
            off += c
        fmt = {'Float64': 'd', 'Float32': 'f', 'Int64': 'q', 'Int32': 'i', 'UInt8': 'B'}[t]
        return struct.unpack('<%d%s' % (len(raw) // struct.calcsize(fmt), fmt), raw)
    pts, con, lab = arr('Points'), arr('connectivity', last=True), arr('label')
    return [pts[i:i + 3] for i in range(0, len(pts), 3)], [con[i:i + 3] for i in range(0, len(con), 3)], lab


def neck(path):
    toks = open(path, 'rb').read().split(b'\n', 3)[3].split()
    i = toks.index(b'POINTS')
    n = int(toks[i + 1])
    v = toks[i + 3:i + 3 + 3 * n]
    return [tuple(float(x) for x in v[j:j + 3]) for j in range(0, 3 * n, 3)]


def main(lumen, neck_path):
    P, F, lab = vtp(lumen)
    N = neck(neck_path)
    nc = [sum(p[d] for p in N) / len(N) for d in range(3)]
    nr = sum(math.dist(p, nc) for p in N) / len(N)
    area, cen, touch = 0.0, [0.0, 0.0, 0.0], float('inf')
    for f, l in zip(F, lab):
        if l != 1:
            continue
        a, b, c = (P[v] for v in f)
        u = [b[d] - a[d] for d in range(3)]
        w = [c[d] - a[d] for d in range(3)]
        n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
        af = 0.5 * math.sqrt(sum(x * x for x in n))
        cc = [(a[d] + b[d] + c[d]) / 3 for d in range(3)]
        area += af
        cen = [cen[d] + af * cc[d] for d in range(3)]
        touch = min(touch, math.dist(cc, nc))
    if area == 0:
        print('no face is labelled aneurysm')
        return 1
    cen = [x / area for x in cen]
    req = math.sqrt(area / (4 * math.pi))
    dist = math.dist(cen, nc)
    ok = touch <= nr + 1.0 and dist <= nr + req + 2.0
    print('sac %s: labelled %.1f mm², nearest labelled face %.2f mm and centroid %.2f mm from the true neck centre (neck radius %.2f mm)'
          % ('found' if ok else 'NOT found', area, touch, dist, nr))
    return 0 if ok else 1


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1], sys.argv[2]))
