#!/usr/bin/env python3
"""Patch frame times from aneusim's ANEU_PATCH_TRACE output (plain or .gz): median, mean, frames in the air (no blade
contact) and pressed, the whole. The first frame (which holds the patch's linearisation) is left out.

usage: python3 frame_times.py TRACE [TRACE ...]
"""
import sys,re,gzip
def load(f):
    op=gzip.open if f.endswith('.gz') else open
    out=[]
    for l in op(f,'rt'):
        m=re.match(r'patch t=([\d.]+) theta .*contacts (\d+)/(\d+).* ([\d.]+) ms \((?:wall|compliance)',l)
        if m: out.append((float(m.group(1)),int(m.group(2))+int(m.group(3)),float(m.group(4))))
    return out
for f in sys.argv[1:]:
    fr=load(f)[1:]  # the first holds the linearisation
    ms=sorted(x[2] for x in fr); pr=[x[2] for x in fr if x[1]>0]; air=sorted(x[2] for x in fr if x[1]==0)
    print(f.split('/')[-1],len(fr),'frames: p50 %.1f mean %.1f ms; air %d p50 %.1f; pressed %d mean %.0f ms; total %.1f s'%(ms[len(ms)//2],sum(ms)/len(ms),len(air),air[len(air)//2],len(pr),sum(pr)/len(pr),sum(ms)/1000))
