// SPDX-License-Identifier: MIT
// Contact on a precomputed compliance (fem::Linearisation, fem::solve_compliant_clip; issue #15's haptic-rate
// contact): on a block of known stiffness the frames reach the hard-contact moment balance solved here by
// bisection; held open, one frame gives the block's force exactly; on a neo-Hookean block, frames each on a
// linearisation at the last frame's state (sequential quadratic programming) reach the equilibrium that the
// barrier Newton solve of ClipBody finds, within the barrier's distance.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <vector>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/compliance.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "clip_test_util.hpp"

using namespace aneu;
using aneu::test::Block;
using aneu::test::test_spring;

namespace {

/// Hard contact on the block: at opening θ the node on blade +1 starts d₀ in front of its face; pressed (d₀ < 0) it
/// moves −d₀ along the face's normal against its ground spring, F = −K d₀, at r from the hinge.
double block_force(double theta) {
    const double phi = 0.5 * theta, d0 = Block::A * std::sin(phi) - Block::H * std::cos(phi);
    return d0 < 0 ? -Block::K * d0 : 0.0;
}
double block_lever(double theta) { return Block::A * std::cos(0.5 * theta) + Block::H * std::sin(0.5 * theta); }

}  // namespace

TEST(CompliantClip, BladeDistanceIsTheFacesOverTheBladeAndTheRoundedEdgesBeside) {
    fem::ClipBlades b;  // hinge at the origin, axis x, up y, 7 × 1 mm, closed gap 0
    // Closed (θ = 0): blade +1's face is the plane y = 0 seen from below (its normal −y), blade −1's from above.
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {3.0, -0.25, 0.1}), 0.25, 1e-12);
    EXPECT_NEAR(fem::blade_distance(b, -1, 0.0, {3.0, 0.25, 0.1}), 0.25, 1e-12);
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {3.0, 0.05, 0.0}), -0.05, 1e-12);  // behind the face
    // Beside the blade (1 mm wide, edges rounded 0.1 mm): 0.3 mm out from the side, level with the face.
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {3.0, -1e-9, 0.8}), std::hypot(0.4, 0.1) - 0.1, 1e-6);
    // Opened by θ: a point on blade +1's direction at r is r sin(θ/2)·… in front of blade −1, on blade +1's face.
    const double th = 0.4;
    Eigen::Vector3d t, n, w;
    b.frame(1, th, t, n, w);
    EXPECT_NEAR(fem::blade_distance(b, 1, th, 4.0 * t + 0.3 * n), 0.3, 1e-12);
}

TEST(CompliantClip, BladeDistanceBeforeTheHeelOfFacesThatBeginThereIsToTheHeelsEdge) {
    // Blades 7 mm from the hinge whose faces begin 3 mm out (ClipBlades::face_from_mm: a fulcrum's arms before the
    // heel do not clamp): a point 1 mm before the heel, level with the face, is its distance to the heel's rounded
    // edge (ρ 0.1 mm: the core from 3.1 mm, 0.1 mm behind the face), not on the face; past the heel the face's plane
    // as before; faces from 0: the old blade.
    fem::ClipBlades b;
    b.face_from_mm = 3.0;
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {2.0, -1e-9, 0.1}), std::hypot(1.1, 0.1) - 0.1, 1e-6);
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {2.0, -0.3, 0.1}), std::hypot(1.1, 0.4) - 0.1, 1e-6);
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {4.0, -0.25, 0.1}), 0.25, 1e-12);
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {3.1, 0.05, 0.0}), -0.05, 1e-12);  // behind the face just past the heel
    b.face_from_mm = 0.0;
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {2.0, -0.25, 0.1}), 0.25, 1e-12);
}

TEST(CompliantClip, BladeDistanceOnACurvedBladeIsAcrossItsCentreLine) {
    fem::ClipBlades b;  // 7 × 1 mm, curved from 2 mm at 5 mm towards +z (= axis × up), closed
    b.curve_radius_mm = 5.0;
    b.curve_from_mm = 2.0;
    // Over the face where it has turned 45° (s = 2 + 5π/4): in front of it by the plane's distance, however far
    // across the straight blade's 1 mm that point lies.
    double r, a, dr, da;
    b.centre_line(2.0 + 5.0 * PI / 4, r, a, dr, da);
    EXPECT_NEAR(r, 2.0 + 5.0 * std::sqrt(0.5), 1e-12);
    EXPECT_NEAR(a, 5.0 * (1 - std::sqrt(0.5)), 1e-12);
    ASSERT_GT(a, 1.0);  // beside a straight blade
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {r, -0.25, a}), 0.25, 1e-12);
    // 0.3 mm out from its side (across the centre line, level with the face): as beside a straight blade.
    const Eigen::Vector2d out = 0.8 * Eigen::Vector2d(-da, dr);  // across the centre line, towards +a's side
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {r + out[0], -1e-9, a + out[1]}), std::hypot(0.4, 0.1) - 0.1, 1e-6);
    // Before the curve (r < 2) the blade is the straight one.
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {1.5, -1e-9, 0.8}), std::hypot(0.4, 0.1) - 0.1, 1e-6);
    // 0.3 mm on from its tip (s = 7) along its end's direction: the tip's rounded edge, the way along it measured on
    // the arc (R atan(0.3/R)).
    b.centre_line(7.0, r, a, dr, da);
    EXPECT_NEAR(fem::blade_distance(b, 1, 0.0, {r + 0.3 * dr, -1e-9, a + 0.3 * da}), std::hypot(5.0 * std::atan(0.3 / 5.0) + 0.1, 0.1) - 0.1, 1e-9);
}

TEST(CompliantClip, HeldOpenOnABlockOneFrameGivesItsHardContactForce) {
    const Block b;
    const fem::ClipSpring spring = test_spring();
    const fem::ClipBlades blades;
    const fem::Linearisation lin(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {2, 3});
    // The compliance of a node on its ground spring: 1/K along each axis, nothing between the two nodes.
    EXPECT_NEAR(lin.compliance(0, 0)(0, 0), 1.0 / Block::K, 1e-12);
    EXPECT_NEAR(lin.compliance(0, 1)(1, 1), 0.0, 1e-12);
    EXPECT_THROW(lin.compliance(2, 0), InputError);
    const double touch = 2 * std::atan(Block::H / Block::A);
    for (const double held : {touch + 0.01, touch - 0.01, touch - 0.03}) {  // clear; pressing 0.02 and 0.06 mm
        const fem::CompliantFrame f = fem::solve_compliant_clip(lin, blades, spring, held, touch + 0.01);
        EXPECT_DOUBLE_EQ(f.theta, held);
        // Exact but for the rows' 10⁻⁹ constraint force mixing.
        EXPECT_NEAR(f.loads.force_n[0], block_force(held), 1e-8 * (1 + block_force(held))) << "held at " << held;
        EXPECT_NEAR(f.loads.force_n[1], block_force(held), 1e-8 * (1 + block_force(held)));
        EXPECT_NEAR(f.loads.moment_nmm[0], block_force(held) * block_lever(held), 1e-8 * (1 + block_force(held) * block_lever(held)));
        EXPECT_LE(f.complementarity_mm, 1e-10);
        // The pressed node ends on the face, no further.
        if (block_force(held) > 0) {
            const Eigen::Vector3d x = b.X.row(2).transpose() + f.candidate_u.segment<3>(0);
            EXPECT_NEAR(fem::blade_distance(blades, 1, held, x), 0.0, 1e-9);
            EXPECT_EQ(f.loads.contacts[0], 1);
        }
    }
    EXPECT_THROW(fem::solve_compliant_clip(lin, blades, spring, -0.1, 0.0), InputError);
    EXPECT_THROW(fem::Linearisation(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {2, 2}), InputError);
    EXPECT_THROW(fem::Linearisation(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(11), {2}), InputError);
}

TEST(CompliantClip, ReleasedOnABlockTheFramesStopAtTheAnalyticAngle) {
    const Block b;
    const fem::ClipSpring spring = test_spring();
    const fem::ClipBlades blades;
    const fem::Linearisation lin(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {2, 3});
    // The balance τ(θ) = F(θ) r(θ), by bisection between closed and touching.
    double lo = 0, hi = 2 * std::atan(Block::H / Block::A);
    auto residual = [&](double th) { return spring.torque(th) - block_force(th) * block_lever(th); };
    ASSERT_LT(residual(lo), 0);
    ASSERT_GT(residual(hi), 0);
    for (int it = 0; it < 200; ++it) (residual(0.5 * (lo + hi)) < 0 ? lo : hi) = 0.5 * (lo + hi);
    const double expected = 0.5 * (lo + hi);
    // Released at 40°: each frame closes at most 0.02 rad and linearises the blades where the last one stopped.
    fem::CompliantFrame f;
    f.theta = 40 * DEG;
    int frames = 0;
    double last = 1e9;
    while (frames < 200 && std::abs(f.theta - last) > 1e-13) {
        last = f.theta;
        f = fem::solve_compliant_clip(lin, blades, spring, std::nullopt, f.theta, &f);
        ++frames;
        EXPECT_GE(last - f.theta, -1e-12);          // it only closes
        EXPECT_LE(last - f.theta, 0.02 + 1e-12);    // by at most a frame's step
    }
    EXPECT_NEAR(f.theta, expected, 1e-9) << "after " << frames << " frames";
    EXPECT_GE(frames, static_cast<int>(std::ceil((40 * DEG - expected) / 0.02)));  // no frame closed more than 0.02 rad
    EXPECT_NEAR(f.loads.moment_nmm[0], f.loads.spring_torque_nmm, 1e-8 * f.loads.spring_torque_nmm);
    EXPECT_NEAR(f.loads.moment_nmm[1], f.loads.spring_torque_nmm, 1e-8 * f.loads.spring_torque_nmm);
    // Without the block the clip closes onto its stop and stays there.
    const fem::Linearisation none(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {});
    fem::CompliantFrame g;
    g.theta = 0.05;
    for (int k = 0; k < 5; ++k) g = fem::solve_compliant_clip(none, blades, spring, std::nullopt, g.theta, &g);
    EXPECT_EQ(g.theta, 0.0);
}

namespace {

/// ClipBody's test block (2 × 1 × 1 mm, 1 MPa, 3 … 5 mm from the hinge, its far face held) released between
/// `blades` at 40°: the linearised frames reach the balance of ClipBody's barrier solve.
void frames_reach_the_barriers_balance(const fem::ClipBlades& blades) {
    const aneu::test::HeldBlock hb;
    const Eigen::MatrixX3d& X = hb.X;
    const fem::NeoHookeanSolid& solid = *hb.solid;
    const std::vector<int>& surface = hb.surface;
    const Eigen::VectorXi& fixed = hb.fixed;
    const fem::ClipSpring spring = test_spring();

    // The reference: ClipBody's barrier (d̂ = 0.01 mm) in one Newton solve, released at 40°.
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(solid.dofs() + 1);
    v0[solid.dofs()] = 40 * DEG;
    const fem::ClipContactParams cp;
    const fem::ClipBody clip(solid, X, surface, v0, blades, spring, cp);
    const fem::NewtonResult ref = fem::solve_neo_hookean(clip, fixed, {}, v0);
    const double theta_ref = ref.u[clip.theta_dof()];
    const fem::BladeLoads Lref = clip.loads(ref.u);

    // The frames: each on a linearisation at the state the last one ended at (its displacement: one back
    // substitution of the frame's forces).
    Eigen::VectorXd u = Eigen::VectorXd::Zero(solid.dofs());
    fem::CompliantFrame f;
    f.theta = 40 * DEG;
    int frames = 0;
    double step = 1e9;
    while (frames < 150 && step > 1e-10) {
        const fem::Linearisation lin(solid, X, fixed, u, surface);
        const double before = f.theta;
        f = fem::solve_compliant_clip(lin, blades, spring, std::nullopt, f.theta, &f);
        const Eigen::VectorXd next = lin.displacement(f.candidate_forces);
        step = std::max((next - u).lpNorm<Eigen::Infinity>(), std::abs(f.theta - before));
        u = next;
        ++frames;
    }
    ASSERT_LE(step, 1e-10) << "not converged in " << frames << " frames";
    EXPECT_LE(f.complementarity_mm, 1e-9);
    // The same balance: the angle within what the barrier's d̂ moves a blade 3–5 mm out (2 d̂ / 3 mm), the grip
    // within 1 %, the mean moment equal to the spring's torque.
    EXPECT_NEAR(f.theta, theta_ref, 2 * cp.gap_mm / 3.0) << "compliant " << f.theta / DEG << "°, barrier " << theta_ref / DEG << "°";
    EXPECT_NEAR(f.loads.force_n[0], Lref.force_n[0], 0.01 * Lref.force_n[0]);
    EXPECT_NEAR(f.loads.force_n[1], Lref.force_n[1], 0.01 * Lref.force_n[1]);
    EXPECT_NEAR(0.5 * (f.loads.moment_nmm[0] + f.loads.moment_nmm[1]), f.loads.spring_torque_nmm, 1e-6 * f.loads.spring_torque_nmm);
    EXPECT_GT(f.loads.contacts[0], 3);
    // The displacement: within 2 d̂ of the barrier's everywhere; no node through a blade by more than the sweeps' tolerance.
    EXPECT_LE((u - ref.u.head(solid.dofs())).lpNorm<Eigen::Infinity>(), 2 * cp.gap_mm + 2 * std::abs(f.theta - theta_ref) * 5.0);
    for (int node : surface) {
        const Eigen::Vector3d x = X.row(node).transpose() + u.segment<3>(3 * node);
        for (int s : {1, -1}) {
            const double d = fem::blade_distance(blades, s, f.theta, x);
            EXPECT_GT(d, -1e-6) << "node " << node << ", blade " << s;
        }
    }
}

}  // namespace

TEST(CompliantClip, LinearisedFramesOnANeoHookeanBlockReachTheBarrierSolvesBalance) {
    fem::ClipBlades blades;  // 2 mm wide: the block's 1 mm face lies within them
    blades.width_mm = 2.0;
    frames_reach_the_barriers_balance(blades);
}

TEST(CompliantClip, OnCurvedBladesTheFramesReachTheBarrierSolvesBalanceToo) {
    // Blades curved from 2 mm at a radius of 8 mm (towards +z): over the block (3 … 5 mm out) their centre line moves
    // 0.06 … 0.58 mm across it, so the block's far corner (z = −0.5) lies beside their rounded side edge, the rest
    // under the face. (Tighter, at 6 mm and less, the block is squeezed sideways off the edge and ClipBody's one
    // Newton solve from 40° needs more than its 30 iterations a step.)
    fem::ClipBlades blades;
    blades.width_mm = 2.0;
    blades.curve_radius_mm = 8.0;
    blades.curve_from_mm = 2.0;
    frames_reach_the_barriers_balance(blades);
}

namespace {

/// A tube (radii 1 and 1.3 mm, 4 mm long, `round` nodes round, ends held, 1 MPa, ν 0.45) between blades that close
/// across its middle from its outer diameter (theta_touch) to 0.5 mm apart (theta_end): less than its two walls
/// (0.6 mm), so the lumen closes and the inner walls press on each other. The blades hinge 100 mm away (nearly
/// parallel) and are 2 mm wide along the tube. Candidates: the outer and inner surfaces' nodes within 1.2 mm of the
/// middle; the inner faces there (F in body numbering, outward of the wall: into the lumen; `faces` in candidates').
struct BladesOnATube {
    static constexpr double FAR = 100.0, GAP_END = 0.5;
    fem::StructuredMesh m;
    fem::NeoHookeanSolid solid;
    Eigen::VectorXi fixed;
    std::vector<int> cand;
    Eigen::MatrixXi F;
    Eigen::MatrixX3i faces;
    Eigen::MatrixX3d Xc;
    fem::ClipBlades blades;
    double theta_touch = 0, theta_end = 0;

