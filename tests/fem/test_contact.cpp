// SPDX-License-Identifier: MIT
// Wall-on-wall contact (fem::ContactBody, issue #15 item 4): two plates pressed together touch and do not
// pass through each other, and the force through them is that of the two plates in series.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <Eigen/Eigenvalues>

#include "aneu/core/bundle.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/structured_mesh.hpp"

using namespace aneu;

namespace {

/// Two 1 × 1 × 0.5 mm plates, one above the other with a 0.05 mm gap (different grids, so the facing nodes
/// do not coincide). The bottom plate's base is held; the top plate's top is pushed down by `push`.
struct Plates {
    static constexpr double H = 0.5, GAP = 0.05;
    Eigen::MatrixX3d V;
    Eigen::MatrixXi T;
    Eigen::VectorXi fixed;
    std::vector<int> top;  // top plate's top nodes
    Eigen::MatrixX3i faces;
    Plates() {
        const fem::StructuredMesh a = fem::box_mesh(1, 1, H, 4, 4, 2), b = fem::box_mesh(1, 1, H, 5, 5, 2);
        V.resize(a.V.rows() + b.V.rows(), 3);
        V << a.V, b.V;
        V.bottomRows(b.V.rows()).col(2).array() += H + GAP;
        T.resize(a.T.rows() + b.T.rows(), 4);
        T << a.T, b.T.array() + static_cast<int>(a.V.rows());
        std::vector<int> fd, facing;
        for (Eigen::Index i = 0; i < V.rows(); ++i) {
            const double z = V(i, 2);
            if (z < 1e-9)
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
            if (z > 2 * H + GAP - 1e-9) top.push_back(static_cast<int>(i));
            if (std::abs(z - H) < 1e-9 || std::abs(z - H - GAP) < 1e-9) facing.push_back(static_cast<int>(i));
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
        const Eigen::VectorXi set = Eigen::Map<Eigen::VectorXi>(facing.data(), static_cast<Eigen::Index>(facing.size()));
        const Eigen::MatrixXi F = fem::boundary_faces_in_set(V, T, set);  // outward: +z below, −z above: towards each other
        faces = F.leftCols(3);
    }
    /// The top plate moved down rigidly until the plates' facing surfaces are `apart` mm apart.
    Eigen::VectorXd pressed(double apart) const {
        Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * V.rows());
        for (Eigen::Index i = 0; i < V.rows(); ++i)
            if (V(i, 2) > H + 1e-9) u[3 * i + 2] = -(GAP - apart);
        return u;
    }
    std::vector<std::pair<int, double>> push(double depth) const {
        std::vector<std::pair<int, double>> p;
        for (int v : top)
            for (int k = 0; k < 3; ++k) p.emplace_back(3 * v + k, k == 2 ? -depth : 0.0);
        return p;
    }
};

double pushing_force(const fem::NewtonResult& r) {
    double f = 0;
    for (Eigen::Index k = 2; k < r.reaction.size(); k += 3) f += r.reaction[k];
    return -f;
}

}  // namespace

TEST(WallContact, TwoPlatesPressedTogetherTouchAndDoNotPassThrough) {
    const Plates p;
    ASSERT_EQ(p.faces.rows(), 2 * (4 * 4 + 5 * 5) * 1);  // two triangles per grid square on both facing sides
    const std::vector<Material> mats = {{"plate", 1.0, 0.0}};  // ν = 0: each plate in uniaxial compression
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), mats);
    constexpr double PUSH = 0.08;
    const auto pres = p.push(PUSH);
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(solid.dofs());

    // Without contact the top plate sinks into the bottom one by push − gap.
    fem::ContactParams cp;
    const fem::NewtonResult free = fem::solve_neo_hookean(solid, p.fixed, pres, u0);
    const fem::ContactBody probe(solid, p.V, p.faces, u0, cp);  // pairs found where the plates start, apart
    EXPECT_LT(probe.min_distance(free.u), -0.025);
    // Pairs already behind their face where a solve starts (a wall's crease, a fold's far side) are not pairs:
    // made in the interpenetrated state, the decorator would not push the plates apart.
    const fem::ContactBody late(solid, p.V, p.faces, free.u, cp);
    EXPECT_EQ(late.active(free.u), 0u);

    // With contact: held about gap_mm apart, no interpenetration, and the force of two plates in series.
    const fem::ContactBody body(solid, p.V, p.faces, u0, cp);
    ASSERT_GT(body.candidates(), 0u);
    const fem::NewtonResult r = fem::solve_neo_hookean(body, p.fixed, pres, u0);
    EXPECT_LT(r.residual, 1e-9);
    const double dmin = body.min_distance(r.u);
    EXPECT_GT(body.active(r.u), 20u);
    EXPECT_GT(dmin, -0.02);   // the interpenetration limit
    EXPECT_LT(dmin, cp.gap_mm);
    // Compression shared by the plates: push − (gap − final separation); each plate's nominal stress in
    // uniaxial compression at stretch λ is μ (λ − 1/λ) (neo-Hookean, λ = 0: ν = 0).
    const double closed = PUSH - (Plates::GAP - std::max(dmin, 0.0));
    const double lambda = 1 - 0.5 * closed / Plates::H, mu = 0.5;
    const double expected = -mu * (lambda - 1 / lambda) * 1.0;  // × the 1 mm² area
    const double f = pushing_force(r);
    std::printf("plates: force %.5f N (two plates in series %.5f N), separation %.4f mm, %zu pairs in contact of %zu, κ %.3g N/mm\n", f,
                expected, dmin, body.active(r.u), body.candidates(), body.stiffness());
    EXPECT_NEAR(f, expected, 0.05 * expected);
}

