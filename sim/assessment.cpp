// SPDX-License-Identifier: MIT
// Measures of a clipping's result: the neck occlusion (assessment.hpp).
#include "aneu/sim/assessment.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/compliance.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/sim/shapes.hpp"
#include "simulator_impl.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <tuple>
#include <optional>
#include <queue>
#include <vector>

#include <Eigen/Geometry>

namespace aneu::sim {

namespace {

/// The closest point of triangle (a, b, c) to p, as barycentric weights of a, b, c (Ericson, Real-Time Collision
/// Detection, 5.1.5).
Eigen::Vector3d closest_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double v = d1 / (d1 - d3);
        return {1 - v, v, 0};
    }
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double w = d2 / (d2 - d6);
        return {1 - w, 0, w};
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return {0, 1 - w, w};
    }
    const double den = 1 / (va + vb + vc), v = vb * den, w = vc * den;
    return {1 - v - w, v, w};
}

}  // namespace

std::vector<NeckPointOnLumen> smoothed_neck_line(const SimLumen& lumen, const std::vector<int>& loop) {
    std::vector<NeckPointOnLumen> out;
    const size_t n = loop.size();
    if (n < 3) return out;
    std::vector<Eigen::Vector3d> p(n), q(n);
    for (size_t k = 0; k < n; ++k) p[k] = lumen.X.row(loop[k]).transpose();
    for (int it = 0; it < NECK_SMOOTHING_PASSES; ++it) {
        for (size_t k = 0; k < n; ++k) q[k] = 0.25 * p[(k + n - 1) % n] + 0.5 * p[k] + 0.25 * p[(k + 1) % n];
        p.swap(q);
    }
    // Back onto the lumen: the closest point of the faces (each smoothed point lies within an element or two of
    // the staircase it came from).
    for (size_t k = 0; k < n; ++k) {
        NeckPointOnLumen best;
        double dbest = std::numeric_limits<double>::infinity();
        for (Eigen::Index f = 0; f < lumen.F.rows(); ++f) {
            const Eigen::Vector3d a = lumen.X.row(lumen.F(f, 0)), b = lumen.X.row(lumen.F(f, 1)), c = lumen.X.row(lumen.F(f, 2));
            if ((a - p[k]).norm() > dbest + (b - a).norm() + (c - a).norm()) continue;
            const Eigen::Vector3d w = closest_barycentric(p[k], a, b, c);
            const double d = (w[0] * a + w[1] * b + w[2] * c - p[k]).norm();
            if (d < dbest) {
                dbest = d;
                best.face = static_cast<int>(f);
                best.weights = w;
            }
        }
        out.push_back(best);
    }
    return out;
}

namespace {

/// Where the ray p + t dir (t of either sign) crosses triangle abc (Möller–Trumbore): false if it misses.
bool ray_crossing(const Eigen::Vector3d& p, const Eigen::Vector3d& dir, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                  const Eigen::Vector3d& c, double& t) {
    const Eigen::Vector3d e1 = b - a, e2 = c - a, pv = dir.cross(e2);
    const double det = e1.dot(pv);
    if (std::abs(det) < 1e-14) return false;
    const Eigen::Vector3d tv = p - a;
    const double u = tv.dot(pv) / det;
    if (u < 0 || u > 1) return false;
    const Eigen::Vector3d qv = tv.cross(e1);
    const double v = dir.dot(qv) / det;
    if (v < 0 || u + v > 1) return false;
    t = e2.dot(qv) / det;
    return true;
}

/// The deformed lumen's geometry for the neck's measures: face and (area-weighted) vertex normals out of the
/// lumen, each vertex's faces, a grid of face centroids; the gap across the lumen along a normal and the lumen's
/// width (the largest ball inside it) at a wall point.
class DeformedLumen {
public:
    /// `wall_mm`: the wall's thickness per vertex (how deep behind a point an opposite wall counts as through it).
    DeformedLumen(const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& y, const Eigen::VectorXd& wall_mm) : m_F(F), m_y(y), m_wall(wall_mm) {
        const Eigen::Index L = y.rows(), NF = m_F.rows();
        m_vn = Eigen::MatrixX3d::Zero(L, 3);
        m_fn.resize(NF, 3);
        m_faces_of.resize(static_cast<size_t>(L));
        m_C.resize(NF, 3);
        for (Eigen::Index f = 0; f < NF; ++f) {
            const Eigen::Vector3d a = y.row(m_F(f, 0)), b = y.row(m_F(f, 1)), c = y.row(m_F(f, 2));
            const Eigen::Vector3d n = (b - a).cross(c - a);  // area weighted
            m_C.row(f) = ((a + b + c) / 3.0).transpose();
            for (int k = 0; k < 3; ++k) {
                m_vn.row(m_F(f, k)) += n.transpose();
                m_faces_of[static_cast<size_t>(m_F(f, k))].push_back(static_cast<int>(f));
                m_reach = std::max(m_reach, (y.row(m_F(f, k)) - m_C.row(f)).norm());
            }
            const double len = n.norm();
            m_fn.row(f) = len > 0 ? Eigen::RowVector3d((n / len).transpose()) : Eigen::RowVector3d::Zero();
        }
        for (Eigen::Index v = 0; v < L; ++v) {
            const double len = m_vn.row(v).norm();
            if (len > 0) m_vn.row(v) /= len;
        }
        // Cells of 1 mm: a width's searches reach across the lumen (a ball's diameter, 0.1-4 mm): finer cells cost more
        // lookups than they save tests.
        m_grid.build(m_C, std::max(1.0, 2 * m_reach));
    }

    const Eigen::MatrixX3d& centroids() const { return m_C; }

    /// The point of `face` at barycentric w, the direction into the lumen there (against the interpolated
    /// normal; the face's own where that vanishes) and the wall's thickness there; false on a degenerate face.
    bool at(int face, const Eigen::Vector3d& w, Eigen::Vector3d& p, Eigen::Vector3d& d, double& wall) const {
        p.setZero();
        Eigen::Vector3d nrm = Eigen::Vector3d::Zero();
        wall = 0;
        for (int k = 0; k < 3; ++k) {
            const int c = m_F(face, k);
            p += w[k] * m_y.row(c).transpose();
            nrm += w[k] * m_vn.row(c).transpose();
            if (c < m_wall.size()) wall += w[k] * m_wall[c];
        }
        if (!(nrm.norm() > 0)) nrm = m_fn.row(face).transpose();
        if (!(nrm.norm() > 0)) return false;
        d = -nrm.normalized();
        return true;
    }

