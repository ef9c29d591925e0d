// SPDX-License-Identifier: MIT
#include "aneu/fem/contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "aneu/core/error.hpp"
#include "ccd.hpp"
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
    if (p.stiffness > 0) {
        m_kappa = p.stiffness;
    } else {
        m_kappa = detail::max_diagonal(body);
    }
    if (p.exclude_rings < 0) throw InputError("contact: exclude_rings must be >= 0");
    if (m_p.depth_mm <= 0) m_p.depth_mm = 0.25;

    for (const auto& q : contact_pairs(X, faces, u0, m_p)) m_pairs.push_back({q[0], q[1]});
}

void ContactBody::build_pattern() const {
    std::call_once(m_pattern_once, [this] {
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
        m_merged = detail::merge_pattern_cached(m_p.pattern_cache.get(), m_body.pattern(), m_body.dofs(), groups);
        for (const auto& g : groups) m_pair_slots.push_back(m_merged->block(g));
    });
}

const Eigen::SparseMatrix<double, Eigen::RowMajor>& ContactBody::pattern() const {
    build_pattern();
    return m_merged->pattern;
}

std::shared_ptr<PatternCache> make_pattern_cache() { return std::make_shared<PatternCache>(); }

std::pair<int, int> pattern_cache_counts(const PatternCache& cache) { return {cache.builds, cache.reuses}; }

namespace {

using Vec3 = Eigen::Vector3d;
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

/// A uniform grid of cells h wide, hashed (contact_pairs' vertices, surface_crossings' faces): a point's cell and a
/// cell's key (distinct cells may share one).
struct CellGrid {
    double h = 1;
    Eigen::Array<std::int64_t, 3, 1> cell(const Vec3& p) const { return (p / h).array().floor().cast<std::int64_t>(); }
    static std::int64_t key(std::int64_t i, std::int64_t j, std::int64_t k) { return (i * 73856093) ^ (j * 19349663) ^ (k * 83492791); }
};

/// D = the squared distance from p to the closest point of the triangle (a, b, c), its gradient and Hessian over
/// (p, a, b, c). The closest point is r = Σ cᵢ xᵢ in parameters s (none at a corner, t along an edge, two
/// barycentrics inside), D = |r|² minimised over s: by the envelope theorem ∇D = 2 cᵢ r, and
/// ∇²D = G_xx − G_xs G_ss⁻¹ G_sx of g(x, s) = |r(x, s)|² (r is linear in s).
struct PointTriangle {
    double D = 0;
    Vec12 g = Vec12::Zero();
    Mat12 H = Mat12::Zero();
    bool inside = false;  ///< the closest point is inside the face
};

PointTriangle point_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, bool hessian) {
    const Vec3 x[4] = {p, a, b, c};
    double cf[4] = {1, 0, 0, 0};   // r = Σ cf_i x_i
    double dc[2][4] = {};          // ∂cf_i/∂s_k
    Vec3 S[2];                     // ∂r/∂s_k
    int k = 0;                     // number of parameters
    const Vec3 e1 = b - a, e2 = c - a, w = p - a;
    const double d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2), w1 = w.dot(e1), w2 = w.dot(e2);
    const double den = d11 * d22 - d12 * d12;
    const double b1 = (d22 * w1 - d12 * w2) / den, b2 = (d11 * w2 - d12 * w1) / den;
    PointTriangle out;
    if (den > 0 && b1 >= 0 && b2 >= 0 && b1 + b2 <= 1) {
        out.inside = true;
        cf[1] = -(1 - b1 - b2);
        cf[2] = -b1;
        cf[3] = -b2;
        k = 2;
        dc[0][1] = 1, dc[0][2] = -1;
        dc[1][1] = 1, dc[1][3] = -1;
        S[0] = -e1;
        S[1] = -e2;
    } else {
        // The nearest of the three edges (a corner when the parameter is clamped).
        double best = std::numeric_limits<double>::infinity();
        int bi = 0, bj = 1;
        double bt = 0;
        for (int e = 0; e < 3; ++e) {
            const int i = 1 + e, j = 1 + (e + 1) % 3;
            const Vec3 ed = x[j] - x[i];
            const double len2 = ed.squaredNorm();
            const double t = len2 > 0 ? std::clamp((p - x[i]).dot(ed) / len2, 0.0, 1.0) : 0.0;
            const double dd = (p - x[i] - t * ed).squaredNorm();
            if (dd < best) best = dd, bi = i, bj = j, bt = t;
        }
        if (bt <= 0 || bt >= 1) {
            cf[bt <= 0 ? bi : bj] = -1;
        } else {
            cf[bi] = -(1 - bt);
            cf[bj] = -bt;
            k = 1;
            dc[0][bi] = 1, dc[0][bj] = -1;
            S[0] = x[bi] - x[bj];
        }
    }
    Vec3 r = Vec3::Zero();
    for (int i = 0; i < 4; ++i) r += cf[i] * x[i];
    out.D = r.squaredNorm();
    for (int i = 0; i < 4; ++i) out.g.segment<3>(3 * i) = 2 * cf[i] * r;
    if (!hessian) return out;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) out.H.block<3, 3>(3 * i, 3 * j) = 2 * cf[i] * cf[j] * Eigen::Matrix3d::Identity();
    if (k > 0) {
        Eigen::Matrix<double, 12, 2> Gxs = Eigen::Matrix<double, 12, 2>::Zero();
        Eigen::Matrix2d Gss = Eigen::Matrix2d::Identity();
        for (int q = 0; q < k; ++q) {
            for (int i = 0; i < 4; ++i) Gxs.block<3, 1>(3 * i, q) = 2 * (dc[q][i] * r + cf[i] * S[q]);
            for (int l = 0; l < k; ++l) Gss(q, l) = 2 * S[q].dot(S[l]);
        }
        if (k == 1)
            out.H -= Gxs.col(0) * Gxs.col(0).transpose() / Gss(0, 0);
        else
            out.H -= Gxs * Gss.inverse() * Gxs.transpose();
    }
    return out;
}