TEST(WallContact, WallsLeftTouchingOrJustThroughAreSeparatedSoThatTheBarrierSolveStarts) {
    // A hard-contact solve leaves walls exactly touching (or a hair through), where the barrier is infinite, a
    // vertex on its face is not its pair, and a solve cannot start. separate_walls() sets every pair's vertex delta in
    // front of its face, moving nothing by more than it had to; from there the plates pressed together solve as from
    // apart, to the same force.
    const Plates p;
    const std::vector<Material> mats = {{"plate", 1.0, 0.0}};
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), mats);
    const fem::ContactParams cp;
    constexpr double PUSH = 0.08, DELTA = 0.005;
    const fem::ContactBody apart(solid, p.V, p.faces, Eigen::VectorXd::Zero(solid.dofs()), cp);
    const fem::NewtonResult ref = fem::solve_neo_hookean(apart, p.fixed, p.push(PUSH), Eigen::VectorXd::Zero(solid.dofs()));
    for (const double at : {0.0, -0.003}) {
        const Eigen::VectorXd u = p.pressed(at);
        if (at == 0.0) {
            EXPECT_FALSE(std::isfinite(apart.energy(u)));  // touching: the barrier's infinity
        }
        const Eigen::VectorXd s = fem::separate_walls(p.V, p.faces, u, cp, DELTA);
        const fem::ContactBody body(solid, p.V, p.faces, s, cp);
        EXPECT_GE(body.candidates(), apart.candidates()) << "from " << at << " mm apart";  // the touching ones' pairs found
        EXPECT_GE(body.min_distance(s), 0.999 * DELTA) << "from " << at << " mm apart";
        EXPECT_LE((s - u).cwiseAbs().maxCoeff(), DELTA - at + 1e-12);
        EXPECT_TRUE(std::isfinite(body.energy(s)));
        const fem::NewtonResult r = fem::solve_neo_hookean(body, p.fixed, p.push(PUSH), s);
        EXPECT_LT(r.residual, 1e-9);
        EXPECT_GT(body.min_distance(r.u), 0.0);
        EXPECT_NEAR(pushing_force(r), pushing_force(ref), 0.01 * pushing_force(ref)) << "from " << at << " mm apart";
    }
    EXPECT_THROW(fem::separate_walls(p.V, p.faces, Eigen::VectorXd::Zero(solid.dofs()), cp, cp.gap_mm), InputError);
}

TEST(WallContact, SurfaceCrossingsSeeEveryVertexThroughAFacePairedOrNot) {
    // Without contact the top plate is carried rigidly 0.08 mm down: its facing vertices end 0.03 mm behind the
    // bottom plate's faces and the bottom's 0.03 mm behind the top's. A ContactBody made in that state has no pair
    // that sees it (its pairs are those in front where it starts); surface_crossings sees every one.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.0}});
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(solid.dofs());
    const fem::NewtonResult free = fem::solve_neo_hookean(solid, p.fixed, p.push(0.08), u0);
    const fem::ContactParams cp;
    EXPECT_TRUE(fem::surface_crossings(p.V, p.faces, u0, cp.exclude_rings, 0.25).empty());
    const std::vector<fem::SurfaceCrossing> cross = fem::surface_crossings(p.V, p.faces, free.u, cp.exclude_rings, 0.25);
    std::vector<int> through;
    for (const auto& q : cross) {
        EXPECT_NEAR(q.depth_mm, 0.03, 1e-9);
        // A vertex of one plate behind a face of the other, never of its own.
        EXPECT_NE(p.V(q.v, 2) > Plates::H + 1e-9, p.V(p.faces(q.f, 0), 2) > Plates::H + 1e-9);
        through.push_back(q.v);
    }
    std::sort(through.begin(), through.end());
    through.erase(std::unique(through.begin(), through.end()), through.end());
    // Every facing vertex of both plates off the plates' rim (on the rim a vertex lies on the other plate's edge).
    const auto inner = std::count_if(through.begin(), through.end(), [&](int v) {
        return std::min({p.V(v, 0), p.V(v, 1), 1 - p.V(v, 0), 1 - p.V(v, 1)}) > 1e-9;
    });
    EXPECT_EQ(inner, 3 * 3 + 4 * 4);
    EXPECT_TRUE(fem::surface_crossings(p.V, p.faces, free.u, cp.exclude_rings, 0.029).empty());  // deeper than depth: another part
    const fem::ContactBody late(solid, p.V, p.faces, free.u, cp);
    EXPECT_GT(late.min_distance(free.u), 0.0);  // what the frame's own pairs report
    const fem::ContactBody early(solid, p.V, p.faces, u0, cp);
    EXPECT_TRUE(early.is_pair(cross.front().v, cross.front().f));
    EXPECT_FALSE(late.is_pair(cross.front().v, cross.front().f));
    EXPECT_THROW(fem::surface_crossings(p.V, p.faces, u0.head(3), 2, 0.25), InputError);
}

TEST(WallContact, SurfacesSqueezedTowardsEachOtherFromBehindAreNotThroughEachOther) {
    // The plates' facing surfaces with their normals turned away from the gap: two lumens with the tissue between them
    // (session 46: C0001's two lumens squeezed together past the clip's tips). Pressed from 0.05 to 0.02 mm apart, each
    // plate's facing vertices lie 0.02 mm behind the other's faces, but came from behind: no crossing, whatever the
    // depth counted (0.04 mm: at rest they were deeper than that, and counted until session 46). Pushed through each
    // other, the plates with their faces the right way round cross.
    const Plates p;
    Eigen::MatrixX3i away = p.faces;
    away.col(1).swap(away.col(2));
    EXPECT_TRUE(fem::surface_crossings(p.V, away, p.pressed(0.02), 1, 0.04).empty());
    EXPECT_TRUE(fem::surface_crossings(p.V, away, p.pressed(0.02), 1, 0.25).empty());
    const std::vector<fem::SurfaceCrossing> through = fem::surface_crossings(p.V, p.faces, p.pressed(-0.02), 1, 0.04);
    ASSERT_FALSE(through.empty());
    for (const auto& q : through) EXPECT_NEAR(q.depth_mm, 0.02, 1e-9);
}