    /// The faces round `face`'s corners and their one ring (sorted): not "opposite" walls.
    void two_ring(int face, std::vector<int>& out) const {
        out.clear();
        for (int k = 0; k < 3; ++k)
            for (int f : m_faces_of[static_cast<size_t>(m_F(face, k))])
                for (int j = 0; j < 3; ++j)
                    for (int g : m_faces_of[static_cast<size_t>(m_F(f, j))]) out.push_back(g);
        std::sort(out.begin(), out.end());
        out.erase(std::unique(out.begin(), out.end()), out.end());
    }

    /// Whether face g faces back along d (its normal more than 120° from the point's: an opposite wall).
    bool opposite(int g, const Eigen::Vector3d& d) const { return m_fn.row(g).dot(d) >= 0.5; }

    /// The gap at a point of the neck line (neck_occlusion): along the ray from it across the lumen, the nearest
    /// crossing of an opposite face not in its two rings, in front (the gap) or behind within its own wall
    /// (negative: the walls pass through each other), +inf where none lies within `search`.
    double gap(int face, const Eigen::Vector3d& w, double search, Eigen::Vector3d& where) {
        Eigen::Vector3d d;
        double behind = 0;
        if (!at(face, w, where, d, behind)) return std::numeric_limits<double>::infinity();
        two_ring(face, m_ring);
        double gap = std::numeric_limits<double>::infinity();
        for (Eigen::Index f = 0; f < m_F.rows(); ++f) {
            if (!opposite(static_cast<int>(f), d) || std::binary_search(m_ring.begin(), m_ring.end(), static_cast<int>(f))) continue;
            const Eigen::Vector3d a = m_y.row(m_F(f, 0)), b = m_y.row(m_F(f, 1)), c = m_y.row(m_F(f, 2));
            if ((a - where).norm() > search + (b - a).norm() + (c - a).norm()) continue;  // cheap reject
            double hit;
            if (ray_crossing(where, d, a, b, c, hit) && hit <= search && hit >= -behind && std::abs(hit) < std::abs(gap)) gap = hit;
        }
        return gap;
    }

    /// The diameter of the largest ball inside the lumen touching the wall at the point of `face` with weights w,
    /// at most cap. Each constraint alone allows radii [0, r_k] (a triangle's or point's distance from the centre
    /// p + r d, less r, does not grow with r: the distance is 1-Lipschitz), so the radius is the least r_k; a
    /// constraint farther from p than twice the radius found so far cannot lower it.
    double width(int face, const Eigen::Vector3d& w, double cap) {
        Eigen::Vector3d p, d;
        double behind = 0;
        if (!at(face, w, p, d, behind)) return 0.0;  // a degenerate face: no width to speak of
        // The two rings round the face: their vertices (not the face's own) are point constraints.
        two_ring(face, m_ring);
        double r = 0.5 * cap;
        for (int g : m_ring)
            for (int j = 0; j < 3; ++j) {
                const int v = m_F(g, j);
                if (v == m_F(face, 0) || v == m_F(face, 1) || v == m_F(face, 2)) continue;
                const Eigen::Vector3d q = m_y.row(v).transpose() - p;
                const double h = q.dot(d);
                if (h > 0) r = std::min(r, q.squaredNorm() / (2 * h));
            }
        // Along the inward normal: an opposite wall (facing back at the point: normals more than 120° apart)
        // crossed at t bounds the diameter by t; one at the point or behind it within the point's own wall means
        // the walls touch or pass through each other (a ball beside a wall that lies on the point is "clear" of
        // it, so this is where touching walls are seen).
        behind = std::max(behind, 1e-9);
        // Faces are found by their centroids, each within m_reach of any point of its face: those the segment from
        // p − behind d to p + 2 r d crosses have theirs within m_reach of its box. (In the grid's order: the least
        // bound is the same in any order, the ball's radius below to within the bisection's 0.1 µm.)
        {
            const Eigen::Vector3d s0 = p - behind * d, s1 = p + 2 * r * d, pad = Eigen::Vector3d::Constant(m_reach + 1e-9);
            m_grid.query(Aabb{s0.cwiseMin(s1) - pad, s0.cwiseMax(s1) + pad}, m_cand, false);
        }
        for (int g : m_cand) {
            if (!opposite(g, d) || std::binary_search(m_ring.begin(), m_ring.end(), g)) continue;
            double t;
            if (!ray_crossing(p, d, m_y.row(m_F(g, 0)).transpose(), m_y.row(m_F(g, 1)).transpose(), m_y.row(m_F(g, 2)).transpose(), t)) continue;
            if (t < -behind || t > 2 * r) continue;
            if (t <= 0) return 0.0;
            r = 0.5 * t;
        }
        // The faces that can touch the ball as it now stands: their centroids within r + m_reach of its centre.
        {
            const Eigen::Vector3d centre = p + r * d, pad = Eigen::Vector3d::Constant(r + m_reach + 1e-9);
            m_grid.query(Aabb{centre - pad, centre + pad}, m_cand, false);
        }
        for (int g : m_cand) {
            if (std::binary_search(m_ring.begin(), m_ring.end(), g)) continue;
            const Eigen::Vector3d a = m_y.row(m_F(g, 0)), b = m_y.row(m_F(g, 1)), c = m_y.row(m_F(g, 2));
            if ((m_C.row(g).transpose() - (p + r * d)).norm() >= r + m_reach) continue;  // clear of the ball as it stands
            // Clear within 1 nm: a wall the ball touches tangentially (a round lumen's) needs no bisection.
            auto clear = [&](double s) { return (closest_point_on_triangle(p + s * d, a, b, c) - (p + s * d)).norm() >= s - 1e-9; };
            if (clear(r)) continue;
            double lo = 0, hi = r;
            for (int it = 0; it < 40 && hi - lo > 1e-7; ++it) {
                const double mid = 0.5 * (lo + hi);
                (clear(mid) ? lo : hi) = mid;
            }
            r = lo;
        }
        return 2 * r;
    }

private:
    const Eigen::MatrixX3i& m_F;
    const Eigen::MatrixX3d& m_y;
    const Eigen::VectorXd& m_wall;
    Eigen::MatrixX3d m_vn, m_fn, m_C;
    std::vector<std::vector<int>> m_faces_of;
    double m_reach = 0;
    PointGrid m_grid;
    std::vector<int> m_ring, m_cand;
};

double point_segment_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const Eigen::Vector3d ab = b - a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    return (a + t * ab - p).norm();
}

