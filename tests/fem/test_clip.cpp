// SPDX-License-Identifier: MIT
// The clip as a spring (fem::ClipBody, issue #15 item 3): a released clip closes on a block of known stiffness
// and stops at the angle where the block pushes back as hard as the spring (the moment balance, solved here
// independently by bisection); held open, the forceps holds the spring's torque less the tissue's moment.
#include <gtest/gtest.h>

#include <cmath>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "clip_test_util.hpp"

using namespace aneu;
using aneu::test::Block;
using aneu::test::test_spring;

namespace {

/// The barrier's push at distance D from a blade face (ClipBody's law, written out here): −κ d̂ b'(D/d̂),
/// b(x) = −(x − 1)² ln x, for 0 < D < d̂.
double barrier_push(double D, double kappa, double gap) {
    if (D >= gap) return 0;
    const double x = D / gap, m = x - 1;
    return kappa * gap * (2 * m * std::log(x) + m * m / x);
}

/// The moment balance of blade +1 on the block, independently of ClipBody: the node moves along the blade's
/// normal only (its ground spring is isotropic, the blade frictionless), so its force is that of the ground
/// spring and the blade's barrier in series: K (D − d₀) = push(D), D its distance from the face, d₀ that of its
/// rest place, acting at r = its distance along the blade.
double block_residual(double theta, const fem::ClipSpring& s, double kappa, double gap) {
    const double phi = 0.5 * theta;
    const double d0 = Block::A * std::sin(phi) - Block::H * std::cos(phi);
    const double r = Block::A * std::cos(phi) + Block::H * std::sin(phi);
    double F = 0;
    if (d0 < gap) {  // bisection on K (D − d₀) − push(D): negative just above max(d₀, 0), positive at d̂
        double lo = std::max(d0, 0.0), hi = gap;
        for (int it = 0; it < 200; ++it) {
            const double mid = 0.5 * (lo + hi);
            (Block::K * (mid - d0) - barrier_push(mid, kappa, gap) < 0 ? lo : hi) = mid;
        }
        F = Block::K * (0.5 * (lo + hi) - d0);
    }
    return s.torque(theta) - F * r;
}

/// The displacement that puts block node `node` (2: on blade +1, 3: on blade −1) at (r along, a across, p in
/// front of) its blade at opening θ.
Eigen::Vector3d place(const Block& b, const fem::ClipBlades& bl, int node, double theta, double r, double a, double p) {
    Eigen::Vector3d t, n, w;
    bl.frame(node == 2 ? 1 : -1, theta, t, n, w);
    return bl.hinge + r * t + a * w + (p - 0.5 * bl.closed_gap_mm) * n - b.X.row(node).transpose();
}

/// The clip's force is its energy's derivative and its tangent the force's, by central differences of step h over
/// the DOFs from `first` on (the block's free nodes and θ).
void expect_derivatives(const fem::ClipBody& clip, const Eigen::VectorXd& v, Eigen::Index first, double h) {
    const Eigen::VectorXd g = clip.internal_force(v);
    const Eigen::MatrixXd K = Eigen::MatrixXd(clip.tangent(v));
    for (Eigen::Index i = first; i < clip.dofs(); ++i) {
        Eigen::VectorXd p = v, m = v;
        p[i] += h;
        m[i] -= h;
        EXPECT_NEAR(g[i], (clip.energy(p) - clip.energy(m)) / (2 * h), 1e-5 * (1 + std::abs(g[i]))) << "dof " << i;
        const Eigen::VectorXd col = (clip.internal_force(p) - clip.internal_force(m)) / (2 * h);
        for (Eigen::Index j = first; j < clip.dofs(); ++j)
            EXPECT_NEAR(K(j, i), col[j], 1e-4 * (1 + std::abs(col[j]))) << "entry " << j << ", " << i;
    }
}

}  // namespace

