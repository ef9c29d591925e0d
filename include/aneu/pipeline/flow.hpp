// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// `aneuprep flow`: a steady incompressible Navier–Stokes solve in the lumen (the blood domain) with OpenFOAM
/// (snappyHexMesh + simpleFoam as child processes on a generated case), for the residual flow after clipping
/// (issue #17): the undeformed lumen (the pre-clip baseline) or a frame of the simulator's series (the wall's
/// deformation recovered from the simulated surface's, the pinched lumen's reachable part), with the residual
/// sac inflow against the pre-clip value.
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

/// Blood: density 1,060 kg/m³, dynamic viscosity 3.5 mPa·s (Newtonian).
inline constexpr double BLOOD_DENSITY_KG_M3 = 1060.0;
inline constexpr double BLOOD_VISCOSITY_PA_S = 3.5e-3;

/// Parameters of `aneuprep flow`.
struct FlowParams {
    double inflow_cm_s = 30.0;     ///< mean (plug) inflow velocity; 30 cm/s ≈ an ICA's mean (4.8 mL/s in 4.5 mm)
    int inlet_end = -1;            ///< end id of the inlet; -1 = the end with the largest cross-section
    double cell_mm = 0.0;          ///< fluid cell size; 0 = an eighth of the inlet's radius, within [0.1, 0.3]
    int layers = 3;                ///< prism layers at the wall
    int max_iterations = 3000;     ///< SIMPLE iterations at most
    double residual = 1e-6;        ///< converged when p's initial residual is below this and U's below a tenth of it
    double time_budget_s = 600.0;  ///< mesh + solve; the child process is stopped past it (a stage failure)
    std::string case_dir;          ///< keep the OpenFOAM case here (ParaView: case.foam); "" = a temporary folder
    /// The blood domain: "surface" = the capped lumen as it is (it must not self-intersect); "voxel" = the part of
    /// it reachable from the inlet without crossing a wall (reachable_distance + isosurface: a pinched lumen);
    /// "auto" = voxel for a simulator frame (and its pre-clip baseline), surface otherwise.
    std::string domain = "auto";
    std::string series;            ///< the simulator's series (SCENE_series.h5): solve a deformed frame of it
    int frame = -1;                ///< frame of the series; -1 = the last
    /// "newtonian" (3.5 mPa·s) or "carreau-yasuda" (blood, Abraham, Behr & Heinkenschloss 2005: μ0 0.16 Pa·s,
    /// μ∞ 3.5 mPa·s, λ 8.2 s, n 0.2128, a 0.64; OpenFOAM's BirdCarreau with its exponent a).
    std::string viscosity = "newtonian";
    /// "zero-pressure" (every outlet at p = 0) or "murray" (the inflow split by Murray's law, Q ∝ r³, r from each
    /// outlet's area: flowRateOutletVelocity on all but the largest outlet, which stays at p = 0).
    std::string outlets = "zero-pressure";
};

/// Carreau–Yasuda blood (Abraham, Behr & Heinkenschloss 2005): μ = μ∞ + (μ0 − μ∞)(1 + (λγ̇)^a)^((n−1)/a).
inline constexpr double CY_MU0_PA_S = 0.16, CY_MUINF_PA_S = 3.5e-3, CY_LAMBDA_S = 8.2, CY_N = 0.2128, CY_A = 0.64;
inline double carreau_yasuda_pa_s(double shear_rate_per_s) {
    return CY_MUINF_PA_S + (CY_MU0_PA_S - CY_MUINF_PA_S) * std::pow(1 + std::pow(CY_LAMBDA_S * shear_rate_per_s, CY_A), (CY_N - 1) / CY_A);
}

