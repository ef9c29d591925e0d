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
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"
#include "aneu/fem/assembly.hpp"
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
/// The options of `aneuprep tubewall`, declared once.
inline const opt::Spec<TubeWallParams>& tubewall_spec() {
    using namespace opt;
    using P = TubeWallParams;
    static const Spec<P> spec = [] {
        Spec<P> s("tubewall");
        s.real("inner-radius-mm", &P::inner_radius_mm, "mm", gt(0), "lumen radius")
            .real("thickness-mm", &P::thickness_mm, "mm", gt(0), "wall thickness")
            .real("length-mm", &P::length_mm, "mm", gt(0), "length along the centerline")
            .real("bend-radius-mm", &P::bend_radius_mm, "mm", ge(0), "centerline bend radius (0 = straight)")
            .integer("n-theta", &P::n_theta, closed(3, 4096), "segments around")
            .integer("n-z", &P::n_z, closed(1, 100000), "segments along")
            .real("sac-radius-mm", &P::sac_radius_mm, "mm", ge(0), "add a spherical sac of this lumen radius (0 = none)")
            .real("sac-thickness-mm", &P::sac_thickness_mm, "mm", gt(0), "sac wall thickness")
            .real("neck-radius-mm", &P::neck_radius_mm, "mm", gt(0), "radius of the sac's neck")
            .real("edge-mm", &P::edge_mm, "mm", gt(0), "target edge length of the surface with a sac")
            .rule([](const P& p) {
                if (p.sac_radius_mm > 0 && p.bend_radius_mm != 0) throw InputError("tubewall: a sac needs a straight tube (bend_radius_mm = 0)");
                if (p.sac_radius_mm > 0 && !(p.neck_radius_mm < p.sac_radius_mm)) {
                    throw InputError("tubewall: neck_radius_mm = " + shortest(p.neck_radius_mm) + ": must be in (0, sac_radius_mm)");
                }
                if (p.bend_radius_mm != 0 && !(p.bend_radius_mm > p.inner_radius_mm + p.thickness_mm)) {
                    throw InputError("tubewall: bend_radius_mm = " + shortest(p.bend_radius_mm) + ": must be 0 (straight) or > inner radius + thickness");
                }
            });
        return s;
    }();
    return spec;
}
inline void validate(const TubeWallParams& p) { tubewall_spec().validate(p); }

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
/// The options of `aneuprep assemble`, declared once.
inline const opt::Spec<AssembleParams>& assemble_spec() {
    using namespace opt;
    using P = AssembleParams;
    static const Spec<P> spec = [] {
        Spec<P> s("assemble");
        s.integer("element-order", &P::element_order, closed(1, 2), "1: linear, 2: quadratic tetrahedra")
            .real("E-artery-mpa", &P::E_artery_mpa, "MPa", any(), "Young's modulus of the artery wall")
            .real("nu-artery", &P::nu_artery, "", any(), "Poisson's ratio of the artery wall")
            .real("E-aneurysm-mpa", &P::E_aneurysm_mpa, "MPa", any(), "Young's modulus of the sac wall")
            .real("nu-aneurysm", &P::nu_aneurysm, "", any(), "Poisson's ratio of the sac wall")
            .rule([](const P& p) {
                fem::validate_materials({{"artery", p.E_artery_mpa, p.nu_artery}, {"aneurysm", p.E_aneurysm_mpa, p.nu_aneurysm}}, 2);
            });
        return s;
    }();
    return spec;
}
inline void validate(const AssembleParams& p) { assemble_spec().validate(p); }

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
/// The options of `aneuprep condense`, declared once (the numerical ones in fem::condense_numeric_spec).
inline const opt::Spec<CondenseStageParams>& condense_spec() {
    using namespace opt;
    using P = CondenseStageParams;
    static const Spec<P> spec = [] {
        Spec<P> s("condense");
        s.include(fem::condense_numeric_spec(), [](P& p) -> fem::CondenseParams& { return p.numeric; })
            .optional_numbers<4>("region-sphere", &P::region_sphere, "mm", "", "working region x,y,z,radius")
            .named("region_sphere_mm")
            .optional_numbers<6>("region-box", &P::region_box, "mm", "", "working region xmin,ymin,zmin,xmax,ymax,zmax")
            .named("region_box_mm")
            .text("region-label", &P::region_label, {},
                  "only nodes of this tissue region (artery, aneurysm) and --region-margin-mm around it; auto: the aneurysm when the mesh "
                  "has one and no sphere/box is given; all: the whole outer surface")
            .real("region-margin-mm", &P::region_margin_mm, "mm", closed_open(0, 1000), "with a region label: also nodes within this distance of the region")
            .text("nodes", &P::nodes, {"corners", "all"}, "10-node tetrahedra: corners (the outer surface's corner nodes; W as small as for 4-node) or all")
            .rule([](const P& p) {
                if (p.region_sphere && !((*p.region_sphere)[3] > 0)) throw InputError("condense: region sphere radius must be > 0");
                if (p.region_box) {
                    const auto& b = *p.region_box;
                    if (!(b[0] < b[3] && b[1] < b[4] && b[2] < b[5])) throw InputError("condense: region box needs min < max on every axis");
                }
            });
        return s;
    }();
    return spec;
}
inline void validate(const CondenseStageParams& p) { condense_spec().validate(p); }

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
