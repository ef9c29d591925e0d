// SPDX-License-Identifier: MIT
#include "aneu/fem/clip.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Geometry>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "ccd.hpp"
#include "merged_pattern.hpp"

namespace aneu::fem {

using RowSparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;

ClipSpring ClipSpring::from_forces(double r_mm, double theta1, double f1, double theta2, double f2) {
    if (!(r_mm > 0) || !(theta1 >= 0) || !(theta2 > theta1) || !(f1 > 0) || !(f2 > f1))
        throw InputError("clip spring: need two closing forces 0 < f1 < f2 [N] at openings 0 <= theta1 < theta2 and a distance r > 0 (got r " +
                         std::to_string(r_mm) + " mm, " + std::to_string(f1) + " N at " + std::to_string(theta1) + " rad, " + std::to_string(f2) +
                         " N at " + std::to_string(theta2) + " rad)");
    ClipSpring s;
    s.k_nmm_per_rad = r_mm * (f2 - f1) / (theta2 - theta1);
    s.preload_rad = f1 * r_mm / s.k_nmm_per_rad - theta1;
    if (!(s.preload_rad > 0))
        throw InputError("clip spring: the two forces extrapolate to no closing force at opening 0 (preload " + std::to_string(s.preload_rad) +
                         " rad); a clip closes with a preload");
    return s;
}

double opening_angle(double r_mm, double opening_mm, double closed_gap_mm) {
    if (!(r_mm > 0) || !(opening_mm >= closed_gap_mm) || opening_mm - closed_gap_mm > 2 * r_mm)
        throw InputError("clip: an opening of " + std::to_string(opening_mm) + " mm cannot be reached " + std::to_string(r_mm) +
                         " mm from the hinge with a closed gap of " + std::to_string(closed_gap_mm) + " mm");
    return 2.0 * std::asin(0.5 * (opening_mm - closed_gap_mm) / r_mm);
}

void ClipBlades::frame(int s, double theta, Eigen::Vector3d& t, Eigen::Vector3d& n, Eigen::Vector3d& w) const {
    const double c = std::cos(0.5 * theta), sn = std::sin(0.5 * theta);
    t = c * axis + s * sn * up;
    n = sn * axis - s * c * up;
    w = axis.cross(up);
}

ClipBlades::FaceCoords ClipBlades::face_coords(double r, double a) const {
    FaceCoords c;
    c.s = r;
    c.a = a;
    if (!curved()) return c;
    c.rho_c = std::hypot(r - curve_from_mm, std::abs(curve_radius_mm) - (curve_radius_mm > 0 ? a : -a));
    if (r <= curve_from_mm) return c;
    // About the centre of curvature C = (r₀, R) in (r, a): with the side's sign g (a_g = g a, R_g = |R|), the point's
    // offset from C is (Δr, Δa) = (r − r₀, R_g − a_g), ρ = |(Δr, Δa)|, the angle turned φ = atan2(Δr, Δa), so
    // s = r₀ + R_g φ and a = g (R_g − ρ). At r = r₀ both equal the straight blade's (φ = 0, ρ = R_g − a_g).
    const double g = curve_radius_mm > 0 ? 1.0 : -1.0, R = std::abs(curve_radius_mm);
    const double dr = r - curve_from_mm, da = R - g * a, rr = dr * dr + da * da, rho = std::sqrt(rr);
    c.rho_c = rho;
    if (!(rho > 1e-9 * R)) {  // the centre itself: no direction (far from any blade valid here)
        c.s = curve_from_mm + R * 0.5 * PI;
        c.a = g * R;
        return c;
    }
    c.s = curve_from_mm + R * std::atan2(dr, da);
    c.a = g * (R - rho);
    // First derivatives on (r, a_g): ∂ρ = (Δr, −Δa)/ρ, ∂φ = (Δa, Δr)/ρ²; on a: × g.
    c.ds = Eigen::Vector2d(R * da / rr, g * R * dr / rr);
    c.da = Eigen::Vector2d(-g * dr / rho, da / rho);
    // Second derivatives: ρ's Hessian on (Δr, Δa) is (I − e eᵀ)/ρ, e = (Δr, Δa)/ρ (Δa = R_g − a_g flips the mixed
    // term's sign; a_g = g a flips it again for g < 0, the squares keep theirs); a = g (R_g − ρ). φ's on (r, a_g):
    // ∂²/∂r² = −2 Δr Δa/ρ⁴, ∂²/∂r∂a_g = (Δa² − Δr²)/ρ⁴, ∂²/∂a_g² = 2 Δr Δa/ρ⁴.
    const double r4 = rr * rr, rho3 = rr * rho;
    Eigen::Matrix2d hrho;
    hrho << da * da / rho3, g * dr * da / rho3, g * dr * da / rho3, dr * dr / rho3;
    c.ha = -g * hrho;
    c.hs << -2 * R * dr * da / r4, g * R * (da * da - dr * dr) / r4, g * R * (da * da - dr * dr) / r4, 2 * R * dr * da / r4;
    return c;
}

void ClipBlades::centre_line(double s, double& r, double& a, double& dr, double& da) const {
    if (!curved() || s <= curve_from_mm) {
        r = s;
        a = 0;
        dr = 1;
        da = 0;
        return;
    }
    const double g = curve_radius_mm > 0 ? 1.0 : -1.0, R = std::abs(curve_radius_mm), phi = (s - curve_from_mm) / R;
    r = curve_from_mm + R * std::sin(phi);
    a = g * R * (1 - std::cos(phi));
    dr = std::cos(phi);
    da = g * std::sin(phi);
}

void ClipBlades::check_curve() const {
    if (!curved()) return;
    const double R = std::abs(curve_radius_mm);
    if (!std::isfinite(R) || R < 2.0 || R <= width_mm)
        throw InputError("clip: a blade curve radius of " + std::to_string(curve_radius_mm) + " mm; expected 0 (straight) or |R| >= 2 mm and more than the blade's width (" +
                         std::to_string(width_mm) + " mm)");
    if (!(curve_from_mm >= 0) || curve_from_mm >= length_mm)
        throw InputError("clip: the blades' curve starts " + std::to_string(curve_from_mm) + " mm from the hinge; expected within the blade (0 to " +
                         std::to_string(length_mm) + " mm)");
    if ((length_mm - curve_from_mm) / R > 0.5 * PI + 1e-12)
        throw InputError("clip: a blade of " + std::to_string(length_mm - curve_from_mm) + " mm curved at a radius of " + std::to_string(R) +
                         " mm bends past 90 degrees; expected |R| >= " + std::to_string((length_mm - curve_from_mm) / (0.5 * PI)) + " mm");
}

bool ClipBlades::near_wedge(double theta, const Eigen::Vector3d& p, double margin) const {
    const Eigen::Vector3d rel = p - hinge, w = axis.cross(up);
    const double r = rel.dot(axis);
    if (r < -margin || r > length_mm + margin) return false;
    if (curved()) {  // along and across the curved blade's centre line
        const FaceCoords fc = face_coords(r, rel.dot(w));
        if (fc.s > length_mm + margin || std::abs(fc.a) > 0.5 * width_mm + margin) return false;
    } else if (std::abs(rel.dot(w)) > 0.5 * width_mm + margin) {
        return false;
    }
    const double rr = std::clamp(r, 0.0, length_mm);
    return std::abs(rel.dot(up)) <= rr * std::tan(0.5 * theta) + 0.5 * closed_gap_mm + thickness_mm + margin;
}

ClipBody::ClipBody(const ElasticBody& body, const Eigen::MatrixX3d& X, const std::vector<int>& candidates, const Eigen::VectorXd& v0,
                   const ClipBlades& blades, const ClipSpring& spring, const ClipContactParams& p, const std::vector<BladeGrip>* grips)
    : m_body(body), m_X(X), m_nodes(candidates), m_blades(blades), m_spring(spring), m_p(p) {
    if (3 * X.rows() != body.dofs()) throw InputError("clip: " + std::to_string(X.rows()) + " nodes for a body of " + std::to_string(body.dofs()) + " DOFs");
    for (int c : candidates)
        if (c < 0 || c >= X.rows()) throw InputError("clip: candidate node " + std::to_string(c) + " outside the body");
    if (!(spring.k_nmm_per_rad > 0) || !(spring.preload_rad >= 0)) throw InputError("clip: the spring needs k > 0 and a preload >= 0");
    if (!(blades.length_mm > 0) || !(blades.width_mm > 0) || !(blades.thickness_mm > 0) || !(blades.closed_gap_mm >= 0))
        throw InputError("clip: blade length, width and thickness must be > 0 and the closed gap >= 0");
    if (std::abs(blades.axis.norm() - 1) > 1e-9 || std::abs(blades.up.norm() - 1) > 1e-9 || std::abs(blades.axis.dot(blades.up)) > 1e-9)
        throw InputError("clip: the blade axis and opening direction must be orthonormal");
    blades.check_curve();
    if (!(blades.face_from_mm >= 0) || !(blades.face_from_mm < blades.length_mm))
        throw InputError("clip: the blades' faces begin " + std::to_string(blades.face_from_mm) + " mm from the hinge; expected within the blade (0 to " +
                         std::to_string(blades.length_mm) + " mm)");
    if (!(p.gap_mm > 0)) throw InputError("clip: the blades' barrier distance d̂ (gap) must be > 0 mm (got " + std::to_string(p.gap_mm) + ")");
    if (!(p.friction >= 0) || !std::isfinite(p.friction)) throw InputError("clip: the blades' friction coefficient must be >= 0 (got " + std::to_string(p.friction) + ")");
    if (!(p.stick_mm > 0)) throw InputError("clip: the friction's stick slip must be > 0 mm (got " + std::to_string(p.stick_mm) + ")");
    if (v0.size() != dofs()) throw InputError("clip: the starting state has " + std::to_string(v0.size()) + " entries, expected " + std::to_string(dofs()));
    m_rho = std::min({EDGE_MM, 0.5 * blades.thickness_mm, 0.25 * blades.width_mm, 0.25 * blades.length_mm});
    // Which blade faces each candidate can touch, and from where. A node in front of a blade where the solve starts
    // (D > 0) meets the barrier at its true distance. One just behind it (D ≤ 0, up to 0.02 mm: the blades moved
    // with the applier since the last frame, or the linear model's handover) meets it at a distance counted from
    // a tenth of d̂ behind where it is, so that it is pushed back out, not through (the barrier is infinite at
    // D = 0); deeper nodes are outside the clip (tissue beside the blades) and left alone.
    constexpr double BEHIND_AT_START = 0.02;  // mm: the interpenetration the issue allows
    if (p.stiffness > 0) {
        m_kappa = p.stiffness;
    } else {
        m_kappa = detail::max_diagonal(body);
    }
    for (int c : m_nodes) {
        std::array<bool, 2> f{};
        std::array<double, 2> off{0, 0};
        for (int i = 0; i < 2; ++i) {
            Touch tc;
            blades.frame(i == 0 ? 1 : -1, v0[body.dofs()], tc.t, tc.n, tc.w);
            const Eigen::Vector3d rel = X.row(c).transpose() + v0.segment<3>(3 * c) - blades.hinge;
            const double d = blade_distance(rel, tc);
            f[static_cast<size_t>(i)] = d >= -BEHIND_AT_START;
            if (d <= 0) off[static_cast<size_t>(i)] = d - 0.1 * p.gap_mm;
        }
        m_front.push_back(f);
        m_offset.push_back(off);
    }
    // The closed stop: blades that meet cannot close further. A penalty on θ < 0 stiff enough that the preload
    // pushes them past closed by 1e-4 of θ₀ at most.
    m_stop = 1e4 * spring.k_nmm_per_rad;

    m_grip.assign(m_nodes.size(), {});
    if (p.friction > 0) {
        if (grips) {
            std::vector<int> cand_of(static_cast<size_t>(X.rows()), -1);
            for (size_t k = 0; k < m_nodes.size(); ++k) cand_of[static_cast<size_t>(m_nodes[k])] = static_cast<int>(k);
            for (const BladeGrip& g : *grips) {
                if (g.node < 0 || g.node >= X.rows() || cand_of[static_cast<size_t>(g.node)] < 0 || (g.blade != 1 && g.blade != -1) ||
                    !(g.normal_n >= 0) || !std::isfinite(g.r) || !std::isfinite(g.a))
                    throw InputError("clip: a grip on node " + std::to_string(g.node) + ", blade " + std::to_string(g.blade) +
                                     ": expected a candidate node, blade +1 or -1 and a normal force >= 0");
                if (g.normal_n > 0)
                    m_grip[static_cast<size_t>(cand_of[static_cast<size_t>(g.node)])][g.blade > 0 ? 0 : 1] = Grip{true, g.r, g.a, g.normal_n};
            }
        } else {
            auto tc = touches(v0);
            for (size_t k = 0; k < m_nodes.size(); ++k)
                for (int s : {1, -1}) {
                    Touch& c = tc[s > 0 ? 0 : 1];
                    if (measure(v0, k, s, c)) m_grip[k][s > 0 ? 0 : 1] = Grip{true, c.r, c.a, press(c.d).f};
                }
        }
    }

}

void ClipBody::build_pattern() const {
    std::call_once(m_pattern_once, [this] {
        const auto th = static_cast<int>(m_body.dofs());
        std::vector<std::array<int, 4>> groups;  // each candidate's DOFs and θ
        groups.reserve(m_nodes.size() + 1);
        for (int c : m_nodes) groups.push_back({3 * c, 3 * c + 1, 3 * c + 2, th});
        groups.push_back({th, th, th, th});  // (θ, θ) even without candidates
        m_merged = detail::merge_pattern_cached(m_p.pattern_cache.get(), m_body.pattern(), dofs(), groups);
        for (size_t k = 0; k < m_nodes.size(); ++k) m_slots.push_back(m_merged->block(groups[k]));
    });
}

const Eigen::SparseMatrix<double, Eigen::RowMajor>& ClipBody::pattern() const {
    build_pattern();
    return m_merged->pattern;
}

std::array<ClipBody::Touch, 2> ClipBody::touches(const Eigen::VectorXd& v) const {
    std::array<Touch, 2> c;
    m_blades.frame(1, v[theta_dof()], c[0].t, c[0].n, c[0].w);
    m_blades.frame(-1, v[theta_dof()], c[1].t, c[1].n, c[1].w);
    return c;
}

double ClipBody::blade_distance(const Eigen::Vector3d& rel, Touch& c) const {
    // In the blade's frame: r along it from the hinge, a across it, p = the plane distance in front of its face.
    // The blade is the set within ρ of its core, the rectangle r ∈ [0, L − ρ] (from F + ρ with its faces beginning
    // at F, ClipBlades::face_from_mm), |a| ≤ W/2 − ρ at ρ behind the face:
    // a flat face of W − 2ρ with edges rounded to the radius ρ at the sides and the tip. Over the core the distance
    // is the plane's, however deep (a node that came through the face is pushed back out of it, not through it);
    // beside it the distance to the core's edge, the node's height above the core's plane counted only in front
    // of it (beside the blade, below its face, the blade's side pushes it sideways). A node more than ρ behind the
    // face right at the core's edge is the one place where the two disagree (it has come far through the blade).
    // A curved blade (ClipBlades::curved): the same in its face coordinates (s along the centre line, a across it).
    c.r = rel.dot(c.t);
    c.a = rel.dot(c.w);
    const double p = 0.5 * m_blades.closed_gap_mm + rel.dot(c.n);
    const double half = 0.5 * m_blades.width_mm - m_rho, tip = m_blades.length_mm - m_rho;
    c.curved = m_blades.curved();
    double along = c.r, across = c.a;
    if (c.curved) {
        c.fc = m_blades.face_coords(c.r, c.a);
        along = c.fc.s;
        across = c.fc.a;
    }
    const double vr = along - std::clamp(along, m_blades.core_from(m_rho, tip), tip), va = across - std::clamp(across, -half, half);
    if (vr == 0 && va == 0) {
        c.u = Eigen::Vector3d(0, 0, 1);
        c.dist = 0;
        return p;
    }
    const double vd = std::max(p + m_rho, 0.0), dist = std::sqrt(vr * vr + va * va + vd * vd);
    c.u = Eigen::Vector3d(vr, va, vd) / dist;
    c.dist = dist;
    c.mr = vr != 0 ? 1.0 : 0.0;
    c.ma = va != 0 ? 1.0 : 0.0;
    c.md = p + m_rho > 0 ? 1.0 : 0.0;
    return dist - m_rho;
}

ClipBody::Press ClipBody::press(double D) const {
    // The barrier κ d̂² b(D/d̂), b(x) = −(x − 1)² ln x (Li et al. 2020): zero from d̂ outward, C2 there, infinite at
    // D = 0. With b' and b'': e = κ d̂² b, f = −κ d̂ b' (≥ 0, the push), k = κ b'' (> 0).
    const double dh = m_p.gap_mm;
    Press r;
    if (D >= dh) return r;
    if (D <= 0) {
        r.e = std::numeric_limits<double>::infinity();
        return r;
    }
    const double x = D / dh, l = std::log(x), m = x - 1;
    r.e = m_kappa * dh * dh * (-m * m * l);
    r.f = -m_kappa * dh * (-2 * m * l - m * m / x);
    r.k = m_kappa * (-2 * l - 4 * m / x + m * m / (x * x));
    return r;
}

bool ClipBody::measure(const Eigen::VectorXd& v, size_t k, int s, Touch& c) const {
    if (!m_front[k][s > 0 ? 0 : 1]) return false;
    const int node = m_nodes[k];
    const Eigen::Vector3d rel = m_X.row(node).transpose() + v.segment<3>(3 * node) - m_blades.hinge;
    c.d = blade_distance(rel, c) - m_offset[k][s > 0 ? 0 : 1];
    c.q = rel.dot(c.n);
    return c.d < m_p.gap_mm;
}

bool ClipBody::pair_terms(const Eigen::VectorXd& v, size_t k, int s, Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H,
                          bool project) const {
    if (!measure(v, k, s, c)) return false;
    // ψ(D) (press(): the barrier), dP = −∇D; ∇D = u_r ∇r + u_a ∇a + u_d ∇p in the blade's
    // frame (u: the unit vector from the core's nearest point), with ∇r = (t, −q/2), ∇a = (w, 0), ∇p = (n, r/2),
    // q = rel·n.
    if (c.curved) return pair_terms_curved(c, e, grad, H, project);
    Eigen::Vector4d dP;
    dP << -(c.u[0] * c.t + c.u[1] * c.w + c.u[2] * c.n), -(c.u[0] * (-0.5 * c.q) + c.u[2] * 0.5 * c.r);
    const Press pr = press(c.d);
    e = pr.e;
    if (!std::isfinite(e)) return true;  // on or behind the face: infinite energy (a step that got there is rejected)
    grad = pr.f * dP;
    if (H) {
        // ψ'' ∇P ∇Pᵀ (Gauss–Newton) + ψ' ∇²P: from the frame's turning with θ (∂²r/∂x∂θ = −n/2, ∂²r/∂θ² = −r/4,
        // ∂²p/∂x∂θ = t/2, ∂²p/∂θ² = −q/4) and, round a rounded edge, from the turning of u there: in the blade's
        // frame y = (r, a, p) the distance |v| − ρ to the core has the Hessian M (I − u uᵀ) M / |v| (M: the
        // components of v that follow y), carried to (x, θ) by J = ∂y/∂(x, θ). Both are dropped for a projected
        // (semidefinite) tangent; without the edge's part Newton converges only linearly where nodes press round
        // an edge (a sac bulging beside a narrow blade).
        *H = pr.k * dP * dP.transpose();
        if (!project && c.dist > 0) {
            Eigen::Matrix<double, 3, 4> J;
            J << c.t.transpose(), -0.5 * c.q, c.w.transpose(), 0.0, c.n.transpose(), 0.5 * c.r;
            const Eigen::Vector3d m(c.mr, c.ma, c.md);
            const Eigen::Matrix3d Hy = m.asDiagonal() * (Eigen::Matrix3d::Identity() - c.u * c.u.transpose()) * m.asDiagonal() / c.dist;
            *H -= pr.f * J.transpose() * Hy * J;
        }
        if (!project) {
            const double kp = pr.f;
            const Eigen::Vector3d xt = -(c.u[0] * (-0.5) * c.n + c.u[2] * 0.5 * c.t);
            H->block<3, 1>(0, 3) += kp * xt;
            H->block<1, 3>(3, 0) += kp * xt.transpose();
            (*H)(3, 3) += -kp * (c.u[0] * (-0.25 * c.r) + c.u[2] * (-0.25 * c.q));
        }
    }
    return true;
}

bool ClipBody::pair_terms_curved(const Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H, bool project) const {
    // pair_terms on a curved blade: D = |v| − ρ in the face coordinates y = (s, a, p) (p as on a straight blade), each
    // a function of the straight ones (r, a) (ClipBlades::face_coords). On (x, θ): ∇r = (t, −q/2), ∇a = (w, 0),
    // ∇p = (n, r/2), ∇s = s_r ∇r + s_a ∇a (and a's alike); ∇²r has ∂²r/∂x∂θ = −n/2, ∂²r/∂θ² = −r/4, ∇²p has
    // ∂²p/∂x∂θ = t/2, ∂²p/∂θ² = −q/4, ∇²a = 0, and ∇²s = s_r ∇²r + Gᵀ S G with G = (∇r; ∇a), S the 2 × 2 Hessian of s
    // on (r, a). ∇²D = Jᵀ Hy J + Σ u_i ∇²y_i (J = ∂y/∂(x, θ), Hy the edge's part as on a straight blade).
    Eigen::Vector4d gr, ga, gp;
    gr << c.t, -0.5 * c.q;
    ga << c.w, 0.0;
    gp << c.n, 0.5 * c.r;
    const Eigen::Vector4d gs = c.fc.ds[0] * gr + c.fc.ds[1] * ga, gac = c.fc.da[0] * gr + c.fc.da[1] * ga;
    const Eigen::Vector4d dP = -(c.u[0] * gs + c.u[1] * gac + c.u[2] * gp);
    const Press pr = press(c.d);
    e = pr.e;
    if (!std::isfinite(e)) return true;
    grad = pr.f * dP;
    if (!H) return true;
    *H = pr.k * dP * dP.transpose();
    if (project) return true;
    Eigen::Matrix4d hr = Eigen::Matrix4d::Zero(), hp = Eigen::Matrix4d::Zero();
    hr.block<3, 1>(0, 3) = -0.5 * c.n;
    hr.block<1, 3>(3, 0) = -0.5 * c.n.transpose();
    hr(3, 3) = -0.25 * c.r;
    hp.block<3, 1>(0, 3) = 0.5 * c.t;
    hp.block<1, 3>(3, 0) = 0.5 * c.t.transpose();
    hp(3, 3) = -0.25 * c.q;
    Eigen::Matrix<double, 2, 4> G;
    G.row(0) = gr.transpose();
    G.row(1) = ga.transpose();
    const Eigen::Matrix4d hs = c.fc.ds[0] * hr + G.transpose() * c.fc.hs * G;
    const Eigen::Matrix4d hac = c.fc.da[0] * hr + G.transpose() * c.fc.ha * G;
    Eigen::Matrix4d d2 = c.u[0] * hs + c.u[1] * hac + c.u[2] * hp;
    if (c.dist > 0) {
        Eigen::Matrix<double, 3, 4> J;
        J.row(0) = gs.transpose();
        J.row(1) = gac.transpose();
        J.row(2) = gp.transpose();
        const Eigen::Vector3d m(c.mr, c.ma, c.md);
        const Eigen::Matrix3d Hy = m.asDiagonal() * (Eigen::Matrix3d::Identity() - c.u * c.u.transpose()) * m.asDiagonal() / c.dist;
        d2 += J.transpose() * Hy * J;
    }
    *H -= pr.f * d2;
    return true;
}

bool ClipBody::grip_terms(const Eigen::VectorXd& v, size_t k, int s, const Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H,
                          bool project, bool* slid) const {
    const Grip& g = m_grip[k][s > 0 ? 0 : 1];
    if (!g.on) return false;
    const int node = m_nodes[k];
    const Eigen::Vector3d rel = m_X.row(node).transpose() + v.segment<3>(3 * node) - m_blades.hinge;
    const double r = rel.dot(c.t), q = rel.dot(c.n);
    const Eigen::Vector2d D(r - g.r, rel.dot(c.w) - g.a);  // the slip from the grip point, along t and w
    const double y = D.norm(), limit = m_p.friction * g.lambda;  // the largest tangential force [N]
    const double eps = m_p.stick_mm;
    // J = ∂(Δ_t, Δ_w)/∂(x, θ): ∂r/∂x = t, ∂r/∂θ = rel·∂t/∂θ = −q/2; ∂a/∂x = w, ∂a/∂θ = 0.
    Eigen::Matrix<double, 2, 4> J;
    J << c.t.transpose(), -0.5 * q, c.w.transpose(), 0.0;
    Eigen::Vector2d gD;
    Eigen::Matrix2d HD;
    // ψ(y) = μλ ε f(y/ε), f(s) = s² − s³/3 (s < 1), s − 1/3 beyond: the force ψ' = μλ (2s − s²) rises smoothly to
    // μλ at the slip ε and stays there (ψ is C2, so Newton keeps its pace across stick and slip).
    const double sl = y / eps;
    if (sl < 1) {  // sticking
        e = limit * eps * (sl * sl - sl * sl * sl / 3);
        const double over_y = limit / eps * (2 - sl);                // ψ'/y
        const double d2 = limit / eps * (2 - 2 * sl);                // ψ''
        gD = over_y * D;
        HD = over_y * Eigen::Matrix2d::Identity();
        if (y > 0) HD += (d2 - over_y) * D * D.transpose() / (y * y);
        if (slid) *slid = false;
    } else {  // sliding: the force stays μλ along the slip
        e = limit * (y - eps / 3);
        gD = (limit / y) * D;
        HD = (limit / y) * (Eigen::Matrix2d::Identity() - D * D.transpose() / (y * y));
        if (slid) *slid = true;
    }
    grad = J.transpose() * gD;
    if (H) {
        *H = J.transpose() * HD * J;
        if (!project) {  // + ∂ψ/∂r ∇²r: ∂²r/∂x∂θ = −n/2, ∂²r/∂θ² = −r/4
            H->block<3, 1>(0, 3) -= 0.5 * gD[0] * c.n;
            H->block<1, 3>(3, 0) -= 0.5 * gD[0] * c.n.transpose();
            (*H)(3, 3) -= 0.25 * gD[0] * r;
        }
    }
    return true;
}

std::vector<BladeGrip> ClipBody::grips(const Eigen::VectorXd& v) const {
    std::vector<BladeGrip> out;
    if (!(m_p.friction > 0)) return out;
    auto tc = touches(v);
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            Touch c = tc[s > 0 ? 0 : 1];
            const int node = m_nodes[k];
            const Eigen::Vector3d rel = m_X.row(node).transpose() + v.segment<3>(3 * node) - m_blades.hinge;
            const Eigen::Vector2d at(rel.dot(c.t), rel.dot(c.w));
            if (!measure(v, k, s, c)) continue;  // not pressing: let go
            BladeGrip g;
            g.node = node;
            g.blade = s;
            g.normal_n = press(c.d).f;
            Eigen::Vector2d anchor = at;
            const Grip& old = m_grip[k][s > 0 ? 0 : 1];
            if (old.on) {
                anchor = Eigen::Vector2d(old.r, old.a);
                const Eigen::Vector2d D = at - anchor;
                const double y = D.norm();
                if (y > m_p.stick_mm) anchor = at - D * (m_p.stick_mm / y);  // slid: the grip trails its node by ε
            }
            g.r = anchor[0];
            g.a = anchor[1];
            out.push_back(g);
        }
    return out;
}