/// Neck loop l's line on the lumen: SimLumen::neck_line's when set, else smoothed here.
std::vector<NeckPointOnLumen> neck_line_of(const SimLumen& lumen, size_t l) {
    return l < lumen.neck_line.size() ? lumen.neck_line[l] : smoothed_neck_line(lumen, lumen.neck_loops[l]);
}

// The neck line at rest, as segments (all loops).
std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> neck_segments_at_rest(const SimLumen& lumen) {
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> seg;
    for (size_t l = 0; l < lumen.neck_loops.size(); ++l) {
        const std::vector<NeckPointOnLumen> line = neck_line_of(lumen, l);
        std::vector<Eigen::Vector3d> pts;
        for (const NeckPointOnLumen& q : line) {
            Eigen::Vector3d x = Eigen::Vector3d::Zero();
            for (int k = 0; k < 3; ++k) x += q.weights[k] * lumen.X.row(lumen.F(q.face, k)).transpose();
            pts.push_back(x);
        }
        for (size_t k = 0; k < pts.size(); ++k) seg.emplace_back(pts[k], pts[(k + 1) % pts.size()]);
    }
    return seg;
}

}  // namespace

Eigen::VectorXd lumen_edges_mm(const SimLumen& lumen) {
    const Eigen::MatrixX3i& F = lumen.F;
    const Eigen::Index NF = F.rows();
    Eigen::VectorXd shortest(NF);
    std::vector<std::vector<int>> faces_of(static_cast<size_t>(lumen.X.rows()));
    for (Eigen::Index f = 0; f < NF; ++f) {
        shortest[f] = std::numeric_limits<double>::infinity();
        for (int k = 0; k < 3; ++k) {
            shortest[f] = std::min(shortest[f], (lumen.X.row(F(f, k)) - lumen.X.row(F(f, (k + 1) % 3))).norm());
            faces_of[static_cast<size_t>(F(f, k))].push_back(static_cast<int>(f));
        }
    }
    Eigen::VectorXd out(NF);
    std::vector<int> ring;
    for (Eigen::Index f = 0; f < NF; ++f) {
        ring.clear();
        for (int k = 0; k < 3; ++k) ring.insert(ring.end(), faces_of[static_cast<size_t>(F(f, k))].begin(), faces_of[static_cast<size_t>(F(f, k))].end());
        std::sort(ring.begin(), ring.end());
        ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
        double sum = 0;
        for (int g : ring) sum += shortest[g];
        out[f] = sum / static_cast<double>(ring.size());
    }
    return out;
}

NeckOcclusion neck_occlusion(const SimLumen& lumen, const Eigen::MatrixX3d& y, double gap_tol_mm, const Eigen::VectorXd& wall_mm) {
    NeckOcclusion out;
    if (lumen.neck_loops.empty()) return out;
    DeformedLumen geo(lumen.F, y, wall_mm);
    constexpr double SEARCH_MM = 12.0;  // across the widest neck
    const double inf = std::numeric_limits<double>::infinity();
    out.min_gap_mm = inf;
    for (size_t l = 0; l < lumen.neck_loops.size(); ++l) {
        const std::vector<NeckPointOnLumen> line = neck_line_of(lumen, l);
        if (line.empty()) continue;
        std::vector<double> g(line.size());
        std::vector<Eigen::Vector3d> at(line.size());
        for (size_t k = 0; k < line.size(); ++k) {
            g[k] = geo.gap(line[k].face, line[k].weights, SEARCH_MM, at[k]);
            out.min_gap_mm = std::min(out.min_gap_mm, g[k]);
            if (g[k] < 0) out.max_interpenetration_mm = std::max(out.max_interpenetration_mm, -g[k]);
        }
        for (size_t k = 0; k < line.size(); ++k) {
            const size_t m = (k + 1) % line.size();
            const double len = (at[m] - at[k]).norm();
            out.length_mm += len;
            if (g[k] <= gap_tol_mm && g[m] <= gap_tol_mm) out.closed_mm += len;
        }
        out.gap_mm.push_back(g);
        out.points.push_back(at);
        std::vector<int> faces(line.size());
        for (size_t k = 0; k < line.size(); ++k) faces[k] = line[k].face;
        out.faces.push_back(std::move(faces));
    }
    out.fraction = out.length_mm > 0 ? out.closed_mm / out.length_mm : 0.0;
    return out;
}

LumenCrossing lumen_crossing(const SimLumen& lumen, const Eigen::MatrixX3d& y, int exclude_rings, double depth_mm, const LumenTissue* tissue) {
    LumenCrossing out;
    if (lumen.F.rows() == 0) return out;
    if (tissue && (tissue->patch.size() != static_cast<size_t>(lumen.X.rows()) || tissue->inside.size() != tissue->patch.size()))
        throw InputError("lumen_crossing: tissue for " + std::to_string(tissue->patch.size()) + " vertices, the lumen has " + std::to_string(lumen.X.rows()));
    // surface_crossings counts a vertex behind a face against the face's normal: the lumen's faces turned into it.
    const Eigen::MatrixX3i inward = lumen.F(Eigen::all, std::vector<int>{0, 2, 1});
    Eigen::VectorXd u(3 * y.rows());
    for (Eigen::Index v = 0; v < y.rows(); ++v) u.segment<3>(3 * v) = (y.row(v) - lumen.X.row(v)).transpose();
    constexpr double ROUNDOFF_MM = 1e-3;  // a vertex pressed onto a face, a hair behind its plane
    // Through a face means within its wall: deeper behind it than the wall is thick (its corners' mean) lies beyond
    // the wall, another lumen or the far side of a wall folded into the lumen (session 46: C0001's, 0.1-0.5 mm behind
    // faces 2-6 mm past the tips, 0.4 mm walls).
    Eigen::VectorXd wall;
    if (lumen.wall_mm.size() == lumen.X.rows()) {
        wall.resize(lumen.F.rows());
        for (Eigen::Index f = 0; f < lumen.F.rows(); ++f) wall[f] = (lumen.wall_mm[lumen.F(f, 0)] + lumen.wall_mm[lumen.F(f, 1)] + lumen.wall_mm[lumen.F(f, 2)]) / 3.0;
    }
    // The tissue behind the face is known when the vertex and the face's corners are one patch's (away from its
    // interface): then the vertex must lie in it.
    auto beside = [&](const fem::SurfaceCrossing& c) {
        if (!tissue) return false;
        const int p = tissue->patch[static_cast<size_t>(c.v)];
        if (p < 0 || tissue->inside[static_cast<size_t>(c.v)]) return false;
        for (int k = 0; k < 3; ++k)
            if (tissue->patch[static_cast<size_t>(lumen.F(c.f, k))] != p) return false;
        return true;
    };
    std::vector<int> through, aside;
    for (const fem::SurfaceCrossing& c : fem::surface_crossings(lumen.X, inward, u, exclude_rings, depth_mm, wall.size() ? &wall : nullptr)) {
        if (c.depth_mm <= ROUNDOFF_MM) continue;
        if (beside(c)) {
            aside.push_back(c.v);
            out.beside_mm = std::max(out.beside_mm, c.depth_mm);
            continue;
        }
        through.push_back(c.v);
        if (c.depth_mm > out.depth_mm) {
            out.depth_mm = c.depth_mm;
            out.at = y.row(c.v).transpose();
        }
    }
    std::sort(through.begin(), through.end());
    out.vertices = static_cast<int>(std::unique(through.begin(), through.end()) - through.begin());
    std::sort(aside.begin(), aside.end());
    aside.erase(std::unique(aside.begin(), aside.end()), aside.end());
    // A vertex both through one face and beside another counts as through.
    out.beside_vertices = static_cast<int>(std::count_if(aside.begin(), aside.end(), [&](int v) { return !std::binary_search(through.begin(), through.begin() + out.vertices, v); }));
    return out;
}