/// The options of `aneuprep flow`, declared once.
inline const opt::Spec<FlowParams>& flow_spec() {
    using namespace opt;
    using P = FlowParams;
    static const Spec<P> spec = [] {
        Spec<P> s("flow");
        s.real("inflow-cm-s", &P::inflow_cm_s, "cm/s", open_closed(0, 500), "mean inflow velocity, plug profile at the inlet end")
            .integer("inlet-end", &P::inlet_end, ge(-1), "end id of the inlet (-1 = the largest end)")
            .real("cell-mm", &P::cell_mm, "mm", closed(0, 2), "fluid cell size (0 = an eighth of the inlet's radius, 0.1 to 0.3 mm)", "auto")
            .integer("layers", &P::layers, closed(0, 10), "prism layers at the wall")
            .integer("max-iterations", &P::max_iterations, closed(10, 100000), "SIMPLE iterations at most")
            .real("residual", &P::residual, "", open_closed(0, 1e-2), "converged below this initial residual of p (U: a tenth)")
            .real("time-budget-s", &P::time_budget_s, "s", gt(0), "mesh + solve stop past this (a stage failure)")
            .text("case-dir", &P::case_dir, {}, "keep the OpenFOAM case in this folder (open case.foam in ParaView)", "a temporary folder, removed")
            .text("domain", &P::domain, {"auto", "surface", "voxel"}, "blood domain: the capped lumen as it is, or the part reachable from the inlet (pinched lumen); auto = voxel for a series frame")
            .text("series", &P::series, {}, "the simulator's series (SCENE_series.h5) of this case: solve its deformed lumen at --frame, and the pre-clip lumen", "the undeformed lumen")
            .integer("frame", &P::frame, ge(-1), "frame of --series (-1 = the last)")
            .text("viscosity", &P::viscosity, {"newtonian", "carreau-yasuda"}, "blood's viscosity model")
            .text("outlets", &P::outlets, {"zero-pressure", "murray"}, "outlet condition: p = 0 at each, or the flow split by Murray's law (Q ~ r^3)");
        return s;
    }();
    return spec;
}

/// The blood domain of a lumen: the lumen surface with each open end closed by a flat cap (a fan from the loop's
/// centroid), labels "wall" and "end_<id>" (the end ids of the lumen's loops), outward, closed and manifold.
/// @throws InputError the lumen has no open end (no inlet), or the capped surface is not closed
SurfaceData blood_domain(const SurfaceData& lumen);

/// The lumen of `lumen` moved by the wall's deformation in frame `frame` (-1 = last) of a simulator series
/// (SCENE_series.h5: the simulated surface's volume nodes and displacements): the displacement of every node of
/// the bundle's mesh with the series' nodes prescribed, the ends fixed and no other load (the linear model the
/// simulator condensed: exact for it), taken at the lumen's vertices (nodes of the mesh).
/// @throws InputError the series lacks the nodes or the frame, or names nodes outside the mesh; the lumen's
///         vertices are not nodes of the mesh
SurfaceData deformed_lumen(const Bundle& bundle, const SurfaceData& lumen, const std::string& series, int frame, Reporter& rep,
                           int* frame_used = nullptr);

/// A streamline of the blood: points [mm] and the speed there [cm/s].
struct Streamline {
    std::vector<Eigen::Vector3d> points;
    std::vector<double> speed_cm_s;
};

/// Streamlines of a flow stage's velocity field, seeded at `seeds` points spread over the inlet's cap (the blood
/// surface's faces labelled `inlet_patch`, e.g. "end_1"): second-order Runge–Kutta through the cells' velocities
/// (inverse-distance weights of the cells within 1.5 cell sizes), steps of a third of a cell, ending where no
/// cell is near (the wall or an outlet), where the blood is still, or after `max_length_mm`.
std::vector<Streamline> trace_streamlines(const FlowFieldData& field, const SurfaceData& blood, const std::string& inlet_patch, int seeds = 150,
                                          double max_length_mm = 200.0);

/// Runs the flow stage: reads /surface/lumen of `in`, solves, writes `out` with the input's image and surfaces
/// plus /flow (velocity and pressure at the fluid cells) and /surface/blood carrying the face fields wall_shear_stress_pa [F,1], wall_shear_stress_vector_pa [F,3]
/// and pressure_pa [F,1] (zero on the caps for the wall shear stress). Figures in the stage's QA: per end flow
/// (mL/s, positive out of the domain) and mean pressure (Pa), the mass imbalance, the wall shear stress.
void flow_file(const std::string& in, const std::string& out, const FlowParams& p, StageRecord stage, Reporter& rep);

}  // namespace aneu::pipeline