Eigen::VectorXd ClipBody::separated(const Eigen::VectorXd& v, double delta_mm) const {
    if (v.size() != dofs()) throw InputError("clip: the state to separate has the wrong size");
    if (!(delta_mm > 0) || !(delta_mm < m_p.gap_mm)) throw InputError("clip: separate the nodes from the blades by more than 0 and less than the barrier's gap");
    Eigen::VectorXd out = v;
    for (int pass = 0; pass < 4; ++pass) {
        auto tc = touches(out);
        bool moved = false;
        for (size_t k = 0; k < m_nodes.size(); ++k)
            for (int s : {1, -1}) {
                // (The distance itself, not the barrier's: a node that started on the face or just behind it meets the
                // barrier as if the face were a little behind, m_offset.)
                Touch& c = tc[s > 0 ? 0 : 1];
                if (!m_front[k][s > 0 ? 0 : 1]) continue;
                const int node = m_nodes[k];
                const double D = blade_distance(m_X.row(node).transpose() + out.segment<3>(3 * node) - m_blades.hinge, c);
                if (D >= 0.999 * delta_mm) continue;
                // ∇D in x: the unit vector from the core's nearest point, in the blade's frame (a curved blade's: its
                // face's normal, near enough for a move of d̂ / 2).
                const Eigen::Vector3d dir = c.curved ? c.n : Eigen::Vector3d(c.u[0] * c.t + c.u[1] * c.w + c.u[2] * c.n);
                if (!(dir.norm() > 0)) continue;
                out.segment<3>(3 * node) += (delta_mm - D) * dir.normalized();
                moved = true;
            }
        if (!moved) break;
    }
    return out;
}