    explicit BladesOnATube(int round)
        : m(fem::tube_mesh(1.0, 1.3, 4.0, 2, round, 12)), solid(m.V, m.T, Eigen::VectorXi::Zero(m.T.rows()), {{"wall", 1.0, 0.45}}) {
        std::vector<int> fd, inner;
        for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
            const double z = m.V(i, 2), r = std::hypot(m.V(i, 0), m.V(i, 1));
            if (z < 1e-9 || z > 4.0 - 1e-9)
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
            else if (std::abs(z - 2.0) <= 1.2 && (r > 1.3 - 1e-9 || r < 1.0 + 1e-9)) cand.push_back(static_cast<int>(i));
            if (r < 1.0 + 1e-9 && std::abs(z - 2.0) <= 1.2) inner.push_back(static_cast<int>(i));
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
        F = fem::boundary_faces_in_set(m.V, m.T, Eigen::Map<Eigen::VectorXi>(inner.data(), static_cast<Eigen::Index>(inner.size())));
        std::vector<int> slot(static_cast<size_t>(m.V.rows()), -1);
        for (size_t k = 0; k < cand.size(); ++k) slot[static_cast<size_t>(cand[k])] = static_cast<int>(k);
        faces.resize(F.rows(), 3);
        for (Eigen::Index f = 0; f < F.rows(); ++f)
            for (int k = 0; k < 3; ++k) faces(f, k) = slot[static_cast<size_t>(F(f, k))];
        Xc.resize(static_cast<Eigen::Index>(cand.size()), 3);
        for (size_t k = 0; k < cand.size(); ++k) Xc.row(static_cast<Eigen::Index>(k)) = m.V.row(cand[k]);
        blades.hinge = Eigen::Vector3d(-FAR, 0.0, 2.0);  // along x (across the tube), opening along y, 2 mm wide along z
        blades.length_mm = FAR + 3.0;
        blades.width_mm = 2.0;
        theta_touch = 2 * std::asin(1.3 / FAR) + 1e-4;
        theta_end = 2 * std::asin(0.5 * GAP_END / FAR);
    }
};

}  // namespace

TEST(CompliantClip, ATubeFlattenedByTheBladesHasItsInnerWallsTouchingNotThrough) {
    // The tube between the blades (BladesOnATube, 24 nodes round) closed to 0.5 mm.
    const BladesOnATube tube(24);
    const fem::StructuredMesh& m = tube.m;
    const fem::NeoHookeanSolid& solid = tube.solid;
    const Eigen::VectorXi& fixed = tube.fixed;
    const std::vector<int>& cand = tube.cand;
    const Eigen::MatrixXi& F = tube.F;
    const Eigen::MatrixX3d& Xc = tube.Xc;
    const fem::ClipBlades& blades = tube.blades;
    fem::CompliantWalls walls;
    walls.faces = tube.faces;
    const fem::ClipSpring spring = test_spring();
    const double theta_touch = tube.theta_touch, theta_end = tube.theta_end;

    struct End {
        fem::CompliantFrame f;
        Eigen::VectorXd u;
    };
    auto run = [&](bool with_walls, bool one_face = false) {
        fem::CompliantWallSearch cp;  // pairs, close vertices and crossings carried from frame to frame
        fem::CompliantOptions opt;
        opt.wall_one_face = one_face;
        End e;
        e.u = Eigen::VectorXd::Zero(solid.dofs());
        e.f.theta = theta_touch;
        for (int frame = 0; frame < 30; ++frame) {
            const double th = theta_touch + (theta_end - theta_touch) * std::min(1.0, (frame + 1) / 20.0);
            const fem::Linearisation lin(solid, m.V, fixed, e.u, cand);
            const fem::CompliantFrame last = e.f;
            e.f = with_walls ? fem::solve_compliant_clip_walls(lin, Xc, walls.faces, cp, blades, spring, th, last.theta, frame ? &last : nullptr, opt)
                             : fem::solve_compliant_clip(lin, blades, spring, th, last.theta, frame ? &last : nullptr, opt);
            e.u = lin.displacement(e.f.candidate_forces);
        }
        return e;
    };
    // The deepest inner-wall vertex behind the opposite wall, over the whole inner surface.
    auto deepest = [&](const Eigen::VectorXd& u) {
        const std::vector<fem::SurfaceCrossing> c = fem::surface_crossings(m.V, F.leftCols(3), u, fem::ContactParams{}.exclude_rings, 0.25);
        double d = 0;
        for (const auto& x : c) d = std::max(d, x.depth_mm);
        return d;
    };
    const End without = run(false);
    EXPECT_GT(deepest(without.u), 0.05);  // the blades push the walls 0.1 mm past each other
    const End with = run(true);
    // Touching, not through: a pressed vertex ends on its face's plane to the gaps' linearisation (a micrometre, 20
    // times under the issue's 0.02 mm), none went through a face.
    EXPECT_LT(deepest(with.u), 1e-3);
    EXPECT_EQ(with.f.wall_crossings, 0);
    EXPECT_LT(with.f.wall_crossed_mm, 1e-3);  // the frame's own check of its end, rows or none
    EXPECT_GT(with.f.wall_contacts, 20);
    EXPECT_LT(std::abs(with.f.wall_min_distance_mm), 1e-3);
    // Its contact problem solved exactly, not left to the sweeps (block pivoting that cycled on pressed walls used to
    // leave gaps off by up to 0.01 mm on the sample).
    EXPECT_LE(with.f.complementarity_mm, 1e-9);
    EXPECT_GT(with.f.pivots, 0);
    // The walls carry what the blades add beyond the flattened tube's own resistance: with them the blades need half
    // again as much force to close to the same gap.
    EXPECT_GT(with.f.loads.force_n[0], 1.5 * without.f.loads.force_n[0]);
    EXPECT_NEAR(with.f.loads.force_n[0], with.f.loads.force_n[1], 0.02 * with.f.loads.force_n[0]);  // symmetric
    // One wall row per vertex (CompliantOptions::wall_one_face): touching and not through as well, on fewer rows.
    const End one = run(true, true);
    EXPECT_LT(deepest(one.u), 1e-3);
    EXPECT_EQ(one.f.wall_crossings, 0);
    EXPECT_LE(one.f.complementarity_mm, 1e-9);
    EXPECT_LT(one.f.wall_rows, with.f.wall_rows);
    EXPECT_NEAR(one.f.loads.force_n[0], with.f.loads.force_n[0], 0.02 * with.f.loads.force_n[0]);
    std::printf("tube: blade force %.4f N with the walls' contact (%d pairs pressed, %.4f N through them, %d rows; one face a vertex: %.4f N, %d rows), %.4f N without\n",
                with.f.loads.force_n[0], with.f.wall_contacts, with.f.wall_force_n, with.f.wall_rows, one.f.loads.force_n[0], one.f.wall_rows,
                without.f.loads.force_n[0]);
}

TEST(CompliantClip, FramesOnABorrowedComplianceSolveTheNewTangentsProblem) {
    // The tube flattened with the walls' contact (the test above), linearised every frame at the state reached: with
    // every linearisation making its own W, and with three in four borrowing the last one's W (only the tangent
    // factorised at the new state; each pass's end corrected on it by a back substitution). The frames solved are the
    // same problems: where they end agrees to the passes' tolerance, and so do the blades' forces.
    const BladesOnATube tube(24);
    const fem::ClipSpring spring = test_spring();
    struct End {
        fem::CompliantFrame f;
        Eigen::VectorXd u;
        int borrowed = 0, corrected = 0, most_passes = 0, unconverged = 0;
        double worst_mismatch = 0;
    };
    auto run = [&](int reuse) {
        fem::CompliantWallSearch ws;
        End e;
        e.u = Eigen::VectorXd::Zero(tube.solid.dofs());
        e.f.theta = tube.theta_touch;
        std::unique_ptr<fem::Linearisation> lin;
        int in_row = 0;
        for (int frame = 0; frame < 30; ++frame) {
            const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * std::min(1.0, (frame + 1) / 20.0);
            if (lin && in_row < reuse) {
                lin = std::make_unique<fem::Linearisation>(tube.solid, tube.m.V, tube.fixed, e.u, *lin);
                ++in_row;
                ++e.borrowed;
            } else {
                lin = std::make_unique<fem::Linearisation>(tube.solid, tube.m.V, tube.fixed, e.u, tube.cand);
                in_row = 0;
            }
            const fem::CompliantFrame last = e.f;
            e.f = fem::solve_compliant_clip_walls(*lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, last.theta, frame ? &last : nullptr);
            EXPECT_EQ(lin->borrowed(), in_row > 0);
            if (lin->borrowed()) {
                e.worst_mismatch = std::max(e.worst_mismatch, e.f.compliance_mismatch_mm);
                e.most_passes = std::max(e.most_passes, e.f.passes);
                if (e.f.passes > 3) ++e.corrected;
                if (e.f.compliance_mismatch_mm > fem::CompliantOptions{}.borrow_tolerance_mm) ++e.unconverged;
            } else {
                EXPECT_EQ(e.f.compliance_mismatch_mm, 0.0);
            }
            e.u = lin->displacement(e.f.candidate_forces);
            // A frame's end is its forces' displacement on the linearisation's own tangent, borrowed W or not.
            const Eigen::VectorXd cu = lin->candidate_displacement(e.f.candidate_forces);
            for (size_t k = 0; k < tube.cand.size(); ++k)
                EXPECT_LE((cu.segment<3>(3 * static_cast<Eigen::Index>(k)) - e.u.segment<3>(3 * tube.cand[k])).cwiseAbs().maxCoeff(), 1e-12);
            EXPECT_LE((cu - e.f.candidate_u).cwiseAbs().maxCoeff(), 1e-12);
        }
        return e;
    };
    const End own = run(0), lent = run(3);
    EXPECT_EQ(own.borrowed, 0);
    EXPECT_EQ(lent.borrowed, 22);  // frames 1-3, 5-7, ... of 30
    EXPECT_GT(lent.corrected, 0);  // W from up to three frames back is not the tangent's: passes were needed
    for (int side = 0; side < 2; ++side)
        EXPECT_NEAR(lent.f.loads.force_n[side], own.f.loads.force_n[side], 5e-3 * own.f.loads.force_n[side]);
    EXPECT_LE((lent.u - own.u).cwiseAbs().maxCoeff(), 1e-3);
    EXPECT_GT(lent.f.wall_contacts, 20);
    EXPECT_LT(lent.f.wall_crossed_mm, 1e-3);
    EXPECT_LE(lent.worst_mismatch, 1e-3);
    EXPECT_LE(lent.unconverged, 1);
    // A W from a state near the frame's: the passes converge on the tangent's frame (one pass alone is off); from one
    // far from it (0.6 of the way from rest to the flattened tube) they do not, and the frame says so (the simulator
    // then solves it again on a linearisation with its own W).
    for (const double from : {0.95, 0.6}) {
        const fem::Linearisation first(tube.solid, tube.m.V, tube.fixed, own.u * from, tube.cand);
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, own.u, first);
        EXPECT_TRUE(lin.borrowed());
        EXPECT_EQ(lin.compliance_u0(), first.u0());
        EXPECT_EQ(lin.compliance(3, 5), first.compliance(3, 5));
        EXPECT_EQ(lin.candidates(), first.candidates());
        fem::CompliantOptions opt;
        opt.geometry_passes = 1;
        opt.borrow_passes = 1;
        const fem::CompliantFrame one = fem::solve_compliant_clip(lin, tube.blades, spring, tube.theta_end, tube.theta_end, &own.f, opt);
        EXPECT_GT(one.compliance_mismatch_mm, opt.borrow_tolerance_mm);
        const fem::CompliantFrame full = fem::solve_compliant_clip(lin, tube.blades, spring, tube.theta_end, tube.theta_end, &own.f);
        if (from > 0.9) {
            EXPECT_LE(full.compliance_mismatch_mm, opt.borrow_tolerance_mm);
        } else {
            EXPECT_GT(full.compliance_mismatch_mm, 100 * opt.borrow_tolerance_mm);
        }
        std::printf("W borrowed from %.2f of the way: one pass %.3g mm off the tangent's end, %d passes %.3g mm\n", from, one.compliance_mismatch_mm, full.passes,
                    full.compliance_mismatch_mm);
    }
    // A linearisation of another body cannot lend its W.
    const Block b;
    const fem::Linearisation other(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {2, 3});
    EXPECT_THROW(fem::Linearisation(tube.solid, tube.m.V, tube.fixed, own.u, other), InputError);
    std::printf("tube walls, linearised every frame: blades %.4f / %.4f N with its own W each time, %.4f / %.4f N with %d of 30 borrowing (%d took more "
                "than 3 passes, at most %d; %d not within 1e-4 mm, worst %.2e mm); ends %.2e mm apart\n",
                own.f.loads.force_n[0], own.f.loads.force_n[1], lent.f.loads.force_n[0], lent.f.loads.force_n[1], lent.borrowed, lent.corrected,
                lent.most_passes, lent.unconverged, lent.worst_mismatch, (lent.u - own.u).cwiseAbs().maxCoeff());
}