TEST(ClipSpring, TheNextOpeningApproachesTheStopWithoutReachingItThroughTissue) {
    const double deg = M_PI / 180;
    // A spring far stronger than the tissue (R / k = 5°) at 0.576°: held, touching tissue, the step is half the
    // opening left — never the stop in one frame (the 2x-spring run stepped to 0 there and crushed the tissue).
    EXPECT_DOUBLE_EQ(fem::next_spring_opening(0.576 * deg, 5.0, 1.0 / deg, true, true), 0.288 * deg);
    // The same through the air: to the stop.
    EXPECT_DOUBLE_EQ(fem::next_spring_opening(0.576 * deg, 5.0, 1.0 / deg, true, false), 0.0);
    // Released: at most 1° a frame closing, and half the opening left on tissue.
    EXPECT_NEAR(fem::next_spring_opening(10 * deg, 5.0, 1.0 / deg, false, true), 9 * deg, 1e-15);
    EXPECT_NEAR(fem::next_spring_opening(1 * deg, 5.0, 1.0 / deg, false, true), 0.5 * deg, 1e-15);
    // The tissue pushing harder than the spring: opens, at most 1° a frame; a small imbalance by the secant.
    EXPECT_NEAR(fem::next_spring_opening(2 * deg, -5.0, 1.0 / deg, true, true), 3 * deg, 1e-15);
    EXPECT_NEAR(fem::next_spring_opening(2 * deg, -0.25, 1.0 / deg, true, true), 2.25 * deg, 1e-15);
    EXPECT_NEAR(fem::next_spring_opening(2 * deg, 0.25, 1.0 / deg, true, true), 1.75 * deg, 1e-15);
    // A secant that is not a stiffness takes no step.
    EXPECT_EQ(fem::next_spring_opening(2 * deg, 5.0, 0.0, true, true), 2 * deg);
}

TEST(ClipSpring, TwoLabelForcesGiveTheHyperbola) {
    const fem::ClipSpring s = test_spring();
    const double r = 7.0 * 2.0 / 3.0;
    EXPECT_NEAR(s.force_at(r, fem::opening_angle(r, 1.0, 0.0)), 1.5, 1e-12);
    EXPECT_NEAR(s.force_at(r, 40 * DEG), 2.5, 1e-12);
    // Along the blade the force is τ/r: half as far from the hinge, twice the force.
    EXPECT_NEAR(s.force_at(0.5 * r, 0.3), 2.0 * s.force_at(r, 0.3), 1e-12);
    EXPECT_GT(s.preload_rad, 0.0);
    // 2 r sin(θ/2) + closed gap = opening.
    EXPECT_NEAR(2 * 3.0 * std::sin(0.5 * fem::opening_angle(3.0, 1.2, 0.2)) + 0.2, 1.2, 1e-12);
    EXPECT_THROW(fem::ClipSpring::from_forces(r, 0.1, 2.0, 0.5, 1.0), InputError);   // weaker when opened
    EXPECT_THROW(fem::ClipSpring::from_forces(r, 0.1, 0.1, 0.5, 10.0), InputError);  // no preload
    EXPECT_THROW(fem::opening_angle(0.2, 1.0, 0.0), InputError);                     // beyond reach
}

TEST(ClipBody, ReleasedOnABlockItStopsAtTheAnalyticAngle) {
    const Block b;
    const fem::ClipSpring spring = test_spring();
    fem::ClipBlades blades;  // hinge at the origin, axis x, up y, 7 mm × 1 mm
    // Released open (40°, clear of the block): θ is free.
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v0, blades, spring);
    EXPECT_DOUBLE_EQ(clip.stiffness(), Block::K);  // κ: the largest diagonal entry of the body's tangent
    fem::NewtonOptions no;
    no.tolerance = 1e-12;
    const fem::NewtonResult r = fem::solve_neo_hookean(clip, b.fixed, {}, v0, no);
    const double theta = r.u[clip.theta_dof()];
    // The analytic angle: bisection on the balance between the touching angle and closed.
    double lo = 0, hi = 2 * std::atan(Block::H / Block::A);
    ASSERT_LT(block_residual(lo, spring, clip.stiffness(), 0.01), 0);  // the block stops the clip before it closes
    ASSERT_GT(block_residual(hi, spring, clip.stiffness(), 0.01), 0);
    for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (lo + hi);
        (block_residual(mid, spring, clip.stiffness(), 0.01) < 0 ? lo : hi) = mid;
    }
    EXPECT_NEAR(theta, 0.5 * (lo + hi), 1e-9) << "clip at " << theta / DEG << "°";
    // Moment balance of both blades and the hyperbola: each blade's force × its lever = the spring's torque.
    const fem::BladeLoads L = clip.loads(r.u);
    EXPECT_EQ(L.contacts[0], 1);
    EXPECT_EQ(L.contacts[1], 1);
    EXPECT_NEAR(L.moment_nmm[0], L.spring_torque_nmm, 1e-9 * L.spring_torque_nmm);
    EXPECT_NEAR(L.moment_nmm[1], L.spring_torque_nmm, 1e-9 * L.spring_torque_nmm);
    EXPECT_NEAR(L.force_n[0], L.force_n[1], 1e-9);
    // The block nodes moved towards each other along the blades' normals, symmetrically.
    EXPECT_LT(r.u[7], 0);
    EXPECT_NEAR(r.u[7], -r.u[10], 1e-12);
}

