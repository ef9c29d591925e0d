// SPDX-License-Identifier: MIT
#include "aneu/sim/shapes.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"

namespace aneu::sim {
namespace {

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5); region: 0 face,
// 1..3 vertex a,b,c, 4..6 edge ab, bc, ca.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c, int& region) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return region = 1, a;
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return region = 2, b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return region = 4, a + d1 / (d1 - d3) * ab;
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return region = 3, c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return region = 6, a + d2 / (d2 - d6) * ac;
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return region = 5, b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
    const double den = 1.0 / (va + vb + vc);
    region = 0;
    return a + ab * (vb * den) + ac * (vc * den);
}

long long edge_key(long long i, long long j, long long n) { return std::min(i, j) * n + std::max(i, j); }

}  // namespace

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c) {
    int region = 0;
    return closest_on_triangle(p, a, b, c, region);
}

void TriMesh::finish() {
    if (V.rows() == 0 || F.rows() == 0) throw InputError("triangle mesh is empty");
    face_normal.resize(F.rows(), 3);
    vertex_normal.setZero(V.rows(), 3);
    edge_normal.clear();
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        Eigen::Vector3d n = (V.row(F(f, 1)) - V.row(F(f, 0))).transpose().cross((V.row(F(f, 2)) - V.row(F(f, 0))).transpose());
        const double len = n.norm();
        if (len > 0) n /= len;
        face_normal.row(f) = n;
        for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3d e1 = (V.row(F(f, (k + 1) % 3)) - V.row(F(f, k))).normalized();
            const Eigen::Vector3d e2 = (V.row(F(f, (k + 2) % 3)) - V.row(F(f, k))).normalized();
            const double ang = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
            vertex_normal.row(F(f, k)) += ang * n.transpose();
            edge_normal[edge_key(F(f, k), F(f, (k + 1) % 3), V.rows())] += n;
        }
    }
    for (Eigen::Index v = 0; v < V.rows(); ++v) {
        const double len = vertex_normal.row(v).norm();
        if (len > 0) vertex_normal.row(v) /= len;
    }
}

Aabb TriMesh::bounds() const {
    Aabb b;
    for (Eigen::Index v = 0; v < V.rows(); ++v) b.extend(V.row(v).transpose());
    return b;
}

TriMesh read_trimesh(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path + ": cannot open the triangle mesh (expected an STL or OBJ file)");
    std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::string ext = path.size() > 4 ? path.substr(path.size() - 4) : "";
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    std::vector<Eigen::Vector3d> pts;
    std::vector<Eigen::Vector3i> tris;
    std::map<std::array<double, 3>, int> weld;
    auto add = [&](const Eigen::Vector3d& p) {
        const std::array<double, 3> k{p.x(), p.y(), p.z()};
        auto [it, fresh] = weld.emplace(k, static_cast<int>(pts.size()));
        if (fresh) pts.push_back(p);
        return it->second;
    };
    if (ext == ".obj") {
        std::istringstream s(content);
        std::string line;
        int lineno = 0;
        while (std::getline(s, line)) {
            ++lineno;
            std::istringstream ls(line);
            std::string tag;
            ls >> tag;
            if (tag == "v") {
                Eigen::Vector3d p;
                if (!(ls >> p.x() >> p.y() >> p.z())) throw InputError(path + ":" + std::to_string(lineno) + ": bad vertex line");
                pts.push_back(p);
            } else if (tag == "f") {
                std::vector<int> idx;
                std::string tok;
                while (ls >> tok) idx.push_back(std::stoi(tok.substr(0, tok.find('/'))) - 1);
                for (size_t k = 2; k < idx.size(); ++k) tris.emplace_back(idx[0], idx[k - 1], idx[k]);
            }
        }
        for (const auto& t : tris)
            if (t.minCoeff() < 0 || t.maxCoeff() >= static_cast<int>(pts.size()))
                throw InputError(path + ": a face refers to a vertex that does not exist");
    } else if (ext == ".stl") {
        const bool ascii = content.compare(0, 5, "solid") == 0 && content.find("facet") != std::string::npos;
        if (ascii) {
            std::istringstream s(content);
            std::string tok;
            std::vector<int> cur;
            while (s >> tok) {
                if (tok == "vertex") {
                    Eigen::Vector3d p;
                    if (!(s >> p.x() >> p.y() >> p.z())) throw InputError(path + ": bad `vertex` in ASCII STL");
                    cur.push_back(add(p));
                    if (cur.size() == 3) {
                        tris.emplace_back(cur[0], cur[1], cur[2]);
                        cur.clear();
                    }
                }
            }
        } else {
            if (content.size() < 84) throw InputError(path + ": too short for a binary STL (84-byte header expected)");
            std::uint32_t n = 0;
            std::memcpy(&n, content.data() + 80, 4);
            if (content.size() < 84 + 50ull * n)
                throw InputError(path + ": binary STL announces " + std::to_string(n) + " triangles but is truncated");
            for (std::uint32_t t = 0; t < n; ++t) {
                const char* rec = content.data() + 84 + 50ull * t;
                int id[3];
                for (int k = 0; k < 3; ++k) {
                    float xyz[3];
                    std::memcpy(xyz, rec + 12 + 12 * k, 12);
                    id[k] = add(Eigen::Vector3d(xyz[0], xyz[1], xyz[2]));
                }
                tris.emplace_back(id[0], id[1], id[2]);
            }
        }
    } else {
        throw InputError(path + ": unknown mesh format (expected .stl or .obj)");
    }
    TriMesh m;
    m.V.resize(static_cast<Eigen::Index>(pts.size()), 3);
    for (size_t i = 0; i < pts.size(); ++i) m.V.row(static_cast<Eigen::Index>(i)) = pts[i];
    m.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
    for (size_t i = 0; i < tris.size(); ++i) m.F.row(static_cast<Eigen::Index>(i)) = tris[i];
    if (m.F.rows() == 0) throw InputError(path + ": no triangle in the mesh");
    m.finish();
    return m;
}