/// b(x) = −(x − 1)² ln x and its first two derivatives (x < 1).
struct Barrier {
    double b, d1, d2;
};
Barrier barrier(double x) {
    const double l = std::log(x), m = x - 1;
    return {-m * m * l, -2 * m * l - m * m / x, -2 * l - 4 * m / x + m * m / (x * x)};
}

/// The positive semidefinite part of a symmetric 12 × 12 matrix.
Mat12 psd(const Mat12& H) {
    const Eigen::SelfAdjointEigenSolver<Mat12> es(H);
    if (es.eigenvalues().minCoeff() >= 0) return H;
    const Vec12 l = es.eigenvalues().cwiseMax(0.0);
    return es.eigenvectors() * l.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

double signed_vertex_face_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                   Eigen::Matrix<double, 12, 1>* grad) {
    const PointTriangle pt = point_triangle(p, a, b, c, false);
    const double d = std::sqrt(pt.D);
    const double sign = pt.inside && (p - a).dot((b - a).cross(c - a)) < 0 ? -1.0 : 1.0;
    if (grad) *grad = d > 0 ? Vec12(sign * pt.g / (2 * d)) : Vec12::Zero();
    return sign * d;
}

std::vector<int> vertex_surfaces(const Eigen::MatrixX3i& faces, const std::vector<int>& face_surface, Eigen::Index nodes) {
    if (face_surface.empty()) return {};
    if (face_surface.size() != static_cast<size_t>(faces.rows()))
        throw InputError("contact: " + std::to_string(face_surface.size()) + " face surfaces for " + std::to_string(faces.rows()) + " faces");
    std::vector<int> s(static_cast<size_t>(nodes), -1);
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            if (faces(f, k) < 0 || faces(f, k) >= nodes) throw InputError("contact: face " + std::to_string(f) + " names a node outside the body");
            int& v = s[static_cast<size_t>(faces(f, k))];
            if (v < 0) v = face_surface[static_cast<size_t>(f)];
        }
    return s;
}

