// SPDX-License-Identifier: MIT
// FEM stages: `tubewall` (synthetic wall surface), `tetmesh`, `assemble`, `condense`.
#include <memory>

#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/pipeline/stages.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

void add_fem_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action) {
    {
        auto p = std::make_shared<pipeline::TubeWallParams>();
        auto* c = stage_command(
            app, args, action, "tubewall", "closed wall surface of a tube of known dimensions (tests, examples)", false,
            [p](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::tubewall_file(*p, io.output, std::move(r), rep);
            },
            [p] {
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->add_option("--inner-radius-mm", p->inner_radius_mm, "lumen radius")->capture_default_str();
        c->add_option("--thickness-mm", p->thickness_mm, "wall thickness")->capture_default_str();
        c->add_option("--length-mm", p->length_mm, "length along the centerline")->capture_default_str();
        c->add_option("--bend-radius-mm", p->bend_radius_mm, "centerline bend radius (0 = straight)")->capture_default_str();
        c->add_option("--n-theta", p->n_theta, "segments around")->capture_default_str();
        c->add_option("--n-z", p->n_z, "segments along")->capture_default_str();
        c->add_option("--sac-radius-mm", p->sac_radius_mm, "add a spherical sac of this lumen radius (0 = none)")->capture_default_str();
        c->add_option("--sac-thickness-mm", p->sac_thickness_mm, "sac wall thickness")->capture_default_str();
        c->add_option("--neck-radius-mm", p->neck_radius_mm, "radius of the sac's neck")->capture_default_str();
        c->add_option("--edge-mm", p->edge_mm, "target edge length of the surface with a sac")->capture_default_str();
    }
    {
        auto p = std::make_shared<pipeline::TetMeshParams>();
        auto* c = stage_command(
            app, args, action, "tetmesh", "quality tetrahedral mesh of the closed wall surface", true,
            [p](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::tetmesh_file(io.input, io.output, *p, std::move(r), rep);
            },
            [p] {
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->add_option("--mesher", p->mesher, "tetgen or netgen")->capture_default_str();
        c->add_option("--max-volume-mm3", p->max_volume_mm3, "max tet volume (0 = from the surface's edge length)")->capture_default_str();
        c->add_option("--radius-edge-max", p->radius_edge_max, "TetGen radius-edge bound")->capture_default_str();
        c->add_option("--min-dihedral-deg", p->min_dihedral_deg, "TetGen dihedral bound")->capture_default_str();
        c->add_option("--opt-max-dihedral-deg", p->opt_max_dihedral_deg, "TetGen's optimiser flips and smooths tetrahedra with a larger dihedral angle")
            ->capture_default_str();
        c->add_option("--timeout-s", p->timeout_s, "kill the mesher after this")->capture_default_str();
    }
    {
        auto p = std::make_shared<pipeline::AssembleParams>();
        auto* c = stage_command(
            app, args, action, "assemble", "linear-elastic stiffness of the wall mesh", true,
            [p](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::assemble_file(io.input, io.output, *p, std::move(r), rep);
            },
            [p] {
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->add_option("--element-order", p->element_order, "1: linear, 2: quadratic tetrahedra")->capture_default_str();
        c->add_option("--E-artery-mpa", p->E_artery_mpa, "Young's modulus of the artery wall")->capture_default_str();
        c->add_option("--nu-artery", p->nu_artery, "Poisson's ratio of the artery wall")->capture_default_str();
        c->add_option("--E-aneurysm-mpa", p->E_aneurysm_mpa, "Young's modulus of the sac wall")->capture_default_str();
        c->add_option("--nu-aneurysm", p->nu_aneurysm, "Poisson's ratio of the sac wall")->capture_default_str();
    }
    {
        auto p = std::make_shared<pipeline::CondenseStageParams>();
        auto method = std::make_shared<std::string>("sparse");
        auto precision = std::make_shared<std::string>("float32");
        auto sphere = std::make_shared<std::vector<double>>();
        auto box = std::make_shared<std::vector<double>>();
        auto* c = stage_command(
            app, args, action, "condense", "W = (K^-1) on the simulated surface DOFs: the case bundle", true,
            [p](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::condense_file(io.input, io.output, *p, std::move(r), rep);
            },
            [p, method, precision, sphere, box] {
                p->numeric.method = *method == "dense" ? fem::CondenseMethod::DENSE : fem::CondenseMethod::SPARSE;
                p->numeric.precision = *precision == "float64" ? Precision::FLOAT64 : Precision::FLOAT32;
                if (!sphere->empty()) p->region_sphere = std::array<double, 4>{(*sphere)[0], (*sphere)[1], (*sphere)[2], (*sphere)[3]};
                if (!box->empty()) {
                    std::array<double, 6> b{};
                    std::copy(box->begin(), box->end(), b.begin());
                    p->region_box = b;
                }
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->add_option("--method", *method, "sparse (CHOLMOD + SYRK) or dense (Schur complement + LAPACK)")
            ->check(CLI::IsMember({"sparse", "dense"}))
            ->capture_default_str();
        c->add_option("--precision", *precision, "storage precision of W (computed in double)")
            ->check(CLI::IsMember({"float32", "float64"}))
            ->capture_default_str();
        c->add_option("--tile-size", p->numeric.tile_size, "tile edge of W")->capture_default_str();
        c->add_option("--ordering", p->numeric.ordering, "metis, nesdis or amd")->capture_default_str();
        c->add_option("--memory-limit-gb", p->numeric.memory_limit_gb, "refuse above this predicted peak (0 = 90 % of available)")
            ->capture_default_str();
        c->add_option("--region-sphere", *sphere, "working region x,y,z,radius [mm]")->delimiter(',')->expected(4);
        c->add_option("--region-box", *box, "working region xmin,ymin,zmin,xmax,ymax,zmax [mm]")->delimiter(',')->expected(6);
        c->add_option("--region-label", p->region_label,
                      "only nodes of this tissue region (artery, aneurysm) and --region-margin-mm around it; auto: the aneurysm when the mesh has "
                      "one and no sphere/box is given; all: the whole outer surface")
            ->capture_default_str();
        c->add_option("--region-margin-mm", p->region_margin_mm, "with a region label: also nodes within this distance of the region")
            ->capture_default_str();
        c->add_option("--nodes", p->nodes, "10-node tetrahedra: corners (the outer surface's corner nodes; W as small as for 4-node) or all")
            ->check(CLI::IsMember({"corners", "all"}))
            ->capture_default_str();
    }
}

}  // namespace aneu::tools