std::vector<int> lumen_meeting(const SimLumen& lumen, const Eigen::MatrixX3d& y, double approach_mm, double apart_mm, const std::vector<char>* outside) {
    const Eigen::Index L = lumen.X.rows();
    if (y.rows() != L) throw InputError("lumen_meeting: positions of " + std::to_string(y.rows()) + " vertices, the lumen has " + std::to_string(L));
    if (outside && outside->size() != static_cast<size_t>(L))
        throw InputError("lumen_meeting: outside for " + std::to_string(outside->size()) + " vertices, the lumen has " + std::to_string(L));
    std::vector<int> out;
    if (lumen.F.rows() == 0 || !(approach_mm > 0)) return out;
    const Eigen::MatrixX3i inward = lumen.F(Eigen::all, std::vector<int>{0, 2, 1});
    Eigen::VectorXd u(3 * L);
    for (Eigen::Index v = 0; v < L; ++v) u.segment<3>(3 * v) = (y.row(v) - lumen.X.row(v)).transpose();
    fem::ContactParams cp;
    cp.search_mm = approach_mm;
    cp.exclude_rings = LUMEN_CROSSING_RINGS;
    auto at = [](const Eigen::MatrixX3d& m, int a) { return Eigen::Vector3d(m.row(a).transpose()); };
    std::vector<char> take(static_cast<size_t>(L), 0);
    for (const auto& [v, f] : fem::contact_pairs(lumen.X, inward, u, cp, fem::WALL_THROUGH_MM)) {
        const int a = inward(f, 0), b = inward(f, 1), c = inward(f, 2);
        if (outside && !(*outside)[static_cast<size_t>(v)] && !(*outside)[static_cast<size_t>(a)] && !(*outside)[static_cast<size_t>(b)] &&
            !(*outside)[static_cast<size_t>(c)])
            continue;
        const double d = fem::signed_vertex_face_distance(at(y, v), at(y, a), at(y, b), at(y, c));
        if (d > approach_mm) continue;
        // Behind the face: through it only if it came from the face's front (in front of its plane at rest).
        const Eigen::Vector3d n0 = (at(lumen.X, b) - at(lumen.X, a)).cross(at(lumen.X, c) - at(lumen.X, a));
        if (d < 0 && !(n0.dot(at(lumen.X, v) - at(lumen.X, a)) > 0)) continue;
        if (std::abs(fem::signed_vertex_face_distance(at(lumen.X, v), at(lumen.X, a), at(lumen.X, b), at(lumen.X, c))) <= apart_mm) continue;
        take[static_cast<size_t>(v)] = take[static_cast<size_t>(a)] = take[static_cast<size_t>(b)] = take[static_cast<size_t>(c)] = 1;
    }
    for (Eigen::Index v = 0; v < L; ++v)
        if (take[static_cast<size_t>(v)]) out.push_back(static_cast<int>(v));
    return out;
}

double lumen_width(const SimLumen& lumen, const Eigen::MatrixX3d& y, int face, const Eigen::Vector3d& w, double cap_mm) {
    DeformedLumen balls(lumen.F, y, lumen.wall_mm);
    return balls.width(face, w, cap_mm);
}

namespace {
// Per face: the faces sharing an edge with it.
std::vector<std::vector<int>> face_neighbours(const Eigen::MatrixX3i& F) {
    const Eigen::Index NF = F.rows();
    std::vector<std::array<int, 3>> edges;  // (low vertex, high vertex, face)
    for (Eigen::Index f = 0; f < NF; ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = F(f, k), b = F(f, (k + 1) % 3);
            edges.push_back({std::min(a, b), std::max(a, b), static_cast<int>(f)});
        }
    std::sort(edges.begin(), edges.end());
    std::vector<std::vector<int>> nbr(static_cast<size_t>(NF));
    for (size_t i = 0; i < edges.size();) {
        size_t j = i;
        while (j < edges.size() && edges[j][0] == edges[i][0] && edges[j][1] == edges[i][1]) ++j;
        for (size_t p = i; p < j; ++p)
            for (size_t q = i; q < j; ++q)
                if (p != q) nbr[static_cast<size_t>(edges[p][2])].push_back(edges[q][2]);
        i = j;
    }
    return nbr;
}
}  // namespace

std::vector<double> widest_reach(const Eigen::MatrixX3i& F, const std::vector<double>& width, const std::vector<char>& from) {
    const std::vector<std::vector<int>> nbr = face_neighbours(F);
    std::vector<double> reach(static_cast<size_t>(F.rows()), 0.0);
    // Widest first (a maximin Dijkstra): a face's reach is final when it leaves the queue.
    std::priority_queue<std::pair<double, int>> q;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (from[static_cast<size_t>(f)]) {
            reach[static_cast<size_t>(f)] = width[static_cast<size_t>(f)];
            q.emplace(reach[static_cast<size_t>(f)], static_cast<int>(f));
        }
    std::vector<char> done(static_cast<size_t>(F.rows()), 0);
    while (!q.empty()) {
        const auto [r, f] = q.top();
        q.pop();
        if (done[static_cast<size_t>(f)]) continue;
        done[static_cast<size_t>(f)] = 1;
        for (int g : nbr[static_cast<size_t>(f)]) {
            const double c = std::min(r, width[static_cast<size_t>(g)]);
            if (!done[static_cast<size_t>(g)] && c > reach[static_cast<size_t>(g)]) {
                reach[static_cast<size_t>(g)] = c;
                q.emplace(c, g);
            }
        }
    }
    return reach;
}

