# SPDX-License-Identifier: MIT
# Lumen vertices through the lumen's own faces near the neck line's deepest point: a run's end lumen as ANEU_LUMEN_OBJ
# writes it (faces oriented out of the lumen, `# neck LOOP X Y Z GAP` lines). Every vertex within 0.8 mm of the point
# against every face within 1 mm that is not within two rings of it: through it by 0.005-0.3 mm with its projection
# inside the face. (Session 44: whether the assessment's negative gap on C0054's neck line is a vertex through a face.)
#   python3 bench/lumen_vertex_crossings.py LUMEN.obj
import sys, math
obj = sys.argv[1]
V=[]; F=[]; neck=[]
for l in open(obj):
    if l.startswith('v '): V.append(tuple(map(float,l.split()[1:4])))
    elif l.startswith('f '): F.append(tuple(int(t.split('/')[0])-1 for t in l.split()[1:4]))
    elif l.startswith('# neck '):
        p=l.split(); neck.append((tuple(map(float,p[3:6])), float(p[6])))
worst=min(neck,key=lambda x:x[1]); c=worst[0]
print('worst neck point', c, worst[1])
sub=lambda a,b:(a[0]-b[0],a[1]-b[1],a[2]-b[2]); dot=lambda a,b:a[0]*b[0]+a[1]*b[1]+a[2]*b[2]
cross=lambda a,b:(a[1]*b[2]-a[2]*b[1],a[2]*b[0]-a[0]*b[2],a[0]*b[1]-a[1]*b[0])
near=lambda p,r: dot(sub(p,c),sub(p,c))<r*r
vs=[i for i,p in enumerate(V) if near(p,0.8)]
fs=[j for j,f in enumerate(F) if any(near(V[k],1.0) for k in f)]
nb={}
for j,f in enumerate(F):
    for k in f: nb.setdefault(k,set()).update(f)
def ring(v,n):
    s={v}
    for _ in range(n): s=set().union(*[nb[x] for x in s])
    return s
out=[]
for v in vs:
    r=ring(v,2); p=V[v]
    for j in fs:
        f=F[j]
        if any(k in r for k in f): continue
        a,b,cc=(V[k] for k in f); e1=sub(b,a); e2=sub(cc,a); n=cross(e1,e2); ln=math.sqrt(dot(n,n))
        if ln==0: continue
        n=tuple(x/ln for x in n); w=sub(p,a); d=dot(w,n)
        if d<0.005 or d>0.3: continue
        d11=dot(e1,e1); d12=dot(e1,e2); d22=dot(e2,e2); w1=dot(w,e1); w2=dot(w,e2); den=d11*d22-d12*d12
        b1=(d22*w1-d12*w2)/den; b2=(d11*w2-d12*w1)/den; b0=1-b1-b2
        if min(b0,b1,b2)<0: continue
        out.append((d,v,j))
out.sort(reverse=True)
print(len(out),'vertex-face crossings (0.005-0.3 mm through, projection inside, not within 2 rings) within 0.8 mm of it; deepest:')
for d,v,j in out[:8]: print('  vertex %d through face %d by %.4f mm' % (v,j,d))