TEST(ClipBody, ReleasedOnABlockBeforeWhereItsFacesBeginItClosesWithoutTouchingIt) {
    // The block of ReleasedOnABlockItStopsAtTheAnalyticAngle (its nodes 4 mm from the hinge) lies before the faces
    // when they begin 5 mm out (ClipBlades::face_from_mm, a fulcrum's arms): released, the clip closes past it to
    // the blades' own contact, nothing presses it; faces from 3.5 mm stop at the block's analytic angle as before.
    // A face beginning beyond the blade is refused.
    const Block b;
    const fem::ClipSpring spring = test_spring();
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    fem::NewtonOptions no;
    no.tolerance = 1e-12;
    fem::ClipBlades blades;
    blades.face_from_mm = 5.0;
    const fem::ClipBody past(*b.body, b.X, {2, 3}, v0, blades, spring);
    const fem::NewtonResult r = fem::solve_neo_hookean(past, b.fixed, {}, v0, no);
    const double theta_past = r.u[past.theta_dof()];
    const double touch = 2 * std::atan(Block::H / Block::A);  // where the faces from the hinge would meet the block
    EXPECT_LT(theta_past, 0.2 * touch) << theta_past / DEG << "°";
    const fem::BladeLoads L = past.loads(r.u);
    EXPECT_EQ(L.contacts[0] + L.contacts[1], 0);
    EXPECT_NEAR(r.u[7], 0.0, 1e-12);  // the block not moved
    blades.face_from_mm = 3.5;
    const fem::ClipBody on(*b.body, b.X, {2, 3}, v0, blades, spring);
    const fem::NewtonResult r2 = fem::solve_neo_hookean(on, b.fixed, {}, v0, no);
    double lo = 0, hi = touch;
    for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (lo + hi);
        (block_residual(mid, spring, on.stiffness(), 0.01) < 0 ? lo : hi) = mid;
    }
    EXPECT_NEAR(r2.u[on.theta_dof()], 0.5 * (lo + hi), 1e-9);
    blades.face_from_mm = 7.0;
    EXPECT_THROW(fem::ClipBody(*b.body, b.X, {2, 3}, v0, blades, spring), InputError);
}

TEST(ClipBody, HeldOpenTheForcepsHoldsTheSpringLessTheTissue) {
    const Block b;
    const fem::ClipSpring spring = test_spring();
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v0, fem::ClipBlades{}, spring);
    for (const double held : {30 * DEG, 0.2}) {  // clear of the block; pressing on it
        const fem::NewtonResult r =
            fem::solve_neo_hookean(clip, b.fixed, {{static_cast<int>(clip.theta_dof()), held}}, v0);
        EXPECT_NEAR(r.reaction[0], block_residual(held, spring, clip.stiffness(), 0.01), 1e-8) << "held at " << held;
    }
}

