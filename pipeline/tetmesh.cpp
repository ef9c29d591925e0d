// SPDX-License-Identifier: MIT
// TetGen and Netgen volume meshing of the wall surface. Each mesher runs in a forked child process
// (child_process.hpp): a mesher that aborts, crashes or loops forever on a bad surface becomes a MeshingError.
#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <queue>
#include <set>

#include <Eigen/Geometry>
#include <tetgen.h>

#ifdef ANEU_WITH_NETGEN
namespace nglib {
#include <nglib.h>
}
#endif

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/fem/element.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/tetmesh.hpp"
#include "child_process.hpp"

namespace aneu::pipeline {

namespace {



std::string tetgen_error(int code) {
    switch (code) {
        case 1: return "out of memory";
        case 2: return "internal error (please report the surface)";
        case 3: return "the surface self-intersects";
        case 4: return "the surface has a very small feature (two vertices or edges almost touching) relative to its size";
        case 5: return "two surface facets overlap";
        case 10: return "the surface has duplicated or degenerate input";
        default: return "TetGen error " + std::to_string(code);
    }
}

RawMesh run_tetgen(const SurfaceData& s, const TetMeshParams& p, double max_vol) {
    // The optimiser's target: with its default (165°) a thin wall (the sac's 0.13 mm under 0.4 mm edges) kept
    // flat tetrahedra between the inner and the outer surface (4.9° on real cases and the sample); at 140° and
    // level 9 it flips them away (10–11°).
    const std::string sw = "pYQq" + shortest(p.radius_edge_max) + "/" + shortest(p.min_dihedral_deg) + "a" + shortest(max_vol) + "O9/7o/" +
                           shortest(p.opt_max_dihedral_deg);
    return run_isolated(
        [&](RawMesh& out, std::string& msg) {
            // Heap objects that are never freed: this runs in the child process, which exits right after,
            // and TetGen's error paths leave tetgenio in states its destructor cannot free.
            tetgenio& in = *new tetgenio;
            tetgenio& res = *new tetgenio;
            in.firstnumber = 0;
            in.numberofpoints = static_cast<int>(s.V.rows());
            in.pointlist = new REAL[static_cast<size_t>(3 * s.V.rows())];
            for (Eigen::Index i = 0; i < s.V.rows(); ++i)
                for (int a = 0; a < 3; ++a) in.pointlist[3 * i + a] = s.V(i, a);
            in.numberoffacets = static_cast<int>(s.F.rows());
            in.facetlist = new tetgenio::facet[static_cast<size_t>(s.F.rows())];
            for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
                tetgenio::facet& fa = in.facetlist[f];
                tetgenio::init(&fa);
                fa.numberofpolygons = 1;
                fa.polygonlist = new tetgenio::polygon[1];
                tetgenio::init(&fa.polygonlist[0]);
                fa.polygonlist[0].numberofvertices = 3;
                fa.polygonlist[0].vertexlist = new int[3]{s.F(f, 0), s.F(f, 1), s.F(f, 2)};
            }
            tetgenbehavior b;
            std::vector<char> sws(sw.begin(), sw.end());
            sws.push_back('\0');
            if (!b.parse_commandline(sws.data())) {
                msg = "TetGen rejected the switches '" + sw + "'";
                return 1;
            }
            try {
                tetrahedralize(&b, &in, &res, nullptr, nullptr);
            } catch (int code) {
                msg = "TetGen failed (switches '" + sw + "'): " + tetgen_error(code);
                return 1;
            }
            out.points.assign(res.pointlist, res.pointlist + 3 * res.numberofpoints);
            out.cells.resize(static_cast<size_t>(4 * res.numberoftetrahedra));
            for (int t = 0; t < res.numberoftetrahedra; ++t)
                for (int a = 0; a < 4; ++a) out.cells[static_cast<size_t>(4 * t + a)] = res.tetrahedronlist[t * res.numberofcorners + a];
            return 0;
        },
        p.timeout_s, "tetmesh (TetGen)");
}

#ifdef ANEU_WITH_NETGEN
RawMesh run_netgen(const SurfaceData& s, const TetMeshParams& p, double max_vol) {
    return run_isolated(
        [&](RawMesh& out, std::string& msg) {
            nglib::Ng_Init();
            nglib::Ng_Mesh* m = nglib::Ng_NewMesh();
            for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
                double x[3] = {s.V(i, 0), s.V(i, 1), s.V(i, 2)};
                nglib::Ng_AddPoint(m, x);
            }
            for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
                int t[3] = {s.F(f, 0) + 1, s.F(f, 1) + 1, s.F(f, 2) + 1};
                nglib::Ng_AddSurfaceElement(m, nglib::NG_TRIG, t);
            }
            nglib::Ng_Meshing_Parameters mp;
            mp.maxh = std::cbrt(6.0 * std::sqrt(2.0) * max_vol);  // edge of a regular tet of that volume
            mp.optsteps_3d = 3;
            const auto r = nglib::Ng_GenerateVolumeMesh(m, &mp);
            if (r != nglib::NG_OK) {
                msg = "Netgen volume meshing failed (result " + std::to_string(static_cast<int>(r)) + ")";
                return 1;
            }
            const int np = nglib::Ng_GetNP(m), ne = nglib::Ng_GetNE(m);
            out.points.resize(static_cast<size_t>(3 * np));
            for (int i = 0; i < np; ++i) nglib::Ng_GetPoint(m, i + 1, out.points.data() + 3 * i);
            out.cells.resize(static_cast<size_t>(4 * ne));
            for (int e = 0; e < ne; ++e) {
                int t[10];
                nglib::Ng_GetVolumeElement(m, e + 1, t);
                for (int a = 0; a < 4; ++a) out.cells[static_cast<size_t>(4 * e + a)] = t[a] - 1;
            }
            nglib::Ng_DeleteMesh(m);
            nglib::Ng_Exit();
            return 0;
        },
        p.timeout_s, "tetmesh (Netgen)");
}
#endif

