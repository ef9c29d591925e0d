// SPDX-License-Identifier: MIT
// Geometry stages: `segment`, `surface`, `wall`.
#include <memory>

#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace {

/// "x,y,z" or "x,y,z,nx,ny,nz,r" lists from repeated options.
std::vector<std::vector<double>> parse_tuples(const std::vector<std::string>& items, size_t n, const std::string& option) {
    std::vector<std::vector<double>> out;
    for (const auto& s : items) {
        std::vector<double> v;
        size_t pos = 0;
        while (pos <= s.size()) {
            const size_t c = s.find(',', pos);
            const std::string tok = s.substr(pos, c == std::string::npos ? std::string::npos : c - pos);
            try {
                size_t used = 0;
                v.push_back(std::stod(tok, &used));
                if (used != tok.size()) throw std::invalid_argument(tok);
            } catch (const std::exception&) {
                throw InputError(option + " '" + s + "': '" + tok + "' is not a number");
            }
            if (c == std::string::npos) break;
            pos = c + 1;
        }
        if (v.size() != n) throw InputError(option + " '" + s + "': expected " + std::to_string(n) + " comma-separated numbers, got " + std::to_string(v.size()));
        out.push_back(v);
    }
    return out;
}

}  // namespace

void add_geometry_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action) {
    {
        auto p = std::make_shared<pipeline::SegmentParams>();
        auto roi = std::make_shared<std::vector<double>>();
        auto threshold = std::make_shared<std::string>("auto");
        auto upper = std::make_shared<std::string>("none");
        auto seeds = std::make_shared<std::vector<std::string>>();
        auto planes = std::make_shared<std::vector<std::string>>();
        auto png = std::make_shared<std::string>();
        auto* c = stage_command(
            app, args, action, "segment", "CT volume -> lumen mask, centerline and end planes (ITK)", true,
            [p, png](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::segment_file(io.input, io.output, *p, std::move(r), *png, rep);
            },
            [p, roi, threshold, upper, seeds, planes] {
                if (!roi->empty()) {
                    std::array<double, 6> b{};
                    std::copy(roi->begin(), roi->end(), b.begin());
                    p->roi_mm = b;
                }
                auto number = [](const std::string& s, const std::string& opt, const std::string& none) -> std::optional<double> {
                    if (s == none) return std::nullopt;
                    try {
                        size_t used = 0;
                        const double v = std::stod(s, &used);
                        if (used == s.size()) return v;
                    } catch (const std::exception&) {
                    }
                    throw InputError(opt + " '" + s + "': expected a number in HU or '" + none + "'");
                };
                p->threshold_hu = number(*threshold, "--threshold-hu", "auto");
                p->upper_hu = number(*upper, "--upper-hu", "none");
                p->seeds_mm.clear();
                for (const auto& s : parse_tuples(*seeds, 3, "--seed")) p->seeds_mm.push_back({s[0], s[1], s[2]});
                p->planes.clear();
                int id = 0;
                for (const auto& s : parse_tuples(*planes, 7, "--plane")) {
                    EndPlane e;
                    e.id = id++;
                    e.point = Eigen::Vector3d(s[0], s[1], s[2]);
                    e.normal = Eigen::Vector3d(s[3], s[4], s[5]);
                    if (e.normal.norm() > 0) e.normal.normalize();
                    e.radius_mm = s[6];
                    p->planes.push_back(e);
                }
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->get_option("input")->description("CT volume: .nii/.nii.gz, .nrrd, .mha, or a directory with one DICOM series");
        c->add_option("--roi-mm", *roi, "region of interest xmin,ymin,zmin,xmax,ymax,zmax [mm] (default: whole image)")->delimiter(',')->expected(6);
        c->add_option("--smoothing-iterations", p->smoothing_iterations, "anisotropic diffusion steps (0 = off)")->capture_default_str();
        c->add_option("--conductance-hu-per-mm", p->conductance_hu_per_mm, "diffusion keeps gradients well above this as edges")->capture_default_str();
        c->add_option("--threshold-hu", *threshold, "lumen threshold [HU] or 'auto' (half maximum between tissue and lumen)")->capture_default_str();
        c->add_option("--upper-hu", *upper, "upper lumen threshold [HU] or 'none'")->capture_default_str();
        c->add_option("--seed", *seeds, "seed point x,y,z [mm] in the lumen (repeatable; default: automatic)");
        c->add_option("--select", p->select, "seed: the seed-connected lumen; largest: the largest component")
            ->check(CLI::IsMember({"seed", "largest"}))
            ->capture_default_str();
        c->add_flag("--fill-holes,!--no-fill-holes", p->fill_holes, "fill cavities of the mask")->capture_default_str();
        c->add_option("--min-end-area-mm2", p->min_end_area_mm2, "smaller crossings of the ROI border are not vessel ends")->capture_default_str();
        c->add_option("--end-inset-mm", p->end_inset_mm, "end plane distance inside the ROI border along the centerline (0 = automatic)")
            ->capture_default_str();
        c->add_option("--plane", *planes, "end plane x,y,z,nx,ny,nz,radius [mm] (repeatable; replaces the detected planes)");
        c->add_option("--snapshot", *png, "render the mask, centerline and planes to this PNG (needs X: xvfb-run -a)");
    }
    {
        auto p = std::make_shared<pipeline::SurfaceParams>();
        auto sphere = std::make_shared<std::vector<double>>();
        auto png = std::make_shared<std::string>();
        auto* c = stage_command(
            app, args, action, "surface", "lumen surface: isosurface, cut, smooth, remesh, artery/aneurysm labels", true,
            [p, png](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::surface_file(io.input, io.output, *p, std::move(r), *png, rep);
            },
            [p, sphere] {
                if (!sphere->empty()) p->aneurysm_sphere = std::array<double, 4>{(*sphere)[0], (*sphere)[1], (*sphere)[2], (*sphere)[3]};
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->get_option("input")->description("segment stage file (.h5), or a lumen surface from another tool (.stl, .vtp, .vtk, .obj, .ply)");
        c->add_option("--edge-mm", p->edge_mm, "target edge length")->capture_default_str();
        c->add_option("--remesher", p->remesher, "netgen (published method) or cgal (isotropic remeshing)")
            ->check(CLI::IsMember({"netgen", "cgal"}))
            ->capture_default_str();
        c->add_option("--smoothing-iterations", p->smoothing_iterations, "windowed-sinc smoothing iterations (0 = off)")->capture_default_str();
        c->add_option("--smoothing-passband", p->smoothing_passband, "windowed-sinc pass band (smaller = smoother)")->capture_default_str();
        c->add_option("--iso-hu", p->iso_hu, "isosurface level [HU] (0 = the segmentation's threshold)")->capture_default_str();
        c->add_option("--aneurysm-ratio-high", p->aneurysm_ratio_high, "sac seed: centerline distance > this x local radius")->capture_default_str();
        c->add_option("--aneurysm-ratio-low", p->aneurysm_ratio_low, "sac growth: connected faces above this x local radius")->capture_default_str();
        c->add_option("--aneurysm-sphere", *sphere, "override: faces inside x,y,z,r [mm] are the sac")->delimiter(',')->expected(4);
        c->add_option("--aneurysm-labelmap", p->aneurysm_labelmap, "override: image whose non-zero voxels are the sac (e.g. painted in 3D Slicer)");
        c->add_option("--timeout-s", p->timeout_s, "kill Netgen after this many seconds, then remesh with CGAL")->capture_default_str();
        c->add_option("--cap-tolerance-deg", p->cap_tolerance_deg, "surface input: a flat end cap's faces turn at most this from its fitted plane")
            ->capture_default_str();
        c->add_option("--cap-tolerance-mm", p->cap_tolerance_mm, "surface input: a flat end cap's vertices lie at most this from its fitted plane")
            ->capture_default_str();
        c->add_option("--input-scale", p->input_scale, "surface input: multiply coordinates by this (1000 for a file in metres)")->capture_default_str();
        c->add_option("--end-clearance-mm", p->end_clearance_mm, "move end planes inward until other vessels are this far from the cut")
            ->capture_default_str();
        c->add_option("--snapshot", *png, "render the labelled surface to this PNG (needs X: xvfb-run -a)");
    }
    {
        auto p = std::make_shared<pipeline::WallParams>();
        auto png = std::make_shared<std::string>();
        auto* c = stage_command(
            app, args, action, "wall", "closed vessel-wall surface: distance field, varying thickness, annular caps", true,
            [p, png](const StageIo& io, StageRecord r) {
                Reporter rep = make_log_reporter();
                pipeline::wall_file(io.input, io.output, *p, std::move(r), *png, rep);
            },
            [p] {
                pipeline::validate(*p);
                return pipeline::parameter_list(*p);
            });
        c->add_option("--artery-thickness-mm", p->artery_thickness_mm, "wall thickness of the artery")->capture_default_str();
        c->add_option("--aneurysm-thickness-mm", p->aneurysm_thickness_mm, "wall thickness of the sac (0 = one third of the artery's)")
            ->capture_default_str();
        c->add_option("--blend-mm", p->blend_mm, "width of the thickness transition across the neck")->capture_default_str();
        c->add_option("--grid-spacing-mm", p->grid_spacing_mm, "distance-field grid spacing (0 = the thinner of the thinnest wall and half the outer edge)")->capture_default_str();
        c->add_option("--edge-mm", p->edge_mm, "target edge of the outer surface (0 = the lumen's mean edge)")->capture_default_str();
        c->add_option("--remesher", p->remesher, "cgal or netgen, for the outer surface")->check(CLI::IsMember({"netgen", "cgal"}))->capture_default_str();
        c->add_option("--timeout-s", p->timeout_s, "kill Netgen after this many seconds, then remesh with CGAL")->capture_default_str();
        c->add_option("--snapshot", *png, "render the wall coloured by thickness to this PNG (needs X: xvfb-run -a)");
    }
}

}  // namespace aneu::tools
