# Usage: python3 neck_line_in_jaw_frame.py LUMEN.obj  (an OBJ of sim::write_lumen_obj: ANEU_LUMEN_OBJ, aneu_bench_compliance --lumen-obj); the clip frame below is the sample plan's (plan.json beside this)
import sys
o=[8.5366,1.5452,0.7232]; a=[-0.999929,0.0058,-0.0104]; n=[0.011873,0.418718,-0.908039]
def cross(u,v): return [u[1]*v[2]-u[2]*v[1],u[2]*v[0]-u[0]*v[2],u[0]*v[1]-u[1]*v[0]]
def dot(u,v): return sum(x*y for x,y in zip(u,v))
b=cross(n,a)
pts=[]
for l in open(sys.argv[1]):
    if l.startswith('# neck'):
        p=l.split(); pts.append([float(x) for x in p[3:7]])
for i,(x,y,z,g) in enumerate(pts):
    q=[x-o[0],y-o[1],z-o[2]]
    print(f"{i:3d} s={dot(q,a):7.2f} n={dot(q,n):6.2f} b={dot(q,b):6.2f} gap={g:8.4f} {'OPEN' if g>0.05 else ''}")
