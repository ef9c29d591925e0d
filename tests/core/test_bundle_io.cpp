// SPDX-License-Identifier: MIT
// Round trip of every bundle group, and every way a bundle file can be wrong.
#include <filesystem>
#include <fstream>

#include <H5Cpp.h>
#include <gtest/gtest.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/file_summary.hpp"
#include "test_bundles.hpp"

namespace fs = std::filesystem;
using namespace aneu;
using aneu::test::TempDir;

namespace {

void expect_same(const Bundle& a, const Bundle& b) {
    ASSERT_EQ(a.meta.schema_version, b.meta.schema_version);
    EXPECT_EQ(a.meta.case_id, b.meta.case_id);
    EXPECT_EQ(a.meta.units, b.meta.units);
    ASSERT_EQ(a.meta.stages.size(), b.meta.stages.size());
    for (size_t i = 0; i < a.meta.stages.size(); ++i) {
        const auto &x = a.meta.stages[i], &y = b.meta.stages[i];
        EXPECT_EQ(x.stage, y.stage);
        EXPECT_EQ(x.tool_version, y.tool_version);
        EXPECT_EQ(x.git_revision, y.git_revision);
        EXPECT_EQ(x.created_utc, y.created_utc);
        EXPECT_EQ(x.command_line, y.command_line);
        EXPECT_EQ(x.wall_time_s, y.wall_time_s);
        auto px = x.parameters, py = y.parameters;  // attribute order is by name in the file
        std::sort(px.begin(), px.end());
        std::sort(py.begin(), py.end());
        EXPECT_EQ(px, py);
        ASSERT_EQ(x.inputs.size(), y.inputs.size());
        for (size_t k = 0; k < x.inputs.size(); ++k) {
            EXPECT_EQ(x.inputs[k].path, y.inputs[k].path);
            EXPECT_EQ(x.inputs[k].sha256, y.inputs[k].sha256);
        }
    }
    ASSERT_TRUE(a.image && b.image);
    EXPECT_EQ(a.image->grid.size, b.image->grid.size);
    EXPECT_EQ(a.image->grid.origin, b.image->grid.origin);
    EXPECT_EQ(a.image->grid.spacing, b.image->grid.spacing);
    EXPECT_EQ(a.image->grid.direction, b.image->grid.direction);
    EXPECT_EQ(a.image->mask, b.image->mask);
    EXPECT_EQ(a.image->mask_label_names, b.image->mask_label_names);
    EXPECT_EQ(a.image->centerline.points, b.image->centerline.points);
    EXPECT_EQ(a.image->centerline.radius, b.image->centerline.radius);
    EXPECT_EQ(a.image->centerline.offsets, b.image->centerline.offsets);
    ASSERT_EQ(a.image->planes.size(), b.image->planes.size());
    for (size_t i = 0; i < a.image->planes.size(); ++i) {
        EXPECT_EQ(a.image->planes[i].id, b.image->planes[i].id);
        EXPECT_EQ(a.image->planes[i].point, b.image->planes[i].point);
        EXPECT_EQ(a.image->planes[i].normal, b.image->planes[i].normal);
        EXPECT_EQ(a.image->planes[i].radius_mm, b.image->planes[i].radius_mm);
    }
    ASSERT_EQ(a.surfaces.size(), b.surfaces.size());
    for (const auto& [name, s] : a.surfaces) {
        ASSERT_TRUE(b.surfaces.count(name)) << name;
        const SurfaceData& t = b.surfaces.at(name);
        EXPECT_EQ(s.V, t.V);
        EXPECT_EQ(s.F, t.F);
        EXPECT_EQ(s.face_label, t.face_label);
        EXPECT_EQ(s.label_names, t.label_names);
        EXPECT_EQ(s.loop_offsets, t.loop_offsets);
        EXPECT_EQ(s.loop_vertices, t.loop_vertices);
        EXPECT_EQ(s.loop_end_id, t.loop_end_id);
        EXPECT_EQ(s.face_region, t.face_region);
        EXPECT_EQ(s.region_names, t.region_names);
    }
    ASSERT_TRUE(a.volume && b.volume);
    EXPECT_EQ(a.volume->nodes, b.volume->nodes);
    EXPECT_EQ(a.volume->tets, b.volume->tets);
    EXPECT_EQ(a.volume->tet_region, b.volume->tet_region);
    EXPECT_EQ(a.volume->region_names, b.volume->region_names);
    ASSERT_EQ(a.volume->node_sets.size(), b.volume->node_sets.size());
    for (const auto& [k, v] : a.volume->node_sets) EXPECT_EQ(v, b.volume->node_sets.at(k)) << k;
    auto qa = a.volume->quality, qb = b.volume->quality;
    std::sort(qa.begin(), qa.end());
    std::sort(qb.begin(), qb.end());
    EXPECT_EQ(qa, qb);
    ASSERT_TRUE(a.fem && b.fem);
    EXPECT_EQ(a.fem->element_order, b.fem->element_order);
    EXPECT_EQ(a.fem->K_upper_only, b.fem->K_upper_only);
    EXPECT_EQ(Eigen::MatrixXd(a.fem->K), Eigen::MatrixXd(b.fem->K));
    EXPECT_EQ(a.fem->K.nonZeros(), b.fem->K.nonZeros());
    ASSERT_EQ(a.fem->materials.size(), b.fem->materials.size());
    for (size_t i = 0; i < a.fem->materials.size(); ++i) {
        EXPECT_EQ(a.fem->materials[i].region, b.fem->materials[i].region);
        EXPECT_EQ(a.fem->materials[i].E_mpa, b.fem->materials[i].E_mpa);
        EXPECT_EQ(a.fem->materials[i].nu, b.fem->materials[i].nu);
    }
    EXPECT_EQ(a.fem->fixed_dofs, b.fem->fixed_dofs);
    ASSERT_TRUE(a.condensed && b.condensed);
    EXPECT_EQ(a.condensed->dof_node, b.condensed->dof_node);
    EXPECT_EQ(a.condensed->dof_axis, b.condensed->dof_axis);
    EXPECT_EQ(a.condensed->precision, b.condensed->precision);
    EXPECT_EQ(a.condensed->method, b.condensed->method);
    auto da = a.condensed->diagnostics, db = b.condensed->diagnostics;
    std::sort(da.begin(), da.end());
    std::sort(db.begin(), db.end());
    EXPECT_EQ(da, db);
    EXPECT_EQ(a.condensed->W32.size(), b.condensed->W32.size());
    EXPECT_EQ(a.condensed->W32.data(), b.condensed->W32.data());
    EXPECT_EQ(a.condensed->W64.size(), b.condensed->W64.size());
    EXPECT_EQ(a.condensed->W64.data(), b.condensed->W64.data());
}

/// Runs f and returns the InputError's message; fails the test if f does not throw one.
template <class F>
std::string input_error_of(F&& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    ADD_FAILURE() << "expected an InputError";
    return "";
}

}  // namespace

