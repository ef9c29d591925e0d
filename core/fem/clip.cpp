// SPDX-License-Identifier: MIT
#include "aneu/fem/clip.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include "aneu/core/error.hpp"

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

ClipBody::ClipBody(const ElasticBody& body, const Eigen::MatrixX3d& X, const std::vector<int>& candidates, const Eigen::VectorXd& v0,
                   const ClipBlades& blades, const ClipSpring& spring, const ClipContactParams& p)
    : m_body(body), m_X(X), m_nodes(candidates), m_blades(blades), m_spring(spring), m_p(p) {
    if (3 * X.rows() != body.dofs()) throw InputError("clip: " + std::to_string(X.rows()) + " nodes for a body of " + std::to_string(body.dofs()) + " DOFs");
    for (int c : candidates)
        if (c < 0 || c >= X.rows()) throw InputError("clip: candidate node " + std::to_string(c) + " outside the body");
    if (!(spring.k_nmm_per_rad > 0) || !(spring.preload_rad >= 0)) throw InputError("clip: the spring needs k > 0 and a preload >= 0");
    if (!(blades.length_mm > 0) || !(blades.width_mm > 0) || !(blades.thickness_mm > 0) || !(blades.closed_gap_mm >= 0))
        throw InputError("clip: blade length, width and thickness must be > 0 and the closed gap >= 0");
    if (std::abs(blades.axis.norm() - 1) > 1e-9 || std::abs(blades.up.norm() - 1) > 1e-9 || std::abs(blades.axis.dot(blades.up)) > 1e-9)
        throw InputError("clip: the blade axis and opening direction must be orthonormal");
    if (!(p.gap_mm >= 0)) throw InputError("clip: the contact gap must be >= 0");
    if (v0.size() != dofs()) throw InputError("clip: the starting state has " + std::to_string(v0.size()) + " entries, expected " + std::to_string(dofs()));
    constexpr double BEHIND_AT_START = 0.02;  // mm: the interpenetration a step may end with (the limit)
    for (int c : m_nodes) {
        std::array<bool, 2> f{};
        for (int i = 0; i < 2; ++i) {
            Eigen::Vector3d t, n, w;
            blades.frame(i == 0 ? 1 : -1, v0[body.dofs()], t, n, w);
            const Eigen::Vector3d rel = X.row(c).transpose() + v0.segment<3>(3 * c) - blades.hinge;
            f[static_cast<size_t>(i)] = 0.5 * blades.closed_gap_mm + rel.dot(n) >= -BEHIND_AT_START;
        }
        m_front.push_back(f);
    }
    if (p.stiffness > 0) {
        m_kappa = p.stiffness;
    } else {
        const RowSparse K0 = body.tangent(Eigen::VectorXd::Zero(body.dofs()));
        double dmax = 0;
        for (Eigen::Index r = 0; r < K0.rows(); ++r) dmax = std::max(dmax, K0.coeff(r, r));
        m_kappa = 100.0 * dmax;
    }
    // The closed stop: blades that meet cannot close further. A penalty on θ < 0 stiff enough that the preload
    // pushes them past closed by 1e-4 of θ₀ at most.
    m_stop = 1e4 * spring.k_nmm_per_rad;

    const RowSparse& bp = body.pattern();
    const auto th = static_cast<int>(body.dofs());
    std::vector<Eigen::Triplet<double>> tp;
    tp.reserve(static_cast<size_t>(bp.nonZeros()) + 16 * m_nodes.size() + 1);
    for (Eigen::Index r = 0; r < bp.outerSize(); ++r)
        for (RowSparse::InnerIterator it(bp, r); it; ++it) tp.emplace_back(static_cast<int>(r), static_cast<int>(it.col()), 0.0);
    auto dofs_of = [&](int c) { return std::array<int, 4>{3 * c, 3 * c + 1, 3 * c + 2, th}; };
    for (int c : m_nodes)
        for (int i : dofs_of(c))
            for (int j : dofs_of(c)) tp.emplace_back(i, j, 0.0);
    tp.emplace_back(th, th, 0.0);
    m_pattern.resize(dofs(), dofs());
    m_pattern.setFromTriplets(tp.begin(), tp.end());
    m_pattern.makeCompressed();
    auto position = [&](Eigen::Index r, Eigen::Index c) {
        const int* cols = m_pattern.innerIndexPtr() + m_pattern.outerIndexPtr()[r];
        const int* end = m_pattern.innerIndexPtr() + m_pattern.outerIndexPtr()[r + 1];
        return static_cast<std::int64_t>(m_pattern.outerIndexPtr()[r] + (std::lower_bound(cols, end, static_cast<int>(c)) - cols));
    };
    for (Eigen::Index r = 0; r < bp.outerSize(); ++r)
        for (RowSparse::InnerIterator it(bp, r); it; ++it) m_body_to_pattern.push_back(position(r, it.col()));
    for (int c : m_nodes) {
        const auto d = dofs_of(c);
        std::array<std::int64_t, 16> s{};
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) s[static_cast<size_t>(4 * i + j)] = position(d[static_cast<size_t>(i)], d[static_cast<size_t>(j)]);
        m_slots.push_back(s);
    }
}

