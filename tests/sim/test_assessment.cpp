// SPDX-License-Identifier: MIT
// Neck occlusion on scenes with known answers: a tube whose ring at z = 0 is the neck line, flattened by an
// exact "pinch" map (the wall's mid-surface becomes a stadium of half-height g/2 + t/2, so the lumen gap in the
// flat part is exactly g), across the neck and beside it.
#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "aneu/core/error.hpp"
#include "aneu/sim/assessment.hpp"
#include "aneu/sim/shapes.hpp"

using namespace aneu::sim;

namespace {

constexpr double PI = 3.14159265358979323846;
constexpr double R_OUT = 1.5, T = 0.3, R_IN = R_OUT - T;
constexpr int NT = 96, NZ = 81;
constexpr double Z0 = -8.0, Z1 = 8.0;

/// The lumen of a tube (radius R_IN = R_OUT − T) along z, normals out of the lumen; the faces with z > 0
/// are the "sac", so the ring at z = 0 is the neck line.
SimLumen tube() {
    SimLumen s;
    s.X.resize(NT * NZ, 3);
    for (int k = 0; k < NZ; ++k)
        for (int i = 0; i < NT; ++i) {
            const double th = 2 * PI * i / NT;
            s.X.row(k * NT + i) << R_IN * std::cos(th), R_IN * std::sin(th), Z0 + (Z1 - Z0) * k / (NZ - 1);
        }
    s.F.resize(2 * NT * (NZ - 1), 3);
    int f = 0;
    for (int k = 0; k + 1 < NZ; ++k)
        for (int i = 0; i < NT; ++i) {
            const int a = k * NT + i, b = k * NT + (i + 1) % NT, c = a + NT, d = b + NT;
            s.F.row(f++) << a, b, d;  // outward: (b − a) × (d − a) points away from the axis
            s.F.row(f++) << a, d, c;
        }
    s.face_region.resize(s.F.rows());
    for (Eigen::Index g = 0; g < s.F.rows(); ++g) s.face_region[g] = s.X(s.F(g, 0), 2) + s.X(s.F(g, 1), 2) + s.X(s.F(g, 2), 2) > 0 ? 1 : 0;
    std::vector<int> ring;
    for (int i = 0; i < NT; ++i) ring.push_back((NZ / 2) * NT + i);
    s.neck_loops = {ring};
    return s;
}

/// The tube flattened round z = zc (fully within ±1.5 mm, blending back to round over the next 2 mm) so that
/// the lumen gap is g in the flat part: the wall's mid-surface (radius R_OUT − T/2) is mapped by arc length onto
/// a stadium of half-height c = (g + T)/2 with semicircular folds of radius c, and the lumen lies T/2 inside it.
Eigen::MatrixX3d pinched(const SimLumen& s, double zc, double g) {
    const double rm = R_OUT - 0.5 * T, c = 0.5 * (g + T);
    const double L = 0.25 * (2 * PI * rm - 2 * PI * c);  // half the length of each flat side
    Eigen::MatrixX3d x = s.X;
    for (Eigen::Index v = 0; v < s.X.rows(); ++v) {
        const double z = s.X(v, 2), dz = std::abs(z - zc);
        const double phi = dz <= 1.5 ? 1.0 : dz >= 3.5 ? 0.0 : std::pow(std::cos(0.5 * PI * (dz - 1.5) / 2.0), 2);
        double th = std::atan2(s.X(v, 1), s.X(v, 0));
        if (th < 0) th += 2 * PI;
        // Arc length from the fold at +x (th = 0), counter-clockwise; the stadium is walked the same way.
        double a = rm * th;
        const double q = PI * c;  // a quarter... half of one fold's arc
        Eigen::Vector2d p, n;
        auto fold = [&](double cx, double ang) {
            n << std::cos(ang), std::sin(ang);
            p = Eigen::Vector2d(cx, 0) + c * n;
        };
        if (a < 0.5 * q) fold(L, a / c);
        else if ((a -= 0.5 * q) < 2 * L) {
            n << 0, 1;
            p << L - a, c;
        } else if ((a -= 2 * L) < q) fold(-L, 0.5 * PI + a / c);
        else if ((a -= q) < 2 * L) {
            n << 0, -1;
            p << -L + a, -c;
        } else {
            a -= 2 * L;
            fold(L, -0.5 * PI + a / c);
        }
        const Eigen::Vector2d inner = p - 0.5 * T * n;
        const Eigen::Vector2d rest(s.X(v, 0), s.X(v, 1));
        const Eigen::Vector2d moved = rest + phi * (inner - rest);
        x(v, 0) = moved.x();
        x(v, 1) = moved.y();
    }
    return x;
}

}  // namespace

TEST(NeckOcclusion, OpenTubeIsOpen) {
    const SimLumen s = tube();
    const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T);
    const NeckOcclusion o = neck_occlusion(s, s.X, 0.05, wall);
    EXPECT_EQ(o.fraction, 0.0);
    // The lumen's diameter across the neck, 2 (R − t) = 2.4 mm (polygon: cos(π/96) of it).
    EXPECT_NEAR(o.min_gap_mm, 2 * (R_OUT - T), 0.01);
    EXPECT_NEAR(o.length_mm, 2 * PI * (R_OUT - T), 0.01);
    EXPECT_EQ(o.max_interpenetration_mm, 0.0);
}

