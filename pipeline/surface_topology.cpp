// SPDX-License-Identifier: MIT
// Plain topology and measures of triangle surfaces (no heavy library needed).
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <Eigen/Geometry>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace aneu::pipeline {

namespace {
std::string where(const SurfaceData& s, int a, int b) {
    const Eigen::Vector3d x = 0.5 * (s.V.row(a) + s.V.row(b)).transpose();
    return "edge (" + std::to_string(a) + ", " + std::to_string(b) + ") at (" + shortest(x.x()) + ", " + shortest(x.y()) + ", " +
           shortest(x.z()) + ") mm";
}
}  // namespace

std::vector<std::vector<int>> boundary_loops(const SurfaceData& s) {
    // Directed edge a→b of each face; an edge is interior when b→a also exists.
    std::map<std::pair<int, int>, int> directed;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
            if (!directed.emplace(std::make_pair(a, b), static_cast<int>(f)).second) {
                throw InputError("surface: not an oriented 2-manifold: " + where(s, a, b) +
                                 " is used twice in the same direction (non-manifold edge or inconsistent orientation)");
            }
        }
    // Boundary half-edges b→a (reversed so that the loop runs with the hole on its left... kept as the face's direction).
    std::map<int, int> next;  // boundary edge a→b of a face whose twin is missing: loop step a → b
    for (const auto& [e, f] : directed) {
        (void)f;
        if (directed.count({e.second, e.first})) continue;
        if (!next.emplace(e.first, e.second).second) {
            throw InputError("surface: not a 2-manifold: vertex " + std::to_string(e.first) + " at (" + shortest(s.V(e.first, 0)) + ", " +
                             shortest(s.V(e.first, 1)) + ", " + shortest(s.V(e.first, 2)) +
                             ") mm starts two boundary edges (two boundaries touch there)");
        }
    }
    std::vector<std::vector<int>> loops;
    std::map<int, bool> used;
    for (const auto& [a, b] : next) {
        (void)b;
        if (used[a]) continue;
        std::vector<int> loop;
        int v = a;
        while (!used[v]) {
            used[v] = true;
            loop.push_back(v);
            const auto it = next.find(v);
            if (it == next.end()) throw InputError("surface: a boundary is not a closed loop near vertex " + std::to_string(v));
            v = it->second;
        }
        if (v != a) throw InputError("surface: boundary loops share vertex " + std::to_string(v));
        loops.push_back(std::move(loop));
    }
    return loops;
}

SurfaceData sub_surface(const SurfaceData& s, const std::vector<char>& keep) {
    SurfaceData o;
    std::vector<int> map(static_cast<size_t>(s.V.rows()), -1);
    int nv = 0, nf = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (!keep[static_cast<size_t>(f)]) continue;
        ++nf;
        for (int k = 0; k < 3; ++k)
            if (map[static_cast<size_t>(s.F(f, k))] < 0) map[static_cast<size_t>(s.F(f, k))] = nv++;
    }
    o.V.resize(nv, 3);
    for (Eigen::Index i = 0; i < s.V.rows(); ++i)
        if (map[static_cast<size_t>(i)] >= 0) o.V.row(map[static_cast<size_t>(i)]) = s.V.row(i);
    o.F.resize(nf, 3);
    o.face_label.resize(nf);
    const bool reg = s.face_region.size() == s.F.rows();
    if (reg) o.face_region.resize(nf);
    int g = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (!keep[static_cast<size_t>(f)]) continue;
        for (int k = 0; k < 3; ++k) o.F(g, k) = map[static_cast<size_t>(s.F(f, k))];
        o.face_label[g] = s.face_label.size() ? s.face_label[f] : 0;
        if (reg) o.face_region[g] = s.face_region[f];
        ++g;
    }
    o.label_names = s.label_names;
    o.region_names = s.region_names;
    if (s.vertex_thickness.size() == s.V.rows()) {
        o.vertex_thickness.resize(nv);
        for (Eigen::Index i = 0; i < s.V.rows(); ++i)
            if (map[static_cast<size_t>(i)] >= 0) o.vertex_thickness[map[static_cast<size_t>(i)]] = s.vertex_thickness[i];
    }
    return o;
}

