# SPDX-License-Identifier: MIT
"""Report of the speed/accuracy study: bench/run_study.sh's JSON lines -> study.md and PNG plots.

Errors are against the reference point (the finest quadratic model, full FEM, double):
  force error  |F - F_ref| / F_ref, F = the force of an indenter pushing the sac's apex in by 0.2 mm (a smooth
               bump of radius 1.5 mm), the generalised force conjugate to the depth (sum of r_v . u_v / depth);
  displacement error  ||u - u_ref|| / ||u_ref|| over 26 probe points on the outer surface 4 mm around it.
The 'W route' is what the simulator computes (condensed W in its precision); the 'FEM route' the same model
solved directly in double: their difference is the cost of condensation and storage precision.
"""
import json
import math
import os
import sys


def err_u(p, ref):
    num = sum((a - b) ** 2 for pa, pr in zip(p, ref) for a, b in zip(pa, pr))
    den = sum(b ** 2 for pr in ref for b in pr)
    return math.sqrt(num / den)


def phantom_section(path, w):
    rows = [json.loads(l) for l in open(path) if l.strip()]
    if not rows:
        return
    ref = next(r for r in rows if r.get("reference"))
    w("\n## The sample phantom case (CT → every stage), W float32\n")
    w(f"Reference: surface edge {ref['h']} mm, order {ref['element_order']}, {ref['nodes']} nodes, {ref['dofs']} DOFs, full FEM "
      f"(solve {ref['fem_solve_s']:.1f} s): indenter force {ref['force_fem_n']:.4g} N at the sac's apex.\n")
    w("| edge [mm] | order | nodes | tets | kept DOFs | W [MB] | segment / surface / wall / tetmesh / assemble / condense [s] | load [s] | update 100 [Hz] | update 300 [Hz] | force error | u error |")
    w("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted((r for r in rows if not r.get("reference")), key=lambda r: (-r["h"], r["element_order"])):
        e_f = abs((r.get("force_w_n", r["force_fem_n"])) - ref["force_fem_n"]) / ref["force_fem_n"]
        e_u = err_u(r.get("probes_w", r["probes_fem"]), ref["probes_fem"])
        sd = r.get("stage_s", {})
        st = " / ".join(f"{sd.get(k, 0):.1f}" for k in ("segment", "surface", "wall", "tetmesh", "assemble"))
        st += f" / {r['condense_s']:.1f}" if "condense_s" in r else " / -"
        if "force_w_n" in r:
            w(f"| {r['h']} | {r['element_order']} | {r['nodes']} | {r['tets']} | {r['kept_dofs']} | {r['W_bytes'] / 2**20:.0f} | {st} | "
              f"{r['load_s']:.2f} | {r.get('update_hz_100', float('nan')):.0f} | {r.get('update_hz_300', float('nan')):.0f} | {e_f:.3%} | {e_u:.3%} |")
        else:
            w(f"| {r['h']} | {r['element_order']} | {r['nodes']} | {r['tets']} | (FEM only) | - | {st} | - | - | - | {e_f:.3%} | {e_u:.3%} |")
    w("")


def closure_section(path, outdir, w):
    """Linear vs large deformation: bench/bench_closure.cpp's lines (one per closure, a summary last)."""
    rows = [json.loads(l) for l in open(path) if l.strip()]
    summ = next((r for r in rows if r.get("summary")), None)
    steps = [r for r in rows if "closure" in r and "failed" not in r]
    failed = [r for r in rows if "failed" in r]
    if not steps or not summ:
        return
    what = summ.get("label", "sac")
    w(f"\n### Clip closing on the {what}\n")
    mats = ", ".join(f"{m['region']} E {m['E_mpa']:g} MPa, ν {m['nu']:g}" for m in summ["materials"])
    c = summ["clip_centre"]
    w(f"Model: {summ['nodes']} nodes, {summ['tets']} tets, order {summ['element_order']}, {summ['dofs']} DOFs ({mats}); the "
      f"neo-Hookean reference uses the same mesh, elements, quadrature and materials (its tangent at rest equals K to "
      f"{summ['tangent_at_rest_vs_K']:.1e}), solved by Newton's method (bench/bench_closure.cpp, fem::solve_neo_hookean).\n")
    where = {"sac": "across the sac's neck", "artery": "across the parent artery beside the sac (4 mm from its centre along the artery)"}.get(what, "")
    w(f"Clip: two flat blades {summ['blade_width_mm']} mm wide and {summ['blade_length_mm']} mm long along the parent artery, centred "
      f"at ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) {where}, closing along y from touching (gap {summ['gap0_mm']:.2f} mm, closure 0) to "
      f"{summ['full_gap_mm']} mm (twice the {summ['full_gap_mm'] / 2:g} mm wall under the blades: lumen closed, closure 1). Contact as in the simulator (nodes through a blade are "
      f"prescribed onto it and stick; adhesive ones are released), iterated to a settled contact set for each model. "
      f"Errors of the linear model: clip force (the y force of one blade) and displacement of the {summ['probe_nodes']} outer nodes "
      f"within {summ['region_mm']} mm of the clip centre (RMS), both relative to the neo-Hookean solution.\n")
    w("| closure | gap [mm] | force, linear [N] | force, neo-Hookean [N] | force error | displacement error | max |u| [mm] | contact nodes lin / NH | min det F | Newton iterations (cumulative) | time lin / NH [s] (cumulative) |")
    w("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in steps:
        w(f"| {r['closure']:g} | {r['gap_mm']:.2f} | {r['force_linear_N']:.4g} | {r['force_nonlinear_N']:.4g} | {r['force_error']:.1%} | "
          f"{r['u_error']:.1%} | {r['u_max_mm']:.2f} | {r['contacts_linear']} / {r['contacts_nonlinear']} | {r['min_J']:.3f} | "
          f"{r['newton_iterations']} | {r['seconds_linear']:.0f} / {r['seconds_nonlinear']:.0f} |")
    for r in failed:
        w(f"\nThe neo-Hookean solve stopped at closure {r['closure']:g} (gap {r['gap_mm']:.2f} mm): {r['failed']}\n")
    cf, cu = summ["closure_force_error_10pct"], summ["closure_u_error_10pct"]
    t = summ["full_gap_mm"] / 2  # the wall under the blades (full closure = two walls)

    def fmt(x):
        if x < 0:
            return "not within the closures run"
        travel = x * (summ["gap0_mm"] - summ["full_gap_mm"]) / 2
        return (f"{x:.3f} (gap {summ['gap0_mm'] - 2 * travel:.2f} mm; each blade has pushed {travel:.3f} mm = "
                f"{travel / t:.2f} wall thicknesses of {t:g} mm)")
    w(f"\n**The linear model's error passes 10 %** at closure {fmt(cf)} for the clip force and {fmt(cu)} for the clip-region "
      f"displacement (linear interpolation between the closures above, from zero error at closure 0).\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
        x = [r["closure"] for r in steps]
        a1.plot(x, [r["force_linear_N"] for r in steps], "o-", label="linear (simulator)")
        a1.plot(x, [r["force_nonlinear_N"] for r in steps], "s-", label="neo-Hookean")
        a1.set_xlabel("closure")
        a1.set_xscale("log")
        a1.set_ylabel("clip force [N]")
        a1.legend(fontsize=8)
        a1.grid(True, alpha=0.3)
        a2.plot(x, [100 * r["force_error"] for r in steps], "o-", label="clip force")
        a2.plot(x, [100 * r["u_error"] for r in steps], "s-", label="clip-region displacement")
        a2.axhline(10, color="k", lw=0.8, ls="--")
        a2.set_yscale("log")
        a2.set_xscale("log")
        a2.set_xlabel("closure")
        a2.set_ylabel("linear model's error [%]")
        a2.legend(fontsize=8)
        a2.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(outdir, f"closure_error_{what}.png"), dpi=110)
        plt.close(fig)
        w(f"![closure_error_{what}.png](closure_error_{what}.png)\n")
        secs = [r for r in steps if "section" in r]
        if secs:
            nc = min(2, len(secs))
            nr = (len(secs) + nc - 1) // nc
            fig, axs = plt.subplots(nr, nc, figsize=(5.5 * nc, 4.6 * nr), squeeze=False)
            for ax in axs.flat[len(secs):]:
                ax.axis("off")
            for ax, r in zip(axs.flat, secs):
                s = r["section"]
                ax.plot([p[0] for p in s], [p[1] for p in s], ".", ms=2, color="0.7", label="at rest")
                ax.plot([p[2] for p in s], [p[3] for p in s], ".", ms=2, color="tab:blue", label="linear")
                ax.plot([p[4] for p in s], [p[5] for p in s], ".", ms=2, color="tab:red", label="neo-Hookean")
                g = r["gap_mm"] / 2
                x0, hw = summ["clip_centre"][0], summ["blade_width_mm"] / 2
                for yy in (g, -g):
                    ax.plot([x0 - hw, x0 + hw], [summ["clip_centre"][1] + yy] * 2, "k-", lw=2)
                ax.set_aspect("equal")
                ax.set_title(f"closure {r['closure']:g}: section through the clip", fontsize=9)
                ax.set_xlabel("x [mm]")
                ax.set_ylabel("y [mm]")
                ax.legend(fontsize=7, markerscale=4)
            fig.tight_layout()
            fig.savefig(os.path.join(outdir, f"closure_sections_{what}.png"), dpi=110)
            plt.close(fig)
            w(f"![closure_sections_{what}.png](closure_sections_{what}.png)\n")
    except ImportError:
        pass


def recommended_section(pts, regions, w):
    """The defaults the sweep implies, with the figures they give (from the rows above)."""
    cand = [r for r in pts if r["element_order"] == 2 and r.get("precision") == "float32" and "force_w_n" in r]
    if not cand:
        return
    # The coarsest quadratic float32 model whose force error is within 5 %, else the most accurate one (the update
    # rate comes from the working region, below).
    ok = [r for r in cand if r["e_force_w"] <= 0.05]
    pick = max(ok, key=lambda r: r["h"]) if ok else min(cand, key=lambda r: r["e_force_w"])
    lin = [r for r in pts if r["element_order"] == 1 and "force_w_n" in r and r.get("precision") == "float32"]
    f64 = [r for r in pts if r["element_order"] == 2 and r.get("precision") == "float64" and r["h"] == pick["h"] and "force_w_n" in r]
    w("## Recommended defaults\n")
    w(f"- **Element order 2 (10-node tetrahedra).** Linear tetrahedra lock in bending on the thin sac wall: their force error "
      f"is {min(r['e_force_w'] for r in lin):.0%}–{max(r['e_force_w'] for r in lin):.0%} at every mesh size here, "
      f"against {min(r['e_force_w'] for r in cand):.1%}–{max(r['e_force_w'] for r in cand):.1%} for quadratic ones." if lin else
      "- **Element order 2.**")
    w(f"- **Edge length {pick['h']} mm** (tube with sac; the phantom's surface edge 0.45–0.6 mm gives the same accuracy, "
      f"table below): force error {pick['e_force_w']:.1%}, displacement error {pick['e_u_w']:.1%}, {pick['kept_dofs']} kept DOFs, "
      f"precompute {pick['precompute_s']:.1f} s; with every outer node condensed W is {pick['W_bytes'] / 2**20:.0f} MB, loads in "
      f"{pick['load_s']:.2f} s and updates at {pick.get('update_changed_hz_100', float('nan')):.0f} Hz with 100 changing contact "
      f"nodes ({pick.get('update_hz_300', float('nan')):.0f} Hz with 300) — the working region below brings it to haptic rate.")
    if f64:
        r = f64[0]
        w(f"- **W in float32.** Against float64 it changes the answer by {pick['e_u_w_vs_fem']:.0e} (relative to the model's own FEM "
          f"solution; float64 {r['e_u_w_vs_fem']:.0e}), far below the discretisation error, and halves W ({pick['W_bytes'] / 2**20:.0f} "
          f"vs {r['W_bytes'] / 2**20:.0f} MB) and the load time ({pick['load_s']:.2f} vs {r['load_s']:.2f} s) while raising the "
          f"update rate ({pick.get('update_changed_hz_100', 0):.0f} vs {r.get('update_changed_hz_100', 0):.0f} Hz).")
    if regions:
        r4 = [r for r in regions if abs(r["region_mm"] - 4) < 1e-9]
        if r4:
            r = r4[0]
            w(f"- **A working region of 4–6 mm around where the instruments work** instead of all outer nodes: exact inside it "
              f"(the same answer), at h {r['h']} mm W {r['W_bytes'] / 2**20:.0f} MB, condensed in {r.get('condense_s', 0):.1f} s, loaded "
              f"in {r['load_s']:.2f} s, update {r.get('update_hz_100', float('nan')):.0f} Hz with 100 contact nodes and "
              f"{r.get('update_hz_300', float('nan')):.0f} Hz with 300 (4 mm region).")
    w("- **The linear model only for small pushes.** Past about a third of the wall thickness of pushing (0.31 on the artery, 0.37 "
      "on the sac, last section) its clip forces are more than 10 % too large, and from a few tenths of closure several times too "
      "large; the simulator warns past `contact.linear_limit` = 0.3 wall thicknesses.\n")


# What the code does at each extreme (the test named asserts it).
EXTREMES = [
    ("ν → 0.5 (0.3 … 0.4999)", "NearIncompressibleLinearTetsLockQuadraticTetsDoNot",
     "linear tets lock (too stiff); quadratic ones do not; `assemble` warns for ν ≥ 0.49 with 4-node tets, naming the region"),
    ("wall 0.4 → 0.05 mm, one element through it", "VeryThinWallWithOneElementThroughTheThickness",
     "bounded error in membrane action; in bending linear tets lock (study above): quadratic is the default"),
    ("E 1–300 MPa, sac/artery contrast up to 300×, ν 0.4999", "StiffnessRangeContrastAndNearIncompressibility",
     "simulator equals FEM; float32's error stays below 10·cond·ε, the condition the simulator estimates"),
    ("contact sets of adjacent nodes; several hundred nodes", "CrowdedContactSetsRaiseTheConditionEstimate",
     "cond₁(W_CC) estimated twice a second; warning when the forces keep few digits; reported maximum"),
    ("float32 W over a long session (6,000 factor updates)", "LongSessionOfFactorUpdatesDoesNotDrift",
     "every solve checks W_CC f = u and recomputes a factor that drifted"),
    ("sliver tetrahedra", "AssembleNamesSliverTetrahedra",
     "`assemble` computes every tet's quality, stores the minimum, warns naming count, worst and where (< 1e-3)"),
    ("near-degenerate surface triangles", "NearDegenerateSurfaceTrianglesGiveSliversThatAreNamed",
     "TetGen keeps them; the slivers they make are named by `assemble`"),
    ("pushes beyond the linear model's range (clip on a 0.4 mm wall)", "TwoClipsReleasedAndOneRepositioned",
     "aneusim warns once when a prescribed displacement exceeds `contact.linear_limit` × the local wall thickness, reports the largest ratio"),
]


def extremes_section(path, w):
    """The tests' own figures (bench/run_study.sh runs them and keeps their output)."""
    cur, status, figs = None, {}, {}
    for line in open(path):
        line = line.rstrip("\n")
        if line.startswith("[ RUN"):
            cur = line.split()[-1]
            figs.setdefault(cur, [])
        elif line.startswith("[       OK") or line.startswith("[  FAILED"):
            status[line.split()[3] if line.startswith("[       OK") else line.split()[3]] = "passed" if "OK" in line else "FAILED"
        elif cur and not line.startswith(("Running main", "Note: Google Test")):
            figs[cur].append(line)
    w("\n## Stability at the extremes\n")
    w("Each row is a test that asserts the behaviour (`ctest`); its figures, as it printed them in this run.\n")
    w("| extreme | test | result | figures | what the code does |")
    w("|---|---|---|---|---|")
    for what, key, does in EXTREMES:
        names = [n for n in figs if key in n]
        if not names:
            w(f"| {what} | {key} | not run | - | {does} |")
            continue
        lines = [l for n in names for l in figs[n]]
        res = ", ".join(sorted({status.get(n, "?") for n in names}))
        shown = "<br>".join(lines[:8]) if lines else "(asserts only)"
        w(f"| {what} | {', '.join(names)} | {res} | {shown} | {does} |")
    w("")


def main(jsonl, outdir, phantom=None, closure=None, extremes=None):
    rows = [json.loads(l) for l in open(jsonl) if l.strip()]
    ref = next(r for r in rows if r.get("reference"))
    pts = [r for r in rows if not r.get("reference") and "region_mm" not in r]
    regions = [r for r in rows if "region_mm" in r]
    for r in pts + regions:
        r["e_force_fem"] = abs(r["force_fem_n"] - ref["force_fem_n"]) / ref["force_fem_n"]
        r["e_u_fem"] = err_u(r["probes_fem"], ref["probes_fem"])
        if "force_w_n" in r:
            r["e_force_w"] = abs(r["force_w_n"] - ref["force_fem_n"]) / ref["force_fem_n"]
            # probes outside a working region have no W-route answer: the same model's FEM answer stands in
            r["e_u_w"] = err_u(r.get("probes_w", r["probes_fem"]), ref["probes_fem"])
            r["e_u_w_vs_fem"] = err_u(r["probes_w"], r["probes_fem"]) if "probes_w" in r else float("nan")
        st = r.get("stage_s", {})
        r["precompute_s"] = sum(st.get(k, 0) for k in ("tubewall", "tetmesh", "assemble")) + r.get("condense_s", 0)
    out = []
    w = out.append
    w("# Speed/accuracy study: tube with a sac of known dimensions\n")
    w(f"Reference: h {ref['h']} mm, order {ref['element_order']}, {ref['nodes']} nodes, {ref['tets']} tets, {ref['dofs']} DOFs, "
      f"full FEM in double (solve {ref['fem_solve_s']:.1f} s): indenter force {ref['force_fem_n']:.4g} N "
      f"({ref['clip_nodes']} nodes pushed in, up to 0.2 mm, around the sac's apex).\n")
    w("Produced by `bash bench/run_study.sh` (see its header); errors as defined in bench/study_report.py. Condition numbers: "
      "cond₂ of K on the free DOFs and of the Schur complement S = W⁻¹ on the condensed DOFs by power iteration (lower "
      "bounds that converge; S's smallest eigenvalue is 1/λmax(W)); cond₁ of the indenter's W_CC by Hager's estimate, as "
      "the simulator computes it. By interlacing cond(S) ≤ cond(K_ff), and W_CC, a principal block of W, has cond₂ ≤ cond₂(S).\n")
    w("| h [mm] | order | precision | nodes | tets | kept DOFs | W [MB] | precompute [s] | load [s] | update 100 [Hz] | update 300 [Hz] | "
      "100, set changing [Hz] | force error | u error | u error of W vs its FEM | cond₂(K_ff) | cond₂(S) | cond₁(W_CC) indenter | W residual |")
    w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(pts, key=lambda r: (-r["h"], r["element_order"], r.get("precision", ""))):
        if "force_w_n" in r:
            w(f"| {r['h']} | {r['element_order']} | {r['precision']} | {r['nodes']} | {r['tets']} | {r['kept_dofs']} | "
              f"{r['W_bytes'] / 2**20:.0f} | {r['precompute_s']:.1f} | {r['load_s']:.2f} | {r.get('update_hz_100', float('nan')):.0f} | "
              f"{r.get('update_hz_300', float('nan')):.0f} | {r.get('update_changed_hz_100', float('nan')):.0f} | "
              f"{r['e_force_w']:.3%} | {r['e_u_w']:.3%} | {r['e_u_w_vs_fem']:.1e} | {r.get('cond_K_free', float('nan')):.2g} | "
              f"{r.get('cond_schur', float('nan')):.2g} | {r['wcc_condition']:.3g} | {r['condense_residual_max_rel']:.1e} |")
        else:
            w(f"| {r['h']} | {r['element_order']} | (FEM only: W too large) | {r['nodes']} | {r['tets']} | - | - | "
              f"{r['precompute_s']:.1f} | - | - | - | - | {r['e_force_fem']:.3%} | {r['e_u_fem']:.3%} | - | - | - | - | - |")
    w("")
    if regions:
        w("## Condensed set: working regions around the indenter (quadratic, float32)\n")
        w("| h [mm] | region radius [mm] | kept DOFs | W [MB] | condense [s] | load [s] | update 100 [Hz] | update 300 [Hz] | force error | u error |")
        w("|---|---|---|---|---|---|---|---|---|---|")
        full = [r for r in pts if r["element_order"] == 2 and r.get("precision") == "float32" and r["h"] == regions[0]["h"]]
        for r in sorted(regions, key=lambda r: r["region_mm"]) + full:
            w(f"| {r['h']} | {r.get('region_mm', 'all outer nodes')} | {r['kept_dofs']} | {r['W_bytes'] / 2**20:.0f} | {r.get('condense_s', 0):.1f} | "
              f"{r['load_s']:.2f} | {r.get('update_hz_100', float('nan')):.0f} | {r.get('update_hz_300', float('nan')):.0f} | "
              f"{r['e_force_w']:.3%} | {r['e_u_w']:.3%} |")
        w("\nThe indenter lies inside every region, so its force does not change; probes outside a region (the 2.5 mm one "
          "leaves some of the 26 out) are read from the same model's FEM. A region costs only where the simulated "
          "instruments may go (a 300-node patch then covers most of the smallest region).\n")
    plots = []
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        wpts = [r for r in pts if "force_w_n" in r]
        for key, xlabel, fname in (("precompute_s", "precompute time [s]", "error_vs_precompute.png"),
                                   ("update_changed_hz_100", "update rate, 100 contact nodes, set changing [Hz]", "error_vs_rate.png")):
            fig, ax = plt.subplots(figsize=(6.4, 4.2))
            for order, mk in ((1, "o"), (2, "s")):
                for prec, col in (("float32", "tab:blue"), ("float64", "tab:orange")):
                    sel = [r for r in wpts if r["element_order"] == order and r["precision"] == prec]
                    if sel:
                        ax.plot([r[key] for r in sel], [100 * r["e_u_w"] for r in sel], mk, color=col,
                                label=f"order {order}, {prec}")
                        for r in sel:
                            ax.annotate(f"h {r['h']}", (r[key], 100 * r["e_u_w"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("displacement error vs reference [%]")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
            fig.tight_layout()
            fig.savefig(os.path.join(outdir, fname), dpi=110)
            plt.close(fig)
            plots.append(fname)
    except ImportError:
        w("(No plots: python3-matplotlib is not installed.)\n")
    for p in plots:
        w(f"![{p}]({p})\n")
    recommended_section(pts, regions, w)
    if phantom and os.path.exists(phantom):
        phantom_section(phantom, w)
    if extremes and os.path.exists(extremes):
        extremes_section(extremes, w)
    closure_files = [f for f in (closure or "").split(",") if f and os.path.exists(f)]
    if closure_files:
        w("\n## Linear vs large deformation: a clip closing\n")
        for f in closure_files:
            closure_section(f, outdir, w)
    open(os.path.join(outdir, "study.md"), "w").write("\n".join(out) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:6])
