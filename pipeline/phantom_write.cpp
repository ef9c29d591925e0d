// SPDX-License-Identifier: MIT
// `aneuprep phantom`: synthesises the CT from the rasterised anatomy and writes every output atomically.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/pipeline/image_io.hpp"
#include "aneu/pipeline/phantom.hpp"

namespace aneu::pipeline {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr double HU_MIN = -1024.0, HU_MAX = 3071.0;


json vec_json(const Eigen::Vector3d& v) { return json::array({v[0], v[1], v[2]}); }

json grid_json(const ImageGrid& g) {
    return {{"size", g.size}, {"origin_mm", g.origin}, {"spacing_mm", g.spacing}, {"direction_row_major", g.direction}};
}

json truth_json(const PhantomParams& p, const PhantomGeometry& g, const Rasterized& r,
                const std::vector<EndPlane>& planes) {
    json j;
    j["description"] = "aneuclip phantom ground truth; physical LPS frame, mm";
    for (const auto& [k, v] : phantom_spec().parameters(p)) j["parameters"][k] = v;
    j["grid"] = grid_json(r.labels.grid);
    for (const auto& v : g.vessels) {
        json pts = json::array();
        for (Eigen::Index i = 0; i < v.points.rows(); ++i) pts.push_back(vec_json(v.points.row(i).transpose()));
        j["vessels"].push_back({{"name", v.name}, {"radius_mm", v.radius_mm}, {"centerline_mm", pts}});
    }
    if (g.sac) j["sac"] = {{"centre_mm", vec_json(g.sac->centre)}, {"radius_mm", g.sac->radius_mm}};
    if (g.neck) {
        j["neck"] = {{"centre_mm", vec_json(g.neck->centre)}, {"normal", vec_json(g.neck->normal)},
                     {"radius_mm", g.neck->radius_mm}};
    }
    if (g.bone) j["bone"] = {{"centre_mm", vec_json(g.bone->centre)}, {"radii_mm", vec_json(g.bone->radii)}};
    for (const auto& e : planes) {
        j["end_planes"].push_back({{"id", e.id}, {"point_mm", vec_json(e.point)}, {"normal", vec_json(e.normal)},
                                   {"radius_mm", e.radius_mm}});
    }
    for (const auto& [name, vol] : g.part_volumes_mm3) j["analytic_part_volumes_mm3"][name] = vol;
    std::array<size_t, 4> count{0, 0, 0, 0};
    for (auto l : r.labels.data) ++count[l];
    const double vv = r.labels.grid.voxel_volume();
    j["mask_volumes_mm3"] = {{"artery", count[ARTERY] * vv}, {"aneurysm", count[ANEURYSM] * vv}, {"bone", count[BONE] * vv}};
    j["label_values"] = {{"background", 0}, {"artery", 1}, {"aneurysm", 2}, {"bone", 3}};
    return j;
}

}  // namespace

Volume<std::int16_t> synthesize_ct(const PhantomParams& p, const Rasterized& r) {
    Volume<float> ct;
    ct.grid = r.labels.grid;
    const size_t n = ct.grid.voxel_count();
    ct.data.resize(n);
    for (size_t i = 0; i < n; ++i) {
        ct.data[i] = static_cast<float>(p.tissue_hu + r.lumen_fraction[i] * (p.lumen_hu - p.tissue_hu) +
                                        r.bone_fraction[i] * (p.bone_hu - p.tissue_hu));
    }
    ct = gaussian_blur(ct, p.psf_sigma_mm);
    std::mt19937_64 rng(p.seed);
    std::normal_distribution<double> noise(0.0, 1.0);
    Volume<std::int16_t> out;
    out.grid = ct.grid;
    out.data.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const double v = ct.data[i] + (p.noise_sd_hu > 0 ? p.noise_sd_hu * noise(rng) : 0.0);
        out.data[i] = static_cast<std::int16_t>(std::lround(std::clamp(v, HU_MIN, HU_MAX)));
    }
    return out;
}


void write_phantom(const PhantomParams& p, const PhantomOutputs& outputs, const std::string& out_dir,
                   StageRecord stage, Reporter& rep) {
    validate(p);
    const Stopwatch clock;
    const fs::path target = fs::path(out_dir).lexically_normal();
    AtomicPath out(out_dir, AtomicPath::Kind::DIRECTORY);
    const fs::path dir(out.tmp());

    const PhantomGeometry geom = make_phantom_geometry(p);
    const ImageGrid grid = make_phantom_grid(p);
    rep.info("phantom: grid " + std::to_string(grid.size[0]) + "x" + std::to_string(grid.size[1]) + "x" +
             std::to_string(grid.size[2]) + " voxels");
    const Rasterized r = rasterize(geom, grid, p.supersampling);
    rep.progress("phantom", 1, 4);
    const Volume<std::int16_t> ct = synthesize_ct(p, r);
    rep.progress("phantom", 2, 4);

    if (outputs.nifti) write_image(dir / "ct.nii.gz", ct);
    if (outputs.nrrd) write_image(dir / "ct.nrrd", ct);
    if (outputs.mha) write_image(dir / "ct.mha", ct);
    if (outputs.dicom) {
        fs::create_directory(dir / "dicom");
        write_dicom_series((dir / "dicom").string(), ct, DicomSeriesInfo{});
    }
    rep.progress("phantom", 3, 4);
    write_image((dir / "truth_labels.nrrd").string(), r.labels);
    const std::vector<EndPlane> planes = true_end_planes(geom, grid);
    {
        std::ofstream js(dir / "truth.json");
        js << truth_json(p, geom, r, planes).dump(1) << "\n";
        if (!js) throw IoError((target / "truth.json").string() + ": write failed");
    }
    Bundle b;
    b.meta.case_id = target.filename().string();
    stage.wall_time_s = clock.seconds();
    b.meta.stages.push_back(std::move(stage));
    ImageData im;
    im.grid = grid;
    im.mask = r.labels.data;
    im.mask_label_names = {"background", "artery", "aneurysm", "bone"};
    im.centerline = true_centerline(geom, grid);
    im.planes = planes;
    b.image = std::move(im);
    write_bundle((dir / "truth.h5").string(), b);

    out.commit();
    rep.progress("phantom", 4, 4);
    rep.info("phantom: wrote " + out_dir + " (" + std::to_string(planes.size()) + " vessel ends) in " +
             std::to_string(clock.seconds()) + " s");
}

}  // namespace aneu::pipeline
