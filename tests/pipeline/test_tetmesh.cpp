// SPDX-License-Identifier: MIT
// tetmesh: boundary preserved, volume conserved, node sets, quality, error paths; stage chain.
#include <gtest/gtest.h>

#include <functional>
#include <set>

#include <Eigen/Geometry>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/element.hpp"
#include "aneu/pipeline/stages.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/tetmesh.hpp"
#include "test_bundles.hpp"

using namespace aneu;
using namespace aneu::pipeline;

namespace {

double enclosed_volume(const SurfaceData& s) {
    double v = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) v += s.V.row(s.F(f, 0)).dot(s.V.row(s.F(f, 1)).cross(s.V.row(s.F(f, 2)))) / 6.0;
    return v;
}

double mesh_volume(const VolumeData& v, double* min_vol = nullptr) {
    double sum = 0, mn = 1e300;
    for (Eigen::Index t = 0; t < v.tets.rows(); ++t) {
        Eigen::Matrix<double, 4, 3> X;
        for (int a = 0; a < 4; ++a) X.row(a) = v.nodes.row(v.tets(t, a));
        const double vol = fem::tet_volume(X);
        sum += vol;
        mn = std::min(mn, vol);
    }
    if (min_vol) *min_vol = mn;
    return sum;
}

double quality(const VolumeData& v, const std::string& k) {
    for (const auto& [n, x] : v.quality)
        if (n == k) return x;
    ADD_FAILURE() << "no quality figure " << k;
    return 0;
}

std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

}  // namespace

class Mesher : public ::testing::TestWithParam<std::string> {};

TEST_P(Mesher, TubeWallIsFilledExactlyWithPositiveTets) {
    const SurfaceData s = tube_wall_surface(1.7, 0.3, 4.0, 24, 12, 15.0);
    TetMeshParams p;
    p.mesher = GetParam();
    const VolumeData v = tetmesh(s, p);
    double min_vol = 0;
    EXPECT_NEAR(mesh_volume(v, &min_vol), enclosed_volume(s), 1e-9 * enclosed_volume(s));
    EXPECT_GT(min_vol, 0.0);
    EXPECT_EQ(v.node_sets.at("inner").size(), 24 * 13);
    EXPECT_EQ(v.node_sets.at("outer").size(), 24 * 13);
    EXPECT_EQ(v.node_sets.at("fixed").size(), 2 * 2 * 24);
    EXPECT_GT(quality(v, "min_dihedral_deg"), 0.0);
    EXPECT_GE(quality(v, "layers_min"), 1.0);
    EXPECT_EQ(v.tet_region.size(), v.tets.rows());
    EXPECT_EQ(v.region_names, std::vector<std::string>{"artery"});
    if (GetParam() == "tetgen") {  // boundary preserved: surface vertices are the first nodes, unmoved
        EXPECT_EQ(v.nodes.topRows(s.V.rows()), s.V);
    }
}
INSTANTIATE_TEST_SUITE_P(TetGenAndNetgen, Mesher, ::testing::Values("tetgen", "netgen"));

TEST(TetMesh, BadSurfacesAreRefusedWithTheReason) {
    SurfaceData s = tube_wall_surface(1.7, 0.3, 4.0, 16, 6);
    SurfaceData open = s;
    open.F.conservativeResize(s.F.rows() - 1, 3);
    open.face_label.conservativeResize(s.F.rows() - 1);
    EXPECT_NE(error_of([&] { tetmesh(open, {}); }).find("not closed: 3 boundary edges"), std::string::npos);
    SurfaceData flipped = s;
    flipped.F.col(1).swap(flipped.F.col(2));
    EXPECT_NE(error_of([&] { tetmesh(flipped, {}); }).find("not positive"), std::string::npos);
    // Two copies of the wall, the second shifted into the first: closed and oriented, but self-intersecting.
    SurfaceData twice = s;
    twice.V.resize(2 * s.V.rows(), 3);
    twice.V << s.V, (s.V.rowwise() + Eigen::RowVector3d(0.55, 0.1, 0.7));
    twice.F.resize(2 * s.F.rows(), 3);
    twice.F << s.F, (s.F.array() + static_cast<int>(s.V.rows())).matrix();
    twice.face_label.resize(2 * s.F.rows());
    twice.face_label << s.face_label, s.face_label;
    twice.face_region = Eigen::VectorXi::Zero(2 * s.F.rows());
    const std::string m = error_of([&] { tetmesh(twice, {}); });
    EXPECT_NE(m.find("self-intersect"), std::string::npos) << m;
    TetMeshParams quick;
    quick.timeout_s = 1e-3;
    quick.max_volume_mm3 = 1e-5;
    EXPECT_NE(error_of([&] { tetmesh(s, quick); }).find("killed"), std::string::npos);
    TetMeshParams bad;
    bad.mesher = "gmsh";
    EXPECT_NE(error_of([&] { tetmesh(s, bad); }).find("mesher = 'gmsh'"), std::string::npos);
}