TEST(BundleIO, RoundTripEveryGroupFloat64) {
    TempDir d("rt64");
    const Bundle b = test::full_bundle(Precision::FLOAT64);
    write_bundle(d.file("b.h5"), b, BundleWriteOptions{4});
    expect_same(b, read_bundle(d.file("b.h5")));
}

TEST(BundleIO, RoundTripEveryGroupFloat32) {
    TempDir d("rt32");
    const Bundle b = test::full_bundle(Precision::FLOAT32, 64, 32);  // n a multiple of the tile: no padding
    write_bundle(d.file("b.h5"), b, BundleWriteOptions{0});          // and no compression
    expect_same(b, read_bundle(d.file("b.h5")));
}

TEST(BundleIO, EmptyBundleHasOnlyMeta) {
    TempDir d("empty");
    Bundle b;
    b.meta.case_id = "x";
    write_bundle(d.file("m.h5"), b);
    const Bundle r = read_bundle(d.file("m.h5"));
    EXPECT_EQ(r.meta.case_id, "x");
    EXPECT_FALSE(r.image || r.volume || r.fem || r.condensed);
    EXPECT_TRUE(r.surfaces.empty());
}

TEST(BundleIO, ColumnSubsetEqualsFullMatrixColumns) {
    TempDir d("cols");
    const Bundle b = test::full_bundle(Precision::FLOAT64, 301, 64);
    write_bundle(d.file("b.h5"), b);
    const Eigen::MatrixXd W = b.condensed->W64.to_dense();
    const std::vector<int> cols{300, 0, 63, 64, 65, 127, 200, 64};  // tile edges, duplicates, any order
    const Eigen::MatrixXd Wc = read_condensed_columns(d.file("b.h5"), cols);
    ASSERT_EQ(Wc.rows(), 301);
    ASSERT_EQ(Wc.cols(), static_cast<Eigen::Index>(cols.size()));
    for (size_t q = 0; q < cols.size(); ++q) EXPECT_EQ(Wc.col(q), W.col(cols[q])) << "column " << cols[q];
    const Eigen::MatrixXf Wf = read_condensed_columns_f(d.file("b.h5"), cols);
    for (size_t q = 0; q < cols.size(); ++q) EXPECT_EQ(Wf.col(q), W.col(cols[q]).cast<float>());
    const std::string m = input_error_of([&] { read_condensed_columns(d.file("b.h5"), {301}); });
    EXPECT_NE(m.find("column 301 of W requested, W has 301 columns"), std::string::npos) << m;
}