TEST(WallContact, ANodePushedIntoTheOtherPlateLiesInItsTissueAndNotBefore) {
    // fem::nodes_inside_elements: the plates' facing nodes against both plates' tetrahedra. Apart (at rest, or
    // pressed to 0.02 mm) none lies in the other plate; pushed 0.05 mm into each other, the inner facing nodes of each
    // (those not on the plates' sides: 4 × 4 of the top's, 3 × 3 of the bottom's) lie in an element of the other plate
    // that does not have them as a node; 0.0005 mm into each other, too (nodes on a diagonal of the other plate's cells
    // included: they lie on a face between two of its tetrahedra).
    const Plates p;
    std::vector<int> facing;
    for (Eigen::Index f = 0; f < p.faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) facing.push_back(p.faces(f, k));
    std::sort(facing.begin(), facing.end());
    facing.erase(std::unique(facing.begin(), facing.end()), facing.end());
    auto at = [&](const Eigen::VectorXd& u) {
        Eigen::MatrixX3d x = p.V;
        for (Eigen::Index i = 0; i < x.rows(); ++i) x.row(i) += u.segment<3>(3 * i).transpose();
        return x;
    };
    auto count = [](const std::vector<int>& in) { return std::count_if(in.begin(), in.end(), [](int e) { return e >= 0; }); };
    const Eigen::Index bottom_nodes = fem::box_mesh(1, 1, Plates::H, 4, 4, 2).V.rows(), bottom_tets = fem::box_mesh(1, 1, Plates::H, 4, 4, 2).T.rows();
    EXPECT_EQ(count(fem::nodes_inside_elements(p.V, p.T, facing)), 0);
    EXPECT_EQ(count(fem::nodes_inside_elements(at(p.pressed(0.02)), p.T, facing)), 0);
    const Eigen::MatrixX3d x = at(p.pressed(-0.05));
    std::vector<double> depth;
    const std::vector<int> in = fem::nodes_inside_elements(x, p.T, facing, &depth);
    int top_in = 0, bottom_in = 0;
    for (size_t i = 0; i < facing.size(); ++i) {
        if (in[i] < 0) {
            EXPECT_EQ(depth[i], 0.0);
            continue;
        }
        // 0.05 mm below the other plate's facing surface: its elements' boundary faces there (or, for an element with
        // none, a lower bound).
        EXPECT_LE(depth[i], 0.05 + 1e-9);
        EXPECT_GT(depth[i], 0.0);
        const bool top = facing[i] >= bottom_nodes;
        (top ? top_in : bottom_in) += 1;
        EXPECT_EQ(top, in[i] < bottom_tets) << "node " << facing[i] << " in its own plate's element " << in[i];
        for (int k = 0; k < 4; ++k) EXPECT_NE(p.T(in[i], k), facing[i]);
        const double xs = x(facing[i], 0), ys = x(facing[i], 1);
        EXPECT_TRUE(xs > 1e-9 && xs < 1 - 1e-9 && ys > 1e-9 && ys < 1 - 1e-9) << "a node on the plates' sides";
    }
    EXPECT_EQ(top_in, 16);
    EXPECT_EQ(bottom_in, 9);
    EXPECT_EQ(count(fem::nodes_inside_elements(at(p.pressed(-0.0005)), p.T, facing)), 25);
    EXPECT_THROW(fem::nodes_inside_elements(x, p.T.leftCols(3), facing), InputError);
    EXPECT_THROW(fem::nodes_inside_elements(x, p.T, {static_cast<int>(x.rows())}), InputError);
}

TEST(WallContact, ATenNodeElementHoldsWhatItsCurvedEdgeTakesIn) {
    // One 10-node tetrahedron, the unit corner one, its mid-edge node on edge 1-2 pushed out from (0.5, 0.5, 0) to
    // (0.6, 0.6, 0): the point (0.52, 0.52, 0.02) lies beyond the corners' plane x + y + z = 1 but inside the element's
    // eight straight pieces (their volume 0.1917 against the corners' 1/6). As a 4-node element it holds nothing
    // there; a point within (0.2, 0.2, 0.2) both; the element's own node none.
    Eigen::MatrixX3d x(12, 3);
    x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.5, 0, 0, 0.6, 0.6, 0, 0, 0.5, 0, 0, 0, 0.5, 0.5, 0, 0.5, 0, 0.5, 0.5,  //
        0.52, 0.52, 0.02, 0.2, 0.2, 0.2;
    Eigen::MatrixXi t10(1, 10);
    t10 << 0, 1, 2, 3, 4, 5, 6, 7, 8, 9;
    EXPECT_EQ(fem::nodes_inside_elements(x, t10, {10, 11, 5}), (std::vector<int>{0, 0, -1}));
    EXPECT_EQ(fem::nodes_inside_elements(x, t10.leftCols(4), {10, 11}), (std::vector<int>{-1, 0}));
}