double mean_edge_length(const SurfaceData& s) {
    double sum = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) sum += (s.V.row(s.F(f, k)) - s.V.row(s.F(f, (k + 1) % 3))).norm();
    return sum / (3.0 * static_cast<double>(s.F.rows()));
}

/// Nearest-point queries on a point set, on a uniform grid of buckets.
class PointGrid {
public:
    PointGrid(const Eigen::MatrixX3d& P, double cell) : m_P(P), m_h(cell) {
        m_lo = P.colwise().minCoeff().transpose();
        for (Eigen::Index i = 0; i < P.rows(); ++i) m_cells[key(P.row(i).transpose())].push_back(static_cast<int>(i));
    }
    int nearest(const Eigen::Vector3d& x) const {
        int best = -1;
        double bd = std::numeric_limits<double>::infinity();
        const auto c = cell_of(x);
        for (int r = 0; best < 0 || (r - 1) * m_h < std::sqrt(bd); ++r) {  // rings of cells until none can be closer
            for (int i = -r; i <= r; ++i)
                for (int j = -r; j <= r; ++j)
                    for (int k = -r; k <= r; ++k) {
                        if (std::max({std::abs(i), std::abs(j), std::abs(k)}) != r) continue;
                        const auto it = m_cells.find({c[0] + i, c[1] + j, c[2] + k});
                        if (it == m_cells.end()) continue;
                        for (int v : it->second) {
                            const double d = (m_P.row(v).transpose() - x).squaredNorm();
                            if (d < bd) {
                                bd = d;
                                best = v;
                            }
                        }
                    }
            if (r > 10000) break;
        }
        return best;
    }

private:
    std::array<long, 3> cell_of(const Eigen::Vector3d& x) const {
        const Eigen::Vector3d q = (x - m_lo) / m_h;
        return {static_cast<long>(std::floor(q[0])), static_cast<long>(std::floor(q[1])), static_cast<long>(std::floor(q[2]))};
    }
    std::array<long, 3> key(const Eigen::Vector3d& x) const { return cell_of(x); }
    const Eigen::MatrixX3d& m_P;
    double m_h;
    Eigen::Vector3d m_lo;
    std::map<std::array<long, 3>, std::vector<int>> m_cells;
};

}  // namespace