TEST(NeckOcclusion, TubePinchedFlatAcrossTheNeckIsClosed) {
    const SimLumen s = tube();
    const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T);
    const NeckOcclusion o = neck_occlusion(s, pinched(s, 0.0, 0.0), 0.05, wall);
    EXPECT_GE(o.fraction, 0.97) << o.closed_mm << " of " << o.length_mm;
    EXPECT_NEAR(o.min_gap_mm, 0.0, 0.01);
    EXPECT_LE(o.max_interpenetration_mm, 0.01);
    // Flattened to a 0.3 mm slit: the gap is measured, nothing is closed at tolerance 0.05 mm.
    const NeckOcclusion slit = neck_occlusion(s, pinched(s, 0.0, 0.3), 0.05, wall);
    EXPECT_LE(slit.fraction, 0.03);
    EXPECT_NEAR(slit.min_gap_mm, 0.3, 0.02);
    // ... and everything is closed at a tolerance above the slit.
    EXPECT_GE(neck_occlusion(s, pinched(s, 0.0, 0.3), 0.35, wall).fraction, 0.9);
    // Pressed through each other by 0.1 mm: closed, and the interpenetration is reported. (The folds are then
    // inverted — the inner fold's radius is negative — and the few edges there are not counted closed.)
    const NeckOcclusion through = neck_occlusion(s, pinched(s, 0.0, -0.1), 0.05, wall);
    EXPECT_GE(through.fraction, 0.93);
    EXPECT_NEAR(through.max_interpenetration_mm, 0.1, 0.015);
}

TEST(NeckOcclusion, ClipBesideTheNeckClosesNone) {
    const SimLumen s = tube();
    const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T);
    const NeckOcclusion o = neck_occlusion(s, pinched(s, 5.0, 0.0), 0.05, wall);  // flat at z = 3.5 … 6.5, round at z ≤ 1.5
    EXPECT_EQ(o.fraction, 0.0);
    EXPECT_NEAR(o.min_gap_mm, 2 * (R_OUT - T), 0.01);
}

TEST(NeckOcclusion, AStaircaseNeckLineIsMeasuredOnTheBorderItFollows) {
    // The labels' border as a mesh gives it: a staircase between the rings at z = 0 and z = 0.2 mm (two edges on
    // one ring, up, two on the other, down), 7.54 + 48 × 0.2 = 17.1 mm of edges for a border 2π R = 7.54 mm long
    // at z ≈ 0.1 mm. The occlusion is measured on the border: its length, its height, and the pinch closing it.
    SimLumen s = tube();
    const int k0 = NZ / 2, k1 = k0 + 1;
    auto ring_of = [&](int i) { return (i / 2) % 2 == 0 ? k0 : k1; };
    std::vector<int> loop;
    double stairs = 0;
    for (int i = 0; i < NT; ++i) {
        loop.push_back(ring_of(i) * NT + i);
        const int next = ring_of((i + 1) % NT);
        if (next != ring_of(i)) loop.push_back(next * NT + i);  // the step up or down at column i
    }
    for (size_t k = 0; k < loop.size(); ++k) stairs += (s.X.row(loop[(k + 1) % loop.size()]) - s.X.row(loop[k])).norm();
    ASSERT_NEAR(stairs, 2 * NT * R_IN * std::sin(PI / NT) + NT / 2 * (Z1 - Z0) / (NZ - 1), 1e-9);
    s.neck_loops = {loop};
    const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T);
    const NeckOcclusion open = neck_occlusion(s, s.X, 0.05, wall);
    EXPECT_NEAR(open.length_mm, 2 * PI * R_IN, 0.02 * 2 * PI * R_IN) << "the staircase is " << stairs << " mm";
    ASSERT_EQ(open.points.size(), 1u);
    for (const Eigen::Vector3d& p : open.points[0]) {
        EXPECT_NEAR(p.z(), 0.1, 0.05);                           // between the two rings: the border
        EXPECT_NEAR(std::hypot(p.x(), p.y()), R_IN, 0.01);       // on the lumen
    }
    EXPECT_EQ(open.fraction, 0.0);
    const NeckOcclusion closed = neck_occlusion(s, pinched(s, 0.0, 0.0), 0.05, wall);
    EXPECT_GE(closed.fraction, 0.97) << closed.closed_mm << " of " << closed.length_mm;
    // The model keeps the smoothed line (SimLumen::neck_line); given, it is what is measured.
    s.neck_line = {smoothed_neck_line(s, loop)};
    EXPECT_DOUBLE_EQ(neck_occlusion(s, pinched(s, 0.0, 0.0), 0.05, wall).fraction, closed.fraction);
    s.neck_line[0].resize(2);  // a line of two points: one segment there and back
    EXPECT_NEAR(neck_occlusion(s, s.X, 0.05, wall).length_mm,
                2 * (open.points[0][1] - open.points[0][0]).norm(), 1e-9);
}

