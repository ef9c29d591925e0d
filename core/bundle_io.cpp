// SPDX-License-Identifier: MIT
// Case-bundle writer/reader, schema v1. Layout: docs/hdf5_layout.md.
#include "aneu/core/bundle_io.hpp"

#include "aneu/core/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <filesystem>

#include "aneu/core/error.hpp"
#include "condensed_tiles.hpp"
#include "h5_detail.hpp"

namespace aneu {

namespace fs = std::filesystem;
using h5::Ctx;

namespace {

template <class M>
using RowMajorOf = Eigen::Matrix<typename M::Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

template <class M>
void write_matrix(H5::Group& g, const std::string& name, const M& m, const std::string& units, int deflate) {
    const RowMajorOf<M> r = m;
    h5::write_array(g, name, r.data(), {static_cast<hsize_t>(r.rows()), static_cast<hsize_t>(r.cols())},
                    units, deflate);
}

template <class T>
void write_vector(H5::Group& g, const std::string& name, const Eigen::Matrix<T, Eigen::Dynamic, 1>& v,
                  const std::string& units, int deflate) {
    h5::write_array(g, name, v.data(), {static_cast<hsize_t>(v.size())}, units, deflate);
}

/// Reads an [rows, cols] dataset (rows < 0: any; cols < 0: any) into a column-major Eigen matrix.
template <class T>
Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> read_matrix(const H5::Group& g, const std::string& gpath,
                                                             const std::string& name, long long rows,
                                                             long long cols, const Ctx& ctx,
                                                             const std::string& doc) {
    std::vector<hsize_t> dims;
    auto buf = h5::read_array<T>(g, gpath, name, {rows, cols}, dims, ctx, doc);
    using RM = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    return Eigen::Map<RM>(buf.data(), static_cast<Eigen::Index>(dims[0]), static_cast<Eigen::Index>(dims[1]));
}

template <class T>
Eigen::Matrix<T, Eigen::Dynamic, 1> read_vector(const H5::Group& g, const std::string& gpath,
                                                const std::string& name, long long n, const Ctx& ctx,
                                                const std::string& doc) {
    std::vector<hsize_t> dims;
    auto buf = h5::read_array<T>(g, gpath, name, {n}, dims, ctx, doc);
    return Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, 1>>(buf.data(), static_cast<Eigen::Index>(dims[0]));
}

void require(bool ok, const std::string& msg) {
    if (!ok) throw InputError("write_bundle: " + msg);
}

void check_index_range(const Eigen::VectorXi& idx, Eigen::Index n, const std::string& what) {
    for (Eigen::Index i = 0; i < idx.size(); ++i) {
        require(idx[i] >= 0 && idx[i] < n, what + "[" + std::to_string(i) + "] = " + std::to_string(idx[i]) +
                                               " outside [0," + std::to_string(n) + ")");
    }
}

// ---------------------------------------------------------------- /meta
void write_meta(H5::H5File& f, const Meta& m) {
    require(m.schema_version == BUNDLE_SCHEMA_VERSION,
            "meta.schema_version = " + std::to_string(m.schema_version) + ", this build writes " +
                std::to_string(BUNDLE_SCHEMA_VERSION));
    H5::Group g = f.createGroup("/meta");
    h5::write_attr(g, "format", std::string(BUNDLE_FORMAT));
    h5::write_attr(g, "schema_version", static_cast<std::int64_t>(m.schema_version));
    h5::write_attr(g, "case_id", m.case_id);
    h5::write_attr(g, "units", m.units);
    H5::Group prov = g.createGroup("provenance");
    for (size_t i = 0; i < m.stages.size(); ++i) {
        const StageRecord& s = m.stages[i];
        const std::string idx = (i < 10 ? "0" : "") + std::to_string(i) + "_";  // sorts in run order
        H5::Group sg = prov.createGroup(idx + s.stage);
        h5::write_attr(sg, "stage", s.stage);
        h5::write_attr(sg, "tool_version", s.tool_version);
        h5::write_attr(sg, "git_revision", s.git_revision);
        h5::write_attr(sg, "created_utc", s.created_utc);
        h5::write_attr(sg, "command_line", s.command_line);
        h5::write_attr(sg, "wall_time_s", s.wall_time_s);
        H5::Group pg = sg.createGroup("parameters");
        for (const auto& [k, v] : s.parameters) h5::write_attr(pg, k, v);
        std::vector<std::string> paths, hashes;
        for (const auto& in : s.inputs) {
            paths.push_back(in.path);
            hashes.push_back(in.sha256);
        }
        h5::write_strings(sg, "input_paths", paths);
        h5::write_strings(sg, "input_sha256", hashes);
        if (!s.qa.empty()) {
            H5::Group qg = sg.createGroup("qa");
            for (const auto& [k, v] : s.qa) h5::write_attr(qg, k, v);
        }
    }
}

Meta read_meta_group(const H5::H5File& f, const Ctx& ctx) {
    Meta m;
    const H5::Group g = f.openGroup("/meta");
    m.schema_version = static_cast<int>(h5::read_attr_int(g, "/meta", "schema_version", ctx));
    m.case_id = h5::read_attr_string(g, "/meta", "case_id", ctx);
    m.units = h5::read_attr_string(g, "/meta", "units", ctx);
    if (!h5::exists(g, "provenance")) throw InputError(ctx.where("/meta/provenance") + ": missing group");
    const H5::Group prov = g.openGroup("provenance");
    for (const auto& name : h5::child_names(prov)) {
        const std::string p = "/meta/provenance/" + name;
        const H5::Group sg = prov.openGroup(name);
        StageRecord s;
        s.stage = h5::read_attr_string(sg, p, "stage", ctx);
        s.tool_version = h5::read_attr_string(sg, p, "tool_version", ctx);
        s.git_revision = h5::read_attr_string(sg, p, "git_revision", ctx);
        s.created_utc = h5::read_attr_string(sg, p, "created_utc", ctx);
        s.command_line = h5::read_attr_string(sg, p, "command_line", ctx);
        s.wall_time_s = h5::read_attr_double(sg, p, "wall_time_s", ctx);
        if (!h5::exists(sg, "parameters")) throw InputError(ctx.where(p + "/parameters") + ": missing group");
        const H5::Group pg = sg.openGroup("parameters");
        for (const auto& k : h5::attr_names(pg)) {
            s.parameters.emplace_back(k, h5::read_attr_string(pg, p + "/parameters", k, ctx));
        }
        const auto paths = h5::read_strings(sg, p, "input_paths", ctx);
        const auto hashes = h5::read_strings(sg, p, "input_sha256", ctx);
        if (paths.size() != hashes.size()) {
            throw InputError(ctx.where(p) + ": input_paths has " + std::to_string(paths.size()) +
                          " entries but input_sha256 has " + std::to_string(hashes.size()));
        }
        for (size_t i = 0; i < paths.size(); ++i) s.inputs.push_back({paths[i], hashes[i]});
        if (h5::exists(sg, "qa")) {  // optional: stages without QA figures write none
            const H5::Group qg = sg.openGroup("qa");
            for (const auto& k : h5::attr_names(qg)) s.qa.emplace_back(k, h5::read_attr_double(qg, p + "/qa", k, ctx));
        }
        m.stages.push_back(std::move(s));
    }
    return m;
}

// ---------------------------------------------------------------- /image
void write_image(H5::H5File& f, const ImageData& im, int deflate) {
    const ImageGrid& gr = im.grid;
    require(im.mask.size() == gr.voxel_count(),
            "image.mask has " + std::to_string(im.mask.size()) + " voxels, grid has " +
                std::to_string(gr.voxel_count()));
    H5::Group g = f.createGroup("/image");
    h5::write_array(g, "mask", im.mask.data(),
                    {static_cast<hsize_t>(gr.size[2]), static_cast<hsize_t>(gr.size[1]),
                     static_cast<hsize_t>(gr.size[0])},
                    "", deflate);
    h5::write_array(g, "size", gr.size.data(), {3}, "voxels", 0);
    h5::write_array(g, "origin", gr.origin.data(), {3}, "mm", 0);
    h5::write_array(g, "spacing", gr.spacing.data(), {3}, "mm", 0);
    h5::write_array(g, "direction", gr.direction.data(), {3, 3}, "1", 0);
    h5::write_strings(g, "mask_label_names", im.mask_label_names);
    if (!im.intensity.empty()) {
        require(im.intensity.size() == gr.voxel_count(),
                "image.intensity has " + std::to_string(im.intensity.size()) + " voxels, grid has " +
                    std::to_string(gr.voxel_count()));
        h5::write_array(g, "intensity", im.intensity.data(),
                        {static_cast<hsize_t>(gr.size[2]), static_cast<hsize_t>(gr.size[1]),
                         static_cast<hsize_t>(gr.size[0])},
                        "HU", deflate);
        h5::write_attr(g, "threshold_hu", im.threshold_hu);
    }

    const Centerline& c = im.centerline;
    require(c.radius.size() == c.points.rows(), "centerline.radius size != number of points");
    H5::Group cg = g.createGroup("centerline");
    write_matrix(cg, "points", c.points, "mm", deflate);
    write_vector<double>(cg, "radius", c.radius, "mm", deflate);
    write_vector<int>(cg, "offsets", c.offsets, "", deflate);

    H5::Group pg = g.createGroup("planes");
    const auto np = static_cast<Eigen::Index>(im.planes.size());
    Eigen::VectorXi id(np);
    Eigen::MatrixX3d pt(np, 3), nr(np, 3);
    Eigen::VectorXd rad(np);
    for (Eigen::Index i = 0; i < np; ++i) {
        const auto& p = im.planes[static_cast<size_t>(i)];
        id[i] = p.id;
        pt.row(i) = p.point.transpose();
        nr.row(i) = p.normal.transpose();
        rad[i] = p.radius_mm;
    }
    write_vector<int>(pg, "id", id, "", 0);
    write_matrix(pg, "point", pt, "mm", 0);
    write_matrix(pg, "normal", nr, "1", 0);
    write_vector<double>(pg, "radius", rad, "mm", 0);
}

ImageData read_image(const H5::H5File& f, const Ctx& ctx) {
    ImageData im;
    const H5::Group g = f.openGroup("/image");
    std::vector<hsize_t> d;
    auto size = h5::read_array<std::int64_t>(g, "/image", "size", {3}, d, ctx, "[3]");
    auto origin = h5::read_array<double>(g, "/image", "origin", {3}, d, ctx, "[3]");
    auto spacing = h5::read_array<double>(g, "/image", "spacing", {3}, d, ctx, "[3]");
    auto dir = h5::read_array<double>(g, "/image", "direction", {3, 3}, d, ctx, "[3,3]");
    for (int i = 0; i < 3; ++i) {
        im.grid.size[i] = size[i];
        im.grid.origin[i] = origin[i];
        im.grid.spacing[i] = spacing[i];
    }
    std::copy(dir.begin(), dir.end(), im.grid.direction.begin());
    im.mask = h5::read_array<std::uint8_t>(g, "/image", "mask", {size[2], size[1], size[0]}, d, ctx,
                                           "[size_k,size_j,size_i] = " +
                                               h5::shape_string({static_cast<hsize_t>(size[2]),
                                                                 static_cast<hsize_t>(size[1]),
                                                                 static_cast<hsize_t>(size[0])}));
    im.mask_label_names = h5::read_strings(g, "/image", "mask_label_names", ctx);
    if (h5::exists(g, "intensity")) {  // optional: written by segment
        im.intensity = h5::read_array<float>(g, "/image", "intensity", {size[2], size[1], size[0]}, d, ctx,
                                             "[size_k,size_j,size_i] like mask");
        im.threshold_hu = h5::read_attr_double(g, "/image", "threshold_hu", ctx);
    }

    if (!h5::exists(g, "centerline")) throw InputError(ctx.where("/image/centerline") + ": missing group");
    const H5::Group cg = g.openGroup("centerline");
    im.centerline.points = read_matrix<double>(cg, "/image/centerline", "points", -1, 3, ctx, "[P,3]");
    const auto np = im.centerline.points.rows();
    im.centerline.radius = read_vector<double>(cg, "/image/centerline", "radius", np, ctx,
                                               "[P] with P = " + std::to_string(np));
    im.centerline.offsets = read_vector<int>(cg, "/image/centerline", "offsets", -1, ctx, "[L+1]");

    if (!h5::exists(g, "planes")) throw InputError(ctx.where("/image/planes") + ": missing group");
    const H5::Group pg = g.openGroup("planes");
    const Eigen::VectorXi id = read_vector<int>(pg, "/image/planes", "id", -1, ctx, "[E]");
    const auto ne = id.size();
    const std::string doc = "[" + std::to_string(ne) + ",3]";
    const Eigen::MatrixXd pt = read_matrix<double>(pg, "/image/planes", "point", ne, 3, ctx, doc);
    const Eigen::MatrixXd nr = read_matrix<double>(pg, "/image/planes", "normal", ne, 3, ctx, doc);
    const Eigen::VectorXd rad =
        read_vector<double>(pg, "/image/planes", "radius", ne, ctx, "[" + std::to_string(ne) + "]");
    for (Eigen::Index i = 0; i < ne; ++i) {
        im.planes.push_back({id[i], pt.row(i).transpose(), nr.row(i).transpose(), rad[i]});
    }
    return im;
}

// ---------------------------------------------------------------- /surface/<name>
void write_surface(H5::Group& parent, const std::string& name, const SurfaceData& s, int deflate) {
    const std::string ctx = "surface '" + name + "'";
    require(s.face_label.size() == s.F.rows(), ctx + ": face_label size != number of triangles");
    check_index_range(Eigen::Map<const Eigen::VectorXi>(s.F.data(), s.F.size()), s.V.rows(), ctx + ".F");
    check_index_range(s.face_label, static_cast<Eigen::Index>(s.label_names.size()), ctx + ".face_label");
    require(s.loop_offsets.size() == 0 || s.loop_offsets.size() == s.loop_end_id.size() + 1,
            ctx + ": loop_offsets must have #loops+1 entries");
    check_index_range(s.loop_vertices, s.V.rows(), ctx + ".loop_vertices");
    require(s.face_region.size() == 0 || s.face_region.size() == s.F.rows(), ctx + ": face_region size != number of triangles");
    check_index_range(s.face_region, static_cast<Eigen::Index>(s.region_names.size()), ctx + ".face_region");
    H5::Group g = parent.createGroup(name);
    write_matrix(g, "vertices", s.V, "mm", deflate);
    write_matrix(g, "triangles", s.F, "", deflate);
    write_vector<int>(g, "face_label", s.face_label, "", deflate);
    h5::write_strings(g, "label_names", s.label_names);
    write_vector<int>(g, "face_region", s.face_region, "", deflate);
    h5::write_strings(g, "region_names", s.region_names);
    H5::Group lg = g.createGroup("loops");
    write_vector<int>(lg, "offsets", s.loop_offsets, "", deflate);
    write_vector<int>(lg, "vertices", s.loop_vertices, "", deflate);
    write_vector<int>(lg, "end_id", s.loop_end_id, "", deflate);
    if (s.vertex_thickness.size() != 0) {
        require(s.vertex_thickness.size() == s.V.rows(), ctx + ": vertex_thickness size != number of vertices");
        write_vector<double>(g, "vertex_thickness", s.vertex_thickness, "mm", deflate);
    }
    if (!s.face_fields.empty()) {
        H5::Group fg = g.createGroup("face_fields");
        for (const auto& [fname, m] : s.face_fields) {
            require(m.rows() == s.F.rows(), ctx + ": face field '" + fname + "' has " + std::to_string(m.rows()) + " rows, expected one per triangle");
            write_matrix(fg, fname, m, "", deflate);
        }
    }
}

SurfaceData read_surface(const H5::Group& parent, const std::string& name, const Ctx& ctx) {
    const std::string p = "/surface/" + name;
    const H5::Group g = parent.openGroup(name);
    SurfaceData s;
    s.V = read_matrix<double>(g, p, "vertices", -1, 3, ctx, "[V,3]");
    s.F = read_matrix<int>(g, p, "triangles", -1, 3, ctx, "[F,3]");
    const auto nf = s.F.rows();
    s.face_label = read_vector<int>(g, p, "face_label", nf, ctx, "[F] with F = " + std::to_string(nf));
    s.label_names = h5::read_strings(g, p, "label_names", ctx);
    s.face_region = read_vector<int>(g, p, "face_region", -1, ctx, "[F] or [0]");
    if (s.face_region.size() != 0 && s.face_region.size() != nf) {
        throw InputError(ctx.where(p + "/face_region") + ": shape [" + std::to_string(s.face_region.size()) +
                         "], expected [F] with F = " + std::to_string(nf) + " or [0]");
    }
    s.region_names = h5::read_strings(g, p, "region_names", ctx);
    if (!h5::exists(g, "loops")) throw InputError(ctx.where(p + "/loops") + ": missing group");
    const H5::Group lg = g.openGroup("loops");
    s.loop_offsets = read_vector<int>(lg, p + "/loops", "offsets", -1, ctx, "[loops+1]");
    s.loop_vertices = read_vector<int>(lg, p + "/loops", "vertices", -1, ctx, "[n]");
    s.loop_end_id = read_vector<int>(lg, p + "/loops", "end_id", -1, ctx, "[loops]");
    if (h5::exists(g, "vertex_thickness")) {
        s.vertex_thickness = read_vector<double>(g, p, "vertex_thickness", s.V.rows(), ctx, "[V] with V = " + std::to_string(s.V.rows()));
    }
    if (h5::exists(g, "face_fields")) {
        const H5::Group fg = g.openGroup("face_fields");
        for (const auto& fname : h5::child_names(fg))
            s.face_fields[fname] = read_matrix<double>(fg, p + "/face_fields", fname, nf, -1, ctx, "[F,k] with F = " + std::to_string(nf));
    }
    return s;
}

// ---------------------------------------------------------------- /volume
void write_volume(H5::H5File& f, const VolumeData& v, int deflate) {
    require(v.tets.cols() == 4 || v.tets.cols() == 10,
            "volume.tets has " + std::to_string(v.tets.cols()) + " columns, expected 4 or 10");
    require(v.tet_region.size() == v.tets.rows(), "volume.tet_region size != number of tets");
    check_index_range(Eigen::Map<const Eigen::VectorXi>(v.tets.data(), v.tets.size()), v.nodes.rows(),
                      "volume.tets");
    check_index_range(v.tet_region, static_cast<Eigen::Index>(v.region_names.size()), "volume.tet_region");
    H5::Group g = f.createGroup("/volume");
    write_matrix(g, "nodes", v.nodes, "mm", deflate);
    write_matrix(g, "tets", v.tets, "", deflate);
    write_vector<int>(g, "tet_region", v.tet_region, "", deflate);
    h5::write_strings(g, "region_names", v.region_names);
    H5::Group ns = g.createGroup("node_sets");
    for (const auto& [name, idx] : v.node_sets) {
        check_index_range(idx, v.nodes.rows(), "volume.node_sets[" + name + "]");
        write_vector<int>(ns, name, idx, "", deflate);
    }
    H5::Group q = g.createGroup("quality");
    for (const auto& [k, val] : v.quality) h5::write_attr(q, k, val);
}

VolumeData read_volume(const H5::H5File& f, const Ctx& ctx) {
    const H5::Group g = f.openGroup("/volume");
    VolumeData v;
    v.nodes = read_matrix<double>(g, "/volume", "nodes", -1, 3, ctx, "[N,3]");
    v.tets = read_matrix<int>(g, "/volume", "tets", -1, -1, ctx, "[T,4] or [T,10]");
    if (v.tets.cols() != 4 && v.tets.cols() != 10) {
        throw InputError(ctx.where("/volume/tets") + ": shape [" + std::to_string(v.tets.rows()) + "," +
                      std::to_string(v.tets.cols()) + "], expected [T,4] or [T,10]");
    }
    const auto nt = v.tets.rows();
    v.tet_region = read_vector<int>(g, "/volume", "tet_region", nt, ctx, "[T] with T = " + std::to_string(nt));
    v.region_names = h5::read_strings(g, "/volume", "region_names", ctx);
    if (!h5::exists(g, "node_sets")) throw InputError(ctx.where("/volume/node_sets") + ": missing group");
    const H5::Group ns = g.openGroup("node_sets");
    for (const auto& name : h5::child_names(ns)) {
        v.node_sets[name] = read_vector<int>(ns, "/volume/node_sets", name, -1, ctx, "[n]");
    }
    if (!h5::exists(g, "quality")) throw InputError(ctx.where("/volume/quality") + ": missing group");
    const H5::Group q = g.openGroup("quality");
    for (const auto& k : h5::attr_names(q)) {
        v.quality.emplace_back(k, h5::read_attr_double(q, "/volume/quality", k, ctx));
    }
    return v;
}

// ---------------------------------------------------------------- /fem
void write_fem(H5::H5File& f, const FemData& fe, int deflate) {
    require(fe.K.rows() == fe.K.cols(), "fem.K is not square");
    require(fe.K.isCompressed(), "fem.K must be compressed (makeCompressed())");
    check_index_range(fe.fixed_dofs, fe.K.rows(), "fem.fixed_dofs");
    H5::Group g = f.createGroup("/fem");
    h5::write_attr(g, "element_order", static_cast<std::int64_t>(fe.element_order));
    H5::Group kg = g.createGroup("K");
    h5::write_attr(kg, "n", static_cast<std::int64_t>(fe.K.rows()));
    h5::write_attr(kg, "storage", std::string(fe.K_upper_only ? "upper" : "full"));
    std::vector<std::int64_t> indptr(fe.K.outerIndexPtr(), fe.K.outerIndexPtr() + fe.K.rows() + 1);
    h5::write_array(kg, "indptr", indptr.data(), {indptr.size()}, "", deflate);
    h5::write_array(kg, "indices", fe.K.innerIndexPtr(), {static_cast<hsize_t>(fe.K.nonZeros())}, "", deflate);
    // Stiffness values are float64 noise to gzip (level 4 saved a few per cent and cost seconds on a 10-node real
    // case of 16 M stored entries): written uncompressed.
    h5::write_array(kg, "data", fe.K.valuePtr(), {static_cast<hsize_t>(fe.K.nonZeros())}, "N/mm", 0);
    H5::Group mg = g.createGroup("materials");
    std::vector<std::string> names;
    Eigen::VectorXd E(static_cast<Eigen::Index>(fe.materials.size())), nu(E.size());
    for (size_t i = 0; i < fe.materials.size(); ++i) {
        names.push_back(fe.materials[i].region);
        E[static_cast<Eigen::Index>(i)] = fe.materials[i].E_mpa;
        nu[static_cast<Eigen::Index>(i)] = fe.materials[i].nu;
    }
    h5::write_strings(mg, "region", names);
    write_vector<double>(mg, "E", E, "MPa", 0);
    write_vector<double>(mg, "nu", nu, "1", 0);
    write_vector<int>(g, "fixed_dofs", fe.fixed_dofs, "", deflate);
}

FemData read_fem(const H5::H5File& f, const Ctx& ctx) {
    const H5::Group g = f.openGroup("/fem");
    FemData fe;
    fe.element_order = static_cast<int>(h5::read_attr_int(g, "/fem", "element_order", ctx));
    if (!h5::exists(g, "K")) throw InputError(ctx.where("/fem/K") + ": missing group");
    const H5::Group kg = g.openGroup("K");
    const auto n = h5::read_attr_int(kg, "/fem/K", "n", ctx);
    fe.K_upper_only = h5::read_attr_string(kg, "/fem/K", "storage", ctx) == "upper";
    std::vector<hsize_t> d;
    auto indptr = h5::read_array<std::int64_t>(kg, "/fem/K", "indptr", {n + 1}, d, ctx,
                                               "[n+1] with n = " + std::to_string(n));
    const long long nnz = indptr.back();
    const std::string nd = "[nnz] with nnz = indptr[n] = " + std::to_string(nnz);
    auto indices = h5::read_array<std::int32_t>(kg, "/fem/K", "indices", {nnz}, d, ctx, nd);
    auto data = h5::read_array<double>(kg, "/fem/K", "data", {nnz}, d, ctx, nd);
    for (long long i = 0; i < nnz; ++i) {
        if (indices[static_cast<size_t>(i)] < 0 || indices[static_cast<size_t>(i)] >= n) {
            throw InputError(ctx.where("/fem/K/indices") + ": entry " + std::to_string(i) + " = " +
                          std::to_string(indices[static_cast<size_t>(i)]) + " outside [0," +
                          std::to_string(n) + ")");
        }
    }
    std::vector<int> outer(indptr.begin(), indptr.end());
    fe.K = Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>>(
        n, n, nnz, outer.data(), indices.data(), data.data());
    if (!h5::exists(g, "materials")) throw InputError(ctx.where("/fem/materials") + ": missing group");
    const H5::Group mg = g.openGroup("materials");
    const auto names = h5::read_strings(mg, "/fem/materials", "region", ctx);
    const auto nm = static_cast<long long>(names.size());
    const Eigen::VectorXd E = read_vector<double>(mg, "/fem/materials", "E", nm, ctx, "[regions]");
    const Eigen::VectorXd nu = read_vector<double>(mg, "/fem/materials", "nu", nm, ctx, "[regions]");
    for (long long i = 0; i < nm; ++i) fe.materials.push_back({names[static_cast<size_t>(i)], E[i], nu[i]});
    fe.fixed_dofs = read_vector<int>(g, "/fem", "fixed_dofs", -1, ctx, "[n_fixed]");
    return fe;
}

// ---------------------------------------------------------------- /flow
void write_flow(H5::H5File& f, const FlowFieldData& fl, int deflate) {
    const auto n = fl.centre.rows();
    require(fl.velocity.rows() == n && fl.pressure.size() == n && fl.volume.size() == n, "flow: centre, velocity, pressure and volume differ in length");
    H5::Group g = f.createGroup("/flow");
    write_matrix(g, "cell_centre", fl.centre, "mm", deflate);
    write_matrix(g, "velocity", fl.velocity, "mm/s", deflate);
    write_vector<double>(g, "pressure", fl.pressure, "Pa", deflate);
    write_vector<double>(g, "cell_volume", fl.volume, "mm3", deflate);
}

FlowFieldData read_flow(H5::H5File& f, const Ctx& ctx) {
    const H5::Group g = f.openGroup("/flow");
    FlowFieldData fl;
    fl.centre = read_matrix<double>(g, "/flow", "cell_centre", -1, 3, ctx, "[C,3]");
    const auto n = fl.centre.rows();
    const std::string doc = "[C] with C = " + std::to_string(n);
    fl.velocity = read_matrix<double>(g, "/flow", "velocity", n, 3, ctx, "[C,3] with C = " + std::to_string(n));
    fl.pressure = read_vector<double>(g, "/flow", "pressure", n, ctx, doc);
    fl.volume = read_vector<double>(g, "/flow", "cell_volume", n, ctx, doc);
    return fl;
}

}  // namespace

void write_bundle(const std::string& path, const Bundle& b, const BundleWriteOptions& opt, Reporter& rep) {
    h5::silence_hdf5();
    AtomicPath out(path);
    const int total = 2 + (b.image ? 1 : 0) + static_cast<int>(b.surfaces.size()) + (b.volume ? 1 : 0) +
                      (b.fem ? 1 : 0) + (b.condensed ? 1 : 0) + (b.flow ? 1 : 0);
    int done = 0;
    try {
        H5::H5File f(out.tmp(), H5F_ACC_TRUNC);
        write_meta(f, b.meta);
        rep.progress("write", ++done, total);
        if (b.image) {
            write_image(f, *b.image, opt.deflate_level);
            rep.progress("write", ++done, total);
        }
        if (!b.surfaces.empty()) {
            H5::Group sg = f.createGroup("/surface");
            for (const auto& [name, s] : b.surfaces) {
                write_surface(sg, name, s, opt.deflate_level);
                rep.progress("write", ++done, total);
            }
        }
        if (b.volume) {
            write_volume(f, *b.volume, opt.deflate_level);
            rep.progress("write", ++done, total);
        }
        if (b.fem) {
            write_fem(f, *b.fem, opt.deflate_level);
            rep.progress("write", ++done, total);
        }
        if (b.condensed) {
            detail::write_condensed_group(f, *b.condensed, rep);
            rep.progress("write", ++done, total);
        }
        if (b.flow) {
            write_flow(f, *b.flow, opt.deflate_level);
            rep.progress("write", ++done, total);
        }
        f.close();
    } catch (const H5::Exception& e) {
        throw IoError(path + ": HDF5 write failed in " + e.getFuncName() + " (HDF5: " + h5::last_error_detail() +
                      ")");
    }
    out.commit();
    rep.progress("write", total, total);
}

Meta read_meta(const std::string& path) {
    H5::H5File f = h5::open_bundle(path);
    return read_meta_group(f, Ctx{path});
}

Bundle read_bundle(const std::string& path, const BundleParts& parts) {
    H5::H5File f = h5::open_bundle(path);
    const Ctx ctx{path};
    const H5::Group root = f.openGroup("/");
    Bundle b;
    try {
        b.meta = read_meta_group(f, ctx);
        if (parts.image && h5::exists(root, "image")) b.image = read_image(f, ctx);
        if (parts.surfaces && h5::exists(root, "surface")) {
            const H5::Group sg = f.openGroup("/surface");
            for (const auto& name : h5::child_names(sg)) b.surfaces[name] = read_surface(sg, name, ctx);
        }
        if (parts.volume && h5::exists(root, "volume")) b.volume = read_volume(f, ctx);
        if (parts.fem && h5::exists(root, "fem")) b.fem = read_fem(f, ctx);
        if (h5::exists(root, "condensed")) b.condensed = detail::read_condensed_group(f, ctx, parts.condensed_W);
        if (parts.flow && h5::exists(root, "flow")) b.flow = read_flow(f, ctx);
    } catch (const H5::Exception& e) {
        throw InputError(path + ": HDF5 read failed in " + e.getFuncName() + " (HDF5: " + h5::last_error_detail() +
                      ")");
    }
    return b;
}

}  // namespace aneu