void validate(const TetMeshParams& p) {
    tetmesh_spec().validate(p);
#ifndef ANEU_WITH_NETGEN
    if (p.mesher == "netgen") throw InputError("tetmesh: mesher = netgen, but this build has no Netgen (ANEU_WITH_NETGEN=OFF)");
#endif
}


void check_closed_surface(const SurfaceData& s, const std::string& what) {
    if (s.F.rows() < 4) throw InputError(what + ": " + std::to_string(s.F.rows()) + " triangles; a closed surface needs at least 4");
    std::map<std::pair<int, int>, int> directed;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) ++directed[{s.F(f, k), s.F(f, (k + 1) % 3)}];
    auto at = [&](int v) {
        return "(" + shortest(s.V(v, 0)) + ", " + shortest(s.V(v, 1)) + ", " + shortest(s.V(v, 2)) + ")";
    };
    size_t open = 0, nonmanifold = 0;
    std::string example_open, example_nm;
    for (const auto& [e, n] : directed) {
        const auto it = directed.find({e.second, e.first});
        const int back = it == directed.end() ? 0 : it->second;
        if (n > 1 || back > 1) {
            if (nonmanifold++ == 0) example_nm = std::to_string(e.first) + "-" + std::to_string(e.second) + " at " + at(e.first);
        } else if (back == 0) {
            if (open++ == 0) example_open = std::to_string(e.first) + "-" + std::to_string(e.second) + " at " + at(e.first);
        }
    }
    if (nonmanifold) {
        throw InputError(what + ": not 2-manifold or inconsistently oriented: " + std::to_string(nonmanifold) +
                         " edges are used more than once in one direction, e.g. vertices " + example_nm);
    }
    if (open) throw InputError(what + ": not closed: " + std::to_string(open) + " boundary edges, e.g. vertices " + example_open);
    double vol = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        vol += s.V.row(s.F(f, 0)).dot(s.V.row(s.F(f, 1)).cross(s.V.row(s.F(f, 2)))) / 6.0;
    }
    if (!(vol > 0)) throw InputError(what + ": enclosed volume " + shortest(vol) + " mm^3 is not positive (faces oriented inward?)");
}