std::pair<double, int> widest_channel(const Eigen::MatrixX3i& F, const std::vector<double>& width, const std::vector<char>& a_side,
                                      const std::vector<char>& b_side) {
    const Eigen::Index NF = F.rows();
    // Faces joined across their edges, widest first (union–find); the width at which an A face and a B face first
    // share a component is the widest channel between them (a maximin path).
    const std::vector<std::vector<int>> nbr = face_neighbours(F);
    std::vector<int> order(static_cast<size_t>(NF));
    for (int f = 0; f < NF; ++f) order[static_cast<size_t>(f)] = f;
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return width[static_cast<size_t>(a)] > width[static_cast<size_t>(b)]; });
    std::vector<int> up(static_cast<size_t>(NF), -1);
    std::vector<char> has_a(static_cast<size_t>(NF), 0), has_b(static_cast<size_t>(NF), 0);
    auto find = [&](int x) {
        while (up[static_cast<size_t>(x)] != x) {
            up[static_cast<size_t>(x)] = up[static_cast<size_t>(up[static_cast<size_t>(x)])];
            x = up[static_cast<size_t>(x)];
        }
        return x;
    };
    for (int f : order) {
        const size_t fs = static_cast<size_t>(f);
        up[fs] = f;
        has_a[fs] = a_side[fs];
        has_b[fs] = b_side[fs];
        for (int g : nbr[fs]) {
            if (up[static_cast<size_t>(g)] < 0) continue;
            const int a = find(f), b = find(g);
            if (a == b) continue;
            up[static_cast<size_t>(b)] = a;
            has_a[static_cast<size_t>(a)] |= has_a[static_cast<size_t>(b)];
            has_b[static_cast<size_t>(a)] |= has_b[static_cast<size_t>(b)];
        }
        const int r = find(f);
        if (has_a[static_cast<size_t>(r)] && has_b[static_cast<size_t>(r)]) return {width[fs], f};
    }
    return {0.0, -1};
}

NeckChannel neck_channel(const SimLumen& lumen, const Eigen::MatrixX3d& y, int sac_region, double cap_mm, double clear_mm, double measure_mm) {
    NeckChannel out;
    if (lumen.neck_loops.empty() || sac_region < 0) return out;
    const Eigen::MatrixX3i& F = lumen.F;
    const Eigen::Index NF = F.rows();
    const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> seg = neck_segments_at_rest(lumen);
    if (seg.empty()) return out;
    DeformedLumen balls(lumen.F, y, lumen.wall_mm);
    std::vector<double> width(static_cast<size_t>(NF), cap_mm);
    std::vector<char> sac(static_cast<size_t>(NF), 0), parent(static_cast<size_t>(NF), 0);
    bool any_sac = false, any_parent = false;
    const Eigen::Vector3d third = Eigen::Vector3d::Constant(1.0 / 3.0);
    for (Eigen::Index f = 0; f < NF; ++f) {
        const Eigen::Vector3d c = (lumen.X.row(F(f, 0)) + lumen.X.row(F(f, 1)) + lumen.X.row(F(f, 2))).transpose() / 3.0;
        double dist = std::numeric_limits<double>::infinity();
        for (const auto& [a, b] : seg) dist = std::min(dist, point_segment_distance(c, a, b));
        if (dist >= clear_mm) {
            (lumen.face_region[f] == sac_region ? sac : parent)[static_cast<size_t>(f)] = 1;
            (lumen.face_region[f] == sac_region ? any_sac : any_parent) = true;
        }
        if (dist <= measure_mm) {
            width[static_cast<size_t>(f)] = balls.width(static_cast<int>(f), third, cap_mm);
            ++out.faces_measured;
        }
    }
    out.face_width_mm = width;
    if (!any_sac || !any_parent) return out;
    out.reach_mm = widest_reach(F, width, parent);
    const auto [w, at] = widest_channel(F, width, sac, parent);
    out.width_mm = w;  // 0: separated at every width (a sac and parent on different pieces of lumen)
    if (at >= 0) {
        out.at = balls.centroids().row(at).transpose();
        out.face = at;
    }
    return out;
}