TEST(ClipBody, ForcesAndTangentAreTheEnergysDerivatives) {
    const Block b;
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;  // open: both nodes in front of their blade
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v0, fem::ClipBlades{}, test_spring());
    Eigen::VectorXd v = Eigen::VectorXd::Zero(clip.dofs());
    const fem::ClipBlades bl;
    v.segment<3>(6) = place(b, bl, 2, 0.2, 4.01, 0.02, 0.004);   // node 2 within d̂ of blade +1
    v.segment<3>(9) = place(b, bl, 3, 0.2, 3.98, 0.01, 0.007);   // node 3 within d̂ of blade −1
    v[clip.theta_dof()] = 0.2;
    const fem::BladeLoads L = clip.loads(v);
    ASSERT_EQ(L.contacts[0] + L.contacts[1], 2);
    // The tissue's net force on the blades is the blades' part of the nodes' internal force (the body's removed).
    auto net_of = [&](const Eigen::VectorXd& s) {
        const Eigen::VectorXd gb = clip.internal_force(s).head(b.body->dofs()) - b.body->internal_force(s.head(b.body->dofs()));
        return Eigen::Vector3d(gb.segment<3>(6) + gb.segment<3>(9));
    };
    EXPECT_GT(L.net_force.norm(), 0.0);
    EXPECT_LT((L.net_force - net_of(v)).norm(), 1e-12 * (1 + net_of(v).norm()));
    const double h = 1e-6;
    expect_derivatives(clip, v, 6, h);
    // Over a rounded edge (node 2 over the blade's side edge, node 3 over its tip; the edges' radius is 0.1 mm):
    // the force there is the energy's derivative too, and the tangent its derivative (the frame's part).
    // (ρ = 0.1: over the side edge, 0.05 out from the core, D = √(0.05² + (p + ρ)²) − ρ = 0.005 at p = −0.00767.)
    Eigen::VectorXd e = v;
    e.segment<3>(6) = place(b, bl, 2, 0.2, 4.01, 0.45, -0.00767);
    e.segment<3>(9) = place(b, bl, 3, 0.2, 6.95, 0.0, -0.00767);
    ASSERT_EQ(clip.loads(e).contacts[0] + clip.loads(e).contacts[1], 2) << clip.loads(e).contacts[0] << " " << clip.loads(e).contacts[1];
    EXPECT_LT((clip.loads(e).net_force - net_of(e)).norm(), 1e-12 * (1 + net_of(e).norm()));  // around the edges too
    const Eigen::VectorXd ge = clip.internal_force(e);
    expect_derivatives(clip, e, 6, h);  // the tangent too: with the edge's curvature (without it Newton is linear)
    // Around the rounded edge the force turns with the surface: on node 2 it has a part across the blade (along w,
    // pushing it off the side) besides the part along the normal.
    const Eigen::Vector3d f2 = -ge.segment<3>(6) + b.body->internal_force(e.head(b.body->dofs())).segment<3>(6);
    EXPECT_GT(f2.z(), 0.1 * f2.norm());
    // Past closed, the stop pushes back: the torque turns steeply opening-wards below θ = 0.
    Eigen::VectorXd c = Eigen::VectorXd::Zero(clip.dofs());
    c[6] = c[9] = 4.0;  // the block nodes 1 mm beyond the blades' tips
    c[clip.theta_dof()] = -1e-3;
    EXPECT_LT(clip.internal_force(c)[clip.theta_dof()], 0.0);
}

TEST(ClipBlades, ACurvedBladesFaceCoordinatesFollowItsCentreLineWithTheirDerivatives) {
    fem::ClipBlades b;
    b.length_mm = 9.0;
    b.curve_from_mm = 2.0;
    for (double R : {6.0, -6.0}) {
        b.curve_radius_mm = R;
        EXPECT_NO_THROW(b.check_curve());
        // On the centre line s is its length and the offset 0; 0.3 mm across it (towards +a's side) the offset is 0.3.
        for (double s : {1.0, 2.0, 4.5, 9.0}) {
            double r, a, dr, da;
            b.centre_line(s, r, a, dr, da);
            EXPECT_NEAR(std::hypot(dr, da), 1.0, 1e-12);
            const fem::ClipBlades::FaceCoords on = b.face_coords(r, a), off = b.face_coords(r - 0.3 * da, a + 0.3 * dr);
            EXPECT_NEAR(on.s, s, 1e-12) << R << " " << s;
            EXPECT_NEAR(on.a, 0.0, 1e-12);
            EXPECT_NEAR(off.s, s, 1e-12);
            EXPECT_NEAR(off.a, 0.3, 1e-12);
        }
        // A point on the blade's axis 7 mm into the curve: |R| − its distance from the centre of curvature across it.
        EXPECT_NEAR(b.face_coords(9.0, 0.0).a * R, std::abs(R) * (std::abs(R) - std::hypot(7.0, std::abs(R))), 1e-9);
        // The derivatives, by central differences, where it curves (also for points inside the bend and beyond the tip).
        for (const Eigen::Vector2d& q : {Eigen::Vector2d(4.0, 0.2), Eigen::Vector2d(6.5, -0.7), Eigen::Vector2d(8.0, 2.5), Eigen::Vector2d(3.0, 1.0)}) {
            const fem::ClipBlades::FaceCoords c = b.face_coords(q[0], q[1]);
            const double h = 1e-5;
            for (int i = 0; i < 2; ++i) {
                Eigen::Vector2d p = q, m = q;
                p[i] += h;
                m[i] -= h;
                const fem::ClipBlades::FaceCoords cp = b.face_coords(p[0], p[1]), cm = b.face_coords(m[0], m[1]);
                EXPECT_NEAR(c.ds[i], (cp.s - cm.s) / (2 * h), 1e-8);
                EXPECT_NEAR(c.da[i], (cp.a - cm.a) / (2 * h), 1e-8);
                for (int j = 0; j < 2; ++j) {
                    EXPECT_NEAR(c.hs(j, i), (cp.ds[j] - cm.ds[j]) / (2 * h), 1e-6) << R << " (" << q.transpose() << ") " << j << i;
                    EXPECT_NEAR(c.ha(j, i), (cp.da[j] - cm.da[j]) / (2 * h), 1e-6) << R << " (" << q.transpose() << ") " << j << i;
                }
            }
        }
    }
    // Before the curve: the straight blade's coordinates.
    const fem::ClipBlades::FaceCoords st = b.face_coords(1.5, 0.4);
    EXPECT_EQ(st.s, 1.5);
    EXPECT_EQ(st.a, 0.4);
    // Too tight a curve, or one bending the blade past 90°, is refused.
    b.curve_radius_mm = 1.5;
    EXPECT_THROW(b.check_curve(), InputError);
    b.curve_radius_mm = -4.0;  // 7 mm of arc at 4 mm: 100°
    EXPECT_THROW(b.check_curve(), InputError);
    b.length_mm = 4.0;  // 2 mm of arc at 2.5 mm: 46°, but the blade 3 mm wide
    b.curve_radius_mm = 2.5;
    b.width_mm = 3.0;
    EXPECT_THROW(b.check_curve(), InputError);
    b.width_mm = 1.0;
    EXPECT_NO_THROW(b.check_curve());
}