std::vector<std::pair<std::string, double>> mesh_quality(const VolumeData& v) {
    const Eigen::Index nt = v.tets.rows();
    double min_dih = 180, max_dih = 0, max_re = 0, sum_re = 0;
    int slivers = 0;
    Eigen::Index worst = 0;
    static constexpr int FACES[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
    for (Eigen::Index t = 0; t < nt; ++t) {
        Eigen::Vector3d x[4];
        for (int a = 0; a < 4; ++a) x[a] = v.nodes.row(v.tets(t, a)).transpose();
        Eigen::Vector3d n[4];
        for (int f = 0; f < 4; ++f) n[f] = (x[FACES[f][1]] - x[FACES[f][0]]).cross(x[FACES[f][2]] - x[FACES[f][0]]).normalized();
        double tmin = 180;
        for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) {
                const double ang = 180.0 - std::acos(std::clamp(n[i].dot(n[j]), -1.0, 1.0)) * 180.0 / PI;
                tmin = std::min(tmin, ang);
                max_dih = std::max(max_dih, ang);
            }
        if (tmin < min_dih) worst = t;
        min_dih = std::min(min_dih, tmin);
        slivers += tmin < 5.0;
        const Eigen::Vector3d a = x[1] - x[0], b = x[2] - x[0], c = x[3] - x[0];
        const Eigen::Vector3d num_v = a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b);
        const double R = num_v.norm() / (2.0 * std::abs(a.dot(b.cross(c))));
        double emin = std::numeric_limits<double>::infinity();
        for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) emin = std::min(emin, (x[i] - x[j]).norm());
        const double re = R / emin;
        max_re = std::max(max_re, re);
        sum_re += re;
    }
    std::vector<std::pair<std::string, double>> q{{"n_nodes", static_cast<double>(v.nodes.rows())},
                                                  {"n_tets", static_cast<double>(nt)},
                                                  {"min_dihedral_deg", min_dih},
                                                  {"max_dihedral_deg", max_dih},
                                                  {"max_radius_edge", max_re},
                                                  {"mean_radius_edge", nt ? sum_re / static_cast<double>(nt) : 0.0},
                                                  {"slivers_below_5deg", static_cast<double>(slivers)}};
    if (nt > 0) {  // where the flattest tetrahedron is, and how many of its nodes lie on the caps, inner and outer wall
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int a = 0; a < 4; ++a) c += v.nodes.row(v.tets(worst, a)).transpose() / 4.0;
        q.emplace_back("worst_tet_x_mm", c.x());
        q.emplace_back("worst_tet_y_mm", c.y());
        q.emplace_back("worst_tet_z_mm", c.z());
        for (const char* set : {"fixed", "inner", "outer"}) {
            const auto it = v.node_sets.find(set);
            if (it == v.node_sets.end()) continue;
            int on = 0;
            for (int a = 0; a < 4; ++a) on += (it->second.array() == v.tets(worst, a)).any();
            q.emplace_back(std::string("worst_tet_nodes_") + set, on);
        }
    }
    // Layers through the wall: edge-graph distance from the inner nodes, read at the outer nodes.
    const auto in_it = v.node_sets.find("inner"), out_it = v.node_sets.find("outer");
    if (in_it != v.node_sets.end() && out_it != v.node_sets.end() && in_it->second.size() && out_it->second.size()) {
        std::vector<std::vector<int>> adj(static_cast<size_t>(v.nodes.rows()));
        for (Eigen::Index t = 0; t < nt; ++t)
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b)
                    if (a != b) adj[static_cast<size_t>(v.tets(t, a))].push_back(v.tets(t, b));
        std::vector<int> dist(static_cast<size_t>(v.nodes.rows()), -1);
        std::queue<int> q0;
        for (Eigen::Index k = 0; k < in_it->second.size(); ++k) {
            dist[static_cast<size_t>(in_it->second[k])] = 0;
            q0.push(in_it->second[k]);
        }
        while (!q0.empty()) {
            const int u = q0.front();
            q0.pop();
            for (int w : adj[static_cast<size_t>(u)])
                if (dist[static_cast<size_t>(w)] < 0) {
                    dist[static_cast<size_t>(w)] = dist[static_cast<size_t>(u)] + 1;
                    q0.push(w);
                }
        }
        std::vector<int> d;
        const auto& fixed = v.node_sets.count("fixed") ? v.node_sets.at("fixed") : Eigen::VectorXi();
        std::set<int> fx(fixed.data(), fixed.data() + fixed.size());
        for (Eigen::Index k = 0; k < out_it->second.size(); ++k)
            if (!fx.count(out_it->second[k])) d.push_back(dist[static_cast<size_t>(out_it->second[k])]);
        if (!d.empty()) {
            std::sort(d.begin(), d.end());
            q.emplace_back("layers_min", d.front());
            q.emplace_back("layers_median", percentile(d, 0.5));
            q.emplace_back("layers_max", d.back());
        }
    }
    return q;
}