TEST(BundleIO, HeaderWithoutW) {
    TempDir d("hdr");
    const Bundle b = test::full_bundle(Precision::FLOAT32, 100);
    write_bundle(d.file("b.h5"), b);
    const CondensedData c = read_condensed_header(d.file("b.h5"));
    EXPECT_EQ(c.size(), 100);
    EXPECT_EQ(c.precision, Precision::FLOAT32);
    EXPECT_EQ(c.W32.size(), 0);
    EXPECT_TRUE(c.W32.data().empty());
    EXPECT_EQ(c.dof_node, b.condensed->dof_node);
}

TEST(BundleIO, TruncatedFileIsNamed) {
    TempDir d("trunc");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64));
    const auto size = fs::file_size(d.file("b.h5"));
    {
        std::ifstream in(d.file("b.h5"), std::ios::binary);
        std::string bytes(size / 2, '\0');
        in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        std::ofstream(d.file("half.h5"), std::ios::binary) << bytes;
    }
    const std::string m = input_error_of([&] { read_bundle(d.file("half.h5")); });
    EXPECT_NE(m.find(d.file("half.h5")), std::string::npos) << m;
    EXPECT_NE(m.find("truncated"), std::string::npos) << m;
}

TEST(BundleIO, OtherSchemaVersionIsRefused) {
    TempDir d("schema");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64));
    {
        H5::H5File f(d.file("b.h5"), H5F_ACC_RDWR);
        H5::Group g = f.openGroup("/meta");
        g.removeAttr("schema_version");
        const std::int64_t v = 2;
        g.createAttribute("schema_version", H5::PredType::NATIVE_INT64, H5::DataSpace(H5S_SCALAR))
            .write(H5::PredType::NATIVE_INT64, &v);
    }
    const std::string m = input_error_of([&] { read_bundle(d.file("b.h5")); });
    EXPECT_NE(m.find("schema version 2"), std::string::npos) << m;
    EXPECT_NE(m.find("reads only version 1"), std::string::npos) << m;
}

TEST(BundleIO, MissingDatasetIsNamed) {
    TempDir d("missing");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64));
    {
        H5::H5File f(d.file("b.h5"), H5F_ACC_RDWR);
        f.openGroup("/volume").unlink("tets");
    }
    const std::string m = input_error_of([&] { read_bundle(d.file("b.h5")); });
    EXPECT_NE(m.find(d.file("b.h5") + ": /volume/tets: missing dataset"), std::string::npos) << m;
}

TEST(BundleIO, WrongShapeIsNamed) {
    TempDir d("shape");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64));
    {
        H5::H5File f(d.file("b.h5"), H5F_ACC_RDWR);
        H5::Group g = f.openGroup("/volume");
        g.unlink("nodes");
        const hsize_t dims[2] = {50, 2};
        std::vector<double> zeros(100, 0.0);
        g.createDataSet("nodes", H5::PredType::NATIVE_DOUBLE, H5::DataSpace(2, dims))
            .write(zeros.data(), H5::PredType::NATIVE_DOUBLE);
    }
    const std::string m = input_error_of([&] { read_bundle(d.file("b.h5")); });
    EXPECT_NE(m.find("/volume/nodes: shape [50,2], expected [N,3]"), std::string::npos) << m;
}

TEST(BundleIO, WrongShapeOfDependentDatasetIsNamed) {
    TempDir d("shape2");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64));
    {
        H5::H5File f(d.file("b.h5"), H5F_ACC_RDWR);
        H5::Group g = f.openGroup("/volume");
        g.unlink("tet_region");
        const hsize_t n = 39;
        std::vector<int> zeros(39, 0);
        g.createDataSet("tet_region", H5::PredType::NATIVE_INT32, H5::DataSpace(1, &n))
            .write(zeros.data(), H5::PredType::NATIVE_INT32);
    }
    const std::string m = input_error_of([&] { read_bundle(d.file("b.h5")); });
    EXPECT_NE(m.find("/volume/tet_region: shape [39], expected [T] with T = 40"), std::string::npos) << m;
}