fem::ClipBlades Shape::bent() const {
    fem::ClipBlades b;
    b.length_mm = 2 * half.x();
    b.curve_radius_mm = bend_radius;
    b.curve_from_mm = bend_from;
    return b;
}

std::vector<Eigen::Vector3d> Shape::bent_corners() const {
    // Four corners of the cross-section at 65 places along the centre line (a 90° bend's chords then stray
    // |R|(1 − cos(π/256)) ≈ 8e-5 |R| inside the arc).
    const fem::ClipBlades b = bent();
    std::vector<Eigen::Vector3d> out;
    constexpr int N = 64;
    for (int i = 0; i <= N; ++i) {
        double r, a, dr, da;
        b.centre_line(2 * half.x() * i / N, r, a, dr, da);
        for (double e : {-half.y(), half.y()})
            for (double z : {-half.z(), half.z()})
                out.push_back(centre + (r - half.x() - e * da) * axes.col(0) + (a + e * dr) * axes.col(1) + z * axes.col(2));
    }
    return out;
}

double Shape::sdf(const Eigen::Vector3d& p) const {
    switch (kind) {
        case Kind::BOX: {
            Eigen::Vector3d l = axes.transpose() * (p - centre);
            if (bend_radius != 0) {  // in the bent box's own coordinates: along and across its centre line
                const fem::ClipBlades::FaceCoords fc = bent().face_coords(l.x() + half.x(), l.y());
                l.x() = fc.s - half.x();
                l.y() = fc.a;
            }
            const Eigen::Vector3d q = l.cwiseAbs() - half;
            return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
        }
        case Kind::CAPSULE: {
            const Eigen::Vector3d ab = b - a;
            const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
            return (p - (a + t * ab)).norm() - radius;
        }
        case Kind::MESH: {
            double best = 1e300, sign = 1;
            for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
                int region = 0;
                const Eigen::Vector3d q = closest_on_triangle(p, mesh.V.row(mesh.F(f, 0)), mesh.V.row(mesh.F(f, 1)),
                                                              mesh.V.row(mesh.F(f, 2)), region);
                const double d2 = (p - q).squaredNorm();
                if (d2 >= best) continue;
                best = d2;
                Eigen::Vector3d n;
                if (region == 0) {
                    n = mesh.face_normal.row(f);
                } else if (region <= 3) {
                    n = mesh.vertex_normal.row(mesh.F(f, region - 1));
                } else {
                    const int k = region - 4;
                    n = mesh.edge_normal.at(edge_key(mesh.F(f, k), mesh.F(f, (k + 1) % 3), mesh.V.rows()));
                }
                sign = (p - q).dot(n) < 0 ? -1 : 1;
            }
            return sign * std::sqrt(best);
        }
    }
    return 0;
}