TEST(CompliantClip, TheWallsAtAStateAreWhatAFrameEndingThereReports) {
    // fem::compliant_walls_at, for a state between a frame's start and end (aneusim's shortened frame): at the frame's
    // end it gives the frame's own walls figures, to the bit; further along the frame's step the walls come closer;
    // measured from the start, the start has gone nowhere.
    const BladesOnATube tube(24);
    const fem::ClipSpring spring = test_spring();
    fem::CompliantWallSearch ws;
    fem::CompliantFrame f, last;
    f.theta = tube.theta_touch;
    Eigen::VectorXd u = Eigen::VectorXd::Zero(tube.solid.dofs());
    std::unique_ptr<fem::Linearisation> lin;
    for (int frame = 0; frame < 20; ++frame) {
        const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * (frame + 1) / 20.0;
        lin = std::make_unique<fem::Linearisation>(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
        last = f;
        f = fem::solve_compliant_clip_walls(*lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, last.theta, frame ? &last : nullptr);
        u = lin->displacement(f.candidate_forces);
    }
    ASSERT_GT(f.wall_contacts, 0);
    const Eigen::VectorXd& start = last.candidate_u;  // where the last frame started (its warm start's end)
    const fem::CompliantWallsAt end = fem::compliant_walls_at(*lin, tube.Xc, tube.faces, ws, f.candidate_u, start);
    EXPECT_EQ(end.min_distance_mm, f.wall_min_distance_mm);
    EXPECT_EQ(end.crossed_mm, f.wall_crossed_mm);
    // With no pair or crossing taken as started past a limit, the measures from the start are the plain ones ...
    EXPECT_EQ(end.deepened_mm, end.min_distance_mm);
    EXPECT_EQ(end.deepened_crossed_mm, end.crossed_mm);
    // ... and with all of them (a limit of 0), at the start nothing has gone further through than it was.
    const fem::CompliantWallsAt at_start = fem::compliant_walls_at(*lin, tube.Xc, tube.faces, ws, start, start, {}, 0.0);
    EXPECT_GE(at_start.deepened_mm, 0.0);
    EXPECT_EQ(at_start.deepened_crossed_mm, 0.0);
    const Eigen::VectorXd further = start + 4.0 * (f.candidate_u - start);
    const fem::CompliantWallsAt past = fem::compliant_walls_at(*lin, tube.Xc, tube.faces, ws, further, start);
    EXPECT_LT(past.min_distance_mm, end.min_distance_mm);
    std::printf("walls at the frame's end %.5f mm (crossed %.5f), four times its step along %.5f mm (crossed %.5f)\n", end.min_distance_mm, end.crossed_mm,
                past.min_distance_mm, past.crossed_mm);
    EXPECT_THROW(fem::compliant_walls_at(*lin, tube.Xc, tube.faces, ws, f.candidate_u.head(6), start), InputError);
}

TEST(CompliantClip, ABorrowedComplianceOnOtherCandidatesMakesTheAddedOnesColumnsOnTheNewTangent) {
    // A refresh selects its candidates anew; borrowing only where they all were the last W's, C0024's planned clip
    // borrowed 7 of 176 times. Borrowed on other candidates, W's blocks between the old candidates are the old W's, the
    // added candidates' columns (and rows) those of the tangent the old W was made on (W is one tangent's inverse on
    // the new candidates), and the dropped candidates are gone. The frames then correct W to the new tangent.
    const BladesOnATube tube(24);
    const fem::ClipSpring spring = test_spring();
    fem::CompliantWallSearch ws;
    fem::CompliantFrame f;
    f.theta = tube.theta_touch;
    Eigen::VectorXd u = Eigen::VectorXd::Zero(tube.solid.dofs()), u_last = u;
    for (int frame = 0; frame < 16; ++frame) {  // part of the way to the flattened tube, each frame on its own W
        u_last = u;
        const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * (frame + 1) / 20.0;
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
        const fem::CompliantFrame last = f;
        f = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, last.theta, frame ? &last : nullptr);
        u = lin.displacement(f.candidate_forces);
    }
    ASSERT_GT(f.loads.force_n[0], 0.05);
    // The old W on three in four of the candidates, in the reverse order, made where the last frame started
    std::vector<int> old_cand;
    for (size_t k = tube.cand.size(); k-- > 0;)
        if (k % 4 != 1) old_cand.push_back(tube.cand[k]);
    const fem::Linearisation first(tube.solid, tube.m.V, tube.fixed, u_last, old_cand);
    const fem::Linearisation first_all(tube.solid, tube.m.V, tube.fixed, u_last, tube.cand);  // first's tangent on all
    const fem::Linearisation own(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
    const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u, tube.cand, first);
    EXPECT_TRUE(lin.borrowed());
    EXPECT_EQ(lin.candidates(), tube.cand);
    const int n = static_cast<int>(tube.cand.size());
    EXPECT_EQ(lin.added_candidates, n - static_cast<int>(old_cand.size()));
    EXPECT_GT(lin.added_candidates, 10);
    std::map<int, int> old_slot;
    for (size_t k = 0; k < old_cand.size(); ++k) old_slot[old_cand[k]] = static_cast<int>(k);
    double scale = 0, added_err = 0, asym = 0;
    for (int a = 0; a < n; ++a) scale = std::max(scale, own.compliance(a, a).cwiseAbs().maxCoeff());
    for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) {
            const auto ia = old_slot.find(tube.cand[static_cast<size_t>(a)]), ib = old_slot.find(tube.cand[static_cast<size_t>(b)]);
            if (ia != old_slot.end() && ib != old_slot.end()) {
                EXPECT_EQ(lin.compliance(a, b), first.compliance(ia->second, ib->second));  // the old W's, bit for bit
            } else {
                added_err = std::max(added_err, (lin.compliance(a, b) - first_all.compliance(a, b)).cwiseAbs().maxCoeff());
            }
            asym = std::max(asym, (lin.compliance(a, b) - lin.compliance(b, a).transpose()).cwiseAbs().maxCoeff());
        }
    EXPECT_LE(added_err, 1e-9 * scale);  // the old tangent's, as its W on all the candidates has them
    EXPECT_LE(asym, 1e-9 * scale);
    // A frame on it solves the new tangent's problem, as one on the tangent's own W does
    const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * 17 / 20.0;  // the next frame
    fem::CompliantWallSearch ws_own = ws;
    const fem::CompliantFrame next_own = fem::solve_compliant_clip_walls(own, tube.Xc, tube.faces, ws_own, tube.blades, spring, th, f.theta, &f);
    const fem::CompliantFrame next = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, f.theta, &f);
    EXPECT_LE(next.compliance_mismatch_mm, fem::CompliantOptions{}.borrow_tolerance_mm);
    for (int side = 0; side < 2; ++side) EXPECT_NEAR(next.loads.force_n[side], next_own.loads.force_n[side], 1e-3 * next_own.loads.force_n[side]);
    EXPECT_LE((next.candidate_u - next_own.candidate_u).cwiseAbs().maxCoeff(), 1e-3);
    // Fewer candidates than the lender: its blocks, nothing made
    std::vector<int> fewer(tube.cand.begin(), tube.cand.begin() + n / 2);
    const fem::Linearisation less(tube.solid, tube.m.V, tube.fixed, u, fewer, own);
    EXPECT_EQ(less.added_candidates, 0);
    EXPECT_EQ(less.candidates(), fewer);
    for (int a = 0; a < n / 2; ++a) EXPECT_EQ(less.compliance(a, n / 2 - 1 - a), own.compliance(a, n / 2 - 1 - a));
    std::printf("W borrowed on %d candidates, %d of them added: added columns %.2e of W's scale off the old tangent's; a frame on it %d passes, %.2e mm "
                "from the tangent's end; blades %.4f / %.4f N (own W %.4f / %.4f N)\n",
                n, lin.added_candidates, added_err / scale, next.passes, next.compliance_mismatch_mm, next.loads.force_n[0], next.loads.force_n[1],
                next_own.loads.force_n[0], next_own.loads.force_n[1]);
}

TEST(CompliantClip, RowKindsNameTheClipTheSideAndTheDirection) {
    for (int clip = 0; clip < 4; ++clip)
        for (int side = 0; side < 2; ++side) {
            const fem::CompliantRowKind b = fem::compliant_row_kind(fem::compliant_blade_row(clip, side));
            EXPECT_TRUE(b.blade && !b.friction && !b.wall);
            EXPECT_EQ(b.clip, clip);
            EXPECT_EQ(b.side, side);
            for (int dir = 0; dir < 2; ++dir) {
                const fem::CompliantRowKind f = fem::compliant_row_kind(fem::compliant_friction_row(clip, side, dir));
                EXPECT_TRUE(f.friction && !f.blade && !f.wall);
                EXPECT_EQ(f.clip, clip);
                EXPECT_EQ(f.side, side);
                EXPECT_EQ(f.dir, dir);
            }
        }
    // The first clip's rows as they always were: blades ±1, friction −2 − (2 side + dir); walls 2 + face.
    EXPECT_EQ(fem::compliant_blade_row(0, 0), 1);
    EXPECT_EQ(fem::compliant_blade_row(0, 1), -1);
    EXPECT_EQ(fem::compliant_friction_row(0, 1, 1), -5);
    const fem::CompliantRowKind w = fem::compliant_row_kind(2 + 17);
    EXPECT_TRUE(w.wall && !w.blade && !w.friction);
    EXPECT_EQ(w.face, 17);
}

TEST(CompliantClip, TandemClipsSideBySideFlattenTheTubeUnderBothInOneContactProblem) {
    // Two clips with 1 mm blades side by side across the tube of the test above (BladesOnATube, 24 nodes round), 0.1 mm
    // apart along it (z = 2 ∓ 0.55), both closed to 0.5 mm in the same frames (the second a further clip, held), against
    // one of them alone: a neck line spread wider than one blade is what tandem clips are for.
    const BladesOnATube tube(24);
    const fem::ClipSpring spring = test_spring();
    fem::ClipBlades a = tube.blades, b = tube.blades, far = tube.blades;
    a.width_mm = b.width_mm = far.width_mm = 1.0;
    a.hinge.z() = 2.0 - 0.55;
    b.hinge.z() = 2.0 + 0.55;
    far.hinge.z() = 50.0;  // nowhere near the tube
    struct End {
        fem::CompliantFrame f;
        Eigen::VectorXd u;
    };
    auto run = [&](const fem::ClipBlades& first, const std::vector<fem::ClipBlades>& others) {
        fem::CompliantWallSearch ws;
        // One wall row a vertex, as aneusim's patch frames: with every face a vertex lies over as a row, the flattened
        // band under both clips (500 rows) made the LCP so nearly degenerate that block pivoting took thousands of
        // single flips and did not finish in 5,000 (with one face: at most 14).
        fem::CompliantOptions opt;
        opt.wall_one_face = true;
        End e;
        e.u = Eigen::VectorXd::Zero(tube.solid.dofs());
        e.f.theta = tube.theta_touch;
        for (int frame = 0; frame < 24; ++frame) {
            const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * std::min(1.0, (frame + 1) / 16.0);
            std::vector<fem::CompliantClip> more;
            for (const fem::ClipBlades& o : others) {
                fem::CompliantClip c;
                c.blades = o;
                c.theta = th;
                c.theta_start = e.f.theta;
                more.push_back(c);
            }
            const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, e.u, tube.cand);
            const fem::CompliantFrame last = e.f;
            e.f = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, first, spring, th, last.theta, frame ? &last : nullptr, opt, nullptr, nullptr,
                                                  &more);
            e.u = lin.displacement(e.f.candidate_forces);
        }
        return e;
    };
    auto deepest = [&](const Eigen::VectorXd& u) {
        double d = 0;
        for (const auto& x : fem::surface_crossings(tube.m.V, tube.F.leftCols(3), u, 1, 0.25)) d = std::max(d, x.depth_mm);
        return d;
    };
    // Along the tube, the span of the inner-wall vertices pressed on the opposite wall.
    auto pressed_span = [&](const End& e) {
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        for (size_t i = 0; i < e.f.constraint.size(); ++i)
            if (fem::compliant_row_kind(e.f.constraint[i].second).wall && e.f.lambda[i] > 0) {
                const int k = e.f.constraint[i].first;
                const double z = tube.Xc(k, 2) + e.f.candidate_u[3 * k + 2];
                lo = std::min(lo, z);
                hi = std::max(hi, z);
            }
        return hi - lo;
    };
    const End one = run(a, {});
    const End pair = run(a, {b});
    const End swapped = run(b, {a});
    const End with_far = run(a, {far});
    ASSERT_EQ(pair.f.more_loads.size(), 1u);
    // Both clips press, alike (the pair is symmetric about z = 2, the tube's tetrahedra nearly so), and the walls under
    // both touch, not through.
    const double fa = pair.f.loads.force_n[0], fb = pair.f.more_loads[0].force_n[0];
    EXPECT_GT(fa, 0.0);
    EXPECT_NEAR(fb, fa, 0.02 * fa);
    EXPECT_NEAR(pair.f.more_loads[0].force_n[1], fb, 0.02 * fb);
    EXPECT_GT(pair.f.more_loads[0].contacts[0], 0);
    EXPECT_NEAR(pair.f.more_loads[0].opening_rad, tube.theta_end, 1e-15);
    EXPECT_LT(deepest(pair.u), 1e-3);
    EXPECT_LE(pair.f.complementarity_mm, 1e-9);
    // Which of the two is the first clip does not matter.
    EXPECT_NEAR(swapped.f.loads.force_n[0], fb, 1e-3 * fb);
    EXPECT_NEAR(swapped.f.more_loads[0].force_n[0], fa, 1e-3 * fa);
    // The second clip flattens the tube over its own width too: the pressed walls span its offset further.
    const double span_one = pressed_span(one), span_pair = pressed_span(pair);
    EXPECT_GT(span_pair, span_one + 0.8);
    // Together they push harder than one alone (a wider band flattened).
    EXPECT_GT(fa + fb, one.f.loads.force_n[0]);
    // A further clip that reaches nothing leaves the frame the single clip's, to the bit, with loads of zero.
    EXPECT_EQ(with_far.f.loads.force_n[0], one.f.loads.force_n[0]);
    EXPECT_EQ(with_far.f.loads.moment_nmm[1], one.f.loads.moment_nmm[1]);
    EXPECT_EQ(with_far.u, one.u);
    EXPECT_EQ(with_far.f.more_loads[0].contacts[0] + with_far.f.more_loads[0].contacts[1], 0);
    EXPECT_EQ(with_far.f.more_loads[0].force_n[0], 0.0);
    // With blade friction, each clip's pressed nodes get their own friction rows (held where they stood on its blades).
    {
        fem::CompliantOptions fo;
        fo.wall_one_face = true;
        fo.blade_friction = 0.3;
        std::vector<fem::CompliantClip> more(1);
        more[0].blades = b;
        more[0].theta = more[0].theta_start = tube.theta_end;
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, pair.u, tube.cand);
        fem::CompliantWallSearch ws;
        const fem::CompliantFrame g =
            fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, a, spring, tube.theta_end, tube.theta_end, &pair.f, fo, nullptr, nullptr, &more);
        std::array<int, 2> rows{0, 0};
        for (const auto& c : g.constraint)
            if (const fem::CompliantRowKind k = fem::compliant_row_kind(c.second); k.friction) ++rows[static_cast<size_t>(k.clip)];
        EXPECT_GT(rows[0], 0);
        EXPECT_GT(rows[1], 0);
        EXPECT_LE(g.complementarity_mm, 1e-6);
        EXPECT_NEAR(g.more_loads[0].force_n[0], fb, 0.05 * fb);  // held where it was: about the same grip
    }
    // The setup for both: a node near either clip's wedge, once.
    Eigen::MatrixX3d x = tube.m.V;
    std::vector<int> reach;
    for (Eigen::Index i = 0; i < x.rows(); ++i) reach.push_back(static_cast<int>(i));
    Eigen::MatrixX3i inner = tube.F.leftCols(3);
    std::vector<fem::CompliantClip> both(2);
    both[0].blades = a;
    both[1].blades = b;
    both[0].theta = both[1].theta = tube.theta_touch;
    const fem::CompliantSetup sa = fem::compliant_setup(a, tube.theta_touch, x, reach, inner, 0.0), sb = fem::compliant_setup(b, tube.theta_touch, x, reach, inner, 0.0);
    const fem::CompliantSetup sab = fem::compliant_setup(both, x, reach, inner, 0.0);
    std::vector<int> want(sa.candidates.begin(), sa.candidates.begin() + static_cast<long>(sa.blade_candidates));
    want.insert(want.end(), sb.candidates.begin(), sb.candidates.begin() + static_cast<long>(sb.blade_candidates));
    std::sort(want.begin(), want.end());
    want.erase(std::unique(want.begin(), want.end()), want.end());
    std::vector<int> got(sab.candidates.begin(), sab.candidates.begin() + static_cast<long>(sab.blade_candidates));
    std::sort(got.begin(), got.end());
    EXPECT_EQ(got, want);
    EXPECT_GT(sab.blade_candidates, std::max(sa.blade_candidates, sb.blade_candidates));
    EXPECT_GE(sab.faces.rows(), std::max(sa.faces.rows(), sb.faces.rows()));
    EXPECT_THROW(fem::compliant_setup(std::vector<fem::CompliantClip>{}, x, reach, inner), InputError);
    // A further clip's opening below 0 is refused.
    {
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, Eigen::VectorXd::Zero(tube.solid.dofs()), tube.cand);
        std::vector<fem::CompliantClip> bad(1);
        bad[0].blades = b;
        bad[0].theta = -0.1;
        EXPECT_THROW(fem::solve_compliant_clip(lin, a, spring, tube.theta_touch, tube.theta_touch, nullptr, {}, nullptr, nullptr, &bad), InputError);
    }
    std::printf("tandem 1 mm clips on the tube: %.4f + %.4f N (swapped %.4f + %.4f), one alone %.4f N; pressed walls span %.3f mm (one: %.3f)\n", fa, fb,
                swapped.f.loads.force_n[0], swapped.f.more_loads[0].force_n[0], one.f.loads.force_n[0], span_pair, span_one);
}