TEST(LumenMeeting, WallsBroughtWithinReachOfEachOtherAreFoundTheLumensOwnWidthIsNot) {
    const SimLumen s = tube();
    // Open, and flattened to a 1 mm slit: no wall within 0.3 mm of the opposite one (the folds' own curvature is not
    // a meeting: faces whose normals differ by more than 90 degrees round a 0.5 mm fold lie 0.7 mm apart).
    EXPECT_TRUE(lumen_meeting(s, s.X, 0.3, 0.6).empty());
    EXPECT_TRUE(lumen_meeting(s, pinched(s, 0.0, 1.0), 0.3, 0.6).empty());
    // Flattened to 0.1 mm: both flat sides where the pinch is flat, none beyond the blend (|z| <= 3.5 mm).
    const std::vector<int> near = lumen_meeting(s, pinched(s, 0.0, 0.1), 0.3, 0.6);
    ASSERT_FALSE(near.empty());
    EXPECT_TRUE(std::is_sorted(near.begin(), near.end()));
    int up = 0, down = 0, mid = 0;
    for (int v : near) {
        EXPECT_LE(std::abs(s.X(v, 2)), 3.5 + 1e-9) << v;
        if (std::abs(s.X(v, 2)) < 0.05) (s.X(v, 1) > 0 ? up : down) += 1;
        mid += std::abs(s.X(v, 2)) < 1.5 ? 1 : 0;
    }
    EXPECT_GT(up, NT / 8) << "the flat side above";
    EXPECT_GT(down, NT / 8) << "the flat side below";
    // Pressed 0.1 mm through each other (they came from each other's front): found as well, and more of the blend.
    EXPECT_GE(lumen_meeting(s, pinched(s, 0.0, -0.1), 0.3, 0.6).size(), near.size());
    // Walls that lay within apart_mm at rest are the lumen's own width, not a meeting (the tube is 2.4 mm across).
    EXPECT_TRUE(lumen_meeting(s, pinched(s, 0.0, 0.1), 0.3, 2.5).empty());
    // Only where a side of the meeting lies outside: with |z| < 1 mm inside, the meetings deep inside are left out
    // (a vertex at z = 0 meets faces within 0.3 mm of it), those reaching out are kept, and all inside: none.
    std::vector<char> outside(static_cast<size_t>(s.X.rows()), 0);
    for (Eigen::Index v = 0; v < s.X.rows(); ++v) outside[static_cast<size_t>(v)] = std::abs(s.X(v, 2)) > 1.0 ? 1 : 0;
    const std::vector<int> out = lumen_meeting(s, pinched(s, 0.0, 0.1), 0.3, 0.6, &outside);
    ASSERT_FALSE(out.empty());
    EXPECT_LT(out.size(), near.size());
    for (int v : out) EXPECT_GE(std::abs(s.X(v, 2)), 1.0 - 0.3 - 0.2 - 1e-9) << v << " lies deep inside";
    EXPECT_TRUE(std::any_of(out.begin(), out.end(), [&](int v) { return std::abs(s.X(v, 2)) > 1.0; }));
    std::fill(outside.begin(), outside.end(), 0);
    EXPECT_TRUE(lumen_meeting(s, pinched(s, 0.0, 0.1), 0.3, 0.6, &outside).empty());
    outside.pop_back();
    EXPECT_THROW(lumen_meeting(s, s.X, 0.3, 0.6, &outside), aneu::InputError);
    EXPECT_THROW(lumen_meeting(s, s.X.topRows(10), 0.3, 0.6), aneu::InputError);
}

TEST(LumenCrossing, WallsPressedThroughEachOtherAreCrossedByTheirDepthABulgeIsNot) {
    const SimLumen s = tube();
    // Open, flattened to a slit, pressed flat: nothing of the lumen lies behind a face of it.
    EXPECT_EQ(lumen_crossing(s, s.X).vertices, 0);
    EXPECT_EQ(lumen_crossing(s, pinched(s, 0.0, 0.3)).vertices, 0);
    EXPECT_LE(lumen_crossing(s, pinched(s, 0.0, 0.0)).depth_mm, 0.005);
    // Pressed 0.1 mm through each other: each flat side's vertices lie 0.1 mm behind the other side's faces (and the
    // inverted folds' inner halves behind their outer ones by less); the deepest is where the pinch is flat.
    const LumenCrossing through = lumen_crossing(s, pinched(s, 0.0, -0.1));
    EXPECT_NEAR(through.depth_mm, 0.1, 0.005);
    EXPECT_LE(std::abs(through.at.z()), 1.5 + 1e-9);
    EXPECT_GT(through.vertices, 2 * NT / 4 * 10) << "about half of each ring in the 3 mm flat, on both sides";
    // Shallower than the depth searched only (deeper: another part of the vessel, not this wall), and the inverted
    // folds' vertices over faces one or two rings away count with one ring left out, not with two.
    const LumenCrossing shallow = lumen_crossing(s, pinched(s, 0.0, -0.1), 1, 0.05);
    EXPECT_LT(shallow.depth_mm, 0.05);
    EXPECT_LT(shallow.vertices, through.vertices);
    EXPECT_LT(lumen_crossing(s, pinched(s, 0.0, -0.1), 2).vertices, through.vertices);
    // Through a face means within its wall: with the wall known 0.3 mm thick the same; 0.05 mm thick, the flat's
    // vertices lie beyond it (another lumen, the far side of a fold) and only the shallower fold pieces count.
    SimLumen walled = s;
    walled.wall_mm = Eigen::VectorXd::Constant(s.X.rows(), T);
    EXPECT_NEAR(lumen_crossing(walled, pinched(s, 0.0, -0.1)).depth_mm, through.depth_mm, 1e-12);
    walled.wall_mm.setConstant(0.05);
    const LumenCrossing thin = lumen_crossing(walled, pinched(s, 0.0, -0.1));
    EXPECT_LE(thin.depth_mm, 0.05);
    EXPECT_LT(thin.vertices, through.vertices);
    // A vertex pushed 0.2 mm out of the lumen takes its own faces with it: a bulge, not a crossing.
    Eigen::MatrixX3d bulge = s.X;
    const int v = (NZ / 2) * NT + 5;
    bulge.row(v) += 0.2 * Eigen::RowVector3d(s.X(v, 0), s.X(v, 1), 0).normalized();
    EXPECT_EQ(lumen_crossing(s, bulge).vertices, 0);
    // Where a patch holds the tissue: a vertex behind a face counts only if it lies in an element that is not its own.
    // All in no tissue: none through, all beside, as deep; all inside: as without the tissue; the vertices off the
    // patch (or on its interface, −1) count as before.
    LumenTissue none{std::vector<int>(static_cast<size_t>(s.X.rows()), 0), std::vector<char>(static_cast<size_t>(s.X.rows()), 0)};
    const LumenCrossing aside = lumen_crossing(s, pinched(s, 0.0, -0.1), LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &none);
    EXPECT_EQ(aside.vertices, 0);
    EXPECT_EQ(aside.depth_mm, 0.0);
    EXPECT_EQ(aside.beside_vertices, through.vertices);
    EXPECT_DOUBLE_EQ(aside.beside_mm, through.depth_mm);
    LumenTissue all = none;
    std::fill(all.inside.begin(), all.inside.end(), 1);
    const LumenCrossing in = lumen_crossing(s, pinched(s, 0.0, -0.1), LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &all);
    EXPECT_EQ(in.vertices, through.vertices);
    EXPECT_DOUBLE_EQ(in.depth_mm, through.depth_mm);
    EXPECT_EQ(in.beside_vertices, 0);
    LumenTissue unknown = none;
    std::fill(unknown.patch.begin(), unknown.patch.end(), -1);
    EXPECT_EQ(lumen_crossing(s, pinched(s, 0.0, -0.1), LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &unknown).vertices, through.vertices);
    LumenTissue two = none;  // the faces' corners another patch's than the vertex's: not known there
    for (Eigen::Index v = 0; v < s.X.rows(); ++v) two.patch[static_cast<size_t>(v)] = s.X(v, 1) > 0 ? 1 : 0;
    const LumenCrossing across = lumen_crossing(s, pinched(s, 0.0, -0.1), LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &two);
    EXPECT_NEAR(across.depth_mm, 0.1, 0.005);
    EXPECT_GT(across.vertices, 0);
    LumenTissue short_one = none;
    short_one.patch.pop_back();
    EXPECT_THROW(lumen_crossing(s, s.X, LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &short_one), aneu::InputError);
}