TEST(ClipBody, OnCurvedBladesForcesAndTangentAreTheEnergysDerivatives) {
    // The block's nodes against blades curved from 1 mm at a radius of 6 mm: node 2 over blade +1's face where it has
    // turned, node 3 over blade −1's side edge there; both within d̂.
    const Block b;
    fem::ClipBlades bl;
    bl.curve_radius_mm = 6.0;
    bl.curve_from_mm = 1.0;
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v0, bl, test_spring());
    auto on = [&](int node, double theta, double s, double across, double p) {  // (across: along the centre line's normal)
        double r, a, dr, da;
        bl.centre_line(s, r, a, dr, da);
        return place(b, bl, node, theta, r - across * da, a + across * dr, p);
    };
    Eigen::VectorXd v = Eigen::VectorXd::Zero(clip.dofs());
    v.segment<3>(6) = on(2, 0.2, 4.0, 0.1, 0.004);
    v.segment<3>(9) = on(3, 0.2, 4.5, 0.45, -0.00767);  // over the side edge (see ForcesAndTangentAreTheEnergysDerivatives)
    v[clip.theta_dof()] = 0.2;
    const fem::BladeLoads L = clip.loads(v);
    ASSERT_EQ(L.contacts[0], 1);
    ASSERT_EQ(L.contacts[1], 1);
    expect_derivatives(clip, v, 6, 1e-6);
    // The force on node 3 turns round the edge across the curved blade (along its centre line's normal, not z).
    const Eigen::VectorXd g = clip.internal_force(v);
    const Eigen::Vector3d f3 = -g.segment<3>(9) + b.body->internal_force(v.head(b.body->dofs())).segment<3>(9);
    double r, a, dr, da;
    bl.centre_line(4.5, r, a, dr, da);
    Eigen::Vector3d t, n, w;
    bl.frame(-1, 0.2, t, n, w);
    const Eigen::Vector3d across = -da * t + dr * w;
    EXPECT_GT(f3.dot(across), 0.1 * f3.norm());
    EXPECT_LT(std::abs(f3.dot(dr * t + da * w)), 1e-9 * f3.norm());  // nothing along the centre line
}