ParentChannel parent_channel(const SimLumen& lumen, const Eigen::MatrixX3d& y, int sac_region, double cap_mm, double end_mm) {
    ParentChannel out;
    const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> seg = neck_segments_at_rest(lumen);
    if (seg.empty() || sac_region < 0) return out;
    const Eigen::MatrixX3i& F = lumen.F;
    const Eigen::Index NF = F.rows();
    // The parent's ends: its faces at least end_mm from the neck line, in pieces joined across edges.
    std::vector<char> near(static_cast<size_t>(NF), 0), sac(static_cast<size_t>(NF), 0);
    std::vector<int> end(static_cast<size_t>(NF), -1);
    for (Eigen::Index f = 0; f < NF; ++f) {
        const Eigen::Vector3d c = (lumen.X.row(F(f, 0)) + lumen.X.row(F(f, 1)) + lumen.X.row(F(f, 2))).transpose() / 3.0;
        double dist = std::numeric_limits<double>::infinity();
        for (const auto& [a, b] : seg) dist = std::min(dist, point_segment_distance(c, a, b));
        sac[static_cast<size_t>(f)] = lumen.face_region[f] == sac_region;
        near[static_cast<size_t>(f)] = dist < end_mm;
    }
    const std::vector<std::vector<int>> nbr = face_neighbours(F);
    for (Eigen::Index f0 = 0; f0 < NF; ++f0) {
        if (near[static_cast<size_t>(f0)] || sac[static_cast<size_t>(f0)] || end[static_cast<size_t>(f0)] >= 0) continue;
        std::vector<int> stack{static_cast<int>(f0)};
        end[static_cast<size_t>(f0)] = out.ends;
        while (!stack.empty()) {
            const int f = stack.back();
            stack.pop_back();
            for (int g : nbr[static_cast<size_t>(f)])
                if (!near[static_cast<size_t>(g)] && !sac[static_cast<size_t>(g)] && end[static_cast<size_t>(g)] < 0) {
                    end[static_cast<size_t>(g)] = out.ends;
                    stack.push_back(g);
                }
        }
        ++out.ends;
    }
    if (out.ends < 2) return out;
    // The faces' widths at rest and deformed (the same faces: those near the neck line, the parent's).
    auto widths = [&](DeformedLumen& balls) {
        std::vector<double> w(static_cast<size_t>(NF), cap_mm);
        const Eigen::Vector3d third = Eigen::Vector3d::Constant(1.0 / 3.0);
        for (Eigen::Index f = 0; f < NF; ++f) {
            if (sac[static_cast<size_t>(f)]) w[static_cast<size_t>(f)] = 0.0;
            else if (near[static_cast<size_t>(f)]) w[static_cast<size_t>(f)] = balls.width(static_cast<int>(f), third, cap_mm);
        }
        return w;
    };
    DeformedLumen rest_balls(F, lumen.X, lumen.wall_mm), balls(F, y, lumen.wall_mm);
    const std::vector<double> w0 = widths(rest_balls), w1 = widths(balls);
    for (int a = 0; a < out.ends; ++a)
        for (int b = a + 1; b < out.ends; ++b) {
            std::vector<char> A(static_cast<size_t>(NF), 0), B(static_cast<size_t>(NF), 0);
            for (Eigen::Index f = 0; f < NF; ++f) {
                A[static_cast<size_t>(f)] = end[static_cast<size_t>(f)] == a;
                B[static_cast<size_t>(f)] = end[static_cast<size_t>(f)] == b;
            }
            const double r = widest_channel(F, w0, A, B).first;
            const auto [d, face] = widest_channel(F, w1, A, B);
            if (!(r > 0)) continue;  // joined only through the sac at rest: no parent's channel between them
            const double narrowing = 1.0 - d / r;
            if (std::isnan(out.narrowing) || narrowing > out.narrowing) {
                out.rest_mm = r;
                out.width_mm = d;
                out.narrowing = narrowing;
                out.at = face >= 0 ? Eigen::Vector3d(balls.centroids().row(face).transpose()) : Eigen::Vector3d::Zero();
            }
        }
    return out;
}

double neck_cut_off_fraction(const NeckOcclusion& occ, const NeckChannel& channel, double gap_tol_mm) {
    if (channel.reach_mm.empty()) return -1.0;
    // Segments of the neck line (deformed lengths, as the occlusion's) whose two ends lie on faces the parent's
    // blood reaches only through channels at most the tolerance wide.
    double len = 0, cut = 0;
    for (size_t l = 0; l < occ.points.size(); ++l) {
        const auto& pts = occ.points[l];
        const auto& faces = occ.faces[l];
        for (size_t k = 0; k < pts.size(); ++k) {
            const size_t m = (k + 1) % pts.size();
            const double seg_mm = (pts[m] - pts[k]).norm();
            len += seg_mm;
            if (channel.reach_mm[static_cast<size_t>(faces[k])] <= gap_tol_mm && channel.reach_mm[static_cast<size_t>(faces[m])] <= gap_tol_mm)
                cut += seg_mm;
        }
    }
    return len > 0 ? cut / len : -1.0;
}

std::pair<double, double> neck_in_jaws(const std::vector<std::vector<Eigen::Vector3d>>& loops, const std::vector<JawsBox>& jaws) {
    constexpr double NaN = std::numeric_limits<double>::quiet_NaN();
    double len = 0, in = 0, beside = 0;
    std::vector<fem::ClipBlades> bent(jaws.size());  // (a curved blade's place along and across its centre line)
    for (size_t ji = 0; ji < jaws.size(); ++ji) {
        bent[ji].curve_radius_mm = jaws[ji].curve_radius_mm;
        bent[ji].curve_from_mm = jaws[ji].curve_from_mm;
    }
    for (const auto& pts : loops)
        for (size_t k = 0; k < pts.size(); ++k) {
            const Eigen::Vector3d& q = pts[(k + 1) % pts.size()];
            const Eigen::Vector3d mid = 0.5 * (pts[k] + q);
            const double seg = (q - pts[k]).norm();
            len += seg;
            bool inside = false;
            for (size_t ji = 0; ji < jaws.size(); ++ji) {
                const JawsBox& j = jaws[ji];
                const Eigen::Vector3d r = mid - j.hinge, side = j.axis.cross(j.up).normalized();
                const fem::ClipBlades::FaceCoords fc = bent[ji].face_coords(r.dot(j.axis), r.dot(side));
                const double along = fc.s, wide = std::abs(fc.a) - 0.5 * j.width_mm - j.margin_mm;
                if (r.dot(j.axis) < j.face_from_mm || along > j.length_mm) continue;
                if (wide > 0) beside = std::max(beside, wide);
                else if (std::abs(r.dot(j.up)) <= j.max_up_mm) inside = true;
            }
            if (inside) in += seg;
        }
    if (jaws.empty() || !(len > 0)) return {NaN, NaN};
    return {in / len, beside};
}

Simulator::Impl::PatchRun::TissueOverlap Simulator::Impl::PatchRun::tissue_overlap() const {
    TissueOverlap out;
    out.inside.assign(static_cast<size_t>(X.rows()), 0);
    if (elements.rows() == 0) return out;
    std::vector<int> all;
    for (int a = 0; a < static_cast<int>(X.rows()); ++a)
        if (!pm->on_interface(a)) all.push_back(a);
    std::vector<double> deep;
    const std::vector<int> held = fem::nodes_inside_elements(positions(), elements, all, &deep);
    for (size_t i = 0; i < held.size(); ++i)
        if (held[i] >= 0 && deep[i] > TISSUE_ROUNDOFF_MM) {
            out.inside[static_cast<size_t>(all[i])] = 1;
            ++out.nodes;
            out.deepest_mm = std::max(out.deepest_mm, deep[i]);
        }
    return out;
}

