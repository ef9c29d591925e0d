// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// `aneuprep flow`: a steady incompressible Navier–Stokes solve in the lumen (the blood domain) with OpenFOAM
/// (snappyHexMesh + simpleFoam as child processes on a generated case), for the residual flow after clipping
/// (issue #17). This first step solves the undeformed lumen: the pre-clip baseline.
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
};

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
            .text("case-dir", &P::case_dir, {}, "keep the OpenFOAM case in this folder (open case.foam in ParaView)", "a temporary folder, removed");
        return s;
    }();
    return spec;
}

/// The blood domain of a lumen: the lumen surface with each open end closed by a flat cap (a fan from the loop's
/// centroid), labels "wall" and "end_<id>" (the end ids of the lumen's loops), outward, closed and manifold.
/// @throws InputError the lumen has no open end (no inlet), or the capped surface is not closed
SurfaceData blood_domain(const SurfaceData& lumen);

/// Runs the flow stage: reads /surface/lumen of `in`, solves, writes `out` with the input's image and surfaces
/// plus /surface/blood carrying the face fields wall_shear_stress_pa [F,1], wall_shear_stress_vector_pa [F,3]
/// and pressure_pa [F,1] (zero on the caps for the wall shear stress). Figures in the stage's QA: per end flow
/// (mL/s, positive out of the domain) and mean pressure (Pa), the mass imbalance, the wall shear stress.
void flow_file(const std::string& in, const std::string& out, const FlowParams& p, StageRecord stage, Reporter& rep);

}  // namespace aneu::pipeline