std::vector<std::array<int, 2>> contact_pairs(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, const ContactParams& p,
                                              double behind_mm) {
    if (u.size() != 3 * X.rows()) throw InputError("contact: the state has " + std::to_string(u.size()) + " entries for " + std::to_string(X.rows()) + " nodes");
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k)
            if (faces(f, k) < 0 || faces(f, k) >= X.rows()) throw InputError("contact: face " + std::to_string(f) + " names a node outside the body");
    // A vertex of another surface is never a pair (ContactParams::face_surface).
    const std::vector<int> surface = vertex_surfaces(faces, p.face_surface, X.rows());
    const auto other_surface = [&](int v, Eigen::Index f) {
        return !surface.empty() && surface[static_cast<size_t>(v)] != p.face_surface[static_cast<size_t>(f)];
    };
    const auto xat = [&](int node) -> Eigen::Vector3d { return X.row(node).transpose() + u.segment<3>(3 * node); };
    std::vector<std::array<int, 2>> pairs;
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
        const Eigen::Vector3d a = xat(faces(f, 0)), n = (xat(faces(f, 1)) - a).cross(xat(faces(f, 2)) - a);
        for (int k = 0; k < 3; ++k) vn[static_cast<size_t>(faces(f, k))] += n;
    }
    std::vector<int> ring(static_cast<size_t>(X.rows()), -1);  // face index that last marked the vertex as near
    std::vector<int> frontier, next;
    // The vertices in a uniform grid (cells of the mean edge, at least the search distance): each face looks only at
    // those in the cells its reach covers, in the same ascending order as a scan of all of them (the pairs and their
    // order are the scan's; session 46: compliant_setup searches a patch's whole inner surface at every selection).
    double h = 0;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) h += (xat(faces(f, 1)) - xat(faces(f, 0))).norm();
    h = std::max(faces.rows() > 0 ? h / static_cast<double>(faces.rows()) : 0.0, p.search_mm);
    if (!(h > 0)) h = 1.0;
    const CellGrid cg{h};
    auto cell = [&](const Eigen::Vector3d& q) { return cg.cell(q); };
    const auto key = CellGrid::key;
    std::unordered_map<std::int64_t, std::vector<int>> grid;
    for (int v : verts) {
        const auto c = cell(xat(v));
        grid[key(c[0], c[1], c[2])].push_back(v);
    }
    std::vector<int> near;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
        const Eigen::Vector3d a = xat(faces(f, 0)), b = xat(faces(f, 1)), c = xat(faces(f, 2));
        const Eigen::Vector3d centre = (a + b + c) / 3.0;
        const double r = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()});
        near.clear();
        const auto lo = cell(centre.array() - (r + p.search_mm)), hi = cell(centre.array() + (r + p.search_mm));
        for (auto i = lo[0]; i <= hi[0]; ++i)
            for (auto j = lo[1]; j <= hi[1]; ++j)
                for (auto k = lo[2]; k <= hi[2]; ++k)
                    if (const auto it = grid.find(key(i, j, k)); it != grid.end())
                        for (int v : it->second)
                            if (const auto cv = cell(xat(v)); cv[0] == i && cv[1] == j && cv[2] == k) near.push_back(v);  // (not a hash collision)
        std::sort(near.begin(), near.end());
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
        for (int v : near) {
            if (ring[static_cast<size_t>(v)] == f) continue;  // the face's own corners and their neighbours
            if (other_surface(v, f)) continue;
            if ((xat(v) - centre).norm() > r + p.search_mm) continue;
            if (vn[static_cast<size_t>(v)].dot(fn) >= 0) continue;  // not facing each other: the same wall
            // A vertex behind the face (over it) where the solve starts did not come through it — the barrier lets
            // none through — but lies there: a crease of the wall, the other side of a fold. Not a pair: its
            // barrier would hold it on that side.
            if (signed_vertex_face_distance(xat(v), xat(faces(f, 0)), xat(faces(f, 1)), xat(faces(f, 2))) <= -behind_mm) continue;
            pairs.push_back({v, static_cast<int>(f)});
        }
    }
    // Vertices a trial took through an unpaired face: every face near them but their own.
    if (!p.close_vertices.empty()) {
        for (Eigen::Index f = 0; f < faces.rows(); ++f) {
            const Eigen::Vector3d a = xat(faces(f, 0)), b = xat(faces(f, 1)), c = xat(faces(f, 2));
            const Eigen::Vector3d centre = (a + b + c) / 3.0;
            const double r = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()});
            for (int v : p.close_vertices) {
                if (v < 0 || v >= X.rows()) throw InputError("contact: close vertex " + std::to_string(v) + " outside the body");
                if (faces(f, 0) == v || faces(f, 1) == v || faces(f, 2) == v) continue;
                if (other_surface(v, f)) continue;
                if ((xat(v) - centre).norm() > r + std::max(p.close_search_mm, p.search_mm)) continue;
                if (signed_vertex_face_distance(xat(v), xat(faces(f, 0)), xat(faces(f, 1)), xat(faces(f, 2))) <= -behind_mm) continue;
                pairs.push_back({v, static_cast<int>(f)});
            }
        }
        const auto order = [](const std::array<int, 2>& a, const std::array<int, 2>& b) { return a[1] != b[1] ? a[1] < b[1] : a[0] < b[0]; };
        std::sort(pairs.begin(), pairs.end(), order);
        pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    }
    return pairs;
}

double ContactBody::signed_distance(const Eigen::VectorXd& u, const Pair& q) const {
    return signed_vertex_face_distance(x(u, q.v), x(u, m_F(q.f, 0)), x(u, m_F(q.f, 1)), x(u, m_F(q.f, 2)));
}

double ContactBody::energy(const Eigen::VectorXd& u) const {
    double e = m_body.energy(u);
    if (!std::isfinite(e)) return e;
    const double Dh = m_p.gap_mm * m_p.gap_mm;
    for (const auto& q : m_pairs) {
        const PointTriangle pt = point_triangle(x(u, q.v), x(u, m_F(q.f, 0)), x(u, m_F(q.f, 1)), x(u, m_F(q.f, 2)), false);
        if (pt.D >= Dh) continue;
        if (pt.D <= 0) return std::numeric_limits<double>::infinity();
        e += m_kappa * Dh * barrier(pt.D / Dh).b;
    }
    return e;
}