TEST(Stages, ChainWritesEveryGroupAndProvenance) {
    test::TempDir d("chain");
    TubeWallParams tw;
    tw.n_theta = 16;
    tw.n_z = 10;
    StageRecord r;
    r.stage = "tubewall";
    tubewall_file(tw, d.file("wall.h5"), r);
    r.stage = "tetmesh";
    tetmesh_file(d.file("wall.h5"), d.file("vol.h5"), {}, r);
    AssembleParams ap;
    ap.element_order = 2;
    r.stage = "assemble";
    assemble_file(d.file("vol.h5"), d.file("fem.h5"), ap, r);
    CondenseStageParams cp;
    cp.numeric.precision = Precision::FLOAT64;
    cp.numeric.tile_size = 64;
    // By default only the outer surface's corner nodes are kept (a tube without a sac: the whole surface).
    {
        const VolumeData v = *read_bundle(d.file("fem.h5")).volume;
        std::vector<char> corner(static_cast<size_t>(v.nodes.rows()), 0);
        for (Eigen::Index t = 0; t < v.tets.rows(); ++t)
            for (int a = 0; a < 4; ++a) corner[static_cast<size_t>(v.tets(t, a))] = 1;
        const Eigen::VectorXi& fx = v.node_sets.at("fixed");
        const std::set<int> fixed_set(fx.data(), fx.data() + fx.size());
        size_t corners_free = 0;
        for (Eigen::Index k = 0; k < v.node_sets.at("outer").size(); ++k) {
            const int n = v.node_sets.at("outer")[k];
            corners_free += corner[static_cast<size_t>(n)] && !fixed_set.count(n);
        }
        const std::vector<int> kept = kept_nodes(v, cp);
        EXPECT_EQ(kept.size(), corners_free);
        for (int n : kept) EXPECT_TRUE(corner[static_cast<size_t>(n)]);
        EXPECT_EQ(resolved_region_label(v, cp), "") << "no aneurysm region: the whole surface";
    }
    cp.nodes = "all";  // below: every outer node, mid-edge ones included
    r.stage = "condense";
    condense_file(d.file("fem.h5"), d.file("case.h5"), cp, r);
    const Bundle b = read_bundle(d.file("case.h5"));
    ASSERT_EQ(b.meta.stages.size(), 4u);
    EXPECT_EQ(b.meta.stages[3].stage, "condense");
    ASSERT_TRUE(b.volume && b.fem && b.condensed);
    EXPECT_EQ(b.volume->tets.cols(), 10);
    EXPECT_EQ(b.fem->element_order, 2);
    // Kept = outer, not fixed, all three axes, with quadratic mid-edge nodes on the outer surface.
    std::set<int> fixed(b.volume->node_sets.at("fixed").data(), b.volume->node_sets.at("fixed").data() + b.volume->node_sets.at("fixed").size());
    size_t outer_free = 0;
    for (Eigen::Index k = 0; k < b.volume->node_sets.at("outer").size(); ++k) outer_free += !fixed.count(b.volume->node_sets.at("outer")[k]);
    EXPECT_EQ(static_cast<size_t>(b.condensed->size()), 3 * outer_free);
    EXPECT_GT(outer_free, 16u * 9u);  // more than the corner nodes alone
    // W is SPD: positive diagonal.
    for (Eigen::Index i = 0; i < b.condensed->size(); ++i) ASSERT_GT(b.condensed->W64(i, i), 0.0);

    CondenseStageParams far;
    far.region_sphere = std::array<double, 4>{100, 100, 100, 1};
    r.stage = "condense";
    EXPECT_NE(error_of([&] { condense_file(d.file("fem.h5"), d.file("x.h5"), far, r); }).find("contains no simulated node"),
              std::string::npos);
    Bundle no_wall;
    no_wall.meta.case_id = "x";
    write_bundle(d.file("nowall.h5"), no_wall);
    EXPECT_NE(error_of([&] { tetmesh_file(d.file("nowall.h5"), d.file("y.h5"), {}, r); }).find("no /surface/wall"),
              std::string::npos);
}

