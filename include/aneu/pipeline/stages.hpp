// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// File-level stages: read the previous stage's bundle, add this stage's group and provenance, write the
/// next bundle atomically. The tools call these; tests and batch scripts can too.
#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"
#include "aneu/fem/condense.hpp"
#include "aneu/pipeline/tetmesh.hpp"

namespace aneu::pipeline {

/// Parameters of `aneuprep tubewall`: a synthetic wall surface of known dimensions.
struct TubeWallParams {
    double inner_radius_mm = 1.7;
    double thickness_mm = 0.3;
    double length_mm = 10.0;
    double bend_radius_mm = 0.0;  ///< 0 = straight
    int n_theta = 32;
    int n_z = 40;
    double sac_radius_mm = 0.0;      ///< > 0: add a spherical sac (straight tube only; CGAL boolean + remeshing)
    double sac_thickness_mm = 0.1;
    double neck_radius_mm = 1.5;
    double edge_mm = 0.2;            ///< target edge of the remeshed surface with a sac
};
void validate(const TubeWallParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const TubeWallParams& p);

/// Parameters of `aneuprep assemble`.
struct AssembleParams {
    /// 1: 4-node, 2: 10-node tetrahedra (mid-edge nodes added here). 2 by default: the study's recommendation
    /// (bench/results/study/study.md: clip force within 2.5 % of the fine reference at 0.4 mm elements; the
    /// 4-node element locks at ν 0.45 and is stiffer by tens of per cent on the thin sac wall).
    int element_order = 2;
    double E_artery_mpa = 1.0;
    double nu_artery = 0.45;
    double E_aneurysm_mpa = 1.0;
    double nu_aneurysm = 0.45;
};
void validate(const AssembleParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const AssembleParams& p);

/// Parameters of `aneuprep condense` beyond the numerical ones: the working region.
struct CondenseStageParams {
    fem::CondenseParams numeric;
    std::optional<std::array<double, 4>> region_sphere;  ///< x, y, z, radius [mm]
    std::optional<std::array<double, 6>> region_box;     ///< xmin, ymin, zmin, xmax, ymax, zmax [mm]
    /// Only nodes of tets of this region and those within region_margin_mm of them. "auto" (default): the
    /// "aneurysm" region when the mesh has one and no sphere or box is given, else all; "all" (or ""): all.
    std::string region_label = "auto";
    /// ... and nodes within this distance of them: the neck's surroundings, where the clip closes. 6 mm: the
    /// study's working region (4–6 mm: W 40 MB instead of 619 MB, 4,720 Hz at 100 contact nodes).
    double region_margin_mm = 6.0;
    /// With 10-node tetrahedra: "corners" (default) keeps only the corner nodes of the outer surface — contacts
    /// load the corners, the mid-edge nodes follow from K (they are condensed out with the interior), so W is the
    /// size a 4-node mesh gives while the stiffness keeps the quadratic element's accuracy; "all" keeps the
    /// mid-edge nodes too (4× the DOFs, 16× the size of W).
    std::string nodes = "corners";
};
void validate(const CondenseStageParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const CondenseStageParams& p);

void tubewall_file(const TubeWallParams& p, const std::string& out, StageRecord stage, Reporter& rep = null_reporter());
void tetmesh_file(const std::string& in, const std::string& out, const TetMeshParams& p, StageRecord stage,
                  Reporter& rep = null_reporter());
void assemble_file(const std::string& in, const std::string& out, const AssembleParams& p, StageRecord stage,
                   Reporter& rep = null_reporter());
void condense_file(const std::string& in, const std::string& out, const CondenseStageParams& p, StageRecord stage,
                   Reporter& rep = null_reporter());

/// The region label a condensation uses on this mesh: `p.region_label` with "auto" resolved ("" = all).
std::string resolved_region_label(const VolumeData& v, const CondenseStageParams& p);

/// The kept nodes of a condensation: "outer" minus "fixed", restricted to the region (all given criteria).
/// @throws InputError if the volume lacks the node sets, or the region holds no such node
std::vector<int> kept_nodes(const VolumeData& v, const CondenseStageParams& p);

}  // namespace aneu::pipeline