namespace {
/// Dihedral angle (degrees) of tetrahedron X at its edge (i, j), inside the tetrahedron.
double dihedral_at(const Eigen::Matrix<double, 4, 3>& X, int i, int j) {
    int o[2], n = 0;
    for (int k = 0; k < 4; ++k)
        if (k != i && k != j) o[n++] = k;
    const Eigen::Vector3d e = (X.row(j) - X.row(i)).transpose().normalized();
    Eigen::Vector3d a = (X.row(o[0]) - X.row(i)).transpose(), b = (X.row(o[1]) - X.row(i)).transpose();
    a -= a.dot(e) * e;
    b -= b.dot(e) * e;
    return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / PI;
}
}  // namespace

int remove_boundary_slivers(VolumeData& v, const Eigen::MatrixX3i& faces, const Eigen::VectorXi& labels, double min_deg) {
    using Tri = std::array<int, 3>;
    auto key = [](int a, int b, int c) {
        Tri t{a, b, c};
        std::sort(t.begin(), t.end());
        return t;
    };
    std::map<Tri, int> label_of;  // boundary faces and their labels
    for (Eigen::Index f = 0; f < faces.rows(); ++f) label_of[key(faces(f, 0), faces(f, 1), faces(f, 2))] = labels[f];
    std::map<std::pair<int, int>, int> boundary_edges;  // edge -> boundary faces using it
    auto edge = [](int a, int b) { return std::make_pair(std::min(a, b), std::max(a, b)); };
    for (const auto& [t, l] : label_of)
        for (int k = 0; k < 3; ++k) ++boundary_edges[edge(t[static_cast<size_t>(k)], t[static_cast<size_t>((k + 1) % 3)])];
    std::vector<int> tets_at(static_cast<size_t>(v.nodes.rows()), 0);
    for (Eigen::Index t = 0; t < v.tets.rows(); ++t)
        for (int a = 0; a < 4; ++a) ++tets_at[static_cast<size_t>(v.tets(t, a))];
    std::vector<char> gone(static_cast<size_t>(v.tets.rows()), 0);
    int removed = 0;
    for (int pass = 0; pass < 4; ++pass) {
        int now = 0;
        for (Eigen::Index t = 0; t < v.tets.rows(); ++t) {
            if (gone[static_cast<size_t>(t)]) continue;
            Eigen::Matrix<double, 4, 3> X;
            for (int a = 0; a < 4; ++a) X.row(a) = v.nodes.row(v.tets(t, a));
            double tmin = 180;
            for (int i = 0; i < 4; ++i)
                for (int j = i + 1; j < 4; ++j) tmin = std::min(tmin, dihedral_at(X, i, j));
            if (tmin >= min_deg) continue;
            // Its faces on the boundary: face k leaves out corner k.
            int on[4], n_on = 0, label = -1;
            bool same = true;
            for (int k = 0; k < 4; ++k) {
                int c[3], m = 0;
                for (int a = 0; a < 4; ++a)
                    if (a != k) c[m++] = v.tets(t, a);
                const auto it = label_of.find(key(c[0], c[1], c[2]));
                if (it == label_of.end()) continue;
                same = same && (label < 0 || it->second == label);
                label = it->second;
                on[n_on++] = k;
            }
            if (n_on != 2 || !same) continue;
            // The two boundary faces leave out corners c, d; they share the edge (a, b). Removing the tetrahedron
            // flips the surface's edge ab to cd: only where the two faces are nearly coplanar (a flat sliver, not a
            // spike), cd is not already a boundary edge, and every node keeps a tetrahedron.
            const int ic = on[0], id = on[1];
            int ia = -1, ib = -1;
            for (int k = 0; k < 4; ++k)
                if (k != ic && k != id) (ia < 0 ? ia : ib) = k;
            if (dihedral_at(X, ia, ib) < 150.0) continue;
            const int a = v.tets(t, ia), b = v.tets(t, ib), c = v.tets(t, ic), d = v.tets(t, id);
            if (boundary_edges.count(edge(c, d)) && boundary_edges[edge(c, d)] > 0) continue;
            if (tets_at[static_cast<size_t>(a)] < 2 || tets_at[static_cast<size_t>(b)] < 2 || tets_at[static_cast<size_t>(c)] < 2 ||
                tets_at[static_cast<size_t>(d)] < 2)
                continue;
            for (const Tri& f : {key(a, b, d), key(a, b, c)}) {  // the two boundary faces go
                label_of.erase(f);
                for (int k = 0; k < 3; ++k) --boundary_edges[edge(f[static_cast<size_t>(k)], f[static_cast<size_t>((k + 1) % 3)])];
            }
            for (const Tri& f : {key(a, c, d), key(b, c, d)}) {  // the two inner faces become boundary
                label_of[f] = label;
                for (int k = 0; k < 3; ++k) ++boundary_edges[edge(f[static_cast<size_t>(k)], f[static_cast<size_t>((k + 1) % 3)])];
            }
            for (int k = 0; k < 4; ++k) --tets_at[static_cast<size_t>(v.tets(t, k))];
            gone[static_cast<size_t>(t)] = 1;
            ++now;
        }
        removed += now;
        if (now == 0) break;
    }
    if (removed) {
        Eigen::MatrixXi kept(v.tets.rows() - removed, 4);
        Eigen::Index r = 0;
        for (Eigen::Index t = 0; t < v.tets.rows(); ++t)
            if (!gone[static_cast<size_t>(t)]) kept.row(r++) = v.tets.row(t);
        v.tets = kept;
    }
    return removed;
}