TEST(ClipBody, NodesOnOrJustBehindABladeAreSeparatedFromItToWhereTheBarrierCanStart) {
    // A hard-contact solve leaves pressed nodes exactly on a blade's face (or a hair behind it), where the barrier is
    // infinite: separated() moves each to delta in front of the face, along its normal, and leaves the rest (the
    // other node, far from its blade; the opening) as they are. A clip made there starts with a finite energy.
    const Block b;
    const fem::ClipBlades bl;
    for (const double p : {0.0, -0.01}) {
        Eigen::VectorXd v = Eigen::VectorXd::Zero(13);
        v[12] = 0.2;
        v.segment<3>(6) = place(b, bl, 2, 0.2, 4.0, 0.1, p);
        v.segment<3>(9) = place(b, bl, 3, 0.2, 4.0, 0.0, 0.5);
        const fem::ClipBody clip(*b.body, b.X, {2, 3}, v, bl, test_spring());
        const Eigen::VectorXd s = clip.separated(v, 0.005);
        Eigen::Vector3d t, n, w;
        bl.frame(1, 0.2, t, n, w);
        EXPECT_LT((s.segment<3>(6) - v.segment<3>(6) - (0.005 - p) * n).norm(), 1e-12) << "on blade +1 at p = " << p;
        EXPECT_EQ(s.segment<3>(9), v.segment<3>(9));
        EXPECT_EQ(s[12], v[12]);
        EXPECT_LT((s.segment<3>(6) - place(b, bl, 2, 0.2, 4.0, 0.1, 0.005)).norm(), 1e-12);
        const fem::ClipBody from(*b.body, b.X, {2, 3}, s, bl, test_spring());
        EXPECT_TRUE(std::isfinite(from.energy(s)));
        EXPECT_EQ(from.separated(s, 0.005), s);  // already apart: nothing moves
    }
    EXPECT_THROW(fem::ClipBody(*b.body, b.X, {2, 3}, Eigen::VectorXd::Zero(13), bl, test_spring()).separated(Eigen::VectorXd::Zero(13), 0.02), InputError);
}

TEST(ClipBody, NoStepPassesThroughABlade) {
    // Node 2 0.05 mm in front of blade +1 at θ = 0.2: sent 0.2 mm through the face, the step is cut where it is a
    // tenth of its distance from it; the blades closing to θ = 0 (which would leave it 0.4 mm behind blade +1)
    // are cut too; a step along the face is not.
    const Block b;
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v0, fem::ClipBlades{}, test_spring());
    Eigen::VectorXd v = v0;
    v.segment<3>(6) = place(b, fem::ClipBlades{}, 2, 0.2, 4.0, 0.0, 0.05);
    v.segment<3>(9) = place(b, fem::ClipBlades{}, 3, 0.2, 4.0, 0.0, 0.5);
    v[12] = 0.2;
    Eigen::Vector3d t, n, w;
    fem::ClipBlades{}.frame(1, 0.2, t, n, w);
    Eigen::VectorXd dv = Eigen::VectorXd::Zero(13);
    dv.segment<3>(6) = -0.2 * n;  // through the face at a quarter of the step
    const double a = clip.max_step(v, dv);
    EXPECT_GT(a, 0.2 * 0.9 * 0.25);
    EXPECT_LT(a, 0.25 * (1 - 0.1) + 1e-12);
    EXPECT_TRUE(std::isfinite(clip.energy(v + a * dv)));
    EXPECT_FALSE(std::isfinite(clip.energy(v + 0.3 * dv)));  // past the face: the barrier's infinity
    dv.setZero();
    dv[12] = -0.2;  // the blades close onto it and beyond
    const double ac = clip.max_step(v, dv);
    EXPECT_GT(ac, 0.0);
    EXPECT_LT(ac, 1.0);
    EXPECT_TRUE(std::isfinite(clip.energy(v + ac * dv)));
    EXPECT_FALSE(std::isfinite(clip.energy(v + dv)));
    dv.setZero();
    dv.segment<3>(6) = 0.3 * t;  // along the face
    EXPECT_EQ(clip.max_step(v, dv), 1.0);
}