TEST(BundleIO, NotHdf5AndMissingFileAreNamed) {
    TempDir d("nothdf");
    std::ofstream(d.file("text.h5")) << "hello, not HDF5\n";
    std::string m = input_error_of([&] { read_bundle(d.file("text.h5")); });
    EXPECT_NE(m.find("text.h5: not an HDF5 file"), std::string::npos) << m;
    m = input_error_of([&] { read_bundle(d.file("nope.h5")); });
    EXPECT_NE(m.find("nope.h5: no such file"), std::string::npos) << m;
    {
        H5::H5File f(d.file("foreign.h5"), H5F_ACC_TRUNC);
        f.createGroup("/data");
    }
    m = input_error_of([&] { read_bundle(d.file("foreign.h5")); });
    EXPECT_NE(m.find("not an aneuclip bundle"), std::string::npos) << m;
}

TEST(BundleIO, InterruptedWriteLeavesNothingUnderFinalName) {
    TempDir d("interrupt");
    Reporter cancel;
    cancel.on_progress = [](const std::string& stage, std::int64_t done, std::int64_t) {
        if (stage == "write" && done == 3) throw std::runtime_error("simulated interruption");
    };
    EXPECT_THROW(write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64), {}, cancel), std::runtime_error);
    EXPECT_FALSE(fs::exists(d.file("b.h5")));
    EXPECT_TRUE(fs::is_empty(d.path())) << "temporary file left behind";
}

TEST(BundleIO, InterruptedRewriteKeepsPreviousFile) {
    TempDir d("rewrite");
    Bundle old;
    old.meta.case_id = "previous";
    write_bundle(d.file("b.h5"), old);
    Reporter cancel;
    cancel.on_progress = [](const std::string& stage, std::int64_t done, std::int64_t) {
        if (stage == "write W" && done == 2) throw std::runtime_error("killed while writing W");
    };
    EXPECT_THROW(write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT64, 301, 64), {4}, cancel),
                 std::runtime_error);
    EXPECT_EQ(read_meta(d.file("b.h5")).case_id, "previous");
    EXPECT_EQ(std::distance(fs::directory_iterator(d.path()), fs::directory_iterator()), 1);
}

TEST(BundleIO, InconsistentBundleIsRefusedOnWrite) {
    TempDir d("bad");
    Bundle b = test::full_bundle(Precision::FLOAT64);
    b.volume->tets(3, 2) = 50;  // node index out of range
    const std::string m = input_error_of([&] { write_bundle(d.file("b.h5"), b); });
    EXPECT_NE(m.find("volume.tets"), std::string::npos) << m;
    EXPECT_NE(m.find("outside [0,50)"), std::string::npos) << m;
    EXPECT_FALSE(fs::exists(d.file("b.h5")));
    const std::string m2 = input_error_of([&] { write_bundle(d.file("nodir/b.h5"), b); });
    EXPECT_NE(m2.find("does not exist"), std::string::npos) << m2;
}

TEST(BundleIO, SummaryListsDatasetsUnitsAndLayout) {
    TempDir d("summary");
    write_bundle(d.file("b.h5"), test::full_bundle(Precision::FLOAT32, 301, 64));
    const FileSummary s = summarize_bundle(d.file("b.h5"));
    ASSERT_EQ(s.meta.stages.size(), 2u);
    const H5Entry* nodes = s.find("/volume/nodes");
    ASSERT_NE(nodes, nullptr);
    EXPECT_EQ(nodes->shape, (std::vector<std::uint64_t>{50, 3}));
    EXPECT_EQ(nodes->dtype, "float64");
    EXPECT_EQ(nodes->units, "mm");
    const H5Entry* w = s.find("/condensed/W_tiles");
    ASSERT_NE(w, nullptr);
    EXPECT_EQ(w->shape, (std::vector<std::uint64_t>{15, 64, 64}));  // 5 tile rows -> 5*6/2 tiles
    EXPECT_EQ(w->dtype, "float32");
    EXPECT_EQ(w->units, "mm/N");
    EXPECT_EQ(w->stored_bytes, 15u * 64 * 64 * 4);
    EXPECT_EQ(s.find("/meta"), nullptr);
}