bool ClipBody::measure(const Eigen::VectorXd& v, size_t k, int s, double& d, double& r, Eigen::Vector3d& t, Eigen::Vector3d& n) const {
    if (!m_front[k][s > 0 ? 0 : 1]) return false;
    const int node = m_nodes[k];
    const double theta = v[theta_dof()];
    Eigen::Vector3d w;
    m_blades.frame(s, theta, t, n, w);
    const Eigen::Vector3d rel = m_X.row(node).transpose() + v.segment<3>(3 * node) - m_blades.hinge;
    r = rel.dot(t);
    d = 0.5 * m_blades.closed_gap_mm + rel.dot(n);
    return r >= 0 && r <= m_blades.length_mm && std::abs(rel.dot(w)) <= 0.5 * m_blades.width_mm && d < m_p.gap_mm;
}

double ClipBody::energy(const Eigen::VectorXd& v) const {
    double e = m_body.energy(v.head(m_body.dofs()));
    if (!std::isfinite(e)) return e;
    const double theta = v[theta_dof()];
    e += m_spring.energy(theta);
    if (theta < 0) e += 0.5 * m_stop * theta * theta;
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            double d, r;
            Eigen::Vector3d t, n;
            if (measure(v, k, s, d, r, t, n)) e += 0.5 * m_kappa * (m_p.gap_mm - d) * (m_p.gap_mm - d);
        }
    return e;
}

Eigen::VectorXd ClipBody::internal_force(const Eigen::VectorXd& v) const {
    Eigen::VectorXd g(dofs());
    g.head(m_body.dofs()) = m_body.internal_force(v.head(m_body.dofs()));
    const double theta = v[theta_dof()];
    double& gt = g[theta_dof()];
    gt = m_spring.torque(theta) + (theta < 0 ? m_stop * theta : 0.0);
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            double d, r;
            Eigen::Vector3d t, n;
            if (!measure(v, k, s, d, r, t, n)) continue;
            const double q = -m_kappa * (m_p.gap_mm - d);  // ∂E/∂d
            g.segment<3>(3 * m_nodes[k]) += q * n;                   // ∂d/∂x = n
            gt += q * 0.5 * r;                               // ∂d/∂θ = r/2
        }
    return g;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> ClipBody::tangent(const Eigen::VectorXd& v, bool project) const {
    const RowSparse Kb = m_body.tangent(v.head(m_body.dofs()), project);
    RowSparse K = m_pattern;
    double* val = K.valuePtr();
    for (size_t p = 0; p < m_body_to_pattern.size(); ++p) val[m_body_to_pattern[p]] += Kb.valuePtr()[p];
    const double theta = v[theta_dof()];
    const auto th = theta_dof();
    val[m_pattern.outerIndexPtr()[th + 1] - 1] += m_spring.k_nmm_per_rad + (theta < 0 ? m_stop : 0.0);  // (θ, θ): last in its row
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            double d, r;
            Eigen::Vector3d t, n;
            if (!measure(v, k, s, d, r, t, n)) continue;
            // ½ κ (g − d)²: κ ∇d ∇dᵀ (Gauss–Newton) − κ (g − d) ∇²d, with ∇d = (n, r/2), ∂²d/∂x∂θ = t/2,
            // ∂²d/∂θ² = −(d − closed_gap/2)/4. The second part is dropped for a projected (semidefinite) tangent.
            Eigen::Vector4d gd;
            gd << n, 0.5 * r;
            Eigen::Matrix4d H = m_kappa * gd * gd.transpose();
            if (!project) {
                const double q = -m_kappa * (m_p.gap_mm - d);
                H.block<3, 1>(0, 3) += q * 0.5 * t;
                H.block<1, 3>(3, 0) += q * 0.5 * t.transpose();
                H(3, 3) += q * -0.25 * (d - 0.5 * m_blades.closed_gap_mm);
            }
            for (int i = 0; i < 4; ++i)
                for (int j = 0; j < 4; ++j) val[m_slots[k][static_cast<size_t>(4 * i + j)]] += H(i, j);
        }
    return K;
}

BladeLoads ClipBody::loads(const Eigen::VectorXd& v) const {
    BladeLoads b;
    b.opening_rad = v[theta_dof()];
    b.spring_torque_nmm = m_spring.torque(b.opening_rad);
    for (size_t k = 0; k < m_nodes.size(); ++k)
        for (int s : {1, -1}) {
            double d, r;
            Eigen::Vector3d t, n;
            if (!measure(v, k, s, d, r, t, n)) continue;
            const size_t i = s > 0 ? 0 : 1;
            const double f = m_kappa * (m_p.gap_mm - d);
            b.force_n[i] += f;
            b.moment_nmm[i] += f * r;
            ++b.contacts[i];
        }
    return b;
}

LinearBody::LinearBody(Eigen::SparseMatrix<double, Eigen::RowMajor> K) : m_K(std::move(K)) {
    if (m_K.rows() != m_K.cols()) throw InputError("linear body: K must be square");
    m_K.makeCompressed();
}

}  // namespace aneu::fem