TEST(ClipBody, ReleasedOnANeoHookeanBlockTheBladesBalanceTheSpringWithoutPassingThrough) {
    // A 2 × 1 × 1 mm neo-Hookean block (1 MPa) between the blades, 3 … 5 mm from the hinge, its far face held.
    const aneu::test::HeldBlock hb;
    const Eigen::MatrixX3d& X = hb.X;
    const fem::NeoHookeanSolid& solid = *hb.solid;
    const std::vector<int>& surface = hb.surface;
    fem::ClipBlades blades;
    blades.width_mm = 2.0;
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(solid.dofs() + 1);
    v0[solid.dofs()] = 40 * DEG;
    const fem::ClipBody clip(solid, X, surface, v0, blades, test_spring());
    const Eigen::VectorXi& fixed = hb.fixed;
    const fem::NewtonResult r = fem::solve_neo_hookean(clip, fixed, {}, v0);
    const double theta = r.u[clip.theta_dof()];
    // It closed onto the block and stopped open: 1 mm apart where the block's near face is, less the squeeze.
    EXPECT_GT(theta, 0.0);
    EXPECT_LT(theta, 2 * std::atan(0.5 / 3.0));
    const fem::BladeLoads L = clip.loads(r.u);
    EXPECT_GT(L.contacts[0], 3);
    // One angle for both blades: their mean moment balances the spring (the tetrahedra are not mirror-symmetric,
    // so each blade's own moment differs from it by a little).
    EXPECT_NEAR(0.5 * (L.moment_nmm[0] + L.moment_nmm[1]), L.spring_torque_nmm, 1e-6 * L.spring_torque_nmm);
    EXPECT_NEAR(L.moment_nmm[0], L.spring_torque_nmm, 0.01 * L.spring_torque_nmm);
    EXPECT_NEAR(L.moment_nmm[1], L.spring_torque_nmm, 0.01 * L.spring_torque_nmm);
    // No node passes through a blade face by more than 0.02 mm.
    for (int node : surface) {
        const Eigen::Vector3d x = X.row(node).transpose() + r.u.segment<3>(3 * node);
        for (int s : {1, -1}) {
            Eigen::Vector3d t, n, w;
            blades.frame(s, theta, t, n, w);
            const double along = (x - blades.hinge).dot(t), d = (x - blades.hinge).dot(n);
            if (along >= 0 && along <= blades.length_mm && std::abs(x.dot(w)) <= 1.0) {
                EXPECT_GT(d, -0.02) << "node " << node;
            }
        }
    }
    EXPECT_GT(r.min_J, 0.0);
}

// Blades with friction (serrated jaws): a node pressed on a blade sticks to its grip point until the tangential
// force reaches μλ, then slides with μλ.
TEST(ClipBody, FrictionForcesAndTangentAreTheEnergysDerivatives) {
    const Block b;
    Eigen::VectorXd v = Eigen::VectorXd::Zero(13);
    v.segment<3>(6) = place(b, fem::ClipBlades{}, 2, 0.2, 4.01, 0.02, 0.004);
    v.segment<3>(9) = place(b, fem::ClipBlades{}, 3, 0.2, 3.98, 0.01, 0.007);
    v[12] = 0.2;
    fem::ClipContactParams p;
    p.friction = 0.3;
    p.stiffness = 2000;
    p.stick_mm = 1e-3;
    // Node 2 sticks (its grip 0.5 µm away, inside ε = 1 µm); node 3 slides (its grip 0.1 mm away).
    const double th = 0.2;
    Eigen::Vector3d t, n, w;
    fem::ClipBlades bl;
    bl.frame(1, th, t, n, w);
    const Eigen::Vector3d x2 = b.X.row(2).transpose() + v.segment<3>(6);
    bl.frame(-1, th, t, n, w);
    const Eigen::Vector3d x3 = b.X.row(3).transpose() + v.segment<3>(9);
    Eigen::Vector3d t1, n1, w1;
    bl.frame(1, th, t1, n1, w1);
    const std::vector<fem::BladeGrip> grips{{2, 1, x2.dot(t1) + 0.0004, x2.dot(w1) - 0.0003, 20.0}, {3, -1, x3.dot(t) - 0.08, x3.dot(w) + 0.06, 0.5}};
    const fem::ClipBody clip(*b.body, b.X, {2, 3}, v, bl, test_spring(), p, &grips);
    const fem::BladeLoads L = clip.loads(v);
    EXPECT_EQ(L.sliding[0], 0);
    EXPECT_EQ(L.sliding[1], 1);
    const double s2 = std::hypot(0.0004, 0.0003) / 1e-3;
    EXPECT_NEAR(L.friction_n[0], 0.3 * 20.0 * (2 * s2 - s2 * s2), 1e-9);   // sticking: μλ (2s − s²), s = |Δ|/ε
    EXPECT_NEAR(L.friction_n[1], 0.3 * 0.5, 1e-12);                        // sliding: μ λ
    expect_derivatives(clip, v, 6, 1e-8);
    // A grip on a node that cannot touch the blades is an input error, as is a negative coefficient.
    const std::vector<fem::BladeGrip> bad{{0, 1, 0, 0, 1.0}};
    EXPECT_THROW(fem::ClipBody(*b.body, b.X, {2, 3}, v, bl, test_spring(), p, &bad), InputError);
    p.friction = -0.1;
    EXPECT_THROW(fem::ClipBody(*b.body, b.X, {2, 3}, v, bl, test_spring(), p), InputError);
}