Eigen::Index cap_loops(SurfaceData& s, const std::vector<std::vector<int>>& loops, const std::vector<int>& cap_labels) {
    const Eigen::Index f0 = s.F.rows();
    Eigen::Index nf = f0, nv = s.V.rows();
    for (const auto& l : loops) nf += static_cast<Eigen::Index>(l.size());
    s.V.conservativeResize(nv + static_cast<Eigen::Index>(loops.size()), 3);
    s.F.conservativeResize(nf, 3);
    s.face_label.conservativeResize(nf);
    const bool reg = s.face_region.size() == f0;
    if (reg) s.face_region.conservativeResize(nf);
    Eigen::Index f = f0;
    for (size_t q = 0; q < loops.size(); ++q) {
        const auto& l = loops[q];
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int v : l) c += s.V.row(v).transpose();
        c /= static_cast<double>(l.size());
        s.V.row(nv) = c.transpose();
        for (size_t i = 0; i < l.size(); ++i) {
            // The loop runs along its faces' edges a→b; the cap uses b→a to stay consistently oriented.
            s.F.row(f) << l[(i + 1) % l.size()], l[i], static_cast<int>(nv);
            s.face_label[f] = cap_labels[q];
            if (reg) s.face_region[f] = 0;
            ++f;
        }
        ++nv;
    }
    return f0;
}

NamedValues triangle_quality(const SurfaceData& s) {
    double sum = 0, sum2 = 0, lo = 1e300, hi = 0, min_angle = 180;
    std::size_t ne = 0, below25 = 0, below15 = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const Eigen::Vector3d x[3] = {s.V.row(s.F(f, 0)), s.V.row(s.F(f, 1)), s.V.row(s.F(f, 2))};
        double fmin = 180;
        for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3d e = x[(k + 1) % 3] - x[k];
            const double L = e.norm();
            sum += L;
            sum2 += L * L;
            lo = std::min(lo, L);
            hi = std::max(hi, L);
            ++ne;
            const Eigen::Vector3d u = x[(k + 1) % 3] - x[k], w = x[(k + 2) % 3] - x[k];
            const double ang = std::atan2(u.cross(w).norm(), u.dot(w))  / DEG;
            fmin = std::min(fmin, ang);
        }
        min_angle = std::min(min_angle, fmin);
        below25 += fmin < 25.0;
        below15 += fmin < 15.0;
    }
    // Every interior edge was counted twice (once per face); the statistics are per face-edge.
    const double mean = ne ? sum / static_cast<double>(ne) : 0.0;
    const double sd = ne ? std::sqrt(std::max(0.0, sum2 / static_cast<double>(ne) - mean * mean)) : 0.0;
    const double nf = std::max<double>(1.0, static_cast<double>(s.F.rows()));
    return {{"triangles", static_cast<double>(s.F.rows())},
            {"vertices", static_cast<double>(s.V.rows())},
            {"edge_mean_mm", mean},
            {"edge_sd_mm", sd},
            {"edge_min_mm", ne ? lo : 0.0},
            {"edge_max_mm", hi},
            {"min_angle_deg", s.F.rows() ? min_angle : 0.0},
            {"fraction_min_angle_below_25deg", static_cast<double>(below25) / nf},
            {"fraction_min_angle_below_15deg", static_cast<double>(below15) / nf}};
}

double enclosed_volume(const SurfaceData& s) {
    double v = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
        v += a.dot(b.cross(c)) / 6.0;
    }
    return v;
}

}  // namespace aneu::pipeline