double ClipBody::energy(const Eigen::VectorXd& v) const {
    double e = m_body.energy(v.head(m_body.dofs()));
    if (!std::isfinite(e)) return e;
    const double theta = v[theta_dof()];
    e += m_spring.energy(theta);
    if (theta < 0) e += 0.5 * m_stop * theta * theta;
    auto tc = touches(v);
    double ek;
    Eigen::Vector4d gk;
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            if (pair_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, nullptr, false)) e += ek;
            if (grip_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, nullptr, false)) e += ek;
        }
    return e;
}

Eigen::VectorXd ClipBody::internal_force(const Eigen::VectorXd& v) const {
    Eigen::VectorXd g(dofs());
    g.head(m_body.dofs()) = m_body.internal_force(v.head(m_body.dofs()));
    const double theta = v[theta_dof()];
    double& gt = g[theta_dof()];
    gt = m_spring.torque(theta) + (theta < 0 ? m_stop * theta : 0.0);
    auto tc = touches(v);
    double ek;
    Eigen::Vector4d gk;
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            if (pair_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, nullptr, false)) {
                if (!std::isfinite(ek)) throw NumericalError("clip: node " + std::to_string(m_nodes[k]) + " lies on or behind a blade's face");
                g.segment<3>(3 * m_nodes[k]) += gk.head<3>();
                gt += gk[3];
            }
            if (grip_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, nullptr, false)) {
                g.segment<3>(3 * m_nodes[k]) += gk.head<3>();
                gt += gk[3];
            }
        }
    return g;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> ClipBody::tangent(const Eigen::VectorXd& v, bool project) const {
    build_pattern();
    RowSparse K = m_merged->pattern;
    add_tangent(v, project, K.valuePtr(), nullptr);
    return K;
}