TEST(WallContact, ANodePushedALittleIntoItsNeighbourIsThatLittleDeep) {
    // Two tetrahedra on the face (a, b, c) in z = 0: A above it with its apex q, B below. q (on the boundary) pushed
    // 0.005 mm through the face lies in B, 0.005 mm deep: it leaves B back into its own tissue across that face (before
    // session 48 it was given the distance to B's faces on the boundary, 0.241 mm). A node of neither element at the
    // same point (a surface vertex of another part) leaves B only through its faces on the boundary, 0.241 mm off.
    Eigen::MatrixX3d x(6, 3);
    x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0.25, 0.25, 1, 0.25, 0.25, -1, 0.25, 0.25, -0.005;
    Eigen::MatrixXi t(2, 4);
    t << 0, 1, 2, 3, 0, 2, 1, 4;  // A (a, b, c, q), B (a, c, b, r)
    std::vector<double> depth;
    EXPECT_EQ(fem::nodes_inside_elements(x, t, {3, 5}, &depth), (std::vector<int>{-1, 1}));  // q at rest: in none
    x.row(3) = x.row(5);
    EXPECT_EQ(fem::nodes_inside_elements(x, t, {3, 5}, &depth), (std::vector<int>{1, 1}));
    EXPECT_NEAR(depth[0], 0.005, 1e-12);
    EXPECT_NEAR(depth[1], 0.25 * (1 - 0.005) / std::sqrt(1 + 0.25 * 0.25), 1e-12);  // to the face (a, b, r)
    // Six tetrahedra round the edge a = (0, 0, 0), b = (1, 0, 0), to the points P_k at 60° steps round it 1 mm off: the
    // node P_0 (of the first and the last) moved into the one opposite, 0.003 mm from the edge, lies in it 0.003 mm
    // deep: it leaves the other tissue at the edge it shares with its own elements (session 48: a lumen node of the
    // sample's patch was given 0.37 mm, the distance to its holder's faces on the boundary; the holder's faces by the
    // edge lie between it and other elements of the fan).
    {
        Eigen::MatrixX3d f(8, 3);
        f.row(0) << 0, 0, 0;
        f.row(1) << 1, 0, 0;
        for (int k = 0; k < 6; ++k) f.row(2 + k) << 0.5, std::cos(k * M_PI / 3), std::sin(k * M_PI / 3);
        Eigen::MatrixXi fan(6, 4);
        for (int k = 0; k < 6; ++k) fan.row(k) << 0, 1, 2 + k, 2 + (k + 1) % 6;
        for (int k = 0; k < 6; ++k)  // each positive
            if ((f.row(fan(k, 1)) - f.row(fan(k, 0))).dot((f.row(fan(k, 2)) - f.row(fan(k, 0))).cross(f.row(fan(k, 3)) - f.row(fan(k, 0)))) < 0) std::swap(fan(k, 2), fan(k, 3));
        f.row(2) << 0.5, 0.003 * std::cos(210 * M_PI / 180), 0.003 * std::sin(210 * M_PI / 180);
        EXPECT_EQ(fem::nodes_inside_elements(f, fan, {2}, &depth), (std::vector<int>{3}));
        EXPECT_NEAR(depth[0], 0.003, 1e-12);
    }
    // A node inside a mesh came through no surface: it lies in a neighbour when its own elements are tangled, and its
    // depth is how far past the holding element's nearest face it lies, not the distance to the mesh's boundary. A wall
    // two cells thick (0.2 mm, 0.25 mm cells), its mid-plane node in the middle moved 0.2 mm sideways and 0.02 mm up:
    // in an element of the upper layer not its own, 0.02 mm above the mid-plane, 0.08 mm below the wall's top (the
    // depth before session 48).
    const fem::StructuredMesh wall = fem::box_mesh(1, 1, 0.2, 4, 4, 2);
    int middle = -1;
    for (Eigen::Index i = 0; i < wall.V.rows(); ++i)
        if ((wall.V.row(i) - Eigen::RowVector3d(0.5, 0.5, 0.1)).norm() < 1e-12) middle = static_cast<int>(i);
    ASSERT_GE(middle, 0);
    int held_somewhere = 0;
    for (const double dx : {0.2, -0.2})
        for (const double dy : {0.1, -0.1, 0.15}) {
            Eigen::MatrixX3d y = wall.V;
            y.row(middle) += Eigen::RowVector3d(dx, dy, 0.02);
            const std::vector<int> held = fem::nodes_inside_elements(y, wall.T, {middle}, &depth);
            if (held[0] < 0) continue;  // still within its own elements
            ++held_somewhere;
            const Eigen::Vector3d p = y.row(middle).transpose();
            double nearest = 1e9;
            for (int k = 0; k < 4; ++k) {
                const Eigen::Vector3d a = y.row(wall.T(held[0], (k + 1) % 4)), b = y.row(wall.T(held[0], (k + 2) % 4)), c = y.row(wall.T(held[0], (k + 3) % 4));
                nearest = std::min(nearest, std::abs((p - a).dot((b - a).cross(c - a).normalized())));
            }
            EXPECT_LE(depth[0], 0.02 + 1e-12);
            EXPECT_NEAR(depth[0], nearest, 1e-12);
        }
    EXPECT_GT(held_somewhere, 0);
}