// The channel through the neck: the widest lumen joining the sac (faces with z > 1 mm) to the parent (z < −1 mm).
TEST(NeckChannel, AnOpenTubeIsWideOpenAndItsWidthIsItsDiameter) {
    const SimLumen s = tube();
    // A point halfway along the tube, on a face's centroid: the ball touching the wall there is the tube's inscribed
    // circle, 2 (R − t) (the polygon's, cos(π/96) of it, within the faceting).
    const int face = 2 * (NZ / 2 * NT + 7);
    EXPECT_NEAR(lumen_width(s, s.X, face, Eigen::Vector3d::Constant(1.0 / 3.0), 12.0), 2 * R_IN, 0.01);
    EXPECT_DOUBLE_EQ(lumen_width(s, s.X, face, Eigen::Vector3d::Constant(1.0 / 3.0), 1.0), 1.0);  // capped
    const NeckChannel ch = neck_channel(s, s.X, 1);
    EXPECT_DOUBLE_EQ(ch.width_mm, 2.0);  // at least the cap
    EXPECT_GT(ch.faces_measured, 0);
    EXPECT_TRUE(std::isnan(neck_channel(s, s.X, -1).width_mm));  // no aneurysm region: nothing to seal
}

TEST(NeckChannel, APinchAcrossTheNeckSealsItAndASlitLeavesAChannelOfItsGap) {
    const SimLumen s = tube();
    // Pressed flat (folds of zero inner radius): sealed.
    const NeckChannel flat = neck_channel(s, pinched(s, 0.0, 0.0), 1);
    EXPECT_LE(flat.width_mm, 0.01);
    // Flattened to a 0.3 mm slit: the folds' inner diameter is the slit's gap too (their mid-surface radius is
    // (g + t) / 2), so the widest channel is 0.3 mm, through the pinch (|z| ≤ 1.5 mm).
    const Eigen::MatrixX3d y = pinched(s, 0.0, 0.3);
    const NeckChannel slit = neck_channel(s, y, 1);
    EXPECT_NEAR(slit.width_mm, 0.3, 0.02);
    EXPECT_LE(std::abs(slit.at.z()), 1.5 + 0.2);
    // The width at a flat side's point and at a fold's apex (θ = 0 is the fold at +x; the flat sides lie round
    // θ = π/2): both the gap.
    const int k = NZ / 2 - 1;
    EXPECT_NEAR(lumen_width(s, y, 2 * (k * NT + NT / 4), Eigen::Vector3d::Constant(1.0 / 3.0), 2.0), 0.3, 0.02);
    EXPECT_NEAR(lumen_width(s, y, 2 * (k * NT + 0), Eigen::Vector3d(0.5, 0.0, 0.5), 2.0), 0.3, 0.03);
}

