// SPDX-License-Identifier: MIT
#pragma once
// Bundles with every group filled by seeded random data, and a temporary directory, for the tests.
#include <filesystem>
#include <random>
#include <string>

#include <unistd.h>

#include "aneu/core/bundle.hpp"

namespace aneu::test {

/// A fresh directory under the system temp dir, removed with everything in it at scope exit.
class TempDir {
public:
    explicit TempDir(const std::string& tag) {
        static int counter = 0;
        m_path = std::filesystem::temp_directory_path() /
                 ("aneu-" + tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        std::filesystem::remove_all(m_path);
        std::filesystem::create_directories(m_path);
    }
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(m_path, ec);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    std::string file(const std::string& name) const { return (m_path / name).string(); }
    const std::filesystem::path& path() const { return m_path; }

private:
    std::filesystem::path m_path;
};

/// A symmetric positive definite n×n matrix (seeded).
inline Eigen::MatrixXd random_spd(int n, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Eigen::MatrixXd A(n, n);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) A(i, j) = u(rng);
    const Eigen::MatrixXd M = A * A.transpose() / n + Eigen::MatrixXd::Identity(n, n);
    return 0.5 * (M + M.transpose());  // exactly symmetric (a + b == b + a in IEEE arithmetic)
}

/// A bundle with every group present; sizes chosen so that W's edge is not a multiple of the tile size.
inline Bundle full_bundle(Precision precision, int n_kept = 301, int tile = 64, unsigned seed = 7) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-10.0, 10.0);
    std::uniform_int_distribution<int> pick(0, 99);
    Bundle b;
    b.meta.case_id = "roundtrip";
    StageRecord s;
    s.stage = "segment";
    s.tool_version = "0.1.0";
    s.git_revision = "abc123";
    s.created_utc = "2026-11-21T11:44:47Z";
    s.command_line = "aneuprep segment 'a b.nii.gz' -o x.h5";
    s.parameters = {{"threshold_hu", "200"}, {"roi_mm", "1,2,3,4,5,6"}, {"seeds_mm", ""}};
    s.inputs = {{"a b.nii.gz", std::string(64, 'a')}};
    s.wall_time_s = 1.25;
    b.meta.stages.push_back(s);
    s.stage = "surface";
    s.inputs.clear();
    b.meta.stages.push_back(s);

    ImageData im;
    im.grid.size = {7, 5, 3};
    im.grid.origin = {-1.5, 2.25, 3.0};
    im.grid.spacing = {0.4, 0.45, 0.7};
    im.grid.direction = {0, 1, 0, -1, 0, 0, 0, 0, 1};
    for (size_t i = 0; i < im.grid.voxel_count(); ++i) im.mask.push_back(static_cast<std::uint8_t>(pick(rng) % 3));
    im.mask_label_names = {"background", "artery", "aneurysm"};
    im.centerline.points = Eigen::MatrixX3d::NullaryExpr(9, 3, [&] { return u(rng); });
    im.centerline.radius = Eigen::VectorXd::NullaryExpr(9, [&] { return std::abs(u(rng)); });
    im.centerline.offsets = (Eigen::VectorXi(3) << 0, 4, 9).finished();
    im.planes.push_back({0, {1, 2, 3}, {0, 0, 1}, 1.5});
    im.planes.push_back({4, {-1, 2.5, 3}, {0.6, 0.8, 0}, 2.0});
    b.image = im;

    SurfaceData sf;
    sf.V = Eigen::MatrixX3d::NullaryExpr(20, 3, [&] { return u(rng); });
    sf.F = Eigen::MatrixX3i::NullaryExpr(30, 3, [&] { return pick(rng) % 20; });
    sf.face_label = Eigen::VectorXi::NullaryExpr(30, [&] { return pick(rng) % 2; });
    sf.label_names = {"artery", "aneurysm"};
    sf.loop_offsets = (Eigen::VectorXi(3) << 0, 3, 7).finished();
    sf.loop_vertices = (Eigen::VectorXi(7) << 1, 2, 3, 4, 5, 6, 7).finished();
    sf.loop_end_id = (Eigen::VectorXi(2) << 0, 4).finished();
    b.surfaces["lumen"] = sf;
    sf.face_region = Eigen::VectorXi::NullaryExpr(30, [&] { return pick(rng) % 2; });
    sf.region_names = {"artery", "aneurysm"};
    sf.label_names = {"inner", "outer", "cap:0", "cap:4"};
    sf.face_label = Eigen::VectorXi::NullaryExpr(30, [&] { return pick(rng) % 4; });
    b.surfaces["wall"] = sf;

    VolumeData v;
    v.nodes = Eigen::MatrixX3d::NullaryExpr(50, 3, [&] { return u(rng); });
    v.tets = Eigen::MatrixXi::NullaryExpr(40, 10, [&] { return pick(rng) % 50; });
    v.tet_region = Eigen::VectorXi::NullaryExpr(40, [&] { return pick(rng) % 2; });
    v.region_names = {"artery", "aneurysm"};
    v.node_sets["outer"] = (Eigen::VectorXi(4) << 1, 5, 9, 49).finished();
    v.node_sets["fixed"] = (Eigen::VectorXi(2) << 0, 3).finished();
    v.node_sets["inner"] = Eigen::VectorXi();
    v.quality = {{"min_dihedral_deg", 11.5}, {"max_radius_edge", 1.9}};
    b.volume = v;

    FemData fe;
    fe.element_order = 2;
    Eigen::SparseMatrix<double, Eigen::RowMajor> K(150, 150);
    std::vector<Eigen::Triplet<double>> trip;
    for (int i = 0; i < 150; ++i) {
        trip.emplace_back(i, i, 10.0 + u(rng));
        if (i + 7 < 150) trip.emplace_back(i, i + 7, u(rng));
    }
    K.setFromTriplets(trip.begin(), trip.end());
    K.makeCompressed();
    fe.K = K;
    fe.materials = {{"artery", 1.0, 0.45}, {"aneurysm", 0.5, 0.49}};
    fe.fixed_dofs = (Eigen::VectorXi(3) << 0, 1, 2).finished();
    b.fem = fe;

    CondensedData c;
    c.dof_node = Eigen::VectorXi::NullaryExpr(n_kept, [&] { return pick(rng) % 50; });
    c.dof_axis = Eigen::VectorXi::NullaryExpr(n_kept, [&] { return pick(rng) % 3; });
    c.precision = precision;
    const Eigen::MatrixXd W = random_spd(n_kept, seed);
    if (precision == Precision::FLOAT32) {
        c.W32 = TiledSymmetric<float>::from_dense(W.cast<float>(), tile);
    } else {
        c.W64 = TiledSymmetric<double>::from_dense(W, tile);
    }
    c.method = "test";
    c.diagnostics = {{"time_s", 0.5}, {"residual", 1e-12}};
    b.condensed = c;
    return b;
}

}  // namespace aneu::test