TEST(WallContact, AVertexThroughAFaceItsPairsLeftOutIsCaughtAndTheSolveRepeated) {
    // The top plate starts lifted 0.5 mm (0.55 mm apart) and is pushed to 0.08 mm down in one solve; pairs are
    // searched 0.02 mm round each face where it starts: none at all, and the top plate sinks through the bottom
    // one. solve_without_crossings sees the vertices behind faces (surface_crossings), pairs them with every face
    // near their path and solves again: no vertex through, and the force of the two plates pressed together, as
    // with pairs found the ordinary way from the plates' rest.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.0}});
    constexpr double PUSH = 0.08, LIFT = 0.5;
    const auto pres = p.push(PUSH);
    Eigen::VectorXd lifted = Eigen::VectorXd::Zero(solid.dofs());
    for (Eigen::Index i = 0; i < p.V.rows(); ++i)
        if (p.V(i, 2) > Plates::H + 1e-9) lifted[3 * i + 2] = LIFT;
    fem::ContactParams cp;
    cp.search_mm = 0.02;
    ASSERT_EQ(fem::ContactBody(solid, p.V, p.faces, lifted, cp).candidates(), 0u);
    int solves = 0;
    const fem::CrossingFreeSolve cs = fem::solve_without_crossings(solid, p.V, p.faces, lifted, cp, [&](const fem::ContactBody& body) {
        ++solves;
        return fem::solve_neo_hookean(body, p.fixed, pres, lifted);
    });
    EXPECT_GE(cs.rounds, 1);
    EXPECT_EQ(solves, cs.rounds + 1);
    EXPECT_TRUE(cs.left.empty());
    EXPECT_GT(cs.pairs, 0u);
    EXPECT_LT(cs.result.residual, 1e-9);
    EXPECT_TRUE(fem::surface_crossings(p.V, p.faces, cs.result.u, cp.exclude_rings, 0.25).empty());
    const fem::ContactBody ordinary(solid, p.V, p.faces, Eigen::VectorXd::Zero(solid.dofs()), fem::ContactParams{});
    const fem::NewtonResult r = fem::solve_neo_hookean(ordinary, p.fixed, pres, Eigen::VectorXd::Zero(solid.dofs()));
    EXPECT_NEAR(pushing_force(cs.result), pushing_force(r), 0.02 * pushing_force(r));
    // No rounds allowed: the crossings are handed back, 0.03 mm deep.
    const fem::CrossingFreeSolve once = fem::solve_without_crossings(
        solid, p.V, p.faces, lifted, cp, [&](const fem::ContactBody& body) { return fem::solve_neo_hookean(body, p.fixed, pres, lifted); }, 0.25, 0);
    EXPECT_EQ(once.rounds, 0);
    ASSERT_FALSE(once.left.empty());
    EXPECT_NEAR(once.left.front().depth_mm, PUSH - Plates::GAP, 1e-9);
    EXPECT_NEAR(once.deepest_mm, PUSH - Plates::GAP, 1e-9);
    EXPECT_EQ(cs.deepest_mm, 0.0);
    EXPECT_EQ(cs.deepest_start_mm, 0.0);
    // A solve that starts with the plates already through each other (where `once` left them) pushed further: what
    // was behind a face at its start goes deeper (no barrier acts on a vertex behind its face); the start's depth is
    // handed back beside the end's, so that a caller can tell how much deeper it went (the simulator refuses a Newton
    // frame that went past its walls' limit so).
    constexpr double FURTHER = 0.12;
    const fem::CrossingFreeSolve deeper = fem::solve_without_crossings(
        solid, p.V, p.faces, once.result.u, cp, [&](const fem::ContactBody& body) { return fem::solve_neo_hookean(body, p.fixed, p.push(FURTHER), once.result.u); }, 0.25, 0);
    EXPECT_NEAR(deeper.deepest_start_mm, PUSH - Plates::GAP, 1e-9);
    EXPECT_NEAR(deeper.deepest_mm, FURTHER - Plates::GAP, 1e-6);
    // The close vertices it paired are handed back (every vertex that went through, with its ring); a solve that
    // starts with them paired within reach of their path (the simulator's next frame: its own reach covers a held
    // vertex's) needs no repeat and ends where the repeat did.
    ASSERT_FALSE(cs.close_vertices.empty());
    EXPECT_TRUE(std::is_sorted(cs.close_vertices.begin(), cs.close_vertices.end()));
    for (const fem::SurfaceCrossing& q : once.left)
        EXPECT_TRUE(std::binary_search(cs.close_vertices.begin(), cs.close_vertices.end(), q.v)) << "vertex " << q.v;
    fem::ContactParams seeded = cp;
    seeded.close_vertices = cs.close_vertices;
    seeded.close_search_mm = 2 * (LIFT + PUSH);
    int seeded_solves = 0;
    const fem::CrossingFreeSolve next = fem::solve_without_crossings(solid, p.V, p.faces, lifted, seeded, [&](const fem::ContactBody& body) {
        ++seeded_solves;
        return fem::solve_neo_hookean(body, p.fixed, pres, lifted);
    });
    EXPECT_EQ(next.rounds, 0);
    EXPECT_EQ(seeded_solves, 1);
    EXPECT_TRUE(next.left.empty());
    EXPECT_EQ(next.close_vertices, cs.close_vertices);
    EXPECT_NEAR(pushing_force(next.result), pushing_force(cs.result), 1e-6 * pushing_force(cs.result));
}