TEST(TubeSac, WallIsClosedLabelledAndMeshesIntoTwoRegions) {
    TubeSacParams p;  // r 1.7, t 0.3, L 12, sac R 2.5, sac wall 0.1, neck 1.5, edge 0.2
    const SurfaceData s = tube_sac_wall_surface(p);
    EXPECT_NO_THROW(check_closed_surface(s, "tube+sac"));
    EXPECT_TRUE(self_intersections(s).empty());
    EXPECT_EQ(s.region_names, (std::vector<std::string>{"artery", "aneurysm"}));
    const Eigen::Vector3d C(p.inner_radius_mm + std::sqrt(p.sac_radius_mm * p.sac_radius_mm - p.neck_radius_mm * p.neck_radius_mm), 0,
                            0.5 * p.length_mm);
    int sac_faces = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (s.face_region[f] != 1) continue;
        ++sac_faces;
        const Eigen::Vector3d c = (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
        ASSERT_LT(std::abs((c - C).norm() - (p.sac_radius_mm + 0.5 * p.sac_thickness_mm)), 0.5 * p.sac_thickness_mm + p.edge_mm);
    }
    EXPECT_GT(sac_faces, 500);
    const VolumeData v = tetmesh(s, {});
    EXPECT_NEAR(mesh_volume(v), enclosed_volume(s), 1e-9 * enclosed_volume(s));
    const Eigen::Index n_sac = (v.tet_region.array() == 1).count();
    EXPECT_GT(n_sac, 100);
    EXPECT_LT(n_sac, v.tets.rows() / 2);
    // Condensing only the aneurysm's nodes keeps nodes on the sac and the ring of its neck.
    CondenseStageParams cp;
    EXPECT_EQ(resolved_region_label(v, cp), "aneurysm") << "the default working region is the sac's";
    cp.region_label = "aneurysm";
    cp.region_margin_mm = 0.0;
    const std::vector<int> kept = kept_nodes(v, cp);
    ASSERT_FALSE(kept.empty());
    for (int n : kept) ASSERT_LT((v.nodes.row(n).transpose() - C).norm(), p.sac_radius_mm + p.sac_thickness_mm + 3 * p.edge_mm);
}

TEST(Stages, AssembleNamesSliverTetrahedra) {
    // Stability at the extremes: a sliver (four nearly coplanar corners, quality 1e-4) beside a regular tetrahedron.
    // Assembly goes on (the element is valid) but warns, naming how many, the worst and where; QA records it.
    test::TempDir d("sliver");
    Bundle b;
    b.meta.case_id = "sliver";
    VolumeData v;
    v.nodes.resize(5, 3);
    v.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.5, 0.5, -1e-4;
    v.tets.resize(2, 4);
    v.tets << 0, 1, 2, 3, 0, 2, 1, 4;
    v.tet_region = Eigen::VectorXi::Zero(2);
    v.region_names = {"artery"};
    v.node_sets["fixed"] = (Eigen::VectorXi(3) << 0, 1, 2).finished();
    v.node_sets["outer"] = (Eigen::VectorXi(2) << 3, 4).finished();
    v.node_sets["inner"] = Eigen::VectorXi();
    b.volume = v;
    write_bundle(d.file("vol.h5"), b);
    std::vector<std::string> warnings;
    Reporter rep;
    rep.on_message = [&](Level lv, const std::string& m) {
        if (lv == Level::WARN) warnings.push_back(m);
    };
    StageRecord r;
    r.stage = "assemble";
    assemble_file(d.file("vol.h5"), d.file("fem.h5"), AssembleParams{}, r, rep);
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("1 sliver tetrahedra"), std::string::npos) << warnings[0];
    EXPECT_NE(warnings[0].find("tet 1 near 0.375, 0.375"), std::string::npos) << warnings[0];
    const Meta m = read_meta(d.file("fem.h5"));
    double q = -1;
    for (const auto& [k, val] : m.stages.back().qa)
        if (k == "min_tet_quality") q = val;
    EXPECT_GT(q, 0.0);
    EXPECT_LT(q, 1e-3);
}