namespace aneu::pipeline {

namespace {
double min_angle_of(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    auto ang = [](const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& r) {
        const Eigen::Vector3d u = q - p, w = r - p;
        return std::atan2(u.cross(w).norm(), u.dot(w));
    };
    return std::min({ang(a, b, c), ang(b, c, a), ang(c, a, b)});
}
}  // namespace

int improve_min_angle(SurfaceData& s, double max_dihedral_deg, int passes) {
    const double cos_max = std::cos(max_dihedral_deg * DEG);
    int total = 0;
    for (int pass = 0; pass < passes; ++pass) {
        // Directed edge → face, to find each interior edge's two faces.
        std::map<std::pair<int, int>, int> face_of;
        for (Eigen::Index f = 0; f < s.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) face_of[{s.F(f, k), s.F(f, (k + 1) % 3)}] = static_cast<int>(f);
        std::vector<char> touched(static_cast<size_t>(s.F.rows()), 0);
        int flips = 0;
        for (const auto& [e, f0] : face_of) {
            const int a = e.first, b = e.second;
            if (a > b) continue;
            const auto it = face_of.find({b, a});
            if (it == face_of.end()) continue;  // boundary edge: kept
            const int f1 = it->second;
            if (touched[static_cast<size_t>(f0)] || touched[static_cast<size_t>(f1)]) continue;
            auto third = [&](int f) {
                for (int k = 0; k < 3; ++k)
                    if (s.F(f, k) != a && s.F(f, k) != b) return s.F(f, k);
                return -1;
            };
            const int c = third(f0), d = third(f1);  // f0 = (a, b, c), f1 = (b, a, d)
            if (c == d || face_of.count({c, d}) || face_of.count({d, c})) continue;
            const Eigen::Vector3d A = s.V.row(a), B = s.V.row(b), C = s.V.row(c), D = s.V.row(d);
            const Eigen::Vector3d n0 = (B - A).cross(C - A), n1 = (A - B).cross(D - B);
            if (n0.normalized().dot(n1.normalized()) < cos_max) continue;  // not flat enough: a flip would change the shape
            const double before = std::min(min_angle_of(A, B, C), min_angle_of(B, A, D));
            const double after = std::min(min_angle_of(A, D, C), min_angle_of(B, C, D));
            // New faces (a, d, c) and (b, c, d) must face the same way as the old ones.
            const Eigen::Vector3d m0 = (D - A).cross(C - A), m1 = (C - B).cross(D - B);
            if (after <= before + 1e-9 || m0.dot(n0 + n1) <= 0 || m1.dot(n0 + n1) <= 0) continue;
            s.F.row(f0) << a, d, c;
            s.F.row(f1) << b, c, d;
            touched[static_cast<size_t>(f0)] = touched[static_cast<size_t>(f1)] = 1;
            ++flips;
        }
        total += flips;
        if (flips == 0) break;
    }
    return total;
}

namespace {
/// Directed edge → face, vertex neighbours and vertex faces of a triangle surface.
struct Adjacency {
    std::map<std::pair<int, int>, int> face_of;
    std::vector<std::set<int>> nb;
    std::vector<std::vector<int>> vf;
    explicit Adjacency(const SurfaceData& s) : nb(static_cast<size_t>(s.V.rows())), vf(static_cast<size_t>(s.V.rows())) {
        for (Eigen::Index f = 0; f < s.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) {
                const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
                face_of[{a, b}] = static_cast<int>(f);
                nb[static_cast<size_t>(a)].insert(b);
                nb[static_cast<size_t>(b)].insert(a);
                vf[static_cast<size_t>(a)].push_back(static_cast<int>(f));
            }
    }
    /// Median length of the edges (each interior edge once, boundary edges once); 0 without faces.
    double median_edge(const SurfaceData& s) const {
        std::vector<double> lengths;
        for (const auto& [e, f] : face_of)
            if (e.first < e.second || !face_of.count({e.second, e.first})) lengths.push_back((s.V.row(e.first) - s.V.row(e.second)).norm());
        if (lengths.empty()) return 0.0;
        std::nth_element(lengths.begin(), lengths.begin() + static_cast<std::ptrdiff_t>(lengths.size() / 2), lengths.end());
        return lengths[lengths.size() / 2];
    }
};
int common_neighbours(const std::vector<std::set<int>>& nb, int a, int b) {
    int common = 0;
    for (int x : nb[static_cast<size_t>(a)]) common += nb[static_cast<size_t>(b)].count(x) ? 1 : 0;
    return common;
}
/// Merges vertex `gone` into `kept`, placed at P (the faces of the collapsed edge are for the caller to drop);
/// both and their neighbours are touched for the rest of the pass.
void collapse_vertex(SurfaceData& s, const std::vector<std::vector<int>>& vf, const std::vector<std::set<int>>& nb, std::vector<char>& touched, int kept,
                     int gone, const Eigen::Vector3d& P) {
    s.V.row(kept) = P.transpose();
    for (int g : vf[static_cast<size_t>(gone)])
        for (int k = 0; k < 3; ++k)
            if (s.F(g, k) == gone) s.F(g, k) = kept;
    for (int v : {kept, gone}) {
        touched[static_cast<size_t>(v)] = 1;
        for (int x : nb[static_cast<size_t>(v)]) touched[static_cast<size_t>(x)] = 1;
    }
}
}  // namespace

int collapse_short_boundary_edges(SurfaceData& s, double min_angle_deg) {
    const double limit = min_angle_deg * DEG;
    int total = 0;
    for (int pass = 0; pass < 5; ++pass) {
        const Adjacency adj(s);
        const auto& [face_of, nb, vf] = adj;
        // Also a boundary edge shorter than a quarter of the median edge, whatever its triangle's angle:
        // a small but well-shaped triangle on a loop still makes a thin triangle where the loop is joined to
        // another (the wall's annular caps: 1.4° on a TOF-MRA's end, from a 0.015 mm loop edge).
        // (A quarter of the median of all edges: a small vessel's loop has short segments throughout, and a quarter of
        // its own median still left 0.037 mm among 0.4 mm edges on a real CTA's A2 end.)
        const double short_edge = 0.25 * adj.median_edge(s);
        const auto min_angle = [](const Eigen::Vector3d* P) {
            double m = PI;
            for (int k = 0; k < 3; ++k) {
                const Eigen::Vector3d u = P[(k + 1) % 3] - P[k], w = P[(k + 2) % 3] - P[k];
                m = std::min(m, std::atan2(u.cross(w).norm(), u.dot(w)));
            }
            return m;
        };
        std::vector<char> keep(static_cast<size_t>(s.F.rows()), 1), touched(static_cast<size_t>(s.V.rows()), 0);
        int n = 0;
        for (const auto& [e, f] : face_of) {
            const auto [a, b] = e;
            if (face_of.count({b, a})) continue;  // interior edge
            int c = -1;
            for (int k = 0; k < 3; ++k)
                if (s.F(f, k) != a && s.F(f, k) != b) c = s.F(f, k);
            const Eigen::Vector3d A = s.V.row(a), B = s.V.row(b), C = s.V.row(c);
            const Eigen::Vector3d u = A - C, w = B - C;
            const bool thin = std::atan2(u.cross(w).norm(), u.dot(w)) < limit;
            if (!thin && (A - B).norm() >= short_edge) continue;
            if (touched[static_cast<size_t>(a)] || touched[static_cast<size_t>(b)] || touched[static_cast<size_t>(c)]) continue;
            if (!thin) {  // a short edge of a well-shaped triangle: only when every triangle round it keeps the limit angle
                const Eigen::Vector3d M = 0.5 * (A + B);
                double after = PI;
                for (int v : {a, b})
                    for (int g : vf[static_cast<size_t>(v)]) {
                        if (g == f) continue;
                        Eigen::Vector3d Q[3];
                        for (int k = 0; k < 3; ++k) {
                            const int x = s.F(g, k);
                            Q[k] = x == a || x == b ? M : Eigen::Vector3d(s.V.row(x).transpose());
                        }
                        after = std::min(after, min_angle(Q));
                    }
                // Not the thin-triangle limit: a segment a tenth of its neighbours' makes slivers in the wall's annular
                // cap whatever the triangles round it look like; only no worse than 5° (what the interior collapse keeps).
                if (after < 5.0 * DEG) continue;
            }
            if (common_neighbours(nb, a, b) != 1) continue;  // link condition for a boundary edge: only c
            collapse_vertex(s, vf, nb, touched, a, b, 0.5 * (A + B));
            keep[static_cast<size_t>(f)] = 0;
            ++n;
        }
        if (!n) break;
        s = sub_surface(s, keep);
        total += n;
    }
    return total;
}

int collapse_short_interior_edges(SurfaceData& s, double fraction) {
    int total = 0;
    for (int pass = 0; pass < 5; ++pass) {
        const Adjacency adj(s);
        const auto& [face_of, nb, vf] = adj;
        if (face_of.empty()) break;
        std::vector<char> on_boundary(static_cast<size_t>(s.V.rows()), 0);
        for (const auto& [e, f] : face_of)
            if (!face_of.count({e.second, e.first})) on_boundary[static_cast<size_t>(e.first)] = on_boundary[static_cast<size_t>(e.second)] = 1;
        const double limit = fraction * adj.median_edge(s);
        std::vector<char> keep(static_cast<size_t>(s.F.rows()), 1), touched(static_cast<size_t>(s.V.rows()), 0);
        int n = 0;
        for (const auto& [e, f0] : face_of) {
            const auto [a, b] = e;
            if (a > b) continue;
            const auto back = face_of.find({b, a});
            if (back == face_of.end()) continue;  // boundary edges: collapse_short_boundary_edges
            const Eigen::Vector3d A = s.V.row(a), B = s.V.row(b);
            if ((A - B).norm() >= limit || touched[static_cast<size_t>(a)] || touched[static_cast<size_t>(b)]) continue;
            const bool ba = on_boundary[static_cast<size_t>(a)], bb = on_boundary[static_cast<size_t>(b)];
            if (ba && bb) continue;  // a chord between two boundary vertices: collapsing it would pinch the loop
            const int f1 = back->second;
            if (common_neighbours(nb, a, b) != 2) continue;  // link condition: only the two opposite vertices
            const int kept = bb ? b : a, gone = bb ? a : b;
            const Eigen::Vector3d P = ba ? A : bb ? B : Eigen::Vector3d(0.5 * (A + B));
            // Every other face round a and b keeps its orientation and a minimum angle of 5°.
            bool ok = true;
            for (int v : {a, b})
                for (int g : vf[static_cast<size_t>(v)]) {
                    if (g == f0 || g == f1 || !ok) continue;
                    Eigen::Vector3d X[3], Y[3];
                    for (int k = 0; k < 3; ++k) {
                        const int x = s.F(g, k);
                        X[k] = s.V.row(x).transpose();
                        Y[k] = x == a || x == b ? P : X[k];
                    }
                    const Eigen::Vector3d n0 = (X[1] - X[0]).cross(X[2] - X[0]), n1 = (Y[1] - Y[0]).cross(Y[2] - Y[0]);
                    double m = PI;
                    for (int k = 0; k < 3; ++k) {
                        const Eigen::Vector3d u = Y[(k + 1) % 3] - Y[k], w = Y[(k + 2) % 3] - Y[k];
                        m = std::min(m, std::atan2(u.cross(w).norm(), u.dot(w)));
                    }
                    ok = n1.dot(n0) > 0.5 * n0.norm() * n1.norm() && m > 5.0 * DEG;
                }
            if (!ok) continue;
            collapse_vertex(s, vf, nb, touched, kept, gone, P);
            keep[static_cast<size_t>(f0)] = keep[static_cast<size_t>(f1)] = 0;
            ++n;
        }
        if (!n) break;
        s = sub_surface(s, keep);
        total += n;
    }
    return total;
}

void refuse_triangle_count(const std::string& what, double edge_mm, double area_mm2) {
    const double per_triangle = std::sqrt(3.0) / 4.0 * edge_mm * edge_mm;
    const double estimate = area_mm2 / per_triangle;
    if (estimate <= MAX_REMESH_TRIANGLES) return;
    const double smallest = std::sqrt(area_mm2 / MAX_REMESH_TRIANGLES / (std::sqrt(3.0) / 4.0));
    throw InputError(what + " = " + shortest(edge_mm) + " mm would make about " + shortest(std::round(estimate)) + " triangles on " + shortest(area_mm2) +
                     " mm² (at most " + shortest(MAX_REMESH_TRIANGLES) + "); expected an edge of at least " + shortest(std::ceil(smallest * 1e4) / 1e4) + " mm");
}

}  // namespace aneu::pipeline