Eigen::Vector3d Shape::support(const Eigen::Vector3d& n) const {
    switch (kind) {
        case Kind::BOX: {
            if (bend_radius != 0) {  // the bent box's corners along its centre line
                Eigen::Vector3d best = centre;
                double lowest = std::numeric_limits<double>::infinity();
                for (const Eigen::Vector3d& c : bent_corners())
                    if (n.dot(c) < lowest) {
                        lowest = n.dot(c);
                        best = c;
                    }
                return best;
            }
            Eigen::Vector3d p = centre;
            for (int k = 0; k < 3; ++k) p -= (n.dot(axes.col(k)) >= 0 ? 1.0 : -1.0) * half[k] * axes.col(k);
            return p;
        }
        case Kind::CAPSULE:
            return (n.dot(a) <= n.dot(b) ? a : b) - radius * n.normalized();
        case Kind::MESH: {
            Eigen::Index best = 0;
            (mesh.V * n).minCoeff(&best);
            return mesh.V.row(best).transpose();
        }
    }
    return centre;
}

Aabb Shape::bounds() const {
    Aabb bb;
    switch (kind) {
        case Kind::BOX:
            if (bend_radius != 0) {
                for (const Eigen::Vector3d& c : bent_corners()) bb.extend(c);
                return bb;
            }
            for (int s = 0; s < 8; ++s) {
                Eigen::Vector3d p = centre;
                for (int k = 0; k < 3; ++k) p += ((s >> k) & 1 ? 1.0 : -1.0) * half[k] * axes.col(k);
                bb.extend(p);
            }
            return bb;
        case Kind::CAPSULE:
            bb.extend(a);
            bb.extend(b);
            return bb.grown(radius);
        case Kind::MESH:
            return mesh.bounds();
    }
    return bb;
}

double Shape::exit_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& dir) const {
    const Aabb bb = bounds();
    double hi = (bb.hi - bb.lo).norm() + 1e-9, lo = 0;
    if (sdf(p + hi * dir) < 0) return hi;
    for (int it = 0; it < 40; ++it) {
        const double mid = 0.5 * (lo + hi);
        (sdf(p + mid * dir) < 0 ? lo : hi) = mid;
    }
    return hi;
}

void PointGrid::build(const Eigen::MatrixX3d& X, double cell, const std::vector<char>* include) {
    m_cell = cell > 0 ? cell : 1.0;
    m_X = &X;
    m_cells.clear();
    m_points.clear();
    for (Eigen::Index i = 0; i < X.rows(); ++i) {
        if (include && !(*include)[static_cast<size_t>(i)]) continue;
        const auto c = (X.row(i).array() / m_cell).floor().cast<long long>();
        m_cells[key(c[0], c[1], c[2])].push_back(static_cast<int>(i));
        m_points.push_back(static_cast<int>(i));
    }
}

void PointGrid::query(const Aabb& box, std::vector<int>& out, bool sorted) const {
    out.clear();
    if (!m_X) return;
    const Eigen::Array3d lo = (box.lo.array() / m_cell).floor(), hi = (box.hi.array() / m_cell).floor();
    if (((hi - lo) > 1e6).any()) return;
    // A box of more cells than there are points: the points themselves, in increasing order (the same answer; a wide
    // box over a fine grid would visit millions of empty cells).
    if ((hi - lo + 1).prod() > static_cast<double>(m_points.size())) {
        for (int v : m_points) {
            const Eigen::Vector3d p = m_X->row(v);
            if ((p.array() >= box.lo.array()).all() && (p.array() <= box.hi.array()).all()) out.push_back(v);
        }
        return;
    }
    for (long long k = static_cast<long long>(lo[2]); k <= static_cast<long long>(hi[2]); ++k)
        for (long long j = static_cast<long long>(lo[1]); j <= static_cast<long long>(hi[1]); ++j)
            for (long long i = static_cast<long long>(lo[0]); i <= static_cast<long long>(hi[0]); ++i) {
                const auto it = m_cells.find(key(i, j, k));
                if (it == m_cells.end()) continue;
                for (int v : it->second) {
                    const Eigen::Vector3d p = m_X->row(v);
                    if ((p.array() >= box.lo.array()).all() && (p.array() <= box.hi.array()).all()) out.push_back(v);
                }
            }
    if (!sorted) return;
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
}

}  // namespace aneu::sim
