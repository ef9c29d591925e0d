// SPDX-License-Identifier: MIT
#include "aneu/fem/contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

#include "aneu/core/error.hpp"
#include "merged_pattern.hpp"

namespace aneu::fem {

using RowSparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;

ContactBody::ContactBody(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0,
                         const ContactParams& p)
    : m_body(body), m_X(X), m_F(faces), m_p(p) {
    if (3 * X.rows() != body.dofs()) throw InputError("contact: " + std::to_string(X.rows()) + " nodes for a body of " + std::to_string(body.dofs()) + " DOFs");
    if (u0.size() != body.dofs()) throw InputError("contact: the starting state has the wrong size");
    if (!(p.gap_mm >= 0) || !(p.search_mm > p.gap_mm)) throw InputError("contact: need 0 <= gap < search distance");
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k)
            if (faces(f, k) < 0 || faces(f, k) >= X.rows()) throw InputError("contact: face " + std::to_string(f) + " names a node outside the body");
    const RowSparse& bp = body.pattern();
    if (p.stiffness > 0) {
        m_kappa = p.stiffness;
    } else {
        m_kappa = detail::default_penalty(body);
    }
    if (p.exclude_rings < 0) throw InputError("contact: exclude_rings must be >= 0");
    if (m_p.depth_mm <= 0) m_p.depth_mm = 0.25;
    constexpr double BEHIND_AT_START = 0.02;  // mm: the interpenetration a step may end with (the limit)

    // Candidates: a surface vertex and a face without it, apart in the reference shape (opposite walls), near in
    // the starting state.
    std::vector<int> verts;
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) verts.push_back(faces(f, k));
    std::sort(verts.begin(), verts.end());
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    // The surface's vertex graph, for the neighbourhood (rings of edges) of each face.
    std::vector<std::vector<int>> nb(static_cast<size_t>(X.rows()));
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            nb[static_cast<size_t>(faces(f, k))].push_back(faces(f, (k + 1) % 3));
            nb[static_cast<size_t>(faces(f, (k + 1) % 3))].push_back(faces(f, k));
        }
    // Vertex normals at u0 (area-weighted, towards the opposite wall): a pair is a vertex and a face of the
    // opposite wall, facing each other (normals more than 90° apart). Same-wall vertices beyond the excluded
    // rings lie nearly in a face's plane (a flat or flattened wall) and are not pairs.
    std::vector<Eigen::Vector3d> vn(static_cast<size_t>(X.rows()), Eigen::Vector3d::Zero());
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
        const Eigen::Vector3d a = x(u0, faces(f, 0)), n = (x(u0, faces(f, 1)) - a).cross(x(u0, faces(f, 2)) - a);
        for (int k = 0; k < 3; ++k) vn[static_cast<size_t>(faces(f, k))] += n;
    }
    std::vector<int> ring(static_cast<size_t>(X.rows()), -1);  // face index that last marked the vertex as near
    std::vector<int> frontier, next;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
        const Eigen::Vector3d a = x(u0, faces(f, 0)), b = x(u0, faces(f, 1)), c = x(u0, faces(f, 2));
        const Eigen::Vector3d centre = (a + b + c) / 3.0;
        const double r = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()});
        frontier.assign({faces(f, 0), faces(f, 1), faces(f, 2)});
        for (int w : frontier) ring[static_cast<size_t>(w)] = static_cast<int>(f);
        for (int k = 0; k < p.exclude_rings; ++k) {
            next.clear();
            for (int w : frontier)
                for (int y : nb[static_cast<size_t>(w)])
                    if (ring[static_cast<size_t>(y)] != f) {
                        ring[static_cast<size_t>(y)] = static_cast<int>(f);
                        next.push_back(y);
                    }
            frontier.swap(next);
        }
        const Eigen::Vector3d fn = (b - a).cross(c - a);
        for (int v : verts) {
            if (ring[static_cast<size_t>(v)] == f) continue;  // the face's own corners and their neighbours
            if ((x(u0, v) - centre).norm() > r + p.search_mm) continue;
            if (vn[static_cast<size_t>(v)].dot(fn) >= 0) continue;  // not facing each other: the same wall
            // A vertex already behind the face where the solve starts did not come through it (a crease of
            // the wall, the other side of a fold): not a pair. One in contact from the last step is.
            double d;
            Eigen::Vector3d bc, n;
            if (project(u0, {v, static_cast<int>(f)}, d, bc, n) && d < -BEHIND_AT_START) continue;
            m_pairs.push_back({v, static_cast<int>(f)});
        }
    }
    // Pattern: the body's and a 12 × 12 block per pair.
    auto dofs_of = [&](const Pair& q) {
        std::array<int, 12> d{};
        const int nodes[4] = {q.v, m_F(q.f, 0), m_F(q.f, 1), m_F(q.f, 2)};
        for (int i = 0; i < 4; ++i)
            for (int ax = 0; ax < 3; ++ax) d[static_cast<size_t>(3 * i + ax)] = 3 * nodes[i] + ax;
        return d;
    };
    std::vector<std::array<int, 12>> groups;
    groups.reserve(m_pairs.size());
    for (const auto& q : m_pairs) groups.push_back(dofs_of(q));
    detail::MergedPattern mp = detail::merge_pattern(bp, body.dofs(), groups);
    for (const auto& g : groups) m_pair_slots.push_back(mp.block(g));
    m_pattern = std::move(mp.pattern);
    m_body_to_pattern = std::move(mp.body_to_pattern);
}

