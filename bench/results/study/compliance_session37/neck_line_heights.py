#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The neck line of an aneusim report in the clip's frame: per point its distance along the blades from the hinge,
its offset along the closing direction, its height across the jaws' width (+ towards the parent, - towards the sac;
the jaws span +-jaw_width/2) and its gap. The clip's pose from the scene's applier: axis and up (the closing
direction) from its first keyframe, the hinge from the first that closes it (opening 0: where the applier holds it).

usage: neck_line_heights.py SCENE.json REPORT.json"""
import json
import math
import sys


def load_json(path):
    text = open(path).read()
    return json.loads(text[text.index('{'):])  # planned scenes start with // comment lines


def dot(a, b): return sum(x * y for x, y in zip(a, b))
def sub(a, b): return [x - y for x, y in zip(a, b)]
def scale(a, s): return [x * s for x in a]
def unit(a): return scale(a, 1 / math.sqrt(dot(a, a)))
def cross(a, b): return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


scene, report = load_json(sys.argv[1]), load_json(sys.argv[2])
keys = next(i for i in scene['instruments'] if i['kind'] == 'clip_applier')['keyframes']
k0 = keys[0]
hinge = next(k for k in keys if k.get('opening_deg') == 0)['position']  # where the applier closes the clip
axis = unit(k0['axis'])
up = unit(sub(k0['up'], scale(axis, dot(k0['up'], axis))))
width = cross(axis, up)
heights = []
print('point along_mm closing_mm height_mm gap_mm')
for i, p in enumerate(report['neck_line']):
    x = sub(p[:3], hinge)
    heights.append(dot(x, width))
    gap = 'open' if p[3] is None else '%.4f' % p[3]
    print('%d %.2f %.2f %.2f %s' % (i, dot(x, axis), dot(x, up), heights[-1], gap))
print('# heights %.2f .. %.2f mm (span %.2f mm)' % (min(heights), max(heights), max(heights) - min(heights)))