TEST(WallContact, ACrossingIsWorthAnotherSolveOnlyWhereClosePairingChangesThePairs) {
    // Crossings (vertex, face); the pairs in no order; the close vertices sorted (pair_crossings_closely's).
    const std::vector<std::array<int, 2>> pairs = {{7, 3}, {2, 9}, {5, 1}};
    const std::vector<int> close = {2, 5, 8};
    EXPECT_FALSE(fem::crossings_need_pairs({}, pairs, close));                  // nothing went through
    EXPECT_FALSE(fem::crossings_need_pairs({{2, 9}}, pairs, close));            // paired closely already: a crease
    EXPECT_FALSE(fem::crossings_need_pairs({{5, 1}, {2, 9}}, pairs, close));
    EXPECT_TRUE(fem::crossings_need_pairs({{2, 4}}, pairs, close));             // close, but not with that face
    EXPECT_TRUE(fem::crossings_need_pairs({{7, 3}}, pairs, close));             // paired, its ring not yet
    EXPECT_TRUE(fem::crossings_need_pairs({{2, 9}, {6, 0}}, pairs, close));     // one of them new
    EXPECT_TRUE(fem::crossings_need_pairs({{2, 9}}, {}, close));
    // After pair_crossings_closely the vertex is close; with its pair found, nothing is left to gain.
    fem::ContactParams cp;
    cp.close_vertices = close;
    const Eigen::MatrixX3i faces = (Eigen::MatrixX3i(4, 3) << 0, 1, 6, 1, 7, 6, 2, 3, 4, 3, 5, 4).finished();
    const Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * 9);
    fem::pair_crossings_closely(cp, faces, u, u, {{7, 3}});
    EXPECT_FALSE(fem::crossings_need_pairs({{7, 3}}, pairs, cp.close_vertices));
    EXPECT_TRUE(std::binary_search(cp.close_vertices.begin(), cp.close_vertices.end(), 6));  // its ring
}

TEST(WallContact, NeighboursAreNotPairs) {
    // A flat face never pushes on itself. With the whole 4 × 4 grid in reach, a ring count wider than the grid
    // leaves no pair; with two rings, or none, the far vertices of the same wall are not pairs either: their
    // normals face the same way as the faces (a pair is a vertex and a face facing each other).
    const fem::StructuredMesh a = fem::box_mesh(1, 1, 0.5, 4, 4, 2);
    const fem::NeoHookeanSolid solid(a.V, a.T, Eigen::VectorXi::Zero(a.T.rows()), {{"plate", 1.0, 0.3}});
    std::vector<int> topn;
    for (Eigen::Index i = 0; i < a.V.rows(); ++i)
        if (a.V(i, 2) > 0.5 - 1e-9) topn.push_back(static_cast<int>(i));
    const Eigen::VectorXi set = Eigen::Map<Eigen::VectorXi>(topn.data(), static_cast<Eigen::Index>(topn.size()));
    const Eigen::MatrixX3i faces = fem::boundary_faces_in_set(a.V, a.T, set).leftCols(3);
    fem::ContactParams cp;
    cp.search_mm = 0.6;  // the whole face is within reach; only the neighbourhood rule keeps pairs out
    cp.exclude_rings = 8;  // more than the grid's diameter: every vertex is a neighbour of every face
    const fem::ContactBody all_near(solid, a.V, faces, Eigen::VectorXd::Zero(solid.dofs()), cp);
    EXPECT_EQ(all_near.candidates(), 0u);
    for (int rings : {2, 0}) {
        cp.exclude_rings = rings;
        const fem::ContactBody body(solid, a.V, faces, Eigen::VectorXd::Zero(solid.dofs()), cp);
        EXPECT_EQ(body.candidates(), 0u) << rings << " rings";
        EXPECT_EQ(body.active(Eigen::VectorXd::Zero(solid.dofs())), 0u);
    }
    EXPECT_THROW(fem::ContactBody(solid, a.V.topRows(3), faces, Eigen::VectorXd::Zero(solid.dofs()), cp), InputError);
}

TEST(WallContact, ForcesAndTangentAreTheBarriersDerivatives) {
    // The plates 0.004–0.008 mm apart (inside the barrier's reach d̂ = 0.01 mm) and shifted sideways by a few
    // µm, with a random jitter: the top grid's vertices at x or y = 0.5 lie a few µm beside the bottom grid's
    // lines and its rim vertices beside the bottom plate's rim, so the faces' inside, edges and corners are all
    // closest points of active pairs.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.3}});
    Eigen::VectorXd u = Eigen::VectorXd::Zero(solid.dofs());
    std::srand(7);
    for (Eigen::Index i = 0; i < p.V.rows(); ++i) {
        if (p.V(i, 2) < Plates::H + 1e-9) continue;
        u[3 * i + 0] = 0.004 + 0.002 * (std::rand() / double(RAND_MAX) - 0.5);
        u[3 * i + 1] = -0.003 + 0.002 * (std::rand() / double(RAND_MAX) - 0.5);
        u[3 * i + 2] = -(Plates::GAP - 0.006) + 0.004 * (std::rand() / double(RAND_MAX) - 0.5);
    }
    fem::ContactParams cp;
    cp.stiffness = 1.0;
    const fem::ContactBody body(solid, p.V, p.faces, u, cp);
    const auto n_active = body.active(u);
    ASSERT_GT(n_active, 40u);
    const Eigen::VectorXd g = body.internal_force(u);
    const Eigen::SparseMatrix<double, Eigen::RowMajor> K = body.tangent(u);
    const Eigen::VectorXd gs = solid.internal_force(u);
    double worst_g = 0, worst_k = 0, scale_g = 0, scale_k = 0;
    constexpr double h = 1e-7;
    int checked = 0;
    for (Eigen::Index i = 0; i < p.V.rows(); ++i) {
        const double z = p.V(i, 2);
        if (std::abs(z - Plates::H) > 1e-9 && std::abs(z - Plates::H - Plates::GAP) > 1e-9) continue;  // facing nodes only
        for (int a = 0; a < 3; ++a) {
            const Eigen::Index dof = 3 * i + a;
            Eigen::VectorXd up = u, um = u;
            up[dof] += h;
            um[dof] -= h;
            const double fd = (body.energy(up) - body.energy(um)) / (2 * h);
            worst_g = std::max(worst_g, std::abs(fd - g[dof]));
            scale_g = std::max(scale_g, std::abs(g[dof] - gs[dof]));
            const Eigen::VectorXd col = (body.internal_force(up) - body.internal_force(um)) / (2 * h);
            for (Eigen::Index r = 0; r < col.size(); ++r) {
                worst_k = std::max(worst_k, std::abs(col[r] - K.coeff(r, dof)));
                scale_k = std::max(scale_k, std::abs(K.coeff(r, dof)));
            }
            ++checked;
        }
    }
    std::printf("barrier derivatives: %d DOFs, %zu pairs active, force error %.3g of %.3g N, tangent error %.3g of %.3g N/mm\n", checked,
                n_active, worst_g, scale_g, worst_k, scale_k);
    ASSERT_GT(scale_g, 1e-3);  // the barrier pushes
    EXPECT_LT(worst_g, 1e-5 * scale_g);
    EXPECT_LT(worst_k, 1e-4 * scale_k);
    // Projected (tangent(u, true)): positive semidefinite pair blocks, so the sum with the projected solid is too.
    const Eigen::MatrixXd Kp = Eigen::MatrixXd(body.tangent(u, true));
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Kp).eigenvalues().minCoeff(), -1e-9 * scale_k);
}