namespace {

/// The tube (BladesOnATube, 24 nodes round) closed without the walls' contact until its walls are at least
/// `through_mm` through each other, then held there five frames with it, the frames' crease limit `limit_mm`
/// (CompliantOptions::wall_through_mm). Where it started, and how deep the walls end through each other with the frame
/// that ended.
struct HeldThrough {
    double start_mm = 0, end_mm = 0;
    fem::CompliantFrame f;
};
HeldThrough hold_tube_through(double through_mm, double limit_mm) {
    const BladesOnATube tube(24);
    const fem::ClipSpring spring = test_spring();
    auto deepest = [&](const Eigen::VectorXd& u) {
        double d = 0;
        for (const auto& x : fem::surface_crossings(tube.m.V, tube.F.leftCols(3), u, 1, 0.25)) d = std::max(d, x.depth_mm);
        return d;
    };
    Eigen::VectorXd u0 = Eigen::VectorXd::Zero(tube.solid.dofs());
    fem::CompliantFrame f0;
    f0.theta = tube.theta_touch;
    double th = tube.theta_touch;
    for (int frame = 0; frame < 40 && deepest(u0) < through_mm; ++frame) {
        th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * (frame + 1) / 40.0;
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u0, tube.cand);
        const fem::CompliantFrame last = f0;
        f0 = fem::solve_compliant_clip(lin, tube.blades, spring, th, last.theta, frame ? &last : nullptr);
        u0 = lin.displacement(f0.candidate_forces);
    }
    HeldThrough out;
    out.start_mm = deepest(u0);
    fem::CompliantOptions opt;
    opt.wall_through_mm = limit_mm;
    fem::CompliantWallSearch ws;
    Eigen::VectorXd u = u0;
    out.f = f0;
    for (int frame = 0; frame < 5; ++frame) {
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
        const fem::CompliantFrame last = out.f;
        out.f = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, last.theta, &last, opt);
        u = lin.displacement(out.f.candidate_forces);
    }
    out.end_mm = deepest(u);
    return out;
}

}  // namespace

TEST(CompliantClip, WallsThatStartAFrameALittleThroughEachOtherArePushedBackOutNotTakenForACrease) {
    // Closed until its walls are 0.01-0.05 mm through each other (as C0024's crept 0.004 -> 0.022 mm, session 46). The
    // walls were not through each other at rest: the frames push them back out. With the old rule (every vertex more
    // than wall_behind_mm behind its face's plane where the frame starts is a crease) the crossing stays.
    const HeldThrough with = hold_tube_through(0.01, fem::CompliantOptions{}.wall_through_mm);
    ASSERT_GT(with.start_mm, 0.01);
    ASSERT_LT(with.start_mm, 0.05);
    EXPECT_LT(with.end_mm, 1e-3) << "started " << with.start_mm << " mm through";
    EXPECT_LT(with.f.wall_crossed_mm, 1e-3);
    EXPECT_GT(with.f.wall_contacts, 0);
    EXPECT_LE(with.f.complementarity_mm, 1e-9);
    const double kept = hold_tube_through(0.01, 0.0).end_mm;
    EXPECT_GT(kept, 0.5 * with.start_mm) << "the old rule kept the crossing";
    std::printf("tube walls %.4f mm through each other: %.5f mm after five frames with the walls' contact (%.4f mm with every start crossing a crease)\n",
                with.start_mm, with.end_mm, kept);
}

TEST(CompliantClip, WallsThatStartAFrameDeeperThroughEachOtherThanSession46sLimitArePushedBackOutToo) {
    // Closed until its walls are more than 0.05 mm through each other (session 59: C0001's vertex slid 0.23 mm under a
    // face in one frame, and from the next frame on was a crease at session 46's 0.05 mm limit). Within the frames'
    // crossing depth (0.25 mm) the frames push it back out; with the 0.05 mm limit the vertices within it are pushed
    // out and the deeper stay (0.088 -> 0.030 mm).
    const HeldThrough with = hold_tube_through(0.06, fem::CompliantOptions{}.wall_through_mm);
    ASSERT_GT(with.start_mm, 0.05);
    ASSERT_LT(with.start_mm, 0.25);
    EXPECT_LT(with.end_mm, 1e-3) << "started " << with.start_mm << " mm through";
    EXPECT_LT(with.f.wall_crossed_mm, 1e-3);
    EXPECT_GT(with.f.wall_contacts, 0);
    const HeldThrough old = hold_tube_through(0.06, 0.05);
    EXPECT_GT(old.end_mm, 0.02) << "the 0.05 mm limit kept the deeper crossings (the issue's limit 0.02 mm)";
    std::printf("tube walls %.4f mm through each other: %.5f mm after five frames (%.4f mm with session 46's 0.05 mm limit)\n", with.start_mm, with.end_mm,
                old.end_mm);
}

TEST(CompliantClip, HeldOnOneLinearisationAVertexOverAnEdgeKeepsItsFaceAndThePassesSettle) {
    // The flattened tube of the test above with 23 nodes round (not 24): the two walls' nodes are not mirror images,
    // so pressed vertices lie over edges between faces of the opposite wall that are not coplanar. Closed to 0.5 mm
    // over 20 frames and held for 10 (relinearised each), then held on one linearisation frame after frame from the last one's end:
    // the geometry passes settle (the candidates move less than 1000 x the tolerance between two), because a vertex
    // keeps the face its row had before while that face is still among its nearest. (Taking the face its projection
    // lies deepest inside in every pass, some vertices switched faces in every pass and moved back and forth along
    // the two planes: 3 passes, the most, in every held frame. The sample's held clip did the same, 6 µm a pass.)
    const BladesOnATube tube(23);
    const fem::ClipSpring spring = test_spring();
    fem::CompliantWallSearch ws;
    fem::CompliantOptions opt;
    opt.wall_one_face = true;
    Eigen::VectorXd u = Eigen::VectorXd::Zero(tube.solid.dofs());
    fem::CompliantFrame f;
    f.theta = tube.theta_touch;
    for (int frame = 0; frame < 30; ++frame) {
        const double th = tube.theta_touch + (tube.theta_end - tube.theta_touch) * std::min(1.0, (frame + 1) / 20.0);
        const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
        const fem::CompliantFrame last = f;
        f = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, tube.blades, spring, th, last.theta, frame ? &last : nullptr, opt);
        u = lin.displacement(f.candidate_forces);
    }
    ASSERT_GT(f.wall_contacts, 20);
    const fem::Linearisation lin(tube.solid, tube.m.V, tube.fixed, u, tube.cand);
    std::vector<int> passes;
    for (int frame = 0; frame < 4; ++frame) {
        const fem::CompliantFrame last = f;
        f = fem::solve_compliant_clip_walls(lin, tube.Xc, tube.faces, ws, tube.blades, spring, tube.theta_end, last.theta, &last, opt);
        passes.push_back(f.passes);
    }
    EXPECT_LT(passes.back(), opt.geometry_passes) << "the passes did not settle";
    EXPECT_EQ(f.wall_crossings, 0);
    EXPECT_LE(f.complementarity_mm, 1e-9);
    std::printf("held on one linearisation: passes");
    for (int p : passes) std::printf(" %d", p);
    std::printf("\n");
}

namespace {

/// A wall vertex over a crease of the opposite wall (CompliantOptions::wall_one_face's rows), the vertex's own body
/// pushing it through: block B (1 × 1 × 1 mm, its bottom held) whose top is creased along z at x = 0.5 (y = c |x − 0.5|:
/// c > 0 a valley, c < 0 a ridge) and a 0.2 mm cube A (its top held) whose bottom corner v stands 5 µm above where
/// the test puts it. A is linearised squeezed 0.1 mm (its bottom moved by `squeeze` from rest): its free step takes v
/// back by −squeeze, through B's faces unless a row holds it. Faces f (x ≤ 0.5) and g (x ≥ 0.5) of B's top share the
/// crease's edge; their normals point up, out of B. The blades stand far off.
/// Block B (1 × 1 × 1 mm, 2 × 2 × 2 elements, its bottom held) moved down by `drop`, its top nodes raised by
/// rise(x, z), and a 0.2 mm cube A (its top held) whose corner (0, 0, 0) is v, at v_at less the squeeze (its rest
/// place: A overlaps B there, as far as the squeeze); u0 moves A's bottom layer back by the squeeze from where it
/// rests, so a linearisation at u0 has its free step take v back by −squeeze. Neo-Hookean, 1 MPa, ν 0.45.
struct BlockUnderACube {
    fem::StructuredMesh b, a;
    Eigen::MatrixX3d X;
    Eigen::MatrixXi T;
    Eigen::VectorXi fixed;
    Eigen::VectorXd u0;
    int v = -1;
    std::vector<int> top;  // B's top nodes
    BlockUnderACube(double drop, const std::function<double(double, double)>& rise, const Eigen::Vector3d& v_at, const Eigen::Vector3d& squeeze)
        : b(fem::box_mesh(1.0, 1.0, 1.0, 2, 2, 2)), a(fem::box_mesh(0.2, 0.2, 0.2, 1, 1, 1)) {
        const Eigen::Index nb = b.V.rows();
        X.resize(nb + a.V.rows(), 3);
        X.topRows(nb) = b.V;
        for (Eigen::Index i = 0; i < nb; ++i) {
            X(i, 1) -= drop;
            if (b.V(i, 1) > 1.0 - 1e-9) {
                X(i, 1) += rise(b.V(i, 0), b.V(i, 2));
                top.push_back(static_cast<int>(i));
            }
        }
        const Eigen::RowVector3d at = (v_at - squeeze).transpose();
        for (Eigen::Index i = 0; i < a.V.rows(); ++i) X.row(nb + i) = a.V.row(i) + at;
        T.resize(b.T.rows() + a.T.rows(), 4);
        T.topRows(b.T.rows()) = b.T;
        T.bottomRows(a.T.rows()) = a.T.array() + static_cast<int>(nb);
        std::vector<int> fd;
        u0 = Eigen::VectorXd::Zero(3 * X.rows());
        for (Eigen::Index i = 0; i < X.rows(); ++i) {
            const bool in_a = i >= nb;
            const double y0 = in_a ? a.V(i - nb, 1) : b.V(i, 1);
            if ((!in_a && y0 < 1e-9) || (in_a && y0 > 0.2 - 1e-9))
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
            else if (in_a)
                u0.segment<3>(3 * i) = squeeze;  // A's bottom layer moved back from where it rests
            if (in_a && (a.V.row(i - nb)).norm() < 1e-12) v = static_cast<int>(i);
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    }
};

struct VertexOverACrease {
    Eigen::MatrixX3d X;
    std::unique_ptr<fem::NeoHookeanSolid> solid;
    Eigen::VectorXi fixed;
    std::vector<int> cand;  // v, then B's top nodes
    Eigen::MatrixX3i faces; // f, g in candidate numbering
    Eigen::VectorXd u0;
    Eigen::MatrixX3d Xc;
    fem::ClipBlades blades;
    VertexOverACrease(double crease, const Eigen::Vector3d& v_at, const Eigen::Vector3d& squeeze) {
        const BlockUnderACube bc(1.0, [&](double x, double) { return crease * std::abs(x - 0.5); }, v_at, squeeze);
        const fem::StructuredMesh& b = bc.b;
        const Eigen::Index nb = b.V.rows();
        X = bc.X;
        solid = std::make_unique<fem::NeoHookeanSolid>(X, bc.T, Eigen::VectorXi::Zero(bc.T.rows()), std::vector<Material>{Material{"wall", 1.0, 0.45}});
        fixed = bc.fixed;
        u0 = bc.u0;
        const int v = bc.v;
        cand.push_back(v);
        auto node = [&](double x, double z) {  // B's top node at (x, z), as a candidate
            for (Eigen::Index i = 0; i < nb; ++i)
                if (b.V(i, 1) > 1.0 - 1e-9 && std::abs(b.V(i, 0) - x) < 1e-9 && std::abs(b.V(i, 2) - z) < 1e-9) {
                    cand.push_back(static_cast<int>(i));
                    return static_cast<int>(cand.size() - 1);
                }
            return -1;
        };
        const int f0 = node(0.0, 0.0), fe0 = node(0.5, 0.0), fe1 = node(0.5, 1.0), g0 = node(1.0, 0.0);
        faces.resize(2, 3);
        faces << f0, fe1, fe0,   // (b − a) × (c − a) up
            fe0, fe1, g0;
        Xc.resize(static_cast<Eigen::Index>(cand.size()), 3);
        for (size_t k = 0; k < cand.size(); ++k) Xc.row(static_cast<Eigen::Index>(k)) = X.row(cand[k]);
        blades.hinge = Eigen::Vector3d(-50.0, 0.0, 0.5);
        blades.length_mm = 3.0;
    }
    /// The frame from v's rows in a warm frame that ended where A was linearised.
    fem::CompliantFrame frame(const std::vector<int>& warm_faces, const std::vector<std::array<int, 2>>& pairs) const {
        const fem::Linearisation lin(*solid, X, fixed, u0, cand);
        fem::CompliantFrame warm;
        warm.theta = 0.5;
        warm.candidate_u = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(cand.size()));
        for (size_t k = 0; k < cand.size(); ++k) warm.candidate_u.segment<3>(3 * static_cast<Eigen::Index>(k)) = u0.segment<3>(3 * cand[k]);
        warm.candidate_forces = Eigen::VectorXd::Zero(warm.candidate_u.size());
        for (int f : warm_faces) {
            warm.constraint.emplace_back(0, 2 + f);
            warm.lambda.push_back(0.01);
        }
        fem::CompliantWalls walls;
        walls.faces = faces;
        walls.pairs = pairs;
        fem::CompliantOptions opt;
        opt.wall_one_face = true;
        return fem::solve_compliant_clip(lin, blades, test_spring(), 0.5, 0.5, &warm, opt, &walls);
    }
};

int wall_rows_of_v(const fem::CompliantFrame& f) {
    int n = 0;
    for (const auto& c : f.constraint) n += c.first == 0 && c.second >= 2;
    return n;
}

}  // namespace