TEST(ClipBody, AGrippedNodeHoldsUpToMuLambdaThenSlides) {
    // The block between held blades; then its ground springs are pulled along blade +1 by δ. The node's normal
    // force λ does not change (isotropic ground spring, flat blade), and along the blade the ground spring and the
    // grip balance: K (δ − y) = μλ (2s − s²), s = y/ε, y the node's slip, while it sticks; μλ once it slides.
    const Block b;
    fem::ClipContactParams p;
    p.friction = 0.3;
    const fem::ClipBlades bl;
    const double th = 0.2;
    Eigen::VectorXd v0 = Eigen::VectorXd::Zero(13);
    v0[12] = 40 * DEG;
    const fem::ClipBody open(*b.body, b.X, {2, 3}, v0, bl, test_spring(), p);
    fem::NewtonOptions no;
    no.tolerance = 1e-12;
    const fem::NewtonResult r1 = fem::solve_neo_hookean(open, b.fixed, {{12, th}}, v0, no);
    const std::vector<fem::BladeGrip> g1 = open.grips(r1.u);
    ASSERT_EQ(g1.size(), 2u);
    const double lambda = g1[0].normal_n, limit = 0.3 * lambda;
    EXPECT_NEAR(lambda, open.loads(r1.u).force_n[0], 1e-12);
    Eigen::Vector3d t, n, w;
    bl.frame(1, th, t, n, w);
    for (const double delta : {0.3 * limit / Block::K, 3 * limit / Block::K + 0.01}) {
        const fem::ClipBody held(*b.body, b.X, {2, 3}, r1.u, bl, test_spring(), p, &g1);
        Eigen::VectorXi fixed(3);
        fixed << 3, 4, 5;
        std::vector<std::pair<int, double>> pre{{12, th}};
        for (int k = 0; k < 3; ++k) pre.emplace_back(k, delta * t[k]);
        const fem::NewtonResult r2 = fem::solve_neo_hookean(held, fixed, pre, r1.u, no);
        const fem::BladeLoads L = held.loads(r2.u);
        EXPECT_NEAR(L.force_n[0], lambda, 1e-9 * lambda) << "the normal force stays";
        const double y = (r2.u - r1.u).segment<3>(6).dot(t);  // the node's slip along the blade
        if (delta < limit / Block::K) {
            EXPECT_EQ(L.sliding[0], 0);
            EXPECT_GT(y, 0.0);
            EXPECT_LT(y, p.stick_mm);
            EXPECT_NEAR(L.friction_n[0], Block::K * (delta - y), 1e-9 * limit);
            EXPECT_LT(L.friction_n[0], limit);
        } else {
            EXPECT_EQ(L.sliding[0], 1);
            EXPECT_NEAR(L.friction_n[0], limit, 1e-9 * limit);
            EXPECT_NEAR(Block::K * (delta - y), limit, 1e-9 * limit);
            // The grip slid with the node: the next grip trails it by ε.
            const std::vector<fem::BladeGrip> g2 = held.grips(r2.u);
            const Eigen::Vector3d x = b.X.row(2).transpose() + r2.u.segment<3>(6);
            EXPECT_NEAR(x.dot(t) - g2[0].r, p.stick_mm, 1e-9);
        }
        // The other node, not pulled, stays where it gripped.
        EXPECT_NEAR(L.friction_n[1], 0.0, 1e-9);
    }
}

TEST(LinearBody, AnUpperTriangleIsMirroredAndHalfAMatrixIsRefused) {
    // A bundle's K holds its upper triangle: as given it would make forces K u that are not ½ uᵀ K u's gradient.
    const Block b;
    const Eigen::SparseMatrix<double, Eigen::RowMajor> full = b.body->tangent(Eigen::VectorXd::Zero(12));
    const Eigen::SparseMatrix<double, Eigen::RowMajor> upper = full.triangularView<Eigen::Upper>();
    const fem::LinearBody mirrored(upper, true);
    Eigen::VectorXd u(12);
    for (int k = 0; k < 12; ++k) u[k] = 0.01 * (k + 1) * (k % 2 ? 1 : -1);
    EXPECT_LT((mirrored.internal_force(u) - full * u).norm(), 1e-12 * (full * u).norm());
    EXPECT_NEAR(mirrored.energy(u), 0.5 * u.dot(full * u), 1e-15);
    EXPECT_THROW(fem::LinearBody(upper, false), InputError);
}
