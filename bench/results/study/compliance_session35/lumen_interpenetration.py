#!/usr/bin/env python3
"""Inner walls through each other anywhere on a lumen OBJ (aneusim's ANEU_LUMEN_OBJ), not only on the neck line.

For each vertex, every face within 0.25 mm of its plane whose corners are outside the vertex's two rings and over
which the vertex projects: the vertex's signed distance along the face's normal. The OBJ's normals point out of the
lumen (checked at the end), so a positive distance is a vertex through the opposite wall; negative ones are the
lumen's gaps and the surface's own curvature. Prints the deepest of both signs.

usage: python3 lumen_interpenetration.py LUMEN.obj   (pure Python, a minute on the sample)
"""
import sys, math
from collections import defaultdict
V=[];F=[]
for l in open(sys.argv[1]):
    if l.startswith('v '): V.append(tuple(map(float,l.split()[1:4])))
    elif l.startswith('f '): F.append(tuple(int(x.split('/')[0])-1 for x in l.split()[1:4]))
nbr=defaultdict(set)
for f in F:
    for a in f:
        nbr[a].update(f)
def ring2(v):
    s=set(nbr[v])
    for u in list(s): s|=nbr[u]
    return s
def sub(a,b): return (a[0]-b[0],a[1]-b[1],a[2]-b[2])
def dot(a,b): return a[0]*b[0]+a[1]*b[1]+a[2]*b[2]
def cross(a,b): return (a[1]*b[2]-a[2]*b[1],a[2]*b[0]-a[0]*b[2],a[0]*b[1]-a[1]*b[0])
H=0.3
grid=defaultdict(list)
for i,f in enumerate(F):
    c=[sum(V[k][d] for k in f)/3 for d in range(3)]
    grid[tuple(int(math.floor(x/H)) for x in c)].append(i)
res=[]
for v in range(len(V)):
    p=V[v]; ex=ring2(v); g=tuple(int(math.floor(x/H)) for x in p)
    for dx in (-1,0,1):
     for dy in (-1,0,1):
      for dz in (-1,0,1):
        for i in grid.get((g[0]+dx,g[1]+dy,g[2]+dz),()):
            f=F[i]
            if ex & set(f): continue
            a,b,c=V[f[0]],V[f[1]],V[f[2]]
            e1=sub(b,a);e2=sub(c,a);n=cross(e1,e2);ln=math.sqrt(dot(n,n))
            if ln==0: continue
            n=tuple(x/ln for x in n); w=sub(p,a); d=dot(n,w)
            if abs(d)>0.25: continue
            d11=dot(e1,e1);d12=dot(e1,e2);d22=dot(e2,e2);w1=dot(w,e1);w2=dot(w,e2);den=d11*d22-d12*d12
            b1=(d22*w1-d12*w2)/den;b2=(d11*w2-d12*w1)/den;b0=1-b1-b2
            if min(b0,b1,b2)<0: continue
            res.append((d,v,i,p))
res.sort()
print('most negative:'); [print('%.4f v%d f%d (%.3f %.3f %.3f)'%(d,v,i,*p)) for d,v,i,p in res[:8]]
print('most positive:'); [print('%.4f v%d f%d (%.3f %.3f %.3f)'%(d,v,i,*p)) for d,v,i,p in res[-8:]]
neg=[r for r in res if r[0]<0]; pos=[r for r in res if r[0]>0]
print(len(neg),len(pos))
C=[sum(v[d] for v in V)/len(V) for d in range(3)]
s=0
for f in F:
    a,b,c=V[f[0]],V[f[1]],V[f[2]]
    n=cross(sub(b,a),sub(c,a)); cc=[(a[d]+b[d]+c[d])/3-C[d] for d in range(3)]
    s+=dot(n,cc)
print('sum n.(c-C) (positive: outward normals):', s)