TEST(CompliantClip, AVertexSlidPastItsFacesEdgeKeepsItsRowAndAValleysTwoSidesBothHoldIt) {
    // The sample's held clip (session 44, ANEU_WALL_TRACE): a pressed vertex slid along its face within a pass and
    // ended 0.12-0.24 of the face beyond its edge, over none of its pairs' faces within the tenth that makes a row
    // (the wedge over a ridge); the next pass had no row on it and took it 0.04-0.17 mm back through the face.
    const double y5 = 0.005;
    {
        // A ridge (c = −0.3), v 0.1 mm beyond face f's edge (0.2 of f's 0.5 mm), 5 µm above f's plane, pushed down
        // 0.1 mm. With f its row in the last pass, the row holds it (hysteresis to 0.5); without, it goes through.
        const Eigen::Vector3d at(0.6, 0.3 * 0.1 + y5, 0.5 - 0.1);  // f's plane rises on beyond the ridge
        const VertexOverACrease c(-0.3, at, Eigen::Vector3d(0, 0.1, 0));
        // v's distance from f's plane where the frame ends (beyond the tenth, the frames' measure leaves it out)
        const fem::Linearisation lin(*c.solid, c.X, c.fixed, c.u0, c.cand);
        auto from_f = [&](const fem::CompliantFrame& f) {  // f's plane where its corners end
            const Eigen::VectorXd ud = lin.displacement(f.candidate_forces);
            auto x = [&](int k) { return Eigen::Vector3d(c.X.row(c.cand[static_cast<size_t>(k)]).transpose() + ud.segment<3>(3 * c.cand[static_cast<size_t>(k)])); };
            const Eigen::Vector3d a = x(c.faces(0, 0)), n = (x(c.faces(0, 1)) - a).cross(x(c.faces(0, 2)) - a).normalized();
            return n.dot(x(0) - a);
        };
        const fem::CompliantFrame kept = c.frame({0}, {{0, 0}});
        EXPECT_EQ(wall_rows_of_v(kept), 1);
        EXPECT_GT(from_f(kept), -1e-3);
        EXPECT_GT(kept.wall_contacts, 0);
        const fem::CompliantFrame fresh = c.frame({}, {{0, 0}});  // not its row before: beyond the tenth, no row
        EXPECT_EQ(wall_rows_of_v(fresh), 0);
        EXPECT_LT(from_f(fresh), -0.02);
        std::printf("ridge: v %.5f mm from f's plane with its row kept, %.4f mm without\n", from_f(kept), from_f(fresh));
    }
    {
        // A valley (c = 0.3, the normals 33° apart), v 0.02 mm on g's side of the crease, 5 µm above g, pushed down
        // and towards f. Rows on both faces in the last pass: both stay (one row would let it through the other face).
        const Eigen::Vector3d at(0.52, 0.3 * 0.02 + y5, 0.5);
        const VertexOverACrease c(0.3, at, Eigen::Vector3d(0.08, 0.08, 0));
        const fem::CompliantFrame both = c.frame({0, 1}, {{0, 0}, {0, 1}});
        EXPECT_EQ(wall_rows_of_v(both), 2);
        EXPECT_GT(both.wall_min_distance_mm, -1e-3);
        EXPECT_GT(both.wall_contacts, 0);
        // From a row on g alone: it keeps g's and slides along g through f in the first pass; the next takes f's row
        // too (v behind f, over it) and the frame ends with v out of both.
        const fem::CompliantFrame one = c.frame({1}, {{0, 0}, {0, 1}});
        EXPECT_EQ(wall_rows_of_v(one), 2);
        EXPECT_GT(one.wall_min_distance_mm, -1e-3);
        std::printf("valley: v held %.5f mm from the nearer face with %d rows; from g's row alone %.5f mm, %d rows\n", both.wall_min_distance_mm,
                    wall_rows_of_v(both), one.wall_min_distance_mm, wall_rows_of_v(one));
    }
}

namespace {

/// The box-constrained LCP's solution by enumeration: each row at its lower bound, free, or at its upper bound; the
/// one assignment whose solve keeps the free rows within their bounds and the bounded rows' w of the right sign.
Eigen::VectorXd box_lcp_by_enumeration(const Eigen::MatrixXd& A, const Eigen::VectorXd& q, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi) {
    const int n = static_cast<int>(q.size());
    int states = 1;
    for (int i = 0; i < n; ++i) states *= 3;
    for (int code = 0; code < states; ++code) {
        std::vector<int> st(static_cast<size_t>(n));
        bool usable = true;
        for (int i = 0, c = code; i < n; ++i, c /= 3) {
            st[static_cast<size_t>(i)] = c % 3;  // 0 at lo, 1 free, 2 at hi
            if ((c % 3 == 0 && !std::isfinite(lo[i])) || (c % 3 == 2 && !std::isfinite(hi[i]))) usable = false;
        }
        if (!usable) continue;
        Eigen::VectorXd z = Eigen::VectorXd::Zero(n), rhs = -q;
        std::vector<int> F;
        for (int i = 0; i < n; ++i) {
            if (st[static_cast<size_t>(i)] == 1) {
                F.push_back(i);
                continue;
            }
            z[i] = st[static_cast<size_t>(i)] == 0 ? lo[i] : hi[i];
            rhs -= z[i] * A.col(i);
        }
        if (!F.empty()) {
            Eigen::MatrixXd Af(F.size(), F.size());
            Eigen::VectorXd bf(F.size());
            for (size_t a = 0; a < F.size(); ++a) {
                bf[static_cast<Eigen::Index>(a)] = rhs[F[a]];
                for (size_t c = 0; c < F.size(); ++c) Af(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(c)) = A(F[a], F[c]);
            }
            const Eigen::VectorXd zf = Af.llt().solve(bf);
            for (size_t a = 0; a < F.size(); ++a) z[F[a]] = zf[static_cast<Eigen::Index>(a)];
        }
        const Eigen::VectorXd w = q + A * z;
        bool ok = true;
        for (int i = 0; i < n && ok; ++i) {
            const int s = st[static_cast<size_t>(i)];
            if (s == 1) ok = z[i] >= lo[i] - 1e-12 && z[i] <= hi[i] + 1e-12;
            else ok = s == 0 ? w[i] >= -1e-12 : w[i] <= 1e-12;
        }
        if (ok) return z;
    }
    return Eigen::VectorXd();
}

/// The plain LCP's (z ≥ 0, w ≥ 0, zᵀ w = 0): the box [0, ∞).
Eigen::VectorXd lcp_by_enumeration(const Eigen::MatrixXd& A, const Eigen::VectorXd& q) {
    return box_lcp_by_enumeration(A, q, Eigen::VectorXd::Zero(q.size()), Eigen::VectorXd::Constant(q.size(), std::numeric_limits<double>::infinity()));
}

}  // namespace

// Flipping every wrong row at once cycles on this 3 x 3 SPD problem from the empty active set ({0} → {1, 2} → {0, 1}
// → {0} …, found by a random search); Júdice & Pires' safeguard (single flips after three solves without fewer
// wrong rows) reaches the solution, which enumeration confirms.
TEST(Lcp, BlockPivotingThatWouldCycleReachesTheSolutionBySingleFlips) {
    Eigen::MatrixXd A(3, 3);
    A << 62.5, -50, -23, -50, 62.5, 45, -23, 45, 41.5;
    const Eigen::Vector3d q(-4, 3, 1);
    const Eigen::VectorXd ref = lcp_by_enumeration(A, q);
    ASSERT_EQ(ref.size(), 3);
    Eigen::VectorXd z = Eigen::VectorXd::Zero(3);
    fem::LcpOptions o;
    o.max_sweeps = 0;  // pivoting from the empty set
    o.accept = 1e-300; // no sweeps after it either: the pivoting alone must find it
    const fem::LcpResult r = fem::solve_lcp(A, q, z, o);
    EXPECT_GE(r.single_pivots, 1);
    EXPECT_LE(r.violation, 1e-12);
    EXPECT_LE((z - ref).norm(), 1e-12 * ref.norm());
    // Without the safeguard's single flips (too few solves allowed to reach them) it does not: the sweeps after it
    // only approach the solution.
    Eigen::VectorXd z3 = Eigen::VectorXd::Zero(3);
    o.max_pivots = 3;
    o.accept = 1e-4;
    const fem::LcpResult r3 = fem::solve_lcp(A, q, z3, o);
    EXPECT_EQ(r3.single_pivots, 0);
    EXPECT_GT(r3.sweeps, 0);
}

// Random SPD problems (including nearly redundant rows: two of them almost equal, as a vertex pressed on two faces of
// an edge) against enumeration, from a zero and from a perturbed warm start.
TEST(Lcp, RandomProblemsWithNearlyRedundantRowsMatchEnumeration) {
    std::srand(11);
    auto rnd = [] { return 2.0 * std::rand() / RAND_MAX - 1.0; };
    int solved = 0, singles = 0;
    for (int trial = 0; trial < 300; ++trial) {
        const int n = 4 + trial % 7, k = n + 2;
        Eigen::MatrixXd J(n, k);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < k; ++j) J(i, j) = rnd();
        if (trial % 2) J.row(1) = J.row(0) + 1e-6 * J.row(1);  // nearly redundant
        Eigen::MatrixXd A = J * J.transpose();
        A.diagonal().array() += 1e-9 * A.diagonal().maxCoeff();  // the frames' mixing
        Eigen::VectorXd q(n);
        for (int i = 0; i < n; ++i) q[i] = rnd();
        const Eigen::VectorXd ref = lcp_by_enumeration(A, q);
        ASSERT_EQ(ref.size(), n) << trial;
        for (int warm = 0; warm < 2; ++warm) {
            Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
            if (warm) {
                for (int i = 0; i < n; ++i) z[i] = std::max(0.0, ref[i] + 0.3 * rnd());
            }
            fem::LcpOptions o;
            o.accept = 1e-300;
            const fem::LcpResult r = fem::solve_lcp(A, q, z, o);
            EXPECT_LE(r.violation, 1e-9) << trial;
            const Eigen::VectorXd w = q + A * z;
            EXPECT_GE(z.minCoeff(), 0.0);
            EXPECT_GE(w.minCoeff(), -1e-9) << trial;
            EXPECT_LE(std::abs(z.dot(w)), 1e-9 * (1 + z.norm())) << trial;
            // The forces themselves are unique only up to the mixing where rows are nearly redundant: compare the
            // gaps (what the frames use) there, the forces elsewhere.
            if (trial % 2 == 0) {
                EXPECT_LE((z - ref).norm(), 1e-7 * (1 + ref.norm())) << trial;
            }
            EXPECT_LE((w - (q + A * ref)).norm(), 1e-7) << trial;
            solved += r.violation <= 1e-9;
            singles += r.single_pivots;
        }
    }
    EXPECT_EQ(solved, 600);
    std::printf("random LCPs: %d solved, %d single flips in all\n", solved, singles);
}

TEST(Lcp, SizesThatDoNotMatchAreRefused) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(2);
    EXPECT_THROW(fem::solve_lcp(Eigen::MatrixXd::Identity(3, 3), Eigen::VectorXd::Ones(3), z), InputError);
}

// Larger problems (40–120 rows, a third of them nearly redundant pairs), started from a perturbed solution as the
// frames start from the last frame's forces: few rows flip, so the active rows' factor is mostly updated row by row
// (appends and cut-outs, not factorised afresh); the LCP's conditions hold at the end (its solution is unique for an
// SPD matrix: these conditions are the check).
TEST(Lcp, LargerProblemsSolvedWithTheActiveFactorUpdatedRowByRow) {
    std::srand(5);
    auto rnd = [] { return 2.0 * std::rand() / RAND_MAX - 1.0; };
    int pivots = 0, refactors = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const int n = 40 + 2 * trial, k = n + 10;
        Eigen::MatrixXd J(n, k);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < k; ++j) J(i, j) = rnd();
        for (int i = 0; i + 1 < n / 3; i += 2) J.row(i + 1) = J.row(i) + 1e-5 * J.row(i + 1);
        Eigen::MatrixXd A = J * J.transpose();
        A.diagonal().array() += 1e-9 * A.diagonal().maxCoeff();
        Eigen::VectorXd q(n);
        for (int i = 0; i < n; ++i) q[i] = rnd();
        Eigen::VectorXd z0 = Eigen::VectorXd::Zero(n);
        fem::LcpOptions o;
        o.accept = 1e-300;
        ASSERT_LE(fem::solve_lcp(A, q, z0, o).violation, 1e-9) << trial;
        // Perturbed: a tenth of the forces moved, some of them to zero or from zero.
        Eigen::VectorXd z = z0;
        for (int i = 0; i < n; i += 10) z[i] = std::max(0.0, z[i] + 0.5 * rnd());
        o.max_sweeps = 0;
        const fem::LcpResult r = fem::solve_lcp(A, q, z, o);
        const Eigen::VectorXd w = q + A * z;
        EXPECT_LE(r.violation, 1e-9) << trial;
        EXPECT_GE(z.minCoeff(), 0.0) << trial;
        EXPECT_GE(w.minCoeff(), -1e-9) << trial;
        EXPECT_LE((w - (q + A * z0)).lpNorm<Eigen::Infinity>(), 1e-7) << trial;
        pivots += r.pivots;
        refactors += r.refactors;
    }
    std::printf("larger LCPs: %d pivoting solves, %d factorisations from scratch\n", pivots, refactors);
    EXPECT_LT(2 * refactors, pivots);
}


// Box-constrained problems (friction-like rows bounded on both sides, normal-like rows bounded below only, some
// rows fixed, lo = hi) against enumeration of the 3^n assignments, from zero and from a perturbed warm start; the
// plain LCP is the box [0, ∞) and gives the same forces through either function.
TEST(Lcp, BoxBoundedProblemsMatchEnumeration) {
    std::srand(23);
    auto rnd = [] { return 2.0 * std::rand() / RAND_MAX - 1.0; };
    const double inf = std::numeric_limits<double>::infinity();
    int with_upper = 0;
    for (int trial = 0; trial < 300; ++trial) {
        const int n = 3 + trial % 5, k = n + 2;
        Eigen::MatrixXd J(n, k);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < k; ++j) J(i, j) = rnd();
        Eigen::MatrixXd A = J * J.transpose();
        A.diagonal().array() += 1e-3 * A.diagonal().maxCoeff();
        Eigen::VectorXd q(n), lo(n), hi(n);
        for (int i = 0; i < n; ++i) {
            q[i] = rnd();
            switch ((trial + i) % 4) {
                case 0: lo[i] = 0; hi[i] = inf; break;                                     // a normal row
                case 1: hi[i] = 0.3 * std::abs(rnd()); lo[i] = -hi[i]; break;              // a friction row
                case 2: lo[i] = -inf; hi[i] = inf; break;                                  // free
                default: lo[i] = 0.1 * rnd(); hi[i] = lo[i] + 0.2 * std::abs(rnd()); break; // a box
            }
        }
        if (trial % 7 == 0) hi[0] = lo[0] = 0.05;  // a fixed row
        const Eigen::VectorXd ref = box_lcp_by_enumeration(A, q, lo, hi);
        ASSERT_EQ(ref.size(), n) << trial;
        for (int warm = 0; warm < 2; ++warm) {
            Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
            if (warm) {
                for (int i = 0; i < n; ++i) z[i] = ref[i] + 0.3 * rnd();
            }
            fem::LcpOptions o;
            o.accept = 1e-300;
            const fem::LcpResult r = fem::solve_box_lcp(A, q, lo, hi, z, o);
            EXPECT_LE(r.violation, 1e-9) << trial;
            EXPECT_LE((z - ref).norm(), 1e-8 * (1 + ref.norm())) << trial;
            EXPECT_TRUE(((z - lo).array() >= 0).all() && ((hi - z).array() >= 0).all()) << trial;
            for (int i = 0; i < n; ++i) with_upper += std::isfinite(hi[i]) && z[i] >= hi[i] ? 1 : 0;
        }
        // The plain problem both ways.
        Eigen::VectorXd z1 = Eigen::VectorXd::Zero(n), z2 = Eigen::VectorXd::Zero(n);
        fem::solve_lcp(A, q, z1);
        fem::solve_box_lcp(A, q, Eigen::VectorXd::Zero(n), Eigen::VectorXd::Constant(n, inf), z2);
        EXPECT_EQ(z1, z2) << trial;
    }
    EXPECT_GT(with_upper, 50);  // upper bounds were reached, not only lower ones
    Eigen::VectorXd z = Eigen::VectorXd::Zero(2);
    EXPECT_THROW(fem::solve_box_lcp(Eigen::MatrixXd::Identity(2, 2), Eigen::VectorXd::Ones(2), Eigen::Vector2d(1, 0), Eigen::Vector2d(0, 1), z), InputError);
}