bool ContactBody::measure(const Eigen::VectorXd& u, const Pair& q, double& d, Eigen::Vector3d& b, Eigen::Vector3d& n) const {
    return project(u, q, d, b, n) && d < m_p.gap_mm && d >= -m_p.depth_mm;
}

bool ContactBody::project(const Eigen::VectorXd& u, const Pair& q, double& d, Eigen::Vector3d& b, Eigen::Vector3d& n) const {
    const Eigen::Vector3d p = x(u, q.v), a = x(u, m_F(q.f, 0)), e1 = x(u, m_F(q.f, 1)) - a, e2 = x(u, m_F(q.f, 2)) - a;
    n = e1.cross(e2);
    const double area2 = n.norm();
    if (area2 <= 0) return false;
    n /= area2;
    d = (p - a).dot(n);
    // Barycentrics of the projection onto the face's plane.
    const Eigen::Vector3d w = p - a - d * n;
    const double d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2), w1 = w.dot(e1), w2 = w.dot(e2);
    const double den = d11 * d22 - d12 * d12;
    const double b1 = (d22 * w1 - d12 * w2) / den, b2 = (d11 * w2 - d12 * w1) / den;
    b = Eigen::Vector3d(1 - b1 - b2, b1, b2);
    constexpr double EDGE_TOLERANCE = 1e-3;  // a vertex over a shared edge belongs to both faces' pairs
    return b.minCoeff() >= -EDGE_TOLERANCE;
}

namespace {

/// ∂d/∂(p, a, b, c) of d = (p − a)·n, n = (b − a)×(c − a) / |…|: the exact gradient, so that Newton's line
/// search on the energy sees the force it minimises (holding n fixed is not a gradient and stalls it).
Eigen::Matrix<double, 12, 1> distance_gradient(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                               const Eigen::Vector3d& c) {
    const Eigen::Vector3d e1 = b - a, e2 = c - a, N = e1.cross(e2);
    const double len = N.norm();
    const Eigen::Vector3d n = N / len;
    const Eigen::Vector3d q = ((p - a) - n * n.dot(p - a)) / len;  // ∂d/∂N
    Eigen::Matrix<double, 12, 1> g;
    g.segment<3>(0) = n;
    g.segment<3>(3) = -n + (e1 - e2).cross(q);
    g.segment<3>(6) = e2.cross(q);
    g.segment<3>(9) = q.cross(e1);
    return g;
}

}  // namespace

double ContactBody::energy(const Eigen::VectorXd& u) const {
    double e = m_body.energy(u);
    if (!std::isfinite(e)) return e;
    for (const auto& q : m_pairs) {
        double d;
        Eigen::Vector3d b, n;
        if (measure(u, q, d, b, n)) e += 0.5 * m_kappa * (m_p.gap_mm - d) * (m_p.gap_mm - d);
    }
    return e;
}

Eigen::VectorXd ContactBody::internal_force(const Eigen::VectorXd& u) const {
    Eigen::VectorXd g = m_body.internal_force(u);
    for (const auto& q : m_pairs) {
        double d;
        Eigen::Vector3d b, n;
        if (!measure(u, q, d, b, n)) continue;
        const double s = -m_kappa * (m_p.gap_mm - d);  // ∂E/∂d
        const auto gd = distance_gradient(x(u, q.v), x(u, m_F(q.f, 0)), x(u, m_F(q.f, 1)), x(u, m_F(q.f, 2)));
        g.segment<3>(3 * q.v) += s * gd.segment<3>(0);
        for (int k = 0; k < 3; ++k) g.segment<3>(3 * m_F(q.f, k)) += s * gd.segment<3>(3 + 3 * k);
    }
    return g;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> ContactBody::tangent(const Eigen::VectorXd& u, bool project) const {
    const RowSparse Kb = m_body.tangent(u, project);
    RowSparse K = m_pattern;
    double* val = K.valuePtr();
    for (size_t p = 0; p < m_body_to_pattern.size(); ++p) val[m_body_to_pattern[p]] += Kb.valuePtr()[p];
    for (size_t k = 0; k < m_pairs.size(); ++k) {
        double d;
        Eigen::Vector3d b, n;
        if (!measure(u, m_pairs[k], d, b, n)) continue;
        const auto& q = m_pairs[k];
        const auto gd = distance_gradient(x(u, q.v), x(u, m_F(q.f, 0)), x(u, m_F(q.f, 1)), x(u, m_F(q.f, 2)));
        const Eigen::Matrix<double, 12, 12> H = m_kappa * gd * gd.transpose();  // Gauss–Newton: κ ∇d ∇dᵀ
        for (int i = 0; i < 12; ++i)
            for (int j = 0; j < 12; ++j) val[m_pair_slots[k][static_cast<size_t>(12 * i + j)]] += H(i, j);
    }
    return K;
}

std::size_t ContactBody::active(const Eigen::VectorXd& u) const {
    std::size_t n_active = 0;
    for (const auto& q : m_pairs) {
        double d;
        Eigen::Vector3d b, n;
        n_active += measure(u, q, d, b, n) ? 1 : 0;
    }
    return n_active;
}

double ContactBody::min_distance(const Eigen::VectorXd& u) const {
    double m = std::numeric_limits<double>::infinity();
    for (const auto& q : m_pairs) {
        double d;
        Eigen::Vector3d b, n;
        if (measure(u, q, d, b, n)) m = std::min(m, d);
    }
    return m;
}

}  // namespace aneu::fem