// The lumen's edge round each face (the resolution a flattened fold's channel depends on) and where the channel is.
TEST(NeckChannel, TheLumensEdgeRoundEachFaceAndTheChannelsFace) {
    SimLumen s = tube();
    // Every face is a right triangle with legs 2 R sin(π/96) round the tube and 0.2 mm along it.
    const double chord = 2 * R_IN * std::sin(PI / NT);
    const Eigen::VectorXd edge = lumen_edges_mm(s);
    ASSERT_EQ(edge.size(), s.F.rows());
    EXPECT_NEAR(edge.minCoeff(), chord, 1e-12);
    EXPECT_NEAR(edge.maxCoeff(), chord, 1e-12);
    // Refined round the tube's ring at z = 2 mm: the faces there see the finer edges, one ring away the coarse.
    SimLumen f = s;
    const Eigen::Index k = NZ / 2 + 10;
    for (int i = 0; i < NT; ++i) f.X(k * NT + i, 2) = f.X((k - 1) * NT + i, 2) + 0.05;  // the ring 0.05 mm from the one before
    const Eigen::VectorXd ef = lumen_edges_mm(f);
    EXPECT_LT(ef[2 * ((k - 1) * NT + 5)], chord);                       // between the close rings: 0.05 mm edges
    EXPECT_NEAR(ef[2 * ((k - 4) * NT + 5)], chord, 1e-12);              // far from them
    // The channel's narrowest place names its face: for the 0.3 mm slit, a face in the pinch.
    const NeckChannel slit = neck_channel(s, pinched(s, 0.0, 0.3), 1);
    ASSERT_GE(slit.face, 0);
    ASSERT_LT(slit.face, s.F.rows());
    EXPECT_LE(std::abs(s.X(s.F(slit.face, 0), 2)), 1.5 + 0.2);
    EXPECT_EQ(neck_channel(s, s.X, -1).face, -1);
}

// The lumen split at mid-edge nodes (the quadratic surface the patch's walls touch on): here every "volume node" is
// a lumen vertex and the mid-edge nodes are extra nodes, on the cylinder (the quadratic surface) or at the chords'
// midpoints (the corner triangles' own surface).
TEST(SplitLumen, FourChildrenPerFaceTheNeckThroughTheMidEdgeVerticesAndItsPointsKept) {
    SimLumen s = tube();
    s.node.resize(s.X.rows());
    s.bind.resize(s.X.rows());
    for (Eigen::Index v = 0; v < s.X.rows(); ++v) s.node[v] = s.bind[v] = static_cast<int>(v);
    s.wall_mm = Eigen::VectorXd::Constant(s.X.rows(), T);
    s.neck_line = {smoothed_neck_line(s, s.neck_loops[0])};
    for (const bool on_cylinder : {false, true}) {
        std::map<std::pair<int, int>, int> mid_of;
        std::vector<Eigen::RowVector3d> extra;
        for (Eigen::Index f = 0; f < s.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) {
                const auto key = std::minmax(s.F(f, k), s.F(f, (k + 1) % 3));
                if (mid_of.count(key)) continue;
                Eigen::RowVector3d m = 0.5 * (s.X.row(key.first) + s.X.row(key.second));
                if (on_cylinder) m.head<2>() *= R_IN / m.head<2>().norm();
                mid_of[key] = static_cast<int>(s.X.rows() + static_cast<Eigen::Index>(extra.size()));
                extra.push_back(m);
            }
        Eigen::MatrixX3d nodes(s.X.rows() + static_cast<Eigen::Index>(extra.size()), 3);
        nodes.topRows(s.X.rows()) = s.X;
        for (size_t e = 0; e < extra.size(); ++e) nodes.row(s.X.rows() + static_cast<Eigen::Index>(e)) = extra[e];
        const auto mid = [&](int a, int b) {
            const auto it = mid_of.find(std::minmax(a, b));
            return it == mid_of.end() ? -1 : it->second;
        };
        const SplitLumen sp = split_lumen(s, mid, nodes);
        const SimLumen& q = sp.lumen;
        ASSERT_EQ(q.F.rows(), 4 * s.F.rows());
        ASSERT_EQ(q.X.rows(), nodes.rows());
        ASSERT_EQ(sp.between.rows(), static_cast<Eigen::Index>(extra.size()));
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            // The children tile the parent: same region, same orientation (normals along the parent's).
            const Eigen::Vector3d n = (s.X.row(s.F(f, 1)) - s.X.row(s.F(f, 0))).cross(s.X.row(s.F(f, 2)) - s.X.row(s.F(f, 0))).transpose();
            for (int c = 0; c < 4; ++c) {
                const Eigen::Index g = 4 * f + c;
                EXPECT_EQ(q.face_region[g], s.face_region[f]);
                const Eigen::Vector3d m = (q.X.row(q.F(g, 1)) - q.X.row(q.F(g, 0))).cross(q.X.row(q.F(g, 2)) - q.X.row(q.F(g, 0))).transpose();
                EXPECT_GT(m.dot(n), 0.0) << f << " " << c;
            }
        }
        // The neck loop passes through its edges' mid-edge vertices: twice the vertices, each new one between its
        // neighbours on the loop.
        ASSERT_EQ(q.neck_loops.size(), 1u);
        const std::vector<int>& loop = q.neck_loops[0];
        ASSERT_EQ(loop.size(), 2 * s.neck_loops[0].size());
        for (size_t k = 1; k < loop.size(); k += 2) {
            const Eigen::Index e = loop[k] - s.X.rows();
            ASSERT_GE(e, 0);
            EXPECT_EQ(std::minmax(sp.between(e, 0), sp.between(e, 1)), std::minmax(loop[k - 1], loop[(k + 1) % loop.size()]));
        }
        // A loop with a step that is not an edge (a neck border that the lumen's edge ends, closed by its two ends):
        // no mid-edge vertex there, and no error (C0043's lumen, session 34: the split threw).
        SimLumen cut = s;
        cut.neck_loops[0].erase(cut.neck_loops[0].begin() + 1);
        const SplitLumen sc = split_lumen(cut, mid, nodes);
        ASSERT_EQ(sc.lumen.neck_loops.size(), 1u);
        EXPECT_EQ(sc.lumen.neck_loops[0].size(), 2 * cut.neck_loops[0].size() - 1);
        EXPECT_EQ(sc.lumen.neck_loops[0][1], cut.neck_loops[0][1]);  // the step 0 -> 2 of the old loop: no vertex between
        // On the chords' midpoints the children are the parent's own plane: every neck point stays where it was.
        ASSERT_EQ(q.neck_line.size(), 1u);
        ASSERT_EQ(q.neck_line[0].size(), s.neck_line[0].size());
        double moved = 0;
        for (size_t k = 0; k < s.neck_line[0].size(); ++k) {
            const NeckPointOnLumen &p = s.neck_line[0][k], &c = q.neck_line[0][k];
            EXPECT_EQ(c.face / 4, p.face);
            EXPECT_GE(c.weights.minCoeff(), -1e-12);
            EXPECT_NEAR(c.weights.sum(), 1.0, 1e-12);
            Eigen::Vector3d xp = Eigen::Vector3d::Zero(), xc = Eigen::Vector3d::Zero();
            for (int j = 0; j < 3; ++j) {
                xp += p.weights[j] * s.X.row(s.F(p.face, j)).transpose();
                xc += c.weights[j] * q.X.row(q.F(c.face, j)).transpose();
            }
            moved = std::max(moved, (xc - xp).norm());
        }
        if (!on_cylinder) {
            EXPECT_LT(moved, 1e-12);
            // The same lumen, measured: the same occlusion, open and pinched shut.
            const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T), wq = Eigen::VectorXd::Constant(q.X.rows(), T);
            EXPECT_NEAR(neck_occlusion(q, pinched(q, 0.0, 0.0), 0.05, wq).fraction, neck_occlusion(s, pinched(s, 0.0, 0.0), 0.05, wall).fraction, 0.03);
        } else {
            EXPECT_LT(moved, R_IN * (1 - std::cos(PI / NT)) + 1e-9);  // at most the chord's sagitta off the cylinder
            EXPECT_NEAR(q.X.row(q.neck_loops[0][1]).head<2>().norm(), R_IN, 1e-12);
        }
    }
    // An edge with no mid-edge node: refused, naming the nodes.
    EXPECT_THROW(split_lumen(s, [](int, int) { return -1; }, s.X), aneu::InputError);
}