Eigen::VectorXd ContactBody::internal_force(const Eigen::VectorXd& u) const {
    Eigen::VectorXd g = m_body.internal_force(u);
    const double Dh = m_p.gap_mm * m_p.gap_mm;
    for (const auto& q : m_pairs) {
        const PointTriangle pt = point_triangle(x(u, q.v), x(u, m_F(q.f, 0)), x(u, m_F(q.f, 1)), x(u, m_F(q.f, 2)), false);
        if (pt.D >= Dh) continue;
        if (pt.D <= 0) throw NumericalError("contact: a vertex lies on a face of the opposite wall");
        const double s = m_kappa * barrier(pt.D / Dh).d1;  // ∂E/∂D
        g.segment<3>(3 * q.v) += s * pt.g.segment<3>(0);
        for (int k = 0; k < 3; ++k) g.segment<3>(3 * m_F(q.f, k)) += s * pt.g.segment<3>(3 + 3 * k);
    }
    return g;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> ContactBody::tangent(const Eigen::VectorXd& u, bool project) const {
    build_pattern();
    RowSparse K = m_merged->pattern;
    add_tangent(u, project, K.valuePtr(), nullptr);
    return K;
}

void ContactBody::add_tangent(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const {
    build_pattern();
    detail::add_body_tangent(m_body, u, project, values, where, *m_merged, m_compose, m_compose_mutex);
    add_pair_tangents(u, project, values, where);
}

void ContactBody::add_pair_tangents(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const {
    const double Dh = m_p.gap_mm * m_p.gap_mm;
    for (size_t k = 0; k < m_pairs.size(); ++k) {
        const auto& q = m_pairs[k];
        const Vec3 p = x(u, q.v), a = x(u, m_F(q.f, 0)), b = x(u, m_F(q.f, 1)), c = x(u, m_F(q.f, 2));
        if (point_triangle(p, a, b, c, false).D >= Dh) continue;  // most candidates: no Hessian for them
        const PointTriangle pt = point_triangle(p, a, b, c, true);
        if (pt.D <= 0) throw NumericalError("contact: a vertex lies on a face of the opposite wall");
        const Barrier bb = barrier(pt.D / Dh);
        Mat12 H = m_kappa * (bb.d2 / Dh * pt.g * pt.g.transpose() + bb.d1 * pt.H);
        if (project || m_p.project_pairs) H = psd(H);
        for (int i = 0; i < 12; ++i)
            for (int j = 0; j < 12; ++j) {
                const std::int64_t slot = m_pair_slots[k][static_cast<size_t>(12 * i + j)];
                values[where ? where[slot] : slot] += H(i, j);
            }
    }
}

double ContactBody::max_step(const Eigen::VectorXd& u, const Eigen::VectorXd& du) const {
    // Additive CCD (Li, Kaufman & Jiang 2021): along the step, a pair's distance falls at most as fast as
    // l = |Δp| + max |Δcorner| (the step's common translation removed), so advancing by a fraction of d / l
    // at a time never passes the face; stop where d is a tenth of its start.
    double alpha = m_body.max_step(u, du);
    for (const auto& q : m_pairs) {
        const int nodes[4] = {q.v, m_F(q.f, 0), m_F(q.f, 1), m_F(q.f, 2)};
        Vec3 dx[4], mean = Vec3::Zero();
        for (int i = 0; i < 4; ++i) mean += (dx[i] = du.segment<3>(3 * nodes[i])) / 4.0;
        for (auto& d : dx) d -= mean;
        const double l = dx[0].norm() + std::max({dx[1].norm(), dx[2].norm(), dx[3].norm()});
        if (!(l > 0)) continue;
        auto dist = [&](double t) {
            Vec3 y[4];
            for (int i = 0; i < 4; ++i) y[i] = x(u, nodes[i]) + t * du.segment<3>(3 * nodes[i]);
            return std::sqrt(point_triangle(y[0], y[1], y[2], y[3], false).D);
        };
        alpha = detail::additive_ccd(dist(0), l, alpha, dist);
    }
    return alpha;
}

std::size_t ContactBody::active(const Eigen::VectorXd& u) const {
    std::size_t n_active = 0;
    for (const auto& q : m_pairs) {
        const double d = signed_distance(u, q);
        n_active += d < m_p.gap_mm && d >= -m_p.depth_mm ? 1 : 0;
    }
    return n_active;
}

bool ContactBody::is_pair(int v, int f) const {
    // The constructor adds pairs face by face, each face's vertices in ascending order.
    return std::binary_search(m_pairs.begin(), m_pairs.end(), Pair{v, f},
                              [](const Pair& a, const Pair& b) { return a.f != b.f ? a.f < b.f : a.v < b.v; });
}

double ContactBody::min_distance(const Eigen::VectorXd& u) const {
    double m = std::numeric_limits<double>::infinity();
    for (const auto& q : m_pairs) {
        const double d = signed_distance(u, q);
        if (d >= -m_p.depth_mm) m = std::min(m, d);
    }
    return m;
}

namespace {
// separate_walls(): a vertex further behind its face than this is left there (a crease, the far side of a fold; the
// compliance frames push a vertex back out from up to 0.05 mm through).
constexpr double SEPARATE_BEHIND_MM = 0.05;
}  // namespace

Eigen::VectorXd separate_walls(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, const ContactParams& p, double delta_mm) {
    if (!(delta_mm > 0) || !(delta_mm < p.gap_mm)) throw InputError("contact: separate the walls by more than 0 and less than the barrier's gap");
    const std::vector<std::array<int, 2>> pairs = contact_pairs(X, faces, u, p, SEPARATE_BEHIND_MM);
    Eigen::VectorXd v = u;
    const auto x = [&](int a) { return Vec3(X.row(a).transpose() + v.segment<3>(3 * a)); };
    for (int pass = 0; pass < 8; ++pass) {
        bool moved = false;
        for (const auto& [vert, f] : pairs) {
            const Vec3 a = x(faces(f, 0)), b = x(faces(f, 1)), c = x(faces(f, 2));
            const double s = signed_vertex_face_distance(x(vert), a, b, c);
            if (s >= 0.999 * delta_mm || s < -SEPARATE_BEHIND_MM) continue;
            const Vec3 nrm = (b - a).cross(c - a);
            if (!(nrm.norm() > 0)) continue;
            v.segment<3>(3 * vert) += (delta_mm - s) * nrm.normalized();
            moved = true;
        }
        if (!moved) break;
    }
    return v;
}

CrossingFreeSolve solve_without_crossings(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0,
                                          ContactParams cp, const std::function<NewtonResult(const ContactBody&)>& solve, double depth, int max_rounds) {
    const Eigen::Index n = body.dofs();
    // What is behind a face where the solve starts stays out of the count (a crease, an earlier crossing).
    std::vector<std::pair<int, int>> before;
    CrossingFreeSolve out;
    for (const SurfaceCrossing& q : surface_crossings(X, faces, u0.head(n), cp.exclude_rings, depth, nullptr, &cp.face_surface)) {
        before.emplace_back(q.v, q.f);
        out.deepest_start_mm = std::max(out.deepest_start_mm, q.depth_mm);
    }
    std::sort(before.begin(), before.end());
    for (int round = 0;; ++round) {
        const ContactBody contact(body, X, faces, u0.head(n), cp);
        out.result = solve(contact);
        out.pairs = contact.candidates();
        out.close_vertices = cp.close_vertices;
        out.left.clear();
        out.deepest_mm = 0;
        for (const SurfaceCrossing& q : surface_crossings(X, faces, out.result.u.head(n), cp.exclude_rings, depth, nullptr, &cp.face_surface)) {
            out.deepest_mm = std::max(out.deepest_mm, q.depth_mm);
            if (!std::binary_search(before.begin(), before.end(), std::make_pair(q.v, q.f))) out.left.push_back(q);
        }
        if (out.left.empty() || round == max_rounds) return out;
        ++out.rounds;
        std::vector<std::pair<int, int>> left;
        for (const SurfaceCrossing& q : out.left) left.emplace_back(q.v, q.f);
        pair_crossings_closely(cp, faces, u0.head(n), out.result.u.head(n), left);
    }
}

void pair_crossings_closely(ContactParams& cp, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0, const Eigen::VectorXd& u1,
                            const std::vector<std::pair<int, int>>& crossings) {
    if (crossings.empty()) return;
    // Each crossing vertex and its ring, paired with every face within reach of its path: as far as it and the
    // face's corners moved, and the wall's reach beyond.
    auto moved_of = [&](int node) { return (u1.segment<3>(3 * node) - u0.segment<3>(3 * node)).norm(); };
    double reach = cp.search_mm;
    for (const auto& [v, f] : crossings) {
        double moved = moved_of(v);
        for (int k = 0; k < 3; ++k) moved += moved_of(faces(f, k)) / 3.0;
        reach = std::max(reach, 2.0 * moved + cp.search_mm);
        cp.close_vertices.push_back(v);
        for (Eigen::Index g = 0; g < faces.rows(); ++g)  // its one ring: the corners of the faces round it
            if (faces(g, 0) == v || faces(g, 1) == v || faces(g, 2) == v)
                for (int k = 0; k < 3; ++k) cp.close_vertices.push_back(faces(g, k));
    }
    std::sort(cp.close_vertices.begin(), cp.close_vertices.end());
    cp.close_vertices.erase(std::unique(cp.close_vertices.begin(), cp.close_vertices.end()), cp.close_vertices.end());
    cp.close_search_mm = std::max(cp.close_search_mm, reach);
}

bool crossings_need_pairs(const std::vector<std::pair<int, int>>& crossings, const std::vector<std::array<int, 2>>& pairs,
                          const std::vector<int>& close_vertices) {
    if (crossings.empty()) return false;
    std::vector<std::array<int, 2>> sorted = pairs;
    std::sort(sorted.begin(), sorted.end());
    return std::any_of(crossings.begin(), crossings.end(), [&](const std::pair<int, int>& c) {
        return !std::binary_search(close_vertices.begin(), close_vertices.end(), c.first) ||
               !std::binary_search(sorted.begin(), sorted.end(), std::array<int, 2>{c.first, c.second});
    });
}

std::vector<SurfaceCrossing> surface_crossings(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, int exclude_rings,
                                               double depth, const Eigen::VectorXd* face_depth, const std::vector<int>* face_surface) {
    if (u.size() != 3 * X.rows()) throw InputError("surface_crossings: the displacement has the wrong size");
    const std::vector<int> surface = face_surface ? vertex_surfaces(faces, *face_surface, X.rows()) : std::vector<int>();
    if (face_depth && face_depth->size() != faces.rows())
        throw InputError("surface_crossings: " + std::to_string(face_depth->size()) + " face depths for " + std::to_string(faces.rows()) + " faces");
    std::vector<SurfaceCrossing> out;
    if (faces.rows() == 0 || !(depth > 0)) return out;
    auto pos = [&](const Eigen::VectorXd* w, int n) {
        Vec3 p = X.row(n).transpose();
        if (w) p += w->segment<3>(3 * n);
        return p;
    };
    // Behind f: the closest point inside the face, on its back, less than depth deep (the signed distance).
    auto behind = [&](const Eigen::VectorXd* w, int v, Eigen::Index f) {
        const Vec3 p = pos(w, v), a = pos(w, faces(f, 0)), b = pos(w, faces(f, 1)), c = pos(w, faces(f, 2));
        const PointTriangle pt = point_triangle(p, a, b, c, false);
        if (!pt.inside || (p - a).dot((b - a).cross(c - a)) >= 0) return 0.0;
        const double d = std::sqrt(pt.D);
        return d < (face_depth ? std::min(depth, (*face_depth)[f]) : depth) ? d : 0.0;
    };
    // Through the face only if it came from its front: in front of the face's plane in the reference shape. A vertex
    // behind that plane there, however deep or wherever beside the face, is on the face's far side (session 46: C0001's
    // two lumens squeezed towards each other past the tips, their vertices 0.5 mm behind each other's faces, had been
    // more than the depth behind or beside them at rest, and were counted as through them).
    auto in_front_at_rest = [&](int v, Eigen::Index f) {
        const Vec3 p = pos(nullptr, v), a = pos(nullptr, faces(f, 0)), b = pos(nullptr, faces(f, 1)), c = pos(nullptr, faces(f, 2));
        return (p - a).dot((b - a).cross(c - a)) > 0;
    };
    std::vector<int> verts;
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) verts.push_back(faces(f, k));
    std::sort(verts.begin(), verts.end());
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    // Faces into the cells their box (grown by depth) covers; cells as large as the mean edge.
    double h = 0;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) h += (pos(&u, faces(f, 1)) - pos(&u, faces(f, 0))).norm();
    h = std::max(h / static_cast<double>(faces.rows()), depth);
    const CellGrid cg{h};
    auto cell = [&](const Vec3& p) { return cg.cell(p); };
    const auto key = CellGrid::key;
    std::unordered_map<std::int64_t, std::vector<int>> grid;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
        Vec3 lo = pos(&u, faces(f, 0)), hi = lo;
        for (int k = 1; k < 3; ++k) {
            lo = lo.cwiseMin(pos(&u, faces(f, k)));
            hi = hi.cwiseMax(pos(&u, faces(f, k)));
        }
        const auto a = cell(lo.array() - depth), b = cell(hi.array() + depth);
        for (auto i = a[0]; i <= b[0]; ++i)
            for (auto j = a[1]; j <= b[1]; ++j)
                for (auto k = a[2]; k <= b[2]; ++k) grid[key(i, j, k)].push_back(static_cast<int>(f));
    }
    std::vector<std::vector<int>> nb(static_cast<size_t>(X.rows()));
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            nb[static_cast<size_t>(faces(f, k))].push_back(faces(f, (k + 1) % 3));
            nb[static_cast<size_t>(faces(f, (k + 1) % 3))].push_back(faces(f, k));
        }
    // v within exclude_rings edges of f's corners (breadth first from the corners; only for the rare hits).
    auto neighbour = [&](int v, Eigen::Index f) {
        std::vector<int> frontier = {faces(f, 0), faces(f, 1), faces(f, 2)}, seen = frontier, next;
        for (int r = 0;; ++r) {
            if (std::find(frontier.begin(), frontier.end(), v) != frontier.end()) return true;
            if (r == exclude_rings) return false;
            next.clear();
            for (int w : frontier)
                for (int y : nb[static_cast<size_t>(w)])
                    if (std::find(seen.begin(), seen.end(), y) == seen.end()) {
                        seen.push_back(y);
                        next.push_back(y);
                    }
            frontier.swap(next);
        }
    };
    for (int v : verts) {
        const auto c = cell(pos(&u, v));
        const auto it = grid.find(key(c[0], c[1], c[2]));
        if (it == grid.end()) continue;
        for (int f : it->second) {
            if (faces(f, 0) == v || faces(f, 1) == v || faces(f, 2) == v) continue;
            if (!surface.empty() && surface[static_cast<size_t>(v)] != (*face_surface)[static_cast<size_t>(f)]) continue;
            const double d = behind(&u, v, f);
            if (d <= 0 || !in_front_at_rest(v, f) || neighbour(v, f)) continue;
            out.push_back({v, f, d});
        }
    }
    return out;
}