TEST(Stages, NearDegenerateSurfaceTrianglesGiveSliversThatAreNamed) {
    // Stability at the extremes: the wall surface carries two needle triangles (an outer edge split 1e-5 of its
    // length from one end). The mesher keeps the surface, so tiny tetrahedra appear there, and assembly names them
    // (never silently).
    test::TempDir d("needle");
    TubeWallParams tw;
    tw.n_theta = 16;
    tw.n_z = 10;
    StageRecord r;
    r.stage = "tubewall";
    tubewall_file(tw, d.file("wall.h5"), r);
    Bundle b = read_bundle(d.file("wall.h5"));
    SurfaceData& w = b.surfaces.at("wall");
    // An outer face (label "outer") and its neighbour across its first edge.
    int outer_label = -1;
    for (size_t k = 0; k < w.label_names.size(); ++k)
        if (w.label_names[k] == "outer") outer_label = static_cast<int>(k);
    ASSERT_GE(outer_label, 0);
    Eigen::Index f0 = -1, f1 = -1;
    for (Eigen::Index f = 0; f < w.F.rows() && f1 < 0; ++f) {
        if (w.face_label[f] != outer_label) continue;
        const int a = w.F(f, 0), bb = w.F(f, 1);
        for (Eigen::Index g = 0; g < w.F.rows(); ++g)
            for (int k = 0; k < 3; ++k)
                if (g != f && w.F(g, k) == bb && w.F(g, (k + 1) % 3) == a) {
                    f0 = f;
                    f1 = g;
                }
    }
    ASSERT_GE(f1, 0);
    const int a = w.F(f0, 0), bb = w.F(f0, 1), c = w.F(f0, 2);
    int dd = -1;
    for (int k = 0; k < 3; ++k)
        if (w.F(f1, k) != a && w.F(f1, k) != bb) dd = w.F(f1, k);
    const int p = static_cast<int>(w.V.rows());
    w.V.conservativeResize(p + 1, 3);
    w.V.row(p) = w.V.row(a) + 1e-5 * (w.V.row(bb) - w.V.row(a));
    const Eigen::Index nf = w.F.rows();
    w.F.conservativeResize(nf + 2, 3);
    w.face_label.conservativeResize(nf + 2);
    if (w.face_region.size() == nf) w.face_region.conservativeResize(nf + 2);
    w.F.row(f0) << a, p, c;
    w.F.row(nf) << p, bb, c;
    w.F.row(f1) << bb, p, dd;
    w.F.row(nf + 1) << p, a, dd;
    w.face_label[nf] = w.face_label[f0];
    w.face_label[nf + 1] = w.face_label[f1];
    if (w.face_region.size() == nf + 2) {
        w.face_region[nf] = w.face_region[f0];
        w.face_region[nf + 1] = w.face_region[f1];
    }
    if (w.vertex_thickness.size() == p) {
        w.vertex_thickness.conservativeResize(p + 1);
        w.vertex_thickness[p] = w.vertex_thickness[a];
    }
    write_bundle(d.file("needle.h5"), b);
    r.stage = "tetmesh";
    // TetGen keeps the needle edge (the boundary is preserved): the mesh is made, with tiny tetrahedra there.
    tetmesh_file(d.file("needle.h5"), d.file("vol.h5"), {}, r);
    std::vector<std::string> warnings;
    Reporter rep;
    rep.on_message = [&](Level lv, const std::string& m) {
        if (lv == Level::WARN) warnings.push_back(m);
    };
    r.stage = "assemble";
    assemble_file(d.file("vol.h5"), d.file("fem.h5"), AssembleParams{}, r, rep);
    double q = -1;
    const Meta meta = read_meta(d.file("fem.h5"));
    for (const auto& [k, val] : meta.stages.back().qa)
        if (k == "min_tet_quality") q = val;
    std::printf("needle triangles: min tet quality %g, %zu warnings\n", q, warnings.size());
    RecordProperty("min_tet_quality", std::to_string(q));
    EXPECT_LT(q, 1e-3);  // measured 4.3e-6
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings.front().find("sliver tetrahedra"), std::string::npos) << warnings.front();
}