bool write_lumen_obj(const std::string& path, const SimLumen& lumen, const Eigen::MatrixX3d& y, const NeckOcclusion& occ, const NeckChannel& channel) {
    std::FILE* fo = std::fopen(path.c_str(), "w");
    if (!fo) return false;
    for (Eigen::Index v = 0; v < y.rows(); ++v) std::fprintf(fo, "v %.6f %.6f %.6f\n", y(v, 0), y(v, 1), y(v, 2));
    for (Eigen::Index f = 0; f < lumen.F.rows(); ++f) std::fprintf(fo, "f %d %d %d\n", lumen.F(f, 0) + 1, lumen.F(f, 1) + 1, lumen.F(f, 2) + 1);
    for (size_t l = 0; l < occ.points.size(); ++l)
        for (size_t k = 0; k < occ.points[l].size(); ++k)
            std::fprintf(fo, "# neck %zu %.6f %.6f %.6f %.6g\n", l, occ.points[l][k].x(), occ.points[l][k].y(), occ.points[l][k].z(), occ.gap_mm[l][k]);
    for (size_t f = 0; f < channel.face_width_mm.size(); ++f) std::fprintf(fo, "# width %zu %.6g\n", f, channel.face_width_mm[f]);
    std::fprintf(fo, "# channel %.6g %.6f %.6f %.6f\n", channel.width_mm, channel.at.x(), channel.at.y(), channel.at.z());
    return std::fclose(fo) == 0;
}

Eigen::MatrixX3d Simulator::Impl::lumen_now(const Eigen::MatrixX3d& x) const {
    const SimLumen& lumen = model.surface.lumen;
    Eigen::MatrixX3d y = lumen.deformed(x, model.surface.X);
    // Inside a nonlinear patch the lumen's vertices are the patch's own nodes: their displacement (the wall's
    // compression under the clip included), plus the linear solve's part at the vertex they are bound to.
    for (const PatchRun& P : patches) {
        if (!P.alive || !P.pm) continue;
        for (Eigen::Index l = 0; l < y.rows(); ++l) {
            const int p = P.pm->local(lumen.node[l]);
            if (p < 0) continue;
            const Eigen::Index b = lumen.bind[l];
            y.row(l) = lumen.X.row(l) + P.v.segment<3>(3 * p).transpose() + (d.row(b) - d_patch.row(b));
        }
    }
    return y;
}

