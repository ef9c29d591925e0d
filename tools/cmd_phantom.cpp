// SPDX-License-Identifier: MIT
// `aneuprep phantom`: synthetic CT angiography with ground truth.
#include <memory>

#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/pipeline/phantom.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace {

struct PhantomCli {
    pipeline::PhantomParams p;
    std::string out;
    std::vector<double> spacing{p.spacing_mm.begin(), p.spacing_mm.end()};
    std::vector<double> fov{p.fov_mm.begin(), p.fov_mm.end()};
    std::vector<double> centre{p.fov_centre_mm.begin(), p.fov_centre_mm.end()};
    std::vector<double> oblique{p.oblique_deg.begin(), p.oblique_deg.end()};
    std::vector<std::string> formats{"nii", "nrrd", "mha", "dicom"};
    bool no_branch = false, no_sac = false;
};

void copy3(const std::vector<double>& v, std::array<double, 3>& a, const char* name) {
    if (v.size() != 3) throw InputError(std::string("phantom: --") + name + " needs 3 values, got " + std::to_string(v.size()));
    std::copy(v.begin(), v.end(), a.begin());
}

}  // namespace

void add_phantom_command(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action) {
    auto cli = std::make_shared<PhantomCli>();
    auto& p = cli->p;
    auto* c = app.add_subcommand("phantom", "synthetic CT angiography of an aneurysm, with ground truth");
    c->add_option("-o,--output", cli->out, "output directory (replaced atomically)")->required();
    c->add_option("--seed", p.seed, "noise seed")->capture_default_str();
    c->add_option("--spacing-mm", cli->spacing, "voxel size i,j,k [mm]")->delimiter(',')->expected(3)->capture_default_str();
    c->add_option("--fov-mm", cli->fov, "grid extent i,j,k [mm]")->delimiter(',')->expected(3)->capture_default_str();
    c->add_option("--fov-centre-mm", cli->centre, "grid centre x,y,z [mm]")->delimiter(',')->expected(3)->capture_default_str();
    c->add_option("--oblique-deg", cli->oblique, "grid rotation about x,y,z [deg]")->delimiter(',')->expected(3)->capture_default_str();
    c->add_option("--parent-radius-mm", p.parent_radius_mm, "parent artery lumen radius")->capture_default_str();
    c->add_option("--bend-radius-mm", p.parent_bend_radius_mm, "parent artery bend radius")->capture_default_str();
    c->add_option("--branch-radius-mm", p.branch_radius_mm, "branch lumen radius")->capture_default_str();
    c->add_option("--dome-diameter-mm", p.dome_diameter_mm, "aneurysm dome diameter")->capture_default_str();
    c->add_option("--neck-diameter-mm", p.neck_diameter_mm, "aneurysm neck diameter (< dome)")->capture_default_str();
    c->add_flag("--no-branch", cli->no_branch, "omit the branch");
    c->add_flag("--no-sac", cli->no_sac, "omit the aneurysm");
    c->add_flag("--bone", p.with_bone, "add a bone-like structure beside the sac");
    c->add_option("--lumen-hu", p.lumen_hu, "contrast-filled lumen [HU]")->capture_default_str();
    c->add_option("--tissue-hu", p.tissue_hu, "soft tissue [HU]")->capture_default_str();
    c->add_option("--bone-hu", p.bone_hu, "bone [HU]")->capture_default_str();
    c->add_option("--bone-gap-mm", p.bone_gap_mm, "gap between the sac and the bone (0 = touching)")->capture_default_str();
    c->add_option("--psf-sigma-mm", p.psf_sigma_mm, "point-spread function sigma [mm]")->capture_default_str();
    c->add_option("--noise-sd-hu", p.noise_sd_hu, "Gaussian noise standard deviation [HU]")->capture_default_str();
    c->add_option("--supersampling", p.supersampling, "sub-samples per voxel edge (partial volume)")->capture_default_str();
    c->add_option("--formats", cli->formats, "CT formats to write: nii, nrrd, mha, dicom")
        ->delimiter(',')
        ->check(CLI::IsMember({"nii", "nrrd", "mha", "dicom"}))
        ->capture_default_str();
    c->callback([cli, &action, args] {
        action = [cli, args] {
            return run_guarded("aneuprep phantom", [&] {
                auto& p = cli->p;
                copy3(cli->spacing, p.spacing_mm, "spacing-mm");
                copy3(cli->fov, p.fov_mm, "fov-mm");
                copy3(cli->centre, p.fov_centre_mm, "fov-centre-mm");
                copy3(cli->oblique, p.oblique_deg, "oblique-deg");
                p.with_branch = !cli->no_branch;
                p.with_sac = !cli->no_sac;
                pipeline::PhantomOutputs o{false, false, false, false};
                for (const auto& f : cli->formats) {
                    o.nifti |= f == "nii";
                    o.nrrd |= f == "nrrd";
                    o.mha |= f == "mha";
                    o.dicom |= f == "dicom";
                }
                pipeline::validate(p);
                auto params = pipeline::parameter_list(p);
                std::string fl;
                for (const auto& f : cli->formats) fl += (fl.empty() ? "" : ",") + f;
                params.emplace_back("formats", fl);
                if (plan_sink()) {
                    plan_sink()(StagePlan{"phantom", params, {}, cli->out});
                    return;
                }
                auto rec = make_stage_record("phantom", shell_join(args), params, {});
                Reporter rep = make_log_reporter();
                pipeline::write_phantom(p, o, cli->out, rec, rep);
            });
        };
    });
}

}  // namespace aneu::tools
