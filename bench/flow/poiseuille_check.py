#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
# Reads the converged OpenFOAM pipe case of poiseuille_openfoam.sh and compares it with Hagen–Poiseuille:
# the developed pressure gradient (cells 20–38 mm from the inlet), the wall shear stress there, and the mass balance.
# Writes bench/results/flow/poiseuille.md. Stdlib only.
import os, re, sys

case, R, L, U, NU, t_mesh, t_solve, N, M, NX = sys.argv[1:11]
R, L, U, NU = float(R) * 1e-3, float(L) * 1e-3, float(U), float(NU)
RHO = 1060.0
times = sorted((d for d in os.listdir(case) if re.fullmatch(r"[0-9.e+-]+", d) and d != "0"), key=float)
last = os.path.join(case, times[-1])

def numbers(s):
    return [float(x) for x in re.findall(r"[-+0-9.eE]+", s)]

def internal(path, vector):
    txt = open(path).read()
    m = re.search(r"internalField\s+nonuniform\s+List<\w+>\s*(\d+)\s*\(", txt)
    n, start = int(m.group(1)), m.end()
    vals = numbers(txt[start:txt.index("\n)", start)])
    return [vals[3 * i:3 * i + 3] for i in range(n)] if vector else vals[:n]

def patch_values(path, patch, vector):
    txt = open(path).read()
    b = txt.index("boundaryField")
    m = re.search(r"\n\s*" + patch + r"\s*\{", txt[b:])
    blk = txt[b + m.end():]
    blk = blk[:blk.index("\n    }")]
    m = re.search(r"value\s+nonuniform\s+List<\w+>\s*(\d+)\s*\(", blk)
    if not m:
        m2 = re.search(r"value\s+uniform\s+(\(?[^;]*\)?);", blk)
        return None if not m2 else numbers(m2.group(1))
    n, start = int(m.group(1)), m.end()
    vals = numbers(blk[start:blk.index("\n)", start)])
    return [vals[3 * i:3 * i + 3] for i in range(n)] if vector else vals[:n]

C = internal(os.path.join(last, "C"), True)
p = internal(os.path.join(last, "p"), False)
sel = [(c[0], pv) for c, pv in zip(C, p) if 0.020 <= c[0] <= 0.038]
n = len(sel)
mx = sum(x for x, _ in sel) / n
my = sum(v for _, v in sel) / n
slope = sum((x - mx) * (v - my) for x, v in sel) / sum((x - mx) ** 2 for x, _ in sel)  # kinematic, 1/s² · m
hp = -8 * NU * U / R ** 2
wall_c = patch_values(os.path.join(last, "C"), "wall", True)
wss = patch_values(os.path.join(last, "wallShearStress"), "wall", True)
tw = [(sum(v * v for v in w)) ** 0.5 for c, w in zip(wall_c, wss) if 0.020 <= c[0] <= 0.038]
tw_mean = sum(tw) / len(tw)
tw_hp = 4 * NU * U / R
phi_in = sum(patch_values(os.path.join(last, "phi"), "inlet", False))
phi_out = sum(patch_values(os.path.join(last, "phi"), "outlet", False))
log = open(os.path.join(case, "log.simpleFoam")).read()
iters = len(re.findall(r"^Time = ", log, re.M))
converged = re.search(r"solution converged in \d+ iterations", log) is not None
cells = len(p)
ep = abs(slope - hp) / abs(hp)
ew = abs(tw_mean - tw_hp) / tw_hp
em = abs(phi_in + phi_out) / abs(phi_in)
here = os.path.dirname(os.path.abspath(__file__))
out = os.path.join(here, "..", "results", "flow")
os.makedirs(out, exist_ok=True)
re_num = U * 2 * R / NU
snappy = N == "snappy"
if snappy:
    title = "snappyHexMesh from a lumen surface"
    how = (f"`bash bench/flow/poiseuille_snappy.sh {M} {NX}`: the pipe given as a closed STL surface with wall, inlet and outlet "
           f"regions (as `aneuprep flow` would write it from a lumen), meshed by snappyHexMesh: {M} mm background cells, "
           f"snapped to the surface, {NX} boundary layers at the wall (expansion 1.2)")
    mesh = f"{cells:,} cells (hexahedra and the layers' prisms)"
else:
    title = "a structured blockMesh pipe"
    how = (f"`bash bench/flow/poiseuille_openfoam.sh {N} {M} {NX}`: a structured O-grid pipe from blockMesh "
           f"({N} × {N} core, 4 × {N} × {M} around, graded 3:1 towards the wall, {NX} along the pipe)")
    mesh = f"{cells:,} hexahedra"
with open(os.path.join(out, "poiseuille_snappy.md" if snappy else "poiseuille.md"), "w") as f:
    f.write(f"""# OpenFOAM on this machine: steady pipe flow against Hagen–Poiseuille, {title} (issue #17)

{how}. Debian's `openfoam` (v1912, binaries in /usr/bin). R = {R*1e3:g} mm, L = {L*1e3:g} mm, blood ρ = {RHO:g} kg/m³,
μ = {NU*RHO*1e3:.2f} mPa·s, plug inflow {U*100:g} cm/s (Re = {re_num:.0f}, entrance length ≈ 0.06 Re D = {0.06*re_num*2*R*1e3:.1f} mm),
outlet p = 0, laminar simpleFoam (linearUpwind, consistent SIMPLE) to residuals 1e-7 (p) and 1e-8 (U).

| quantity | OpenFOAM | Hagen–Poiseuille | error |
|---|---|---|---|
| pressure gradient, developed (cells 20–38 mm) [Pa/mm] | {-slope*RHO*1e-3:.5f} | {-hp*RHO*1e-3:.5f} | {100*ep:.2f} % |
| wall shear stress, mean over 20–38 mm [Pa] | {tw_mean*RHO:.5f} | {tw_hp*RHO:.5f} (4μU/R) | {100*ew:.2f} % |
| mass balance: (inflow − outflow) / inflow | {em:.2e} | 0 | |

- Mesh: {mesh}.
- Time on this machine (1 core): meshing {float(t_mesh):.1f} s, simpleFoam {float(t_solve):.1f} s for {iters} iterations ({'converged to the residual controls' if converged else 'stopped at the iteration limit, NOT converged'}).
""")
print(f"dp/dx error {100*ep:.2f} %, WSS error {100*ew:.2f} %, mass {em:.2e}, {cells} cells, {iters} iterations, converged {converged}, solve {float(t_solve):.1f} s")