TEST(NeckChannel, TheNeckLineCutOffFromTheParentIsWhatItsBloodNoLongerReaches) {
    // Known answers on the tube (sac z > 0, neck line the ring at z = 0, the parent's faces z < −1 mm):
    const SimLumen s = tube();
    const Eigen::VectorXd wall = Eigen::VectorXd::Constant(s.X.rows(), T);
    auto both = [&](const Eigen::MatrixX3d& y) {
        const NeckOcclusion occ = neck_occlusion(s, y, 0.05, wall);
        const NeckChannel ch = neck_channel(s, y, 1);
        return std::make_tuple(occ.fraction, neck_cut_off_fraction(occ, ch, 0.05), ch.width_mm);
    };
    // open: none of it cut off;
    EXPECT_EQ(std::get<1>(both(s.X)), 0.0);
    // pressed flat across the neck: all of it, as the occlusion;
    const auto [closed_flat, cut_flat, ch_flat] = both(pinched(s, 0.0, 0.0));
    EXPECT_GE(cut_flat, 0.97);
    EXPECT_NEAR(cut_flat, closed_flat, 0.03);
    // a 0.3 mm slit across it: none (the parent's blood passes 0.3 mm);
    EXPECT_EQ(std::get<1>(both(pinched(s, 0.0, 0.3))), 0.0);
    // flat on the sac's side (z = 1 … 4): the sac sealed, but the neck line still in the parent's lumen — none of
    // it cut off, none of it closed (a neck remnant);
    const auto [closed_sac, cut_sac, ch_sac] = both(pinched(s, 2.5, 0.0));
    EXPECT_LE(ch_sac, 0.01);
    EXPECT_EQ(closed_sac, 0.0);
    EXPECT_EQ(cut_sac, 0.0);
    // flat on the parent's side (z = −4 … −1): the neck line's walls apart (closed 0), but all of it cut off.
    const auto [closed_par, cut_par, ch_par] = both(pinched(s, -2.5, 0.0));
    EXPECT_LE(ch_par, 0.01);
    EXPECT_EQ(closed_par, 0.0);
    EXPECT_DOUBLE_EQ(cut_par, 1.0);
    // No parent's faces, no reach: not measured.
    EXPECT_EQ(neck_cut_off_fraction(neck_occlusion(s, s.X, 0.05, wall), NeckChannel{}, 0.05), -1.0);
}

TEST(NeckChannel, WidestReachIsTheMaximinPathFromTheSourceFaces) {
    // A strip of 6 faces in a row (a triangle strip), widths 3 2 5 1 4 6, the source the first: each face's reach is
    // the smallest width on the way there.
    Eigen::MatrixX3i F(6, 3);
    for (int i = 0; i < 6; ++i) F.row(i) << i, i + 1, i + 2;
    const std::vector<double> reach = widest_reach(F, {3, 2, 5, 1, 4, 6}, {1, 0, 0, 0, 0, 0});
    const std::vector<double> want{3, 2, 2, 1, 1, 1};
    for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(reach[static_cast<size_t>(i)], want[static_cast<size_t>(i)]) << i;
    // Sources at both ends: each face takes the wider way.
    const std::vector<double> two = widest_reach(F, {3, 2, 5, 1, 4, 6}, {1, 0, 0, 0, 0, 1});
    const std::vector<double> want2{3, 2, 2, 1, 4, 6};
    for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(two[static_cast<size_t>(i)], want2[static_cast<size_t>(i)]) << i;
    // A face on another piece: 0.
    Eigen::MatrixX3i G(2, 3);
    G << 0, 1, 2, 10, 11, 12;
    EXPECT_EQ(widest_reach(G, {1, 1}, {1, 0})[1], 0.0);
}