TEST(WallContact, ADecoratorOverTheContactHasItsTangentEntryForEntry) {
    // A clip body over the wall contact (as in a patch frame) fills its tangent through the contact body's
    // add_tangent, with no copy of the contact body's own: its block on the body's DOFs must be the contact
    // body's tangent (active pairs included) entry for entry. Blades far off: no candidate.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.3}});
    const Eigen::VectorXd u = p.pressed(0.005);
    fem::ContactParams cp;
    cp.stiffness = 1.0;
    const fem::ContactBody body(solid, p.V, p.faces, u, cp);
    ASSERT_GT(body.active(u), 10u);
    fem::ClipBlades bl;
    bl.hinge = Eigen::Vector3d(100, 100, 100);
    const fem::ClipBody clip(body, p.V, {}, (Eigen::VectorXd(u.size() + 1) << u, 0.3).finished(), bl, fem::ClipSpring{1.0, 0.1});
    Eigen::VectorXd v(u.size() + 1);
    v << u, 0.3;
    const Eigen::MatrixXd Kc = Eigen::MatrixXd(clip.tangent(v)).topLeftCorner(u.size(), u.size());
    const Eigen::MatrixXd Kb = Eigen::MatrixXd(body.tangent(u));
    EXPECT_EQ((Kc - Kb).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_GT((Kb - Eigen::MatrixXd(solid.tangent(u))).cwiseAbs().maxCoeff(), 0.1) << "the pairs are in it";
}

TEST(WallContact, APatternCacheServesLaterDecoratorsWithTheirOwnTangent) {
    // Decorators made for successive solves (a simulator's frames) share a PatternCache: one whose pairs the cached
    // pattern holds takes it as it is (structural zeros where its pairs are not), one with a new pair merges the
    // union, one over another body pattern merges afresh. Whatever the pattern, the tangent is the decorator's own:
    // as a dense matrix, equal to an uncached decorator's to the last bit.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.3}});
    const Eigen::VectorXd u = p.pressed(0.005);
    auto params = [](double search, std::shared_ptr<fem::PatternCache> cache) {
        fem::ContactParams cp;
        cp.stiffness = 1.0;
        cp.search_mm = search;
        cp.pattern_cache = std::move(cache);
        return cp;
    };
    auto same_tangent = [&](const fem::ElasticBody& a, const fem::ElasticBody& b) {
        return (Eigen::MatrixXd(a.tangent(u)) - Eigen::MatrixXd(b.tangent(u))).cwiseAbs().maxCoeff() == 0.0;
    };
    const auto cache = fem::make_pattern_cache();
    const fem::ContactBody wide(solid, p.V, p.faces, u, params(0.3, cache));
    (void)wide.pattern();
    EXPECT_EQ(fem::pattern_cache_counts(*cache), std::make_pair(1, 0));
    const fem::ContactBody narrow(solid, p.V, p.faces, u, params(0.02, cache));  // a subset of wide's pairs
    const fem::ContactBody narrow_alone(solid, p.V, p.faces, u, params(0.02, nullptr));
    ASSERT_GT(narrow.candidates(), 0u);
    ASSERT_LT(narrow.candidates(), wide.candidates());
    EXPECT_EQ(&narrow.pattern(), &wide.pattern()) << "the cached pattern, not a copy";
    EXPECT_EQ(fem::pattern_cache_counts(*cache), std::make_pair(1, 1));
    EXPECT_GT(narrow.pattern().nonZeros(), narrow_alone.pattern().nonZeros());
    EXPECT_TRUE(same_tangent(narrow, narrow_alone));
    const fem::ContactBody widest(solid, p.V, p.faces, u, params(0.6, cache));  // pairs beyond the cached ones
    const fem::ContactBody widest_alone(solid, p.V, p.faces, u, params(0.6, nullptr));
    ASSERT_GT(widest.candidates(), wide.candidates());
    (void)widest.pattern();
    EXPECT_EQ(fem::pattern_cache_counts(*cache), std::make_pair(2, 1));
    EXPECT_GE(widest.pattern().nonZeros(), widest_alone.pattern().nonZeros());
    EXPECT_TRUE(same_tangent(widest, widest_alone));
    EXPECT_TRUE(same_tangent(wide, fem::ContactBody(solid, p.V, p.faces, u, params(0.3, nullptr)))) << "an earlier decorator keeps its pattern";
    // The same cache over another body's pattern (the solid with the contact's entries): merged afresh.
    const fem::ContactBody over_contact(narrow_alone, p.V, p.faces, u, params(0.02, cache));
    (void)over_contact.pattern();
    EXPECT_EQ(fem::pattern_cache_counts(*cache), std::make_pair(3, 1));
    EXPECT_TRUE(same_tangent(over_contact, fem::ContactBody(narrow_alone, p.V, p.faces, u, params(0.02, nullptr))));
}

TEST(WallContact, NoStepPassesThroughAFace) {
    // A vertex sent straight through the opposite plate (and one sent sideways past it): the step is cut where
    // the vertex is a tenth of its distance from the face, and the energy there is finite; a step that stays clear
    // is not cut.
    const Plates p;
    const fem::NeoHookeanSolid solid(p.V, p.T, Eigen::VectorXi::Zero(p.T.rows()), {{"plate", 1.0, 0.3}});
    const Eigen::VectorXd u = Eigen::VectorXd::Zero(solid.dofs());
    fem::ContactParams cp;
    const fem::ContactBody body(solid, p.V, p.faces, u, cp);
    int centre = -1;  // the top plate's facing vertex nearest (0.5, 0.5)
    for (Eigen::Index i = 0; i < p.V.rows(); ++i)
        if (std::abs(p.V(i, 2) - Plates::H - Plates::GAP) < 1e-9 &&
            (centre < 0 || (p.V.row(i).head<2>() - Eigen::RowVector2d(0.5, 0.5)).norm() <
                               (p.V.row(centre).head<2>() - Eigen::RowVector2d(0.5, 0.5)).norm()))
            centre = static_cast<int>(i);
    ASSERT_GE(centre, 0);
    Eigen::VectorXd du = Eigen::VectorXd::Zero(solid.dofs());
    du[3 * centre + 2] = -0.2;  // 0.05 mm gap: through the bottom plate's face at a quarter of the step
    const double a = body.max_step(u, du);
    EXPECT_GT(a, 0.2 * 0.9 * 0.25);
    EXPECT_LT(a, 0.25 * (1 - 0.1) + 1e-12);  // stops at or before a tenth of the distance
    const Eigen::VectorXd at = u + a * du;
    EXPECT_GT(body.min_distance(at), 0.0);
    EXPECT_TRUE(std::isfinite(body.energy(at)));
    EXPECT_LT(body.min_distance(u + 0.3 * du), -0.005);  // the whole step would have passed through unseen by the barrier
    du.setZero();
    du[3 * centre + 0] = 0.01;  // sideways along the gap
    EXPECT_EQ(body.max_step(u, du), 1.0);
}

TEST(WallContact, QuadraticPlatesTouchAlongTheirMidEdgeNodesOnlyWithTheSplitFaces) {
    // The plates with 10-node elements, pressed 0.1 mm past touching. Contact on the corner triangles holds the
    // corners off the opposite face's plane, but the quadratic surface between them (its mid-edge nodes) passes
    // through the opposite wall; on the faces split at their mid-edge nodes (fem::quadratic_surface_triangles), no
    // node of either quadratic surface lies behind the other.
    const Plates p;
    const fem::QuadraticMesh q = fem::quadratic_mesh(p.V, p.T);
    const Eigen::VectorXi region = Eigen::VectorXi::Zero(q.T.rows());
    const fem::NeoHookeanSolid solid(q.V, q.T, region, {Material{"wall", 1.0, 0.45}});
    std::vector<int> fd, top;
    for (Eigen::Index i = 0; i < q.V.rows(); ++i) {
        if (q.V(i, 2) < 1e-9)
            for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
        if (q.V(i, 2) > 2 * Plates::H + Plates::GAP - 1e-9) top.push_back(static_cast<int>(i));
    }
    const Eigen::VectorXi fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    std::vector<std::pair<int, double>> pres;
    for (int v : top)
        for (int k = 0; k < 3; ++k) pres.emplace_back(3 * v + k, k == 2 ? -(Plates::GAP + 0.1) : 0.0);
    const Eigen::MatrixX3i split = fem::quadratic_surface_triangles(fem::MidEdgeNodes(q.T), p.faces);
    ASSERT_EQ(split.rows(), 4 * p.faces.rows());
    // The deepest node of either quadratic surface behind the other one's (split) faces, at u.
    auto deepest = [&](const Eigen::VectorXd& u) {
        double worst = 0;
        for (const fem::SurfaceCrossing& c : fem::surface_crossings(q.V, split, u, 2, 0.25)) worst = std::max(worst, c.depth_mm);
        return worst;
    };
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(solid.dofs());
    fem::ContactParams cp;
    const fem::ContactBody corners(solid, q.V, p.faces, u0, cp);
    const fem::NewtonResult rc = fem::solve_neo_hookean(corners, fixed, pres, u0);
    const fem::ContactBody whole(solid, q.V, split, u0, cp);
    const fem::NewtonResult rs = fem::solve_neo_hookean(whole, fixed, pres, u0);
    const double dc = deepest(rc.u), ds = deepest(rs.u);
    std::printf("plates pressed 0.1 mm: corner triangles %.4f N, quadratic surface %.4f mm deep through the other; split faces %.4f N, %.4f mm; "
                "closest split pair %.4f mm\n", pushing_force(rc), dc, pushing_force(rs), ds, whole.min_distance(rs.u));
    // Measured: the corners' contact lets the quadratic surface 0.086 mm through (of the 0.1 mm push) at 0.085 N; the
    // split faces' keeps every node out (closest pair 0.009 mm, within the barrier's 0.01) at 0.145 N.
    EXPECT_GT(dc, 0.02);
    EXPECT_LT(ds, 1e-4);
    EXPECT_GT(whole.min_distance(rs.u), 0.0);
    EXPECT_GT(pushing_force(rs), 1.3 * pushing_force(rc));
}