void ClipBody::add_tangent(const Eigen::VectorXd& v, bool project, double* values, const std::int64_t* where) const {
    build_pattern();
    detail::add_body_tangent(m_body, v.head(m_body.dofs()), project, values, where, *m_merged, m_compose, m_compose_mutex);
    add_own_tangent(v, project, values, where);
}

void ClipBody::add_own_tangent(const Eigen::VectorXd& v, bool project, double* values, const std::int64_t* where) const {
    auto at = [&](std::int64_t slot) -> double& { return values[where ? where[slot] : slot]; };
    const double theta = v[theta_dof()];
    const auto th = theta_dof();
    at(m_merged->pattern.outerIndexPtr()[th + 1] - 1) += m_spring.k_nmm_per_rad + (theta < 0 ? m_stop : 0.0);  // (θ, θ): last in its row
    auto tc = touches(v);
    double ek;
    Eigen::Vector4d gk;
    Eigen::Matrix4d H;
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            if (pair_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, &H, project)) {
                if (!std::isfinite(ek)) throw NumericalError("clip: node " + std::to_string(m_nodes[k]) + " lies on or behind a blade's face");
                for (int i = 0; i < 4; ++i)
                    for (int j = 0; j < 4; ++j) at(m_slots[k][static_cast<size_t>(4 * i + j)]) += H(i, j);
            }
            if (grip_terms(v, k, s, tc[s > 0 ? 0 : 1], ek, gk, &H, project))
                for (int i = 0; i < 4; ++i)
                    for (int j = 0; j < 4; ++j) at(m_slots[k][static_cast<size_t>(4 * i + j)]) += H(i, j);
        }
}