TEST(NeckChannel, APinchBesideTheNeckLeavesItOpen) {
    // Flat across the sac 5 mm beyond the neck (or the parent 5 mm before it): the sac next to the neck still opens
    // into the parent through the round neck.
    const SimLumen s = tube();
    EXPECT_DOUBLE_EQ(neck_channel(s, pinched(s, 5.0, 0.0), 1).width_mm, 2.0);
    EXPECT_DOUBLE_EQ(neck_channel(s, pinched(s, -5.0, 0.0), 1).width_mm, 2.0);
}

TEST(NeckInJaws, ALineWithinTheJawsWidthIsInAndOneSqueezedOutSidewaysIsBesideThemByItsOverhang) {
    // Jaws hinged at the origin along x (8 mm long), opening along z, 1 mm wide along y (x × z = -y: the side).
    const JawsBox j{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ(), 8.0, 1.0};
    // A flattened neck line: a slit from x = 2 to 6 at y = 0, its two sides 0.1 mm apart in z (80 segments round).
    auto slit = [](double y) {
        std::vector<Eigen::Vector3d> pts;
        for (int k = 0; k < 40; ++k) pts.emplace_back(2.0 + 0.1 * k, y, 0.05);
        for (int k = 0; k < 40; ++k) pts.emplace_back(6.0 - 0.1 * k, y, -0.05);
        return std::vector<std::vector<Eigen::Vector3d>>{pts};
    };
    const auto [in, beside] = neck_in_jaws(slit(0.0), {j});
    EXPECT_DOUBLE_EQ(in, 1.0);
    EXPECT_EQ(beside, 0.0);
    // Squeezed 0.8 mm sideways: beside the width by 0.3 mm, nothing in.
    const auto [in2, beside2] = neck_in_jaws(slit(0.8), {j});
    EXPECT_EQ(in2, 0.0);
    EXPECT_NEAR(beside2, 0.3, 1e-12);
    // Half of it past the tips: in for the half along the jaws (the segment that crosses the tip counts by its midpoint).
    std::vector<std::vector<Eigen::Vector3d>> long_slit(1);
    for (int k = 0; k <= 80; ++k) long_slit[0].emplace_back(4.0 + 0.1 * k, 0.0, 0.0);
    for (int k = 79; k >= 1; --k) long_slit[0].emplace_back(4.0 + 0.1 * k, 0.0, 0.0);
    const auto [in3, beside3] = neck_in_jaws(long_slit, {j});
    EXPECT_NEAR(in3, 0.5, 0.0126);
    EXPECT_EQ(beside3, 0.0);
    // With a tolerance beside the width (the closed-clip measure, neck_between_jaws_fraction): the line 0.3 mm beside
    // is in with a 0.31 mm margin; a height limit of 0.04 mm leaves out the slit's sides, 0.05 mm off the mid-plane
    // (all but the two segments that join them across it at its ends, 0.1 mm x 0.1 mm each).
    JawsBox loose = j;
    loose.margin_mm = 0.31;
    EXPECT_DOUBLE_EQ(neck_in_jaws(slit(0.8), {loose}).first, 1.0);
    EXPECT_EQ(neck_in_jaws(slit(0.8), {loose}).second, 0.0);
    loose.max_up_mm = 0.04;
    EXPECT_NEAR(neck_in_jaws(slit(0.0), {loose}).first, 2 * std::sqrt(0.02) / (7.8 + 2 * std::sqrt(0.02)), 1e-9);
    loose.max_up_mm = 0.06;
    EXPECT_DOUBLE_EQ(neck_in_jaws(slit(0.0), {loose}).first, 1.0);
    // Faces that begin 4 mm out (a fulcrum clip's heel, JawsBox::face_from_mm): the half of the slit before them
    // (x = 2 to 4) is not in the jaws, the rest is; faces from 7 mm hold none of it.
    JawsBox heel = j;
    heel.face_from_mm = 4.0;
    EXPECT_NEAR(neck_in_jaws(slit(0.0), {heel}).first, 0.5, 0.0126);
    heel.face_from_mm = 7.0;
    EXPECT_EQ(neck_in_jaws(slit(0.0), {heel}).first, 0.0);
    // No clip, no line: not measured.
    EXPECT_TRUE(std::isnan(neck_in_jaws(slit(0.0), {}).first));
    EXPECT_TRUE(std::isnan(neck_in_jaws({}, {j}).second));
}

TEST(NeckInJaws, ALineAlongACurvedJawIsInWhereTheStraightOneWouldLeaveIt) {
    // Jaws along x from the origin, opening along z, 1 mm wide, curved from 2 mm at a radius of 10 mm towards x × z = −y.
    // A slit along the bent centre line (s = 2.5 … 7.5 mm) is in; the straight jaws leave its far part beside them.
    JawsBox j{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ(), 8.0, 1.0};
    j.curve_radius_mm = 10.0;
    j.curve_from_mm = 2.0;
    std::vector<Eigen::Vector3d> pts;
    for (int side : {1, -1})
        for (int k = 0; k <= 50; ++k) {
            const double s = side > 0 ? 2.5 + 0.1 * k : 7.5 - 0.1 * k, phi = (s - 2.0) / 10.0;
            pts.emplace_back(2.0 + 10.0 * std::sin(phi), -10.0 * (1 - std::cos(phi)), 0.05 * side);
        }
    const std::vector<std::vector<Eigen::Vector3d>> line{pts};
    const auto [in, beside] = neck_in_jaws(line, {j});
    EXPECT_DOUBLE_EQ(in, 1.0);
    EXPECT_EQ(beside, 0.0);
    JawsBox straight = j;
    straight.curve_radius_mm = 0;
    const auto [in_s, beside_s] = neck_in_jaws(line, {straight});
    EXPECT_LT(in_s, 0.8);  // past s ≈ 5.2 the bent line lies more than 0.5 mm across
    EXPECT_NEAR(beside_s, 10.0 * (1 - std::cos(0.55)) - 0.5, 0.02);  // its far end: 1.47 mm across, 0.97 beside
}