static double value(const std::vector<std::pair<std::string, double>>& q, const std::string& k) {
    for (const auto& [n, x] : q)
        if (n == k) return x;
    ADD_FAILURE() << "no " << k;
    return 0;
}

TEST(TetMesh, FlatBoundarySliverIsRemovedAsAnEdgeFlip) {
    // A flat sliver (a, b at z = 0; c, d 0.02 below) under two tetrahedra that share the apex e: its faces abc and
    // abd are the boundary. Removing it flips the bottom's edge ab to cd; the rest stays a closed, manifold mesh.
    VolumeData v;
    v.nodes.resize(5, 3);
    v.nodes << 0, 0, 0, 1, 1, 0, 1, 0, -0.02, 0, 1, -0.02, 0.5, 0.5, 1;
    v.tets.resize(3, 4);
    v.tets << 0, 1, 2, 3, 0, 2, 3, 4, 1, 2, 3, 4;
    for (Eigen::Index t = 0; t < 3; ++t) {
        Eigen::Matrix<double, 4, 3> X;
        for (int a = 0; a < 4; ++a) X.row(a) = v.nodes.row(v.tets(t, a));
        if (fem::tet_volume(X) < 0) std::swap(v.tets(t, 2), v.tets(t, 3));
    }
    Eigen::MatrixX3i faces(6, 3);
    faces << 0, 1, 2, 0, 1, 3, 0, 2, 4, 0, 3, 4, 1, 2, 4, 1, 3, 4;
    const Eigen::VectorXi one_label = Eigen::VectorXi::Zero(6);
    const double before = value(mesh_quality(v), "min_dihedral_deg");
    ASSERT_LT(before, 5.0);
    {
        VolumeData w = v;  // its bottom faces carry two labels (a crease between surfaces): kept
        Eigen::VectorXi two = one_label;
        two[1] = 1;
        EXPECT_EQ(remove_boundary_slivers(w, faces, two, 10.0), 0);
        EXPECT_EQ(w.tets.rows(), 3);
        EXPECT_EQ(remove_boundary_slivers(w, faces, one_label, before * 0.99), 0);  // not below the bound: kept
    }
    {
        VolumeData w = v;  // cd already a boundary edge elsewhere: the flip would make it non-manifold
        Eigen::MatrixX3i more(7, 3);
        more << faces, 2, 3, 4;
        EXPECT_EQ(remove_boundary_slivers(w, more, Eigen::VectorXi::Zero(7), 10.0), 0);
    }
    EXPECT_EQ(remove_boundary_slivers(v, faces, one_label, 10.0), 1);
    ASSERT_EQ(v.tets.rows(), 2);
    EXPECT_GT(value(mesh_quality(v), "min_dihedral_deg"), 10.0);
    // What is left is closed: every face of the two tetrahedra is either shared by both or on the new boundary,
    // which now has acd and bcd at the bottom instead of abc and abd.
    const Eigen::MatrixX3i F = fem::boundary_faces(v.tets);
    EXPECT_EQ(F.rows(), 6);
    std::set<std::array<int, 3>> bottom;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        std::array<int, 3> t{F(f, 0), F(f, 1), F(f, 2)};
        std::sort(t.begin(), t.end());
        if (t[2] != 4) bottom.insert(t);
    }
    EXPECT_EQ(bottom, (std::set<std::array<int, 3>>{{0, 2, 3}, {1, 2, 3}}));
}