VolumeData tetmesh(const SurfaceData& wall, const TetMeshParams& p, Reporter& rep) {
    validate(p);
    check_closed_surface(wall, "tetmesh: wall surface");
    const auto crossing = self_intersections(wall, 16);
    if (!crossing.empty()) {
        const Eigen::RowVector3d c = wall.V.row(wall.F(crossing[0].first, 0));
        throw InputError("tetmesh: wall surface self-intersects: " + std::string(crossing.size() >= 16 ? "16 or more" : std::to_string(crossing.size())) +
                         " pairs of faces cross, e.g. faces " + std::to_string(crossing[0].first) + " and " +
                         std::to_string(crossing[0].second) + " near (" + shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) + ")");
    }
    auto label_index = [&](const std::string& n) {
        const auto it = std::find(wall.label_names.begin(), wall.label_names.end(), n);
        return it == wall.label_names.end() ? -1 : static_cast<int>(it - wall.label_names.begin());
    };
    const int li = label_index("inner"), lo = label_index("outer");
    if (li < 0 || lo < 0) throw InputError("tetmesh: wall surface has no faces labelled 'inner' and 'outer' (labels: " + std::to_string(wall.label_names.size()) + ")");
    const double max_vol = p.max_volume_mm3 > 0 ? p.max_volume_mm3 : std::pow(mean_edge_length(wall), 3) / (6.0 * std::sqrt(2.0));
    rep.info("tetmesh: " + p.mesher + " on " + std::to_string(wall.F.rows()) + " triangles, max volume " + shortest(max_vol) + " mm^3");
    RawMesh raw;
    if (p.mesher == "tetgen") {
        raw = run_tetgen(wall, p, max_vol);
    } else {
#ifdef ANEU_WITH_NETGEN
        raw = run_netgen(wall, p, max_vol);
#endif
    }
    VolumeData v;
    const auto np = static_cast<Eigen::Index>(raw.points.size() / 3), nt = static_cast<Eigen::Index>(raw.cells.size() / 4);
    if (nt == 0) throw MeshingError("tetmesh: the mesher produced no tetrahedra from " + std::to_string(wall.F.rows()) + " faces");
    v.nodes = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(raw.points.data(), np, 3);
    v.tets = Eigen::Map<Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>>(raw.cells.data(), nt, 4);
    int flipped = 0;
    for (Eigen::Index t = 0; t < nt; ++t) {  // consistent positive orientation
        Eigen::Matrix<double, 4, 3> X;
        for (int a = 0; a < 4; ++a) X.row(a) = v.nodes.row(v.tets(t, a));
        if (fem::tet_volume(X) < 0) {
            std::swap(v.tets(t, 2), v.tets(t, 3));
            ++flipped;
        }
    }
    if (flipped) rep.debug("tetmesh: reoriented " + std::to_string(flipped) + " tetrahedra");
    // Surface vertices map to mesh nodes: identical indices with TetGen ('Y'); by position with Netgen.
    std::vector<int> node_of(static_cast<size_t>(wall.V.rows()));
    {
        PointGrid grid(v.nodes, std::max(mean_edge_length(wall), 1e-6));
        for (Eigen::Index i = 0; i < wall.V.rows(); ++i) {
            const int n = grid.nearest(wall.V.row(i).transpose());
            if ((v.nodes.row(n) - wall.V.row(i)).norm() > 1e-6 * (1.0 + wall.V.row(i).norm())) {
                throw MeshingError("tetmesh: surface vertex " + std::to_string(i) + " is not a node of the volume mesh (the mesher moved the boundary)");
            }
            node_of[static_cast<size_t>(i)] = n;
        }
    }
    int removed_slivers = 0;
    {
        // TetGen keeps the boundary ('Y'), so it cannot flip a flat sliver lying on it (four nearly coplanar
        // surface vertices): removing it is that edge flip of the surface.
        Eigen::MatrixX3i bf(wall.F.rows(), 3);
        for (Eigen::Index f = 0; f < wall.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) bf(f, k) = node_of[static_cast<size_t>(wall.F(f, k))];
        removed_slivers = remove_boundary_slivers(v, bf, wall.face_label, p.min_dihedral_deg);
        if (removed_slivers) rep.info("tetmesh: removed " + std::to_string(removed_slivers) + " flat boundary sliver(s) below " + shortest(p.min_dihedral_deg) +
                           " deg (an edge flip of the surface each)");
    }
    const Eigen::Index nt_kept = v.tets.rows();
    std::set<int> inner, outer, fixed;
    for (Eigen::Index f = 0; f < wall.F.rows(); ++f) {
        const int l = wall.face_label[f];
        const bool cap = wall.label_names[static_cast<size_t>(l)].rfind("cap", 0) == 0;
        for (int k = 0; k < 3; ++k) {
            const int n = node_of[static_cast<size_t>(wall.F(f, k))];
            if (l == li) inner.insert(n);
            if (l == lo) outer.insert(n);
            if (cap) fixed.insert(n);
        }
    }
    auto vec = [](const std::set<int>& s) {
        Eigen::VectorXi x(static_cast<Eigen::Index>(s.size()));
        Eigen::Index i = 0;
        for (int v2 : s) x[i++] = v2;
        return x;
    };
    v.node_sets["inner"] = vec(inner);
    v.node_sets["outer"] = vec(outer);
    v.node_sets["fixed"] = vec(fixed);
    // Regions: the region of the nearest surface vertex (from its faces' regions), per tet centroid.
    v.region_names = wall.region_names.empty() ? std::vector<std::string>{"artery"} : wall.region_names;
    Eigen::VectorXi vreg = Eigen::VectorXi::Zero(wall.V.rows());
    if (wall.face_region.size() == wall.F.rows()) {
        for (Eigen::Index f = 0; f < wall.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) vreg[wall.F(f, k)] = std::max(vreg[wall.F(f, k)], wall.face_region[f]);
    }
    PointGrid sg(wall.V, std::max(mean_edge_length(wall), 1e-6));
    v.tet_region.resize(nt_kept);
    for (Eigen::Index t = 0; t < nt_kept; ++t) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int a = 0; a < 4; ++a) c += v.nodes.row(v.tets(t, a)).transpose() / 4.0;
        v.tet_region[t] = vreg[sg.nearest(c)];
    }
    v.quality = mesh_quality(v);
    v.quality.emplace_back("boundary_slivers_removed", removed_slivers);
    rep.info("tetmesh: " + std::to_string(np) + " nodes, " + std::to_string(nt_kept) + " tets");
    return v;
}