double ClipBody::max_step(const Eigen::VectorXd& v, const Eigen::VectorXd& dv) const {
    // Additive CCD (Li, Kaufman & Jiang 2021), as for the walls (ContactBody::max_step): a node's distance D from a
    // blade is 1-Lipschitz in its place in the blade's frame, and along the step that place moves by at most
    // l = |Δx| + R |Δθ|/2 (the blade turns by θ/2 about the hinge; R bounds the node's distance from the hinge on
    // the way), so advancing by a fraction of D / l at a time never reaches the face; stop where D is a tenth of
    // its start.
    double alpha = m_body.max_step(v.head(m_body.dofs()), dv.head(m_body.dofs()));
    const double dth = std::abs(dv[theta_dof()]);
    for (size_t k = 0; k < m_nodes.size(); ++k) {
        const int node = m_nodes[k];
        const Eigen::Vector3d x0 = m_X.row(node).transpose() + v.segment<3>(3 * node), dx = dv.segment<3>(3 * node);
        const double R = (x0 - m_blades.hinge).norm() + dx.norm();
        double l = dx.norm() + 0.5 * R * dth;
        if (m_blades.curved()) {
            // On a curved blade s changes by up to |R_c|/ρ_c per mm across the face (ρ_c: the distance from the
            // centre of curvature, which the step can shorten by l): D is that Lipschitz, not 1.
            const double Rc = std::abs(m_blades.curve_radius_mm);
            double rho_c = std::numeric_limits<double>::infinity();
            for (int s : {1, -1}) {
                Touch c;
                m_blades.frame(s, v[theta_dof()], c.t, c.n, c.w);
                const Eigen::Vector3d rel = x0 - m_blades.hinge;
                rho_c = std::min(rho_c, m_blades.face_coords(rel.dot(c.t), rel.dot(c.w)).rho_c);
            }
            if (std::isfinite(rho_c)) l *= std::max(1.0, Rc / std::max(rho_c - l, 0.25 * Rc));
        }
        if (!(l > 0)) continue;
        for (int s : {1, -1}) {
            const size_t i = s > 0 ? 0 : 1;
            if (!m_front[k][i]) continue;
            auto dist = [&](double t) {
                Touch c;
                m_blades.frame(s, v[theta_dof()] + t * dv[theta_dof()], c.t, c.n, c.w);
                return blade_distance(x0 + t * dx - m_blades.hinge, c) - m_offset[k][i];
            };
            const double d0 = dist(0);
            if (!(d0 > 0)) return 0;  // already on the face: no step is admissible
            alpha = detail::additive_ccd(d0, l, alpha, dist);
        }
    }
    return alpha;
}