// Blade friction on the block: a node pressed on blade +1 whose frame starts δ across the blade from where its ground
// spring holds it (the spring pulls it back with K δ). Within the friction limit μ λ_n it sticks where it started (the
// tangential force is K δ); beyond it, it slides back until the spring's pull is μ λ_n. Frictionless it goes all the way.
TEST(CompliantClip, BladeFrictionHoldsANodeWithinTheLimitAndLetsItSlideBeyond) {
    const Block b;
    const fem::ClipSpring spring = test_spring();
    const fem::ClipBlades blades;
    const fem::Linearisation lin(*b.body, b.X, b.fixed, Eigen::VectorXd::Zero(12), {2, 3});
    const double touch = 2 * std::atan(Block::H / Block::A), held = touch - 0.03;
    const fem::CompliantFrame f1 = fem::solve_compliant_clip(lin, blades, spring, held, touch + 0.01);  // closing onto it
    const double Fn = f1.loads.force_n[0];
    ASSERT_NEAR(Fn, block_force(held), 1e-8 * (1 + Fn));
    Eigen::Vector3d t, n, w;
    blades.frame(1, held, t, n, w);
    constexpr double MU = 0.3;
    for (const double ratio : {0.5, 2.0}) {  // the spring's pull over the friction limit
        const double delta = ratio * MU * Fn / Block::K;
        fem::CompliantFrame start = f1;
        start.candidate_u.segment<3>(0) += delta * w;  // node 2 starts δ across the blade
        fem::CompliantOptions o;
        o.blade_friction = MU;
        const fem::CompliantFrame f = fem::solve_compliant_clip(lin, blades, spring, held, held, &start, o);
        const double across = f.candidate_u.segment<3>(0).dot(w);
        EXPECT_NEAR(f.loads.force_n[0], Fn, 1e-6 * Fn) << ratio;  // the normal force is the frictionless one
        if (ratio < 1) {
            EXPECT_NEAR(across, delta, 1e-8) << "sticks where it started";
            EXPECT_NEAR(f.loads.friction_n[0], Block::K * delta, 1e-6 * Fn);
            EXPECT_EQ(f.loads.sliding[0], 0);
        } else {
            EXPECT_NEAR(across, delta - MU * Fn / Block::K, 1e-8) << "slides back to the limit";
            EXPECT_NEAR(f.loads.friction_n[0], MU * Fn, 1e-6 * Fn);
            EXPECT_EQ(f.loads.sliding[0], 1);
        }
        if (ratio < 1) {
            // Released there (θ free on the spring): the blades still grip. The frames settle on the spring's balance
            // with the node held across the blade where it stood (the across direction is the hinge's: the blade's
            // turn does not move a stick point across it), while the pull stays within the balance's μ λ.
            fem::CompliantFrame r = f;
            for (int k = 0; k < 40; ++k) r = fem::solve_compliant_clip(lin, blades, spring, std::nullopt, r.theta, &r, o);
            const double Fr = r.loads.force_n[0];
            ASSERT_LT(Block::K * delta, MU * Fr) << "the balance's grip is too weak for this test's pull";
            EXPECT_NEAR(r.candidate_u.segment<3>(0).dot(w), delta, 1e-8) << "released: sticks where it stood";
            // Its friction: K δ across, and along the blade what holds the node where the turned blade's normal force
            // would push it; within the limit.
            EXPECT_GE(r.loads.friction_n[0], Block::K * delta - 1e-6 * Fr);
            EXPECT_LE(r.loads.friction_n[0], MU * Fr * (1 + 1e-9));
            EXPECT_EQ(r.loads.sliding[0], 0);
            EXPECT_NEAR(r.loads.moment_nmm[0], r.loads.spring_torque_nmm, 1e-6 * r.loads.spring_torque_nmm);
        }
        o.blade_friction = 0;
        const fem::CompliantFrame g = fem::solve_compliant_clip(lin, blades, spring, held, held, &start, o);
        EXPECT_NEAR(g.candidate_u.segment<3>(0).dot(w), 0.0, 1e-8) << "frictionless: back to the spring's rest";
        EXPECT_EQ(g.loads.friction_n[0], 0.0);
    }
}

TEST(CompliantClip, BladeFrictionCellsShareTheirLimitInProportionToTheNormalForces) {
    // Three nodes on one blade, each on its own ground spring (K 20, 35, 50 N/mm), pressed at different depths (so
    // with different normal forces λ_k), start displaced across the blade by different δ_k. Per node (cells of 0 mm)
    // each sticks with force K_k δ_k or slides to μ λ_k. In one cell, the slip of the three weighted by w_k = λ_k / Λ
    // is held: the cell's force z acts on node k as z w_k, so a_k = z w_k / K_k and Σ w_k (a_k − δ_k) = 0 give
    // z = Σ w_k δ_k / Σ w_k² / K_k while |z| ≤ μ Λ, else z = ±μ Λ.
    constexpr int N = 3;
    const std::array<double, N> K{20, 35, 50}, dx{0.0, 0.2, 0.35}, dz{0.05, 0.15, 0.3};
    Eigen::MatrixX3d X(2 * N, 3);
    std::vector<Eigen::Triplet<double>> t;
    for (int k = 0; k < N; ++k) {
        X.row(k) << Block::A + dx[k], Block::H, dz[k];
        X.row(N + k) = X.row(k);
        for (int ax = 0; ax < 3; ++ax) {
            const int g = 3 * k + ax, b = 3 * (N + k) + ax;
            t.emplace_back(g, g, K[k]);
            t.emplace_back(b, b, K[k]);
            t.emplace_back(g, b, -K[k]);
            t.emplace_back(b, g, -K[k]);
        }
    }
    Eigen::SparseMatrix<double, Eigen::RowMajor> Km(6 * N, 6 * N);
    Km.setFromTriplets(t.begin(), t.end());
    const fem::LinearBody body(Km);
    Eigen::VectorXi fixed(3 * N);
    for (int i = 0; i < 3 * N; ++i) fixed[i] = i;
    const fem::Linearisation lin(body, X, fixed, Eigen::VectorXd::Zero(6 * N), {N, N + 1, N + 2});
    const fem::ClipSpring spring = test_spring();
    const fem::ClipBlades blades;
    const double held = 2 * std::atan(Block::H / (Block::A + dx[2])) - 0.03;  // all three pressed
    const fem::CompliantFrame f1 = fem::solve_compliant_clip(lin, blades, spring, held, held + 0.05);
    Eigen::Vector3d tb, nb, wb;
    blades.frame(1, held, tb, nb, wb);
    std::array<double, N> lambda{};
    double Lam = 0;
    for (int k = 0; k < N; ++k) {
        lambda[k] = f1.candidate_forces.segment<3>(3 * k).norm();
        ASSERT_GT(lambda[k], 0.1) << k;
        Lam += lambda[k];
    }
    ASSERT_GT(std::abs(lambda[0] - lambda[2]), 0.2 * Lam / N) << "the normal forces differ";
    constexpr double MU = 0.3;
    const std::array<double, N> shape{0.5, -0.2, 0.8};  // δ_k = scale × shape_k
    double sw = 0, sw2k = 0;
    for (int k = 0; k < N; ++k) {
        sw += lambda[k] / Lam * shape[k];
        sw2k += (lambda[k] / Lam) * (lambda[k] / Lam) / K[k];
    }
    for (const double ratio : {0.5, 2.0}) {  // the cell's sticking force over its limit
        const double scale = ratio * MU * Lam / (sw / sw2k);
        fem::CompliantFrame start = f1;
        for (int k = 0; k < N; ++k) start.candidate_u.segment<3>(3 * k) += scale * shape[k] * wb;
        fem::CompliantOptions o;
        o.blade_friction = MU;
        o.friction_cell_mm = 5.0;
        const fem::CompliantFrame f = fem::solve_compliant_clip(lin, blades, spring, held, held, &start, o);
        EXPECT_EQ(std::count_if(f.constraint.begin(), f.constraint.end(), [](const auto& c) { return c.second <= -2; }), 2) << "one cell, two rows";
        const double z = ratio < 1 ? scale * sw / sw2k : MU * Lam;
        for (int k = 0; k < N; ++k) {
            EXPECT_NEAR(f.candidate_u.segment<3>(3 * k).dot(wb), z * lambda[k] / Lam / K[k], 1e-8) << ratio << " node " << k;
            EXPECT_NEAR(f.candidate_u.segment<3>(3 * k).dot(tb), start.candidate_u.segment<3>(3 * k).dot(tb), 1e-8) << "no slip along the blade";
            EXPECT_LE(std::abs(f.candidate_forces.segment<3>(3 * k).dot(wb)), MU * lambda[k] * (1 + 1e-9)) << "each node within its own limit";
        }
        EXPECT_NEAR(f.loads.friction_n[0], z, 1e-6 * Lam);
        EXPECT_EQ(f.loads.sliding[0], ratio < 1 ? 0 : 1);
        // Per node: each its own stick or slide.
        o.friction_cell_mm = 0;
        const fem::CompliantFrame g = fem::solve_compliant_clip(lin, blades, spring, held, held, &start, o);
        EXPECT_EQ(std::count_if(g.constraint.begin(), g.constraint.end(), [](const auto& c) { return c.second <= -2; }), 2 * N);
        int sliding = 0;
        for (int k = 0; k < N; ++k) {
            const double delta = scale * shape[k], zk = std::clamp(K[k] * delta, -MU * lambda[k], MU * lambda[k]);
            sliding += std::abs(K[k] * delta) > MU * lambda[k];
            EXPECT_NEAR(g.candidate_u.segment<3>(3 * k).dot(wb), zk / K[k], 1e-8) << ratio << " node " << k;
        }
        EXPECT_EQ(g.loads.sliding[0], sliding);
    }
}

TEST(CompliantClip, TheLinearisationsComplianceIsItsTangentsInverseOnTheCandidates) {
    // W comes from the condensation's sparse route (a factor of its own, a forward solve, SYRK); displacement() from
    // the linearisation's factor by a full solve. On the neo-Hookean block sheared and squeezed (u0 ≠ 0: the tangent
    // is not the one at rest), every candidate's response to a unit force on any candidate is W's column.
    const aneu::test::HeldBlock hb;
    Eigen::VectorXd u0 = Eigen::VectorXd::Zero(hb.solid->dofs());
    for (Eigen::Index i = 0; i < hb.X.rows(); ++i) {
        const double s = 5.0 - hb.X(i, 0);  // 0 at the held face
        u0[3 * i + 1] = 0.15 * s * s - 0.1 * s * hb.X(i, 1);
        u0[3 * i + 2] = 0.05 * s * hb.X(i, 1);
    }
    const std::vector<int>& cand = hb.surface;
    const fem::Linearisation lin(*hb.solid, hb.X, hb.fixed, u0, cand);
    const Eigen::Index nc = static_cast<Eigen::Index>(cand.size());
    const Eigen::VectorXd base = lin.displacement(Eigen::VectorXd::Zero(3 * nc));
    double wmax = 0, err = 0;
    for (Eigen::Index b = 0; b < nc; b += 7)
        for (int ax = 0; ax < 3; ++ax) {
            Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * nc);
            f[3 * b + ax] = 1.0;
            const Eigen::VectorXd du = lin.displacement(f) - base;
            for (Eigen::Index a = 0; a < nc; ++a) {
                const Eigen::Vector3d col = lin.compliance(static_cast<int>(a), static_cast<int>(b)).col(ax);
                wmax = std::max(wmax, col.cwiseAbs().maxCoeff());
                err = std::max(err, (du.segment<3>(3 * cand[static_cast<size_t>(a)]) - col).cwiseAbs().maxCoeff());
            }
        }
    EXPECT_GT(wmax, 1e-3);
    EXPECT_LE(err, 1e-10 * wmax);
    // No force: the free state kept from the constructor's solve (no back substitution), the candidates' rows exactly
    // free_candidate_u.
    for (Eigen::Index a = 0; a < nc; ++a)
        for (int ax = 0; ax < 3; ++ax) EXPECT_EQ(base[3 * cand[static_cast<size_t>(a)] + ax], lin.free_candidate_u()[3 * a + ax]);
    // Symmetric, block by block.
    for (Eigen::Index a = 0; a < nc; a += 5)
        for (Eigen::Index b = 0; b < nc; b += 3)
            EXPECT_LE((lin.compliance(static_cast<int>(a), static_cast<int>(b)) - lin.compliance(static_cast<int>(b), static_cast<int>(a)).transpose()).cwiseAbs().maxCoeff(),
                      1e-12 * wmax);
}

TEST(CompliantClip, ALinearisationAskedToProjectFirstIsTheOneThatFellBackToTheProjectedTangent) {
    // The neo-Hookean block dilated 1.5x each way (J = 3.4 > e: its volumetric energy concave, the tangent indefinite):
    // the linearisation fails to factorise the tangent and projects the element tangents. Asked to project first, it
    // makes the same matrix without the failed attempt: the same W and free state, bit for bit. On a state whose tangent
    // is positive definite, asked to project first it projects all the same (and says so).
    const aneu::test::HeldBlock hb;
    Eigen::VectorXd u0(hb.solid->dofs());
    for (Eigen::Index i = 0; i < hb.X.rows(); ++i) u0.segment<3>(3 * i) = 0.5 * (hb.X.row(i).transpose() - Eigen::Vector3d(5.0, 0.0, 0.0));
    const std::vector<int>& cand = hb.surface;
    const fem::Linearisation fell(*hb.solid, hb.X, hb.fixed, u0, cand);
    ASSERT_TRUE(fell.projected);
    EXPECT_FALSE(fell.projected_first);
    const fem::Linearisation first(*hb.solid, hb.X, hb.fixed, u0, cand, true);
    EXPECT_TRUE(first.projected);
    EXPECT_TRUE(first.projected_first);
    const Eigen::Index nc = static_cast<Eigen::Index>(cand.size());
    EXPECT_EQ(0, std::memcmp(fell.compliance_blocks(), first.compliance_blocks(), sizeof(double) * 9 * static_cast<size_t>(nc * nc)));
    EXPECT_EQ(fell.free_candidate_u(), first.free_candidate_u());
    EXPECT_EQ(fell.free_step, first.free_step);
    // Borrowing (the tangent factorised by CHOLMOD alone): the same.
    const fem::Linearisation fell_b(*hb.solid, hb.X, hb.fixed, u0, fell), first_b(*hb.solid, hb.X, hb.fixed, u0, fell, true);
    EXPECT_TRUE(fell_b.projected && !fell_b.projected_first && first_b.projected && first_b.projected_first);
    EXPECT_EQ(fell_b.free_candidate_u(), first_b.free_candidate_u());
    // At rest the tangent is positive definite: not projected unless asked.
    const Eigen::VectorXd rest = Eigen::VectorXd::Zero(hb.solid->dofs());
    const fem::Linearisation exact(*hb.solid, hb.X, hb.fixed, rest, cand), asked(*hb.solid, hb.X, hb.fixed, rest, cand, true);
    EXPECT_FALSE(exact.projected);
    EXPECT_TRUE(asked.projected && asked.projected_first);
    double wmax = 0, dw = 0;
    for (Eigen::Index k = 0; k < 9 * nc * nc; ++k) {
        wmax = std::max(wmax, std::abs(exact.compliance_blocks()[k]));
        dw = std::max(dw, std::abs(exact.compliance_blocks()[k] - asked.compliance_blocks()[k]));
    }
    EXPECT_LE(dw, 1e-9 * wmax);  // at rest every element tangent is positive semidefinite: projecting leaves it as it is
}