SurfaceData tube_wall_surface(double r_in, double t, double L, int nth, int nz, double R) {
    if (!(r_in > 0 && t > 0 && L > 0 && nth >= 3 && nz >= 1 && (R == 0 || R > r_in + t))) {
        throw InputError("tube_wall_surface: need r_in, thickness, length > 0, n_theta >= 3, n_z >= 1, bend radius 0 or > r_in + t");
    }
    // Centerline point and frame at arc length s: straight along z, or an arc of radius R in the x-z plane.
    auto frame = [&](double s, Eigen::Vector3d& c, Eigen::Vector3d& e1, Eigen::Vector3d& e2) {
        if (R == 0) {
            c = {0, 0, s};
            e1 = Eigen::Vector3d::UnitX();
        } else {
            const double a = s / R;
            c = {R * (1 - std::cos(a)), 0, R * std::sin(a)};
            e1 = {std::cos(a), 0, -std::sin(a)};
        }
        e2 = Eigen::Vector3d::UnitY();
    };
    SurfaceData sf;
    const int ring = nth, nrings = nz + 1;
    sf.V.resize(2 * ring * nrings, 3);
    auto vid = [&](int layer, int j, int k) { return layer * ring * nrings + k * ring + (j % ring); };
    for (int layer = 0; layer < 2; ++layer)
        for (int k = 0; k < nrings; ++k) {
            Eigen::Vector3d c, e1, e2;
            frame(L * k / nz, c, e1, e2);
            for (int j = 0; j < ring; ++j) {
                const double th = 2 * PI * j / ring, r = layer == 0 ? r_in : r_in + t;
                sf.V.row(vid(layer, j, k)) = (c + r * (std::cos(th) * e1 + std::sin(th) * e2)).transpose();
            }
        }
    std::vector<std::array<int, 4>> tris;  // (a, b, c, label)
    for (int k = 0; k < nz; ++k)
        for (int j = 0; j < ring; ++j) {
            // outer: outward normal; inner: normal toward the axis (outward of the wall solid)
            const int o00 = vid(1, j, k), o10 = vid(1, j + 1, k), o01 = vid(1, j, k + 1), o11 = vid(1, j + 1, k + 1);
            tris.push_back({o00, o10, o11, 1});
            tris.push_back({o00, o11, o01, 1});
            const int i00 = vid(0, j, k), i10 = vid(0, j + 1, k), i01 = vid(0, j, k + 1), i11 = vid(0, j + 1, k + 1);
            tris.push_back({i00, i11, i10, 0});
            tris.push_back({i00, i01, i11, 0});
        }
    for (int j = 0; j < ring; ++j) {  // annular caps joining inner and outer rings
        tris.push_back({vid(0, j, 0), vid(0, j + 1, 0), vid(1, j + 1, 0), 2});
        tris.push_back({vid(0, j, 0), vid(1, j + 1, 0), vid(1, j, 0), 2});
        tris.push_back({vid(0, j, nz), vid(1, j + 1, nz), vid(0, j + 1, nz), 3});
        tris.push_back({vid(0, j, nz), vid(1, j, nz), vid(1, j + 1, nz), 3});
    }
    sf.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
    sf.face_label.resize(static_cast<Eigen::Index>(tris.size()));
    for (size_t f = 0; f < tris.size(); ++f) {
        sf.F.row(static_cast<Eigen::Index>(f)) << tris[f][0], tris[f][1], tris[f][2];
        sf.face_label[static_cast<Eigen::Index>(f)] = tris[f][3];
    }
    sf.label_names = {"inner", "outer", "cap:0", "cap:1"};
    sf.face_region = Eigen::VectorXi::Zero(sf.F.rows());
    sf.region_names = {"artery"};
    return sf;
}

}  // namespace aneu::pipeline