// The parent's channel: the tube with a side aneurysm's neck (the sac a patch of its wall, |θ| < π/4 and |z| < 1 mm),
// its ends the pieces of the wall at least 6 mm from the neck line (z < −7 and z > 7 mm).
namespace {
SimLumen tube_with_side_sac() {
    SimLumen s = tube();
    const int k0 = 35, k1 = 45, i0 = -12, i1 = 12;  // z = −1 … 1 mm, θ = −π/4 … π/4
    auto col = [](int i) { return (i % NT + NT) % NT; };
    for (Eigen::Index g = 0; g < s.F.rows(); ++g) {
        const int cell = static_cast<int>(g / 2), k = cell / NT, i = cell % NT;
        const int ii = i >= NT / 2 ? i - NT : i;
        s.face_region[g] = k >= k0 && k < k1 && ii >= i0 && ii < i1 ? 1 : 0;
    }
    std::vector<int> loop;
    for (int i = i0; i < i1; ++i) loop.push_back(k0 * NT + col(i));
    for (int k = k0; k < k1; ++k) loop.push_back(k * NT + col(i1));
    for (int i = i1; i > i0; --i) loop.push_back(k1 * NT + col(i));
    for (int k = k1; k > k0; --k) loop.push_back(k * NT + col(i0));
    s.neck_loops = {loop};
    return s;
}
}  // namespace

TEST(ParentChannel, AnOpenParentKeepsItsDiameterAPinchNarrowsItToItsGap) {
    const SimLumen s = tube_with_side_sac();
    const ParentChannel open = parent_channel(s, s.X, 1);
    EXPECT_EQ(open.ends, 2);
    // The tube's inscribed circle (the polygon's, within the faceting), and not narrowed at all.
    EXPECT_NEAR(open.rest_mm, 2 * R_IN, 0.01);
    EXPECT_DOUBLE_EQ(open.width_mm, open.rest_mm);
    EXPECT_DOUBLE_EQ(open.narrowing, 0.0);
    // Flattened to a 0.3 mm slit across the neck (the whole ring, |z| ≤ 1.5 mm): the parent passes 0.3 mm, narrowed by
    // 1 − 0.3 / 2.4.
    const ParentChannel slit = parent_channel(s, pinched(s, 0.0, 0.3), 1);
    EXPECT_NEAR(slit.width_mm, 0.3, 0.02);
    EXPECT_NEAR(slit.narrowing, 1 - 0.3 / (2 * R_IN), 0.01);
    EXPECT_LE(std::abs(slit.at.z()), 1.5 + 0.2);
    // A pinch on the parent 4 mm from the neck's middle, between it and an end: narrowed as much.
    EXPECT_NEAR(parent_channel(s, pinched(s, 4.0, 0.3), 1).width_mm, 0.3, 0.02);
    // The parent's ends beyond the lumen (nothing 20 mm from the neck line) or no aneurysm: not measured.
    const ParentChannel none = parent_channel(s, s.X, 1, 8.0, 20.0);
    EXPECT_EQ(none.ends, 0);
    EXPECT_TRUE(std::isnan(none.narrowing));
    EXPECT_TRUE(std::isnan(parent_channel(s, s.X, -1).narrowing));
}

TEST(PointGrid, EveryQueryIsTheBoxsPointsWhateverTheBoxsSizeAgainstTheCells) {
    // Points on a 10 × 10 × 10 lattice, 0.3 mm apart, half of them kept; boxes from fewer cells than points to far more
    // cells than points (where the query scans the points instead of the cells): the same points as a brute-force filter, sorted.
    Eigen::MatrixX3d X(1000, 3);
    std::vector<char> keep(1000, 0);
    for (int i = 0; i < 1000; ++i) {
        X.row(i) << 0.3 * (i % 10), 0.3 * (i / 10 % 10), 0.3 * (i / 100);
        keep[static_cast<size_t>(i)] = i % 2;
    }
    PointGrid g;
    g.build(X, 0.05, &keep);
    for (const double half : {0.11, 0.7, 5.0}) {  // 125 cells (fewer than the 500 points), 29³, 201³
        const Eigen::Vector3d c(1.5, 1.5, 0.9), h = Eigen::Vector3d::Constant(half);  // point 355, kept
        std::vector<int> got, unsorted, want;
        g.query(Aabb{c - h, c + h}, got);
        g.query(Aabb{c - h, c + h}, unsorted, false);
        for (int i = 0; i < 1000; ++i)
            if (keep[static_cast<size_t>(i)] && ((X.row(i).transpose() - c).cwiseAbs().array() <= half).all()) want.push_back(i);
        EXPECT_EQ(got, want) << half;
        std::sort(unsorted.begin(), unsorted.end());
        unsorted.erase(std::unique(unsorted.begin(), unsorted.end()), unsorted.end());
        EXPECT_EQ(unsorted, want) << half;
        EXPECT_FALSE(want.empty());
    }
}