Assessment Simulator::Impl::assess() {
    Assessment out = a;
    out.total_time_s = t_phys;
    out.clips_deposited = 0;
    for (const Clip& c : clips)
        if (c.state == Clip::State::DEPOSITED && !c.model.empty()) ++out.clips_deposited;
    out.clip_ends.clear();
    for (const Clip& c : clips) {
        if (c.model.empty()) continue;
        const ClipModel& cm = scene.clip_models.at(c.model);
        out.clip_ends.push_back({c.id, c.model, c.state == Clip::State::DEPOSITED, cm.spring.has_value(), cm.spring_placeholder, c.opening_deg,
                                 c.grip_force_n, c.spring_torque_nmm, c.tissue_moment_nmm, c.label_force_n});
    }
    const Eigen::MatrixX3d x = deformed();
    const SimLumen& lumen = model.surface.lumen;
    const Eigen::MatrixX3d y = lumen_now(x);
    // With a patch of 10-node elements the neck is measured on the quadratic surface (split_lumen): the walls touch
    // there, and on the corner triangles a flattened fold's channel reads about twice as wide (bench/bench_fold.cpp).
    // The mid-edge vertices take the patch's displacement where it has them, else the mean of their corners'.
    const bool quadratic = std::any_of(patches.begin(), patches.end(), [](const PatchRun& P) { return P.alive && P.quadratic; });
    std::optional<SplitLumen> split;
    Eigen::MatrixX3d yq;
    if (quadratic) {
        const fem::MidEdgeNodes mid(model.volume->tets);
        split = split_lumen(lumen, [&](int a, int b) { return mid(a, b); }, model.volume->nodes);
        const SimLumen& Q = split->lumen;
        yq.resize(Q.X.rows(), 3);
        yq.topRows(y.rows()) = y;
        for (Eigen::Index e = 0; e < split->between.rows(); ++e) {
            const Eigen::Index v = y.rows() + e, a = split->between(e, 0), b = split->between(e, 1);
            Eigen::RowVector3d u = 0.5 * ((y.row(a) - lumen.X.row(a)) + (y.row(b) - lumen.X.row(b)));
            for (const PatchRun& P : patches) {
                const int p = P.alive ? P.pm->local(Q.node[v]) : -1;
                if (p < 0) continue;
                const Eigen::Index ba = lumen.bind[a], bb = lumen.bind[b];
                u = P.v.segment<3>(3 * p).transpose() + 0.5 * ((d.row(ba) - d_patch.row(ba)) + (d.row(bb) - d_patch.row(bb)));
                break;
            }
            yq.row(v) = Q.X.row(v) + u;
        }
    }
    const SimLumen& measured = split ? split->lumen : lumen;
    out.neck_on_quadratic_surface = split.has_value();
    const Eigen::MatrixX3d& ym = split ? yq : y;
    const NeckOcclusion occ = neck_occlusion(measured, ym, scene.neck_gap_mm, measured.wall_mm);
    out.neck_closed_fraction = occ.fraction;
    out.neck_length_mm = occ.length_mm;
    out.neck_min_gap_mm = std::isfinite(occ.min_gap_mm) ? occ.min_gap_mm : -1.0;
    out.neck_interpenetration_mm = occ.max_interpenetration_mm;
    // The tissue the patches hold round the lumen: a vertex behind a face there must lie in it to be through it.
    LumenTissue tissue;
    tissue.patch.assign(static_cast<size_t>(measured.X.rows()), -1);
    tissue.inside.assign(tissue.patch.size(), 0);
    // And whether any of a patch's nodes (off its interface: the lumen's, the outer surface's, inside the wall) lies in
    // an element not its own: the tissue overlapping itself, wherever (a wall that passed through another whole lies
    // beside its tissue on the lumen's side, but its nodes in the other's).
    // Deeper than round-off (1 µm: the linear model about rest leaves the tube's nodes 1e-7 mm inside neighbours).
    out.patch_nodes_in_other_tissue = -1;
    out.patch_tissue_overlap_mm = 0;
    for (size_t k = 0; k < patches.size(); ++k) {
        const PatchRun& P = patches[k];
        if (!P.alive || P.elements.rows() == 0) continue;
        const PatchRun::TissueOverlap ov = P.tissue_overlap();
        out.patch_nodes_in_other_tissue = std::max(out.patch_nodes_in_other_tissue, 0) + ov.nodes;
        out.patch_tissue_overlap_mm = std::max(out.patch_tissue_overlap_mm, ov.deepest_mm);
        // The lumen's vertices off the interface are among those nodes.
        const std::vector<char>& in_tissue = ov.inside;
        for (Eigen::Index l = 0; l < measured.X.rows(); ++l) {
            const int p = P.pm->local(measured.node[l]);
            if (p < 0 || P.pm->on_interface(p) || tissue.patch[static_cast<size_t>(l)] >= 0) continue;
            tissue.patch[static_cast<size_t>(l)] = static_cast<int>(k);
            tissue.inside[static_cast<size_t>(l)] = in_tissue[static_cast<size_t>(p)];
        }
    }
    const LumenCrossing crossing = lumen_crossing(measured, ym, LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM, &tissue);
    out.lumen_crossing_mm = crossing.depth_mm;
    out.lumen_crossing_vertices = crossing.vertices;
    out.lumen_crossing_at = crossing.at;
    out.lumen_beside_tissue_mm = crossing.beside_mm;
    out.lumen_beside_tissue_vertices = crossing.beside_vertices;
    out.neck_line.clear();
    NeckChannel channel;
    {
        const auto& names = model.surface.region_names;
        const auto it = std::find(names.begin(), names.end(), "aneurysm");
        channel = neck_channel(measured, ym, it == names.end() ? -1 : static_cast<int>(it - names.begin()));
        out.neck_channel_mm = channel.width_mm;
        out.neck_channel_at = channel.at;
        if (channel.face >= 0) out.neck_channel_edge_mm = lumen_edges_mm(lumen)[split ? channel.face / 4 : channel.face];
        out.neck_cut_off_fraction = neck_cut_off_fraction(occ, channel, scene.neck_gap_mm);
        const ParentChannel parent = parent_channel(measured, ym, it == names.end() ? -1 : static_cast<int>(it - names.begin()));
        out.parent_channel_mm = parent.width_mm;
        out.parent_channel_rest_mm = parent.rest_mm;
        out.parent_narrowing = parent.narrowing;
        out.parent_channel_at = parent.at;
    }
    for (size_t l = 0; l < occ.points.size(); ++l)
        for (size_t k = 0; k < occ.points[l].size(); ++k) out.neck_line.push_back({occ.points[l][k], occ.gap_mm[l][k], static_cast<int>(l)});
    {
        // The deformed neck line against the jaws of the clips held or deposited, at their opening.
        std::vector<JawsBox> jaws;
        for (const Clip& c : clips)
            if (!c.model.empty() && scene.clip_models.count(c.model)) {
                const ClipModel& cm = scene.clip_models.at(c.model);
                jaws.push_back({c.pose.position, c.pose.axis.normalized(), c.pose.up.normalized(), cm.reach_mm(), cm.jaw_width_mm});
                jaws.back().curve_radius_mm = cm.jaw_curve_radius_mm;
                jaws.back().curve_from_mm = cm.fulcrum_mm;
                jaws.back().face_from_mm = cm.blades(c.pose).face_from_mm;
            }
        std::tie(out.neck_in_jaws_fraction, out.neck_beside_jaws_mm) = neck_in_jaws(occ.points, jaws);
    }
    // Debugging and pictures (bench/render_channel.py): the deformed lumen as a Wavefront OBJ, the neck line's points, the
    // faces' widths and the channel listed after it as comments.
    if (const char* obj = std::getenv("ANEU_LUMEN_OBJ")) write_lumen_obj(obj, measured, ym, occ, channel);
    // ANEU_PATCH_DUMP=F: each live patch's nodes (rest, displaced, on the interface, a blade candidate, the element
    // holding it that is not its own, how deep) and elements, for bench/patch_tissue_overlap.py.
    if (const char* dump = std::getenv("ANEU_PATCH_DUMP"))
        if (std::FILE* fo = std::fopen(dump, "w")) {
            for (size_t k = 0; k < patches.size(); ++k) {
                const PatchRun& P = patches[k];
                if (!P.alive || P.elements.rows() == 0) continue;
                const Eigen::MatrixX3d x = P.positions();
                std::vector<int> all(static_cast<size_t>(x.rows()));
                for (size_t a = 0; a < all.size(); ++a) all[a] = static_cast<int>(a);
                std::vector<double> deep;
                const std::vector<int> in = fem::nodes_inside_elements(x, P.elements, all, &deep);
                std::vector<char> cand(all.size(), 0);
                for (int a : P.cand) cand[static_cast<size_t>(a)] = 1;
                std::fprintf(fo, "patch %zu nodes %lld elements %lld\n", k, static_cast<long long>(x.rows()), static_cast<long long>(P.elements.rows()));
                for (Eigen::Index a = 0; a < x.rows(); ++a)
                    std::fprintf(fo, "n %.9f %.9f %.9f %.9f %.9f %.9f %d %d %d %.3e\n", P.X(a, 0), P.X(a, 1), P.X(a, 2), x(a, 0), x(a, 1), x(a, 2),
                                 P.pm->on_interface(static_cast<int>(a)) ? 1 : 0, cand[static_cast<size_t>(a)], in[static_cast<size_t>(a)], deep[static_cast<size_t>(a)]);
                for (Eigen::Index e = 0; e < P.elements.rows(); ++e) {
                    std::fprintf(fo, "e");
                    for (Eigen::Index c = 0; c < P.elements.cols(); ++c) std::fprintf(fo, " %d", P.elements(e, c));
                    std::fprintf(fo, "\n");
                }
            }
            std::fclose(fo);
        }
    // The neck line (the outer surface's) lying between the jaws of a closed clip, within neck_tolerance_mm (where the
    // clip is, not what it achieved).
    {
        std::vector<std::vector<Eigen::Vector3d>> loops;
        for (const auto& loop : model.surface.neck_loops) {
            loops.emplace_back();
            for (int v : loop) loops.back().push_back(x.row(v).transpose());
        }
        std::vector<JawsBox> closed;
        for (const Clip& c : clips)
            if (!c.model.empty() && c.opening_deg <= 1.0) {
                const ClipModel& cm = scene.clip_models.at(c.model);
                closed.push_back({c.pose.position, c.pose.axis.normalized(), c.pose.up.normalized(), cm.reach_mm(), cm.jaw_width_mm,
                                  scene.neck_tolerance_mm, 0.5 * cm.closed_gap_mm + scene.neck_tolerance_mm, cm.jaw_curve_radius_mm, cm.fulcrum_mm,
                                  cm.blades(c.pose).face_from_mm});
            }
        const double f = neck_in_jaws(loops, closed).first;
        out.neck_between_jaws_fraction = std::isnan(f) ? 0.0 : f;
    }
    out.patches.clear();
    for (const PatchRun& P : patches) {
        out.patches.push_back(P.stats);  // min_wall_distance_mm stays +inf when no opposite walls came within reach
    }
    return out;
}

}  // namespace aneu::sim
