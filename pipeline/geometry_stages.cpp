// SPDX-License-Identifier: MIT
// File-level geometry stages: read the input, run the stage, store its QA figures in the provenance
// record, write the next stage file atomically, and render the snapshot if asked.
#include <chrono>

#include "aneu/core/common.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/snapshot.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "stage_util.hpp"

namespace aneu::pipeline {

namespace {

std::string figure(const NamedValues& qa, const std::string& key) {
    for (const auto& [k, v] : qa)
        if (k == key) return shortest(std::round(v * 1000.0) / 1000.0);
    return "-";
}

void log_qa(const std::string& stage, const NamedValues& qa, Reporter& rep) {
    std::string line;
    for (const auto& [k, v] : qa) line += (line.empty() ? "" : ", ") + k + " " + shortest(std::round(v * 10000.0) / 10000.0);
    rep.info(stage + " QA: " + line);
}

bool has_ext(const std::string& path, const std::string& ext) {
    if (path.size() < ext.size()) return false;
    std::string tail = path.substr(path.size() - ext.size());
    for (auto& c : tail) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return tail == ext;
}

}  // namespace

SnapshotScene segment_scene(const ImageData& im, const std::string& title) {
    Volume<float> m{im.grid, std::vector<float>(im.mask.begin(), im.mask.end())};
    SnapshotScene sc;
    SnapshotLayer layer{isosurface(m, 0.5, true, false), ColorBy::LABEL, 0.45, false, ""};
    layer.surface.label_names = {"lumen mask"};
    sc.layers.push_back(std::move(layer));
    sc.centerline = im.centerline;
    sc.planes = im.planes;
    sc.title = title;
    return sc;
}

SnapshotScene surface_scene(const SurfaceData& lumen, const std::vector<EndPlane>& planes, const std::string& title) {
    SnapshotScene sc;
    sc.layers.push_back({lumen, ColorBy::LABEL, 1.0, true, ""});
    sc.planes = planes;
    sc.title = title;
    return sc;
}

SnapshotScene wall_thickness_scene(const SurfaceData& w, const std::string& title) {
    std::vector<char> outer(static_cast<size_t>(w.F.rows()));
    for (Eigen::Index f = 0; f < w.F.rows(); ++f) outer[static_cast<size_t>(f)] = w.face_label[f] != 0;  // outer and caps
    SnapshotScene sc;
    sc.layers.push_back({sub_surface(w, outer), ColorBy::THICKNESS, 1.0, true, ""});
    sc.title = title;
    return sc;
}

void segment_file(const std::string& image_path, const std::string& out, const SegmentParams& p, StageRecord stage,
                  const std::string& snapshot_png, Reporter& rep) {
    validate(p);
    if (!snapshot_png.empty()) require_snapshot_display();
    const Stopwatch t0;
    Segmentation seg = segment(image_path, p, rep);
    log_qa("segment", seg.qa, rep);
    Bundle b;
    b.meta.case_id = case_id_of(out);
    b.image = std::move(seg.image);
    stage.qa = seg.qa;
    finish(b, stage, t0, out, rep);
    if (!snapshot_png.empty()) {
        const ImageData& im = *b.image;
        const SnapshotScene sc = segment_scene(im, "segment " + b.meta.case_id + ": threshold " + figure(seg.qa, "threshold_hu") + " HU, " +
                                                       figure(seg.qa, "lumen_volume_mm3") + " mm3, " + std::to_string(im.planes.size()) + " ends");
        snapshot_scene(sc, snapshot_png);
        rep.info("segment: snapshot " + snapshot_png);
    }
}

void surface_file(const std::string& in, const std::string& out, const SurfaceParams& p, StageRecord stage, const std::string& snapshot_png,
                  Reporter& rep) {
    validate(p);
    if (!snapshot_png.empty()) require_snapshot_display();
    const Stopwatch t0;
    Bundle b;
    LumenResult r;
    if (has_ext(in, ".h5")) {
        b = read_bundle(in);
        if (!b.image) throw InputError(in + ": no /image (run `aneuprep segment` first, or give a surface mesh .stl/.vtp/.vtk/.obj/.ply)");
        r = lumen_from_segmentation(*b.image, p, rep);
    } else {
        b.meta.case_id = case_id_of(out);
        r = lumen_from_mesh(in, p, rep);
    }
    log_qa("surface", r.qa, rep);
    b.image = std::move(r.image);
    b.surfaces["lumen"] = std::move(r.lumen);
    stage.qa = r.qa;
    finish(b, stage, t0, out, rep);
    if (!snapshot_png.empty()) {
        const SnapshotScene sc = surface_scene(b.surfaces["lumen"], b.image->planes,
                                               "surface " + b.meta.case_id + ": " + figure(r.qa, "triangles") + " triangles, edge " +
                                                   figure(r.qa, "edge_mean_mm") + " mm, min angle " + figure(r.qa, "min_angle_deg") + " deg");
        snapshot_scene(sc, snapshot_png);
        rep.info("surface: snapshot " + snapshot_png);
    }
}

void wall_file(const std::string& in, const std::string& out, const WallParams& p, StageRecord stage, const std::string& snapshot_png,
               Reporter& rep) {
    validate(p);
    if (!snapshot_png.empty()) require_snapshot_display();
    const Stopwatch t0;
    Bundle b = read_bundle(in);
    const auto it = b.surfaces.find("lumen");
    if (it == b.surfaces.end()) throw InputError(in + ": no /surface/lumen (run `aneuprep surface` first)");
    if (!b.image) throw InputError(in + ": no /image with the end planes (run `aneuprep surface` first)");
    WallResult r = make_wall(it->second, b.image->planes, p, rep);
    log_qa("wall", r.qa, rep);
    b.surfaces["wall"] = std::move(r.wall);
    stage.qa = r.qa;
    finish(b, stage, t0, out, rep);
    if (!snapshot_png.empty()) {
        const SnapshotScene sc = wall_thickness_scene(b.surfaces["wall"], "wall " + b.meta.case_id + ": thickness median artery " +
                                                                          figure(r.qa, "thickness_artery_median_mm") + " mm, aneurysm " +
                                                                          figure(r.qa, "thickness_aneurysm_median_mm") + " mm");
        snapshot_scene(sc, snapshot_png);
        rep.info("wall: snapshot " + snapshot_png);
    }
}

}  // namespace aneu::pipeline