std::vector<int> nodes_inside_elements(const Eigen::MatrixX3d& x, const Eigen::MatrixXi& elements, const std::vector<int>& query, std::vector<double>* depth) {
    const Eigen::Index cols = elements.cols();
    if (elements.rows() > 0 && cols != 4 && cols != 10)
        throw InputError("nodes_inside_elements: elements with " + std::to_string(cols) + " nodes (expected 4 or 10)");
    for (Eigen::Index e = 0; e < elements.rows(); ++e)
        for (Eigen::Index k = 0; k < cols; ++k)
            if (elements(e, k) < 0 || elements(e, k) >= x.rows())
                throw InputError("nodes_inside_elements: element " + std::to_string(e) + " has node " + std::to_string(elements(e, k)) + " of " + std::to_string(x.rows()));
    for (int q : query)
        if (q < 0 || q >= x.rows()) throw InputError("nodes_inside_elements: query node " + std::to_string(q) + " of " + std::to_string(x.rows()));
    std::vector<int> out(query.size(), -1);
    if (depth) depth->assign(query.size(), 0.0);
    if (elements.rows() == 0 || query.empty()) return out;
    // The straight tetrahedra, in element-local node numbers: a 10-node element's corners 0-3 and mid-edge nodes
    // 4:(0,1) 5:(1,2) 6:(2,0) 7:(0,3) 8:(1,3) 9:(2,3); its inner octahedron split along 4-9, round which 5, 8, 7, 6 lie.
    static const int LINEAR[1][4] = {{0, 1, 2, 3}};
    static const int QUADRATIC[8][4] = {{0, 4, 6, 7}, {4, 1, 5, 8}, {6, 5, 2, 9}, {7, 8, 9, 3}, {4, 9, 5, 8}, {4, 9, 8, 7}, {4, 9, 7, 6}, {4, 9, 6, 5}};
    const int per = cols == 10 ? 8 : 1;
    const int(*sub)[4] = cols == 10 ? QUADRATIC : LINEAR;
    auto corner = [&](Eigen::Index e, int s, int k) { return Vec3(x.row(elements(e, sub[s][k])).transpose()); };
    double h = 0;
    for (Eigen::Index e = 0; e < elements.rows(); ++e) h += (corner(e, 0, 1) - corner(e, 0, 0)).norm();
    h = std::max(h / static_cast<double>(elements.rows()), 1e-9);
    const CellGrid cg{h};
    std::unordered_map<std::int64_t, std::vector<std::int64_t>> grid;  // cell key -> element * 8 + its tetrahedron
    for (Eigen::Index e = 0; e < elements.rows(); ++e)
        for (int s = 0; s < per; ++s) {
            Vec3 lo = corner(e, s, 0), hi = lo;
            for (int k = 1; k < 4; ++k) {
                lo = lo.cwiseMin(corner(e, s, k));
                hi = hi.cwiseMax(corner(e, s, k));
            }
            const auto a = cg.cell(lo), b = cg.cell(hi);
            for (auto i = a[0]; i <= b[0]; ++i)
                for (auto j = a[1]; j <= b[1]; ++j)
                    for (auto k = a[2]; k <= b[2]; ++k) grid[CellGrid::key(i, j, k)].push_back(e * 8 + s);
        }
    // The tetrahedra's faces on the mesh's boundary (one tetrahedron's only): a node must lie in front of those. Across
    // a face between two tetrahedra the tissue goes on, and a node on it (to round-off) lies inside both: a node of one
    // plate pressed onto a diagonal of the other's cells is in its tissue.
    std::unordered_map<std::int64_t, int> face_count;
    auto face_key = [&](Eigen::Index e, int s, int k) {
        std::array<std::int64_t, 3> f = {elements(e, sub[s][(k + 1) % 4]), elements(e, sub[s][(k + 2) % 4]), elements(e, sub[s][(k + 3) % 4])};
        std::sort(f.begin(), f.end());
        const std::int64_t n = x.rows();
        return (f[0] * n + f[1]) * n + f[2];
    };
    for (Eigen::Index e = 0; e < elements.rows(); ++e)
        for (int s = 0; s < per; ++s)
            for (int k = 0; k < 4; ++k) ++face_count[face_key(e, s, k)];
    // Inside: in front of each face, the faces' normals turned towards the opposite corner.
    constexpr double ON_FACE_MM = 1e-9;
    auto inside = [&](const Vec3& p, Eigen::Index e, int s) {
        for (int k = 0; k < 4; ++k) {
            const Vec3 a = corner(e, s, (k + 1) % 4), b = corner(e, s, (k + 2) % 4), c = corner(e, s, (k + 3) % 4);
            Vec3 n = (b - a).cross(c - a);
            const double len = n.norm();
            if (!(len > 0)) return false;  // a flat tetrahedron holds nothing
            n /= len;
            const double towards = (corner(e, s, k) - a).dot(n);
            if (std::abs(towards) < 1e-12) return false;
            const double d = (p - a).dot(n);
            const double m = face_count[face_key(e, s, k)] == 1 ? 0.0 : -ON_FACE_MM;
            if (!((towards > 0 ? d : -d) > m)) return false;
        }
        return true;
    };
    // The elements round each query node (its own tissue), and the nodes on the mesh's boundary, for the depth.
    std::unordered_map<int, std::vector<Eigen::Index>> own_elements;
    std::vector<char> on_boundary;
    if (depth) {
        on_boundary.assign(static_cast<size_t>(x.rows()), 0);
        for (Eigen::Index e = 0; e < elements.rows(); ++e)
            for (int s = 0; s < per; ++s)
                for (int k = 0; k < 4; ++k)
                    if (face_count[face_key(e, s, k)] == 1)
                        for (int j = 1; j < 4; ++j) on_boundary[static_cast<size_t>(elements(e, sub[s][(k + j) % 4]))] = 1;
        for (int q : query) own_elements[q];
        for (Eigen::Index e = 0; e < elements.rows(); ++e)
            for (Eigen::Index k = 0; k < cols; ++k)
                if (const auto it = own_elements.find(elements(e, k)); it != own_elements.end()) it->second.push_back(e);
    }
    auto in_element = [&](Eigen::Index g, int node) {
        for (Eigen::Index k = 0; k < cols; ++k)
            if (elements(g, k) == node) return true;
        return false;
    };
    for (size_t i = 0; i < query.size(); ++i) {
        const int q = query[i];
        const Vec3 p = x.row(q).transpose();
        const auto c = cg.cell(p);
        const auto it = grid.find(CellGrid::key(c[0], c[1], c[2]));
        if (it == grid.end()) continue;
        for (const std::int64_t es : it->second) {
            const Eigen::Index e = es / 8;
            const int s = static_cast<int>(es % 8);
            bool own = false;
            for (Eigen::Index k = 0; k < cols; ++k) own = own || elements(e, k) == q;
            if (own || !inside(p, e, s)) continue;
            if (!depth) {
                out[i] = static_cast<int>(e);
                break;
            }
            {
                // How deep: for a node on the mesh's boundary (a surface that went into the tissue), the distance to
                // the element's own faces (not those between its pieces) by which it leaves the other tissue: those
                // on the mesh's boundary (the tissue ends there) and those it shares with one of the node's own
                // elements (back into its own tissue), where it has any; else, and for a node inside the mesh, all of
                // them (a lower bound: how far past a face of the element it lies). An inside node cannot come through
                // a surface: it lies in a neighbour when its own elements are tangled, and the distance to the
                // neighbour's faces on the boundary would be the wall's thickness, not how far it went in.
                std::vector<std::array<int, 2>> faces;  // (piece, face)
                for (int s2 = 0; s2 < per; ++s2)
                    for (int k = 0; k < 4; ++k) {
                        int within = 0;
                        for (int s3 = 0; s3 < per; ++s3)
                            for (int k3 = 0; k3 < 4; ++k3) within += face_key(e, s3, k3) == face_key(e, s2, k);
                        if (within == 1) faces.push_back({s2, k});
                    }
                auto exit = [&](const std::array<int, 2>& f) {
                    if (!on_boundary[static_cast<size_t>(q)] && !own_elements[q].empty()) return false;  // (a node of no element: another body's)
                    if (face_count[face_key(e, f[0], f[1])] == 1) return true;
                    const std::vector<Eigen::Index>& mine = own_elements[q];
                    return std::any_of(mine.begin(), mine.end(), [&](Eigen::Index g) {
                        for (int k = 1; k < 4; ++k)
                            if (!in_element(g, elements(e, sub[f[0]][(f[1] + k) % 4]))) return false;
                        return true;
                    });
                };
                const bool bounded = std::any_of(faces.begin(), faces.end(), exit);
                double d = std::numeric_limits<double>::infinity();
                for (const auto& f : faces) {
                    if (bounded && !exit(f)) continue;
                    const PointTriangle pt = point_triangle(p, corner(e, f[0], (f[1] + 1) % 4), corner(e, f[0], (f[1] + 2) % 4), corner(e, f[0], (f[1] + 3) % 4), false);
                    d = std::min(d, std::sqrt(pt.D));
                }
                // A node on the boundary near where the element meets its own tissue (an edge or a corner the element
                // shares with one of the node's own elements) leaves the other tissue there: no farther than that
                // edge or corner (session 48: a lumen mid-edge node of the sample's patch 0.004 mm from the edge its
                // element shares with the holding one, 0.37 mm from the holding one's faces on the boundary).
                if (bounded) {
                    std::vector<int> mine;
                    for (Eigen::Index g : own_elements[q])
                        for (Eigen::Index k = 0; k < cols; ++k) mine.push_back(elements(g, k));
                    std::sort(mine.begin(), mine.end());
                    auto shared = [&](int s2, int k) { return std::binary_search(mine.begin(), mine.end(), elements(e, sub[s2][k])); };
                    for (int s2 = 0; s2 < per; ++s2)
                        for (int k = 0; k < 4; ++k) {
                            if (!shared(s2, k)) continue;
                            const Vec3 a = corner(e, s2, k);
                            d = std::min(d, (p - a).norm());
                            for (int j = k + 1; j < 4; ++j) {
                                if (!shared(s2, j)) continue;
                                const Vec3 ab = corner(e, s2, j) - a;
                                const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
                                d = std::min(d, (p - a - t * ab).norm());
                            }
                        }
                }
                // The least over the elements holding it (one holding it on a face between two of them may have on
                // the boundary only a face farther off than the nearest boundary: a plate's side, not its top).
                if (out[i] < 0 || d < (*depth)[i]) {
                    out[i] = static_cast<int>(e);
                    (*depth)[i] = d;
                }
            }
        }
    }
    return out;
}

}  // namespace aneu::fem