TEST(CompliantClip, TheSetupTakesTheNodesNearTheJawsAndTheWallFacesBetweenThem) {
    // Hinge at the origin, axis x, up y, 7 x 1 mm blades open 0.4 rad: within 0.1 mm of the wedge a node is a blade
    // candidate; a lumen face whose three corners lie within 0.3 mm of it is a wall face, its corners candidates after.
    const fem::ClipBlades b;
    Eigen::MatrixX3d x(8, 3);
    x << 3, 0, 0,      // in the wedge
        3, 0, 2,       // 1.5 mm beside the jaws' width
        3, 0, 0.55,    // 0.05 mm beside it
        20, 0, 0,      // past the tips
        2, 0, 0.7, 2.5, 0, 0.75, 3, 0, 0.7,  // a face 0.2-0.25 mm beside the width
        20, 0, 0.1;
    Eigen::MatrixX3i inner(2, 3);
    inner << 4, 5, 6, 0, 4, 7;
    const fem::CompliantSetup s = fem::compliant_setup(b, 0.4, x, {0, 1, 2, 3, 0}, inner);
    EXPECT_EQ(s.candidates, (std::vector<int>{0, 2, 4, 5, 6}));
    EXPECT_EQ(s.blade_candidates, 2u);
    ASSERT_EQ(s.faces.rows(), 1);
    EXPECT_EQ(s.faces.row(0), Eigen::RowVector3i(2, 3, 4));
    // Closed, the wedge is the blades' thickness: the same face is still beside the width, the node in it still in.
    EXPECT_EQ(fem::compliant_setup(b, 0.0, x, {0}, inner).candidates, (std::vector<int>{0, 4, 5, 6}));
    EXPECT_THROW(fem::compliant_setup(b, 0.4, x, {9}, inner), InputError);
}

TEST(CompliantClip, TheSetupTakesTheWallsAboutToMeetPastTheTipsToo) {
    // Two 1 x 1 mm walls of a lumen 5 mm past the 7 mm blades' tips, facing each other across a gap g (session 46: C0001's
    // walls crossed 0.5 mm there, on faces no frame had). Within 0.3 mm (or a hair behind) they are wall faces, their
    // corners candidates; 0.5 mm apart, or 0.1 mm through each other (a crease), or without the approach, they are not.
    const fem::ClipBlades b;
    auto walls = [](double g) {
        Eigen::MatrixX3d x(8, 3);
        x << 12, 0, 0, 13, 0, 0, 13, 0, 1, 12, 0, 1,  // the lower wall, normal +y (into the lumen)
            12, g, 0, 13, g, 0, 13, g, 1, 12, g, 1;   // the upper, normal -y
        return x;
    };
    Eigen::MatrixX3i inner(4, 3);
    inner << 0, 3, 1, 1, 3, 2, 4, 5, 7, 5, 6, 7;
    const fem::CompliantSetup near = fem::compliant_setup(b, 0.4, walls(0.2), {}, inner);
    EXPECT_EQ(near.faces.rows(), 4);
    EXPECT_EQ(near.approach_faces, 4u);
    EXPECT_EQ(near.candidates.size(), 8u);
    EXPECT_EQ(near.blade_candidates, 0u);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(-0.02), {}, inner).faces.rows(), 4);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(0.5), {}, inner).faces.rows(), 0);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(-0.1), {}, inner).faces.rows(), 0);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(0.2), {}, inner, 0.0).faces.rows(), 0);
    // With the rest shape: walls 0.1 or 0.2 mm through each other that were 0.2 mm apart at rest came through each
    // other (session 59: C0001's vertex 0.23 mm under a face); at rest already so, they are a crease; 0.3 mm through,
    // beyond the frames' crossing depth, the far side.
    const Eigen::MatrixX3d apart = walls(0.2), through = walls(-0.1);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, through, {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &apart).faces.rows(), 4);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(-0.2), {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &apart).faces.rows(), 4);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, through, {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &through).faces.rows(), 0);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(-0.3), {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &apart).faces.rows(), 0);
    EXPECT_EQ(fem::compliant_setup(b, 0.4, walls(0.2), {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &apart).faces.rows(), 4);
    const Eigen::MatrixX3d fewer = apart.topRows(7);
    EXPECT_THROW(fem::compliant_setup(b, 0.4, through, {}, inner, fem::COMPLIANT_WALL_APPROACH_MM, Eigen::MatrixX3i(), &fewer), InputError);
    // Only the walls that meet: a third face of the lower wall 2 mm away joins only with its vertex's ring.
    Eigen::MatrixX3d x = walls(0.2);
    x.conservativeResize(10, 3);
    x.row(8) << 15, 0, 0;
    x.row(9) << 15, 0, 1;
    Eigen::MatrixX3i more(6, 3);
    more << inner, 1, 2, 8, 8, 2, 9;  // (1, 2, 8) has corners 1 and 2 of the met wall; (8, 2, 9) has corner 2
    const fem::CompliantSetup s = fem::compliant_setup(b, 0.4, x, {}, more);
    EXPECT_EQ(s.faces.rows(), 6);  // the two beside have a corner under the upper wall's vertices
    x.row(1) << 13, -0.5, 0;       // node 1 bent away from the upper wall, 0.7 mm below its faces
    x.row(2) << 13, -0.5, 1;
    const fem::CompliantSetup bent = fem::compliant_setup(b, 0.4, x, {}, more);
    EXPECT_EQ(bent.faces.rows(), 4) << "the faces with no corner near the upper wall stay out";
}

TEST(CompliantClip, FramesCarriedToAnotherCandidateSetKeepTheRowsOfTheNodesAndFacesStillKept) {
    // Candidates are body nodes 10-13, faces (10 11 12) and (10 12 13); the new set keeps 13, 12, 10 (in that order),
    // drops 11 and adds 20, its one face (10 12 13) with its corners in another order: the same face.
    const std::vector<int> from{10, 11, 12, 13}, to{13, 12, 10, 20};
    Eigen::MatrixX3i ff(2, 3), tf(1, 3);
    ff << 0, 1, 2, 0, 2, 3;
    tf << 2, 1, 0;
    fem::CompliantFrame f;
    // Rows: node 10 on blade +1, node 11 on blade -1, node 13 on face (10 12 13), node 12's friction row, node 10 on
    // face (10 11 12), node 13's friction row.
    f.constraint = {{0, 1}, {1, -1}, {3, 3}, {2, -2}, {0, 2}, {3, -5}};
    f.lambda = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6};
    f.candidate_u = Eigen::VectorXd::LinSpaced(12, 1, 12);
    f.candidate_forces = Eigen::VectorXd::LinSpaced(12, -1, -12);
    fem::CompliantWallSearch ws;
    ws.params.close_vertices = {1, 2, 3};
    ws.pairs = {{0, 1}};
    ws.searched_at = Eigen::VectorXd::Zero(12);
    ws.ended_at = Eigen::VectorXd::Zero(12);
    ws.ended_behind = {{0, 1}};
    Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * 21);
    u.segment<3>(60) << 70, 80, 90;  // node 20
    fem::carry_compliant_frames(from, ff, to, tf, u, f, ws);
    // Node 11's row and the row on face (10 11 12) are gone; the others renumbered (face (10 12 13): new face 0).
    const std::vector<std::pair<int, int>> want{{2, 1}, {0, 2}, {1, -2}, {0, -5}};
    EXPECT_EQ(f.constraint, want);
    EXPECT_EQ(f.lambda, (std::vector<double>{0.1, 0.3, 0.4, 0.6}));
    ASSERT_EQ(f.candidate_u.size(), 12);
    EXPECT_EQ(Eigen::Vector3d(f.candidate_u.segment<3>(0)), Eigen::Vector3d(10, 11, 12));  // node 13 (old 3)
    EXPECT_EQ(Eigen::Vector3d(f.candidate_u.segment<3>(3)), Eigen::Vector3d(7, 8, 9));     // node 12 (old 2)
    EXPECT_EQ(Eigen::Vector3d(f.candidate_u.segment<3>(6)), Eigen::Vector3d(1, 2, 3));     // node 10 (old 0)
    EXPECT_EQ(Eigen::Vector3d(f.candidate_u.segment<3>(9)), Eigen::Vector3d(70, 80, 90));  // node 20, new: the body's
    ASSERT_EQ(f.candidate_forces.size(), 12);
    EXPECT_EQ(Eigen::Vector3d(f.candidate_forces.segment<3>(6)), Eigen::Vector3d(-1, -2, -3));
    EXPECT_EQ(Eigen::Vector3d(f.candidate_forces.segment<3>(9)), Eigen::Vector3d::Zero());
    EXPECT_EQ(ws.params.close_vertices, (std::vector<int>{0, 1}));  // nodes 13, 12 (old 3, 2); 11 dropped
    EXPECT_TRUE(ws.pairs.empty());  // searched again at the next frame
    EXPECT_EQ(ws.searched_at.size(), 0);
    EXPECT_EQ(ws.ended_at.size(), 0);
    EXPECT_TRUE(ws.ended_behind.empty());
    // A face naming a candidate that is not there, a candidate outside the body's displacement: refused.
    Eigen::MatrixX3i bad(1, 3);
    bad << 0, 1, 4;
    EXPECT_THROW(fem::carry_compliant_frames(to, bad, to, tf, u, f, ws), InputError);
    EXPECT_THROW(fem::carry_compliant_frames(to, tf, {10, 30}, Eigen::MatrixX3i(), u, f, ws), InputError);
}

TEST(CompliantClip, TheWallSearchPairsTheTwoWallsOfATightFoldThatTwoRingsWouldLeaveOut) {
    // A strip folded flat into a U, as a clip flattens a neck to a slit: its lower wall runs back under its upper one
    // 2ρ = 0.064 mm below it, joined at the fold by a single row of cells. Each upper vertex of the first row from the
    // fold lies over a lower face, most of them over one with a corner two edges from it (through the fold). The
    // frames' wall search (one ring left out) pairs every such vertex with the face under it; ContactBody's default
    // (two rings) leaves such faces out; neither pairs a wall with its own faces. Farther from the fold both pair the
    // walls. Session 45: two rings hid C0054's walls crossing at such a fold, 0.198 mm deep.
    const double h = 0.1, rho = h / 3.14159265358979323846;
    const int K = 6, NY = 6;  // vertices per wall along x (k = 0 at the fold), across y
    Eigen::MatrixX3d X(2 * K * NY, 3);
    auto id = [&](int wall, int k, int j) { return (wall * K + k) * NY + j; };  // wall 0 upper (z = +ρ), 1 lower
    for (int w = 0; w < 2; ++w)
        for (int k = 0; k < K; ++k)
            for (int j = 0; j < NY; ++j)  // the upper wall's grid a third of a cell off the lower's: over its faces
                X.row(id(w, k, j)) << k * h - (w == 0 ? h / 3 : 0.0), j * h + (w == 0 ? h / 3 : 0.0), w == 0 ? rho : -rho;
    // The strip's cells in order along it: lower wall from its far end to the fold, across it, upper wall outwards.
    std::vector<std::vector<int>> column;
    for (int k = K - 1; k >= 0; --k) {
        column.emplace_back();
        for (int j = 0; j < NY; ++j) column.back().push_back(id(1, k, j));
    }
    for (int k = 0; k < K; ++k) {
        column.emplace_back();
        for (int j = 0; j < NY; ++j) column.back().push_back(id(0, k, j));
    }
    std::vector<Eigen::Vector3i> tri;
    for (size_t c = 0; c + 1 < column.size(); ++c)
        for (int j = 0; j + 1 < NY; ++j) {
            const int a = column[c][j], b = column[c + 1][j], cc = column[c + 1][j + 1], d = column[c][j + 1];
            for (Eigen::Vector3i t : {Eigen::Vector3i(a, b, cc), Eigen::Vector3i(a, cc, d)}) {
                // Normals into the fold, towards the opposite wall: −z on the upper wall, +z on the lower, +x across.
                const Eigen::Vector3d p = X.row(t[0]), q = X.row(t[1]), r = X.row(t[2]), m = (p + q + r) / 3;
                const Eigen::Vector3d inside(std::max(m.x(), 0.0) + h, m.y(), 0.0);
                if ((q - p).cross(r - p).dot(inside - m) < 0) std::swap(t[1], t[2]);
                tri.push_back(t);
            }
        }
    Eigen::MatrixX3i F(static_cast<Eigen::Index>(tri.size()), 3);
    for (size_t f = 0; f < tri.size(); ++f) F.row(static_cast<Eigen::Index>(f)) = tri[f].transpose();
    const Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * X.rows());
    // The lower wall's face whose xy triangle holds the point's (−1: none).
    auto face_under = [&](int v) {
        const Eigen::Vector2d p = X.row(v).head<2>().transpose();
        for (Eigen::Index f = 0; f < F.rows(); ++f) {
            bool lower = true;
            for (int k = 0; k < 3; ++k) lower = lower && X(F(f, k), 2) < 0;
            if (!lower) continue;
            const Eigen::Vector2d a = X.row(F(f, 0)).head<2>().transpose(), b = X.row(F(f, 1)).head<2>().transpose(), c = X.row(F(f, 2)).head<2>().transpose();
            auto side = [](const Eigen::Vector2d& o, const Eigen::Vector2d& e, const Eigen::Vector2d& q) { return (e - o).x() * (q - o).y() - (e - o).y() * (q - o).x(); };
            const double s0 = side(a, b, p), s1 = side(b, c, p), s2 = side(c, a, p);
            if ((s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0)) return static_cast<int>(f);
        }
        return -1;
    };
    // Of the upper wall's row k (inner vertices across), how many are paired with the face under them.
    auto paired_over = [&](const fem::ContactParams& p, int k) {
        const std::vector<std::array<int, 2>> pairs = fem::contact_pairs(X, F, u, p);
        for (const auto& pr : pairs) {
            bool same = true;  // a face wholly on the vertex's own wall
            for (int c = 0; c < 3; ++c) same = same && std::abs(X(F(pr[1], c), 2) - X(pr[0], 2)) < 1e-12;
            EXPECT_FALSE(same) << "vertex " << pr[0] << " paired with a face of its own wall, " << pr[1];
        }
        int n = 0;
        for (int j = 1; j + 2 < NY; ++j) {
            const int v = id(0, k, j), f = face_under(v);
            EXPECT_GE(f, 0) << "vertex " << v << " lies over the lower wall";
            n += std::any_of(pairs.begin(), pairs.end(), [&](const std::array<int, 2>& pr) { return pr[0] == v && pr[1] == f; });
        }
        return n;
    };
    const int row = NY - 3;  // inner vertices of a row
    const fem::CompliantWallSearch ws;
    EXPECT_EQ(ws.params.exclude_rings, 1);
    EXPECT_EQ(paired_over(ws.params, 1), row) << "the frames' search pairs the fold's first row with the faces under it";
    EXPECT_LT(paired_over(fem::ContactParams{}, 1), row) << "two rings leave faces out (those with a corner at the fold)";
    EXPECT_EQ(paired_over(ws.params, 3), row);
    EXPECT_EQ(paired_over(fem::ContactParams{}, 3), row);
}