BladeLoads ClipBody::loads(const Eigen::VectorXd& v) const {
    BladeLoads b;
    b.opening_rad = v[theta_dof()];
    b.spring_torque_nmm = m_spring.torque(b.opening_rad);
    auto tc = touches(v);
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            Touch& c = tc[s > 0 ? 0 : 1];
            double e;
            Eigen::Vector4d g;
            const size_t i = s > 0 ? 0 : 1;
            bool slid = false;
            if (grip_terms(v, k, s, c, e, g, nullptr, false, &slid)) {
                b.net_force += g.head<3>();
                b.friction_n[i] += g.head<3>().norm();  // along the face (t and w)
                b.moment_nmm[i] -= 2 * g[3];  // a radial friction force's moment about the hinge (the face is off it)
                if (slid) ++b.sliding[i];
            }
            if (!pair_terms(v, k, s, c, e, g, nullptr, false)) continue;
            if (!std::isfinite(e)) {  // on or behind the face (a state no solve ends in, e.g. the blades moved on
                ++b.contacts[i];      // ahead of a solve): it touches, with no finite force to report
                continue;
            }
            b.net_force += g.head<3>();  // ∂E/∂x of the node: minus the force the blade applies to it
            const double f = press(c.d).f;
            b.force_n[i] += f;
            b.moment_nmm[i] -= 2 * g[3];  // f r on the face; around a rounded edge the force's own lever
            ++b.contacts[i];
        }
    return b;
}

LinearBody::LinearBody(Eigen::SparseMatrix<double, Eigen::RowMajor> K, bool upper_only) : m_K(std::move(K)) {
    if (m_K.rows() != m_K.cols()) throw InputError("linear body: K must be square");
    if (upper_only) {
        m_K = RowSparse(m_K.selfadjointView<Eigen::Upper>());
    } else {
        // Half a matrix here would give forces K u that are not the energy's gradient (the solve then wanders).
        const double asym = (m_K - RowSparse(m_K.transpose())).norm();
        if (!(asym <= 1e-12 * m_K.norm()))
            throw InputError("linear body: K must be symmetric with both triangles stored (a bundle's upper-triangle K needs upper_only)");
    }
    m_K.makeCompressed();
}

double next_spring_opening(double theta, double R, double k, bool held, bool touching) {
    if (!(k > 0)) return theta;
    double step = R / k;  // > 0: closing
    if (step < 0) step = std::max(step, -1.0 * DEG);
    else {
        if (!held) step = std::min(step, 1.0 * DEG);
        if (touching) step = std::min(step, 0.5 * theta);
    }
    return std::max(0.0, theta - step);
}

}  // namespace aneu::fem