namespace {

/// Two plates (1 mm along x, H thick along y, 4 mm along z, held round their edges x = 0, 1 and z = 0, 4, 1 MPa, ν 0.45;
/// free edges let two pressed plates, frictionless, slide off each other sideways) facing each other
/// across a gap along y, between blades hinged 100 mm away (nearly parallel, 2 mm wide along z, over the plates'
/// middle) that close from the plates' outer faces (theta_touch) until each has pushed its plate 0.1 mm (theta_end):
/// the plates' facing faces meet after GAP / 2 each. What a fold of the outer surface is (two parts of it pressed
/// together), on a body whose answer is plain. `facing`: the facing faces (body numbering, outward of each plate:
/// towards the other), the first half the lower plate's; `reach`: the nodes of both plates' y faces off the held edges.
struct PlatesBetweenBlades {
    static constexpr double FAR = 100.0, H = 0.2, GAP = 0.05, PUSH = 0.1;
    Eigen::MatrixX3d V;
    Eigen::MatrixXi T;
    std::unique_ptr<fem::NeoHookeanSolid> solid;
    Eigen::VectorXi fixed;
    std::vector<int> reach;
    Eigen::MatrixX3i facing;
    fem::ClipBlades blades;
    double theta_touch = 0, theta_end = 0;
    PlatesBetweenBlades() {
        const fem::StructuredMesh p = fem::box_mesh(1.0, H, 4.0, 4, 2, 16);
        const auto n = p.V.rows();
        V.resize(2 * n, 3);
        V << p.V, p.V;
        V.topRows(n).col(1).array() -= 0.5 * GAP + H;  // the lower plate: y in [-GAP/2 - H, -GAP/2]
        V.bottomRows(n).col(1).array() += 0.5 * GAP;    // the upper: y in [GAP/2, GAP/2 + H]
        T.resize(2 * p.T.rows(), 4);
        T << p.T, p.T.array() + static_cast<int>(n);
        solid = std::make_unique<fem::NeoHookeanSolid>(V, T, Eigen::VectorXi::Zero(T.rows()), std::vector<Material>{{"wall", 1.0, 0.45}});
        std::vector<int> fd, lower, upper;
        for (Eigen::Index i = 0; i < V.rows(); ++i) {
            const double y = V(i, 1), z = V(i, 2);
            if (z < 1e-9 || z > 4.0 - 1e-9 || V(i, 0) < 1e-9 || V(i, 0) > 1.0 - 1e-9) {
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
                continue;
            }
            if (std::abs(std::abs(y) - 0.5 * GAP) < 1e-9) (y < 0 ? lower : upper).push_back(static_cast<int>(i));
            if (std::abs(std::abs(y) - 0.5 * GAP) < 1e-9 || std::abs(std::abs(y) - 0.5 * GAP - H) < 1e-9) reach.push_back(static_cast<int>(i));
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
        const Eigen::MatrixXi lo = fem::boundary_faces_in_set(V, T, Eigen::Map<Eigen::VectorXi>(lower.data(), static_cast<Eigen::Index>(lower.size())));
        const Eigen::MatrixXi up = fem::boundary_faces_in_set(V, T, Eigen::Map<Eigen::VectorXi>(upper.data(), static_cast<Eigen::Index>(upper.size())));
        facing.resize(lo.rows() + up.rows(), 3);
        facing << lo.leftCols(3), up.leftCols(3);
        blades.hinge = Eigen::Vector3d(-FAR, 0.0, 2.0);  // along x, opening along y, 2 mm wide along z
        blades.length_mm = FAR + 3.0;
        blades.width_mm = 2.0;
        const double top = 0.5 * GAP + H;
        theta_touch = 2 * std::asin(top / FAR) + 1e-4;
        theta_end = 2 * std::asin((top - PUSH) / (FAR + 0.5));
    }
};

}  // namespace

TEST(CompliantClip, TheOuterSurfacePressedOntoItselfIsKeptApartAndNeverMeetsTheLumen) {
    // Session 48: C0001's outer surface, squeezed along the jaws, folded 0.11 mm into its own wall through faces no
    // frame had. Here two parts of an outer surface (the plates' facing faces) are pressed together by the blades.
    const PlatesBetweenBlades pl;
    const fem::ClipSpring spring = test_spring();
    // The setup takes the outer surface's faces about to meet (0.05 mm apart, within the 0.3 mm approach), all of
    // them, as surface 1, after the lumen's (none here), their corners candidates; without the approach, none.
    const fem::CompliantSetup s = fem::compliant_setup(pl.blades, pl.theta_touch, pl.V, pl.reach, Eigen::MatrixX3i(), fem::COMPLIANT_WALL_APPROACH_MM, pl.facing);
    ASSERT_EQ(s.faces.rows(), pl.facing.rows());
    EXPECT_EQ(s.approach_faces, static_cast<size_t>(pl.facing.rows()));
    EXPECT_EQ(s.face_surface, std::vector<int>(static_cast<size_t>(pl.facing.rows()), 1));
    for (Eigen::Index f = 0; f < s.faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) EXPECT_EQ(s.candidates[static_cast<size_t>(s.faces(f, k))], pl.facing(f, k));
    EXPECT_EQ(fem::compliant_setup(pl.blades, pl.theta_touch, pl.V, pl.reach, Eigen::MatrixX3i(), 0.0, pl.facing).faces.rows(), 0);
    // The same faces as the lumen's (the wedge rule takes them, surface 0): the outer faces then meet none of their own.
    const fem::CompliantSetup as_lumen = fem::compliant_setup(pl.blades, pl.theta_touch, pl.V, pl.reach, pl.facing);
    EXPECT_EQ(as_lumen.face_surface, std::vector<int>(static_cast<size_t>(pl.facing.rows()), 0));

    Eigen::MatrixX3d Xc(static_cast<Eigen::Index>(s.candidates.size()), 3);
    for (size_t k = 0; k < s.candidates.size(); ++k) Xc.row(static_cast<Eigen::Index>(k)) = pl.V.row(s.candidates[k]);
    // Frames closing the blades to theta_end, each on a linearisation where the last ended; the plates' faces labelled
    // `surface` (empty: no wall contact).
    struct End {
        fem::CompliantFrame f;
        Eigen::VectorXd u;
    };
    auto run = [&](const std::vector<int>& surface) {
        fem::CompliantWallSearch ws;
        ws.params.face_surface = surface;
        End e;
        e.u = Eigen::VectorXd::Zero(pl.solid->dofs());
        e.f.theta = pl.theta_touch;
        for (int frame = 0; frame < 24; ++frame) {
            const double th = pl.theta_touch + (pl.theta_end - pl.theta_touch) * std::min(1.0, (frame + 1) / 16.0);
            const fem::Linearisation lin(*pl.solid, pl.V, pl.fixed, e.u, s.candidates);
            const fem::CompliantFrame last = e.f;
            e.f = surface.empty() ? fem::solve_compliant_clip(lin, pl.blades, spring, th, last.theta, frame ? &last : nullptr)
                                  : fem::solve_compliant_clip_walls(lin, Xc, s.faces, ws, pl.blades, spring, th, last.theta, frame ? &last : nullptr);
            e.u = lin.displacement(e.f.candidate_forces);
        }
        return e;
    };
    // The deepest vertex of one plate's facing face behind the other's (body numbering, over all of them).
    auto deepest = [&](const Eigen::VectorXd& u) {
        double d = 0;
        for (const auto& x : fem::surface_crossings(pl.V, pl.facing, u, 1, 0.25)) d = std::max(d, x.depth_mm);
        return d;
    };
    const End without = run({});
    EXPECT_GT(deepest(without.u), 0.05);  // each plate pushed 0.1 mm: 0.2 mm together, less the 0.05 mm gap and the bending
    const std::vector<int> outer = s.face_surface;
    const End with = run(outer);
    EXPECT_LT(deepest(with.u), 1e-3);  // touching, not through: a pressed vertex ends on its face's plane to a micrometre
    EXPECT_EQ(with.f.wall_crossings, 0);
    EXPECT_LT(with.f.wall_crossed_mm, 1e-3);
    EXPECT_GT(with.f.wall_contacts, 10);
    EXPECT_LE(with.f.complementarity_mm, 1e-9);
    // Pressed on each other, the plates take the blades' push together: more force for the same closing.
    EXPECT_GT(with.f.loads.force_n[0], 1.5 * without.f.loads.force_n[0]);
    EXPECT_NEAR(with.f.loads.force_n[0], with.f.loads.force_n[1], 0.02 * with.f.loads.force_n[0]);
    // The same faces as two surfaces (each plate's its own, as the lumen and the outer surface are): no vertex meets the
    // other's faces, and the plates pass through each other as without any wall contact.
    std::vector<int> two(outer.size(), 1);
    for (Eigen::Index f = 0; f < s.faces.rows(); ++f)
        if (pl.V(s.candidates[static_cast<size_t>(s.faces(f, 0))], 1) < 0) two[static_cast<size_t>(f)] = 0;
    const End apart = run(two);
    EXPECT_EQ(apart.f.wall_rows, 0);
    EXPECT_NEAR(deepest(apart.u), deepest(without.u), 1e-9);
    // A face_surface that does not fit the faces is refused.
    fem::CompliantWallSearch bad;
    bad.params.face_surface = {1};
    const fem::Linearisation lin(*pl.solid, pl.V, pl.fixed, Eigen::VectorXd::Zero(pl.solid->dofs()), s.candidates);
    EXPECT_THROW(fem::solve_compliant_clip_walls(lin, Xc, s.faces, bad, pl.blades, spring, pl.theta_touch, pl.theta_touch), InputError);
    std::printf("plates: blade force %.4f N with the outer surface's contact (%d pairs pressed, %.4f N through them), %.4f N without; crossed %.4f mm without\n",
                with.f.loads.force_n[0], with.f.wall_contacts, with.f.wall_force_n, without.f.loads.force_n[0], deepest(without.u));
}

TEST(WallContact, AVertexPairsOnlyWithTheFacesOfItsOwnSurface) {
    // Two facing unit squares 0.05 mm apart (the lower's normal +z, the upper's −z): every vertex faces the other's
    // faces. Labelled one surface they pair and, pushed through, cross; labelled two (the lumen and the outer surface
    // across a wall squeezed thin), neither.
    Eigen::MatrixX3d X(8, 3);
    X << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 0.05, 1, 0, 0.05, 1, 1, 0.05, 0, 1, 0.05;
    Eigen::MatrixX3i F(4, 3);
    F << 0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6;
    fem::ContactParams one, two;
    one.face_surface = {0, 0, 0, 0};
    two.face_surface = {0, 0, 1, 1};
    const Eigen::VectorXd rest = Eigen::VectorXd::Zero(24);
    const auto all = fem::contact_pairs(X, F, rest, fem::ContactParams{});
    EXPECT_EQ(fem::contact_pairs(X, F, rest, one), all);
    EXPECT_FALSE(all.empty());
    EXPECT_TRUE(fem::contact_pairs(X, F, rest, two).empty());
    two.close_vertices = {0, 4};  // close vertices too
    EXPECT_TRUE(fem::contact_pairs(X, F, rest, two).empty());
    Eigen::VectorXd through = rest;
    for (int v = 4; v < 8; ++v) through[3 * v + 2] = -0.1;  // the upper square 0.05 mm through the lower
    EXPECT_EQ(fem::surface_crossings(X, F, through, 1, 0.25, nullptr, &one.face_surface).size(), fem::surface_crossings(X, F, through, 1, 0.25).size());
    EXPECT_FALSE(fem::surface_crossings(X, F, through, 1, 0.25).empty());
    EXPECT_TRUE(fem::surface_crossings(X, F, through, 1, 0.25, nullptr, &two.face_surface).empty());
    const std::vector<int> short_list = {0, 1};
    EXPECT_THROW(fem::surface_crossings(X, F, through, 1, 0.25, nullptr, &short_list), InputError);
    fem::ContactParams bad;
    bad.face_surface = short_list;
    EXPECT_THROW(fem::contact_pairs(X, F, rest, bad), InputError);
}

namespace {

/// A wall vertex pushed into a hollow of the opposite wall: block B (1 × 1 × 1 mm, 2 × 2 × 2 elements, its bottom
/// held) whose top is a bowl, y = 1 + c (|x − 0.5| + |z − 0.5|), lowest at its centre node, its 8 top faces the walls;
/// a 0.2 mm cube A (its top held) whose bottom corner v stands at `v_at`, linearised squeezed by `squeeze` as in
/// VertexOverACrease (its free step takes v back by −squeeze, into the bowl's faces unless rows hold it). One frame
/// with CompliantOptions::wall_one_face, from a warm frame without rows.
fem::CompliantFrame vertex_into_a_hollow(double c, const Eigen::Vector3d& v_at, const Eigen::Vector3d& squeeze, int geometry_passes, int* n_faces = nullptr) {
    const BlockUnderACube bc(0.0, [&](double x, double z) { return c * (std::abs(x - 0.5) + std::abs(z - 0.5)); }, v_at, squeeze);
    const Eigen::MatrixX3d& X = bc.X;
    const std::vector<int>& top = bc.top;
    const fem::NeoHookeanSolid solid(X, bc.T, Eigen::VectorXi::Zero(bc.T.rows()), std::vector<Material>{Material{"wall", 1.0, 0.45}});
    const Eigen::VectorXi& fixed = bc.fixed;
    const Eigen::VectorXd& u0 = bc.u0;
    std::vector<int> cand{bc.v};
    cand.insert(cand.end(), top.begin(), top.end());
    const Eigen::MatrixXi F = fem::boundary_faces_in_set(X, bc.b.T, Eigen::Map<const Eigen::VectorXi>(top.data(), static_cast<Eigen::Index>(top.size())));
    std::vector<int> slot(static_cast<size_t>(X.rows()), -1);
    for (size_t k = 0; k < cand.size(); ++k) slot[static_cast<size_t>(cand[k])] = static_cast<int>(k);
    fem::CompliantWalls walls;
    walls.faces.resize(F.rows(), 3);
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        for (int k = 0; k < 3; ++k) walls.faces(f, k) = slot[static_cast<size_t>(F(f, k))];
        walls.pairs.push_back({0, static_cast<int>(f)});
    }
    if (n_faces) *n_faces = static_cast<int>(F.rows());
    const fem::Linearisation lin(solid, X, fixed, u0, cand);
    fem::ClipBlades blades;
    blades.hinge = Eigen::Vector3d(-50.0, 0.0, 0.5);
    blades.length_mm = 3.0;
    fem::CompliantFrame warm;
    warm.theta = 0.5;
    warm.candidate_u = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(cand.size()));
    for (size_t k = 0; k < cand.size(); ++k) warm.candidate_u.segment<3>(3 * static_cast<Eigen::Index>(k)) = u0.segment<3>(3 * cand[k]);
    warm.candidate_forces = Eigen::VectorXd::Zero(warm.candidate_u.size());
    fem::CompliantOptions opt;
    opt.wall_one_face = true;
    opt.geometry_passes = geometry_passes;
    return fem::solve_compliant_clip(lin, blades, test_spring(), 0.5, 0.5, &warm, opt, &walls);
}

}  // namespace

TEST(CompliantClip, AVertexPushedIntoAHollowOfTheOppositeWallIsHeldOutOfEveryFaceAroundIt) {
    // The sample's held clip with the faces from the heel (session 62, ANEU_WALL_TRACE): a vertex over a hollow of
    // the opposite wall (a fan of faces about one node) had one face's row and a second's in a pass, went 0.021 mm
    // through a third, took that one's neighbour in the next and came back out, and so on to the frame's last pass.
    // Here v is pushed 0.1 mm down into a bowl of 8 faces. A face that pressed it in an earlier pass of the frame
    // keeps its row (CompliantOptions::wall_one_face; its plane more than 10° from the vertex's other rows), so the
    // rows grow to those of the faces around it and v ends on them. Before: two rows, 0.017 mm through (bowl 0.4)
    // and 0.005 mm (0.2).
    for (double c : {0.2, 0.4})
        for (const Eigen::Vector3d& sq : {Eigen::Vector3d(0, 0.1, 0), Eigen::Vector3d(0.03, 0.1, 0.01)}) {
            int nf = 0;
            const fem::CompliantFrame f = vertex_into_a_hollow(c, Eigen::Vector3d(0.5, 1.005, 0.5), sq, fem::CompliantOptions{}.geometry_passes, &nf);
            ASSERT_EQ(nf, 8);
            EXPECT_GT(f.wall_min_distance_mm, -1e-3) << "bowl " << c;
            EXPECT_GE(wall_rows_of_v(f), 3) << "bowl " << c;
            EXPECT_GE(f.wall_contacts, 3) << "bowl " << c;
            EXPECT_LE(f.complementarity_mm, 1e-9) << "bowl " << c;
            std::printf("hollow %.1f, pushed (%.2f %.2f %.2f): v %.5f mm from the nearest face, %d rows, %d pressed, %d passes\n", c, sq.x(), sq.y(), sq.z(),
                        f.wall_min_distance_mm, wall_rows_of_v(f), f.wall_contacts, f.passes);
        }
}
