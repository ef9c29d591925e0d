// SPDX-License-Identifier: MIT
#include "aneu/core/common.hpp"
#include "aneu/sim/model.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <limits>
#include <map>
#include <numeric>
#include <tuple>
#include <unordered_map>

#include <Eigen/Geometry>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/label_loops.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/sim/shapes.hpp"

namespace aneu::sim {
namespace {

// Mid-edge slot (4..9) of the 10-node tetrahedron for the corner pair (a,b) (element.hpp ordering).
int mid_slot(int a, int b) {
    if (a > b) std::swap(a, b);
    static constexpr int slot[4][4] = {{-1, 4, 6, 7}, {4, -1, 5, 8}, {6, 5, -1, 9}, {7, 8, 9, -1}};
    return slot[a][b];
}

std::string fmt3(const Eigen::Vector3d& p) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "(%.3f, %.3f, %.3f)", p.x(), p.y(), p.z());
    return buf;
}

// Neck: the loops between "aneurysm" faces and the others (aneu/core/label_loops.hpp).
// Loops round islands of either label (labelling noise: a few faces) are not neck line.
std::vector<std::vector<int>> neck_loops_of(const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& X, const Eigen::VectorXi& face_region,
                                            const std::vector<std::string>& region_names) {
    const auto it = std::find(region_names.begin(), region_names.end(), "aneurysm");
    if (it == region_names.end()) return {};
    return neck_border_loops(F, X, face_region, static_cast<int>(it - region_names.begin()));
}

}  // namespace

Eigen::VectorXd wall_thickness(const SimSurface& s, const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets,
                               const Eigen::VectorXi& inner) {
    Eigen::VectorXd t = Eigen::VectorXd::Constant(s.size(), std::numeric_limits<double>::quiet_NaN());
    if (inner.size() == 0) return t;
    const Eigen::MatrixXi F = fem::boundary_faces_in_set(nodes, tets, inner);  // corners in columns 0..2
    if (F.rows() == 0) return t;
    Eigen::MatrixX3d C(F.rows(), 3);
    double reach = 0;  // largest centroid-to-corner distance: a face within r of p has its centroid within r + reach
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        C.row(f) = (nodes.row(F(f, 0)) + nodes.row(F(f, 1)) + nodes.row(F(f, 2))) / 3.0;
        for (int k = 0; k < 3; ++k) reach = std::max(reach, (nodes.row(F(f, k)) - C.row(f)).norm());
    }
    PointGrid grid;
    grid.build(C, std::max(0.5, 2 * reach));
    std::vector<int> cand;
    for (Eigen::Index v = 0; v < s.size(); ++v) {
        const Eigen::Vector3d p = s.X.row(v).transpose();
        for (double r = 0.5; r <= 8.0; r *= 2) {
            const Eigen::Vector3d h = Eigen::Vector3d::Constant(r + reach);
            grid.query(Aabb{p - h, p + h}, cand);
            double best = std::numeric_limits<double>::infinity();
            for (int f : cand) {
                const Eigen::Vector3d q = closest_point_on_triangle(p, nodes.row(F(f, 0)).transpose(), nodes.row(F(f, 1)).transpose(),
                                                                    nodes.row(F(f, 2)).transpose());
                best = std::min(best, (q - p).norm());
            }
            if (best <= r) {
                t[v] = best;
                break;
            }
        }
    }
    return t;
}

Eigen::MatrixX3d SimLumen::deformed(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& X_sim) const {
    Eigen::MatrixX3d y = X;
    for (Eigen::Index v = 0; v < X.rows(); ++v) y.row(v) += x.row(bind[v]) - X_sim.row(bind[v]);
    return y;
}

SimLumen extract_lumen(const SimSurface& s, const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets, const Eigen::VectorXi& tet_region,
                       const Eigen::VectorXi& inner) {
    SimLumen L;
    if (inner.size() == 0 || s.size() == 0) return L;
    Eigen::VectorXi face_tet;
    const Eigen::MatrixXi IF = fem::boundary_faces_in_set(nodes, tets, inner, &face_tet);  // outward from the wall
    // Bind each corner node to the nearest simulated vertex within 1.5 mm.
    PointGrid grid;
    grid.build(s.X, 0.75);
    std::unordered_map<int, int> local;  // volume node -> lumen vertex (-1: unbound)
    std::vector<int> bind, order;
    std::vector<int> cand;
    auto vertex_of = [&](int n) {
        const auto it = local.find(n);
        if (it != local.end()) return it->second;
        const Eigen::Vector3d p = nodes.row(n).transpose();
        grid.query(Aabb{p - Eigen::Vector3d::Constant(1.5), p + Eigen::Vector3d::Constant(1.5)}, cand);
        int best = -1;
        double bd = 1.5;
        for (int c : cand) {
            const double d = (s.X.row(c).transpose() - p).norm();
            if (d <= bd) {
                bd = d;
                best = c;
            }
        }
        int id = -1;
        if (best >= 0) {
            id = static_cast<int>(order.size());
            order.push_back(n);
            bind.push_back(best);
        }
        local.emplace(n, id);
        return id;
    };
    std::vector<std::array<int, 3>> tris;
    std::vector<int> reg;
    for (Eigen::Index f = 0; f < IF.rows(); ++f) {
        const int a = vertex_of(IF(f, 0)), b = vertex_of(IF(f, 1)), c = vertex_of(IF(f, 2));
        if (a < 0 || b < 0 || c < 0) continue;
        tris.push_back({a, c, b});  // out of the lumen: against the wall's outward normal
        reg.push_back(tet_region.size() ? tet_region[face_tet[f]] : 0);
    }
    L.X.resize(static_cast<Eigen::Index>(order.size()), 3);
    L.bind.resize(static_cast<Eigen::Index>(order.size()));
    L.node.resize(static_cast<Eigen::Index>(order.size()));
    L.wall_mm.resize(static_cast<Eigen::Index>(order.size()));
    for (size_t i = 0; i < order.size(); ++i) {
        const auto v = static_cast<Eigen::Index>(i);
        L.X.row(v) = nodes.row(order[i]);
        L.bind[v] = bind[i];
        L.node[v] = order[i];
        L.wall_mm[v] = (s.X.row(bind[i]) - L.X.row(v)).norm();
    }
    L.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
    L.face_region.resize(static_cast<Eigen::Index>(tris.size()));
    for (size_t f = 0; f < tris.size(); ++f) {
        for (int k = 0; k < 3; ++k) L.F(static_cast<Eigen::Index>(f), k) = tris[f][static_cast<size_t>(k)];
        L.face_region[static_cast<Eigen::Index>(f)] = reg[f];
    }
    L.neck_loops = neck_loops_of(L.F, L.X, L.face_region, s.region_names);
    for (const auto& loop : L.neck_loops) L.neck_line.push_back(smoothed_neck_line(L, loop));
    return L;
}

SplitLumen split_lumen(const SimLumen& lumen, const std::function<int(int, int)>& mid, const Eigen::MatrixX3d& nodes) {
    SplitLumen out;
    SimLumen& Q = out.lumen;
    const Eigen::Index NL = lumen.X.rows(), NF = lumen.F.rows();
    std::map<std::pair<int, int>, int> vertex_of_edge;  // (low, high lumen vertex) -> split vertex
    std::vector<std::pair<int, int>> between;
    std::vector<int> node;
    auto edge_vertex = [&](int a, int b) {
        const auto key = std::minmax(a, b);
        const auto it = vertex_of_edge.find(key);
        if (it != vertex_of_edge.end()) return it->second;
        const int m = mid(lumen.node[a], lumen.node[b]);
        if (m < 0)
            throw InputError("split_lumen: the lumen's edge between nodes " + std::to_string(lumen.node[a]) + " and " + std::to_string(lumen.node[b]) +
                             " has no mid-edge node");
        const int v = static_cast<int>(NL + static_cast<Eigen::Index>(between.size()));
        vertex_of_edge.emplace(key, v);
        between.emplace_back(key.first, key.second);
        node.push_back(m);
        return v;
    };
    Q.F.resize(4 * NF, 3);
    Q.face_region.resize(4 * NF);
    for (Eigen::Index f = 0; f < NF; ++f) {
        const int a = lumen.F(f, 0), b = lumen.F(f, 1), c = lumen.F(f, 2);
        const int ab = edge_vertex(a, b), bc = edge_vertex(b, c), ca = edge_vertex(c, a);
        Q.F.row(4 * f) << a, ab, ca;
        Q.F.row(4 * f + 1) << ab, b, bc;
        Q.F.row(4 * f + 2) << ca, bc, c;
        Q.F.row(4 * f + 3) << ab, bc, ca;
        Q.face_region.segment(4 * f, 4).setConstant(lumen.face_region[f]);
    }
    const Eigen::Index NE = static_cast<Eigen::Index>(between.size());
    Q.X.resize(NL + NE, 3);
    Q.node.resize(NL + NE);
    Q.bind.resize(NL + NE);
    Q.wall_mm.resize(NL + NE);
    Q.X.topRows(NL) = lumen.X;
    Q.node.head(NL) = lumen.node;
    Q.bind.head(NL) = lumen.bind;
    Q.wall_mm.head(NL) = lumen.wall_mm;
    out.between.resize(NE, 2);
    for (Eigen::Index e = 0; e < NE; ++e) {
        const auto [a, b] = between[static_cast<size_t>(e)];
        out.between.row(e) << a, b;
        Q.X.row(NL + e) = nodes.row(node[static_cast<size_t>(e)]);
        Q.node[NL + e] = node[static_cast<size_t>(e)];
        Q.bind[NL + e] = lumen.bind[a];
        Q.wall_mm[NL + e] = 0.5 * (lumen.wall_mm[a] + lumen.wall_mm[b]);
    }
    for (const auto& loop : lumen.neck_loops) {
        std::vector<int> q;
        for (size_t k = 0; k < loop.size(); ++k) {
            q.push_back(loop[k]);
            // Between consecutive vertices that share a lumen edge, its mid-edge vertex (every face's edges are split
            // above). A step that is not an edge has none: a neck border that the lumen's edge (the working region's
            // cut) ends is a chain whose two ends close the loop (C0043's lumen: the split threw here, session 34).
            const auto it = vertex_of_edge.find(std::minmax(loop[k], loop[(k + 1) % loop.size()]));
            if (it != vertex_of_edge.end()) q.push_back(it->second);
        }
        Q.neck_loops.push_back(q);
    }
    // A point at barycentric w of face f lies in the child holding it: a corner's where that corner's weight is at
    // least ½, else the middle one (the children's coordinates: 2w − 1 and 2w at a corner child's; 1 − 2w at the middle's).
    for (const auto& line : lumen.neck_line) {
        std::vector<NeckPointOnLumen> q;
        for (const NeckPointOnLumen& p : line) {
            const Eigen::Vector3d& w = p.weights;
            NeckPointOnLumen c;
            if (w[0] >= 0.5) {
                c.face = 4 * p.face;
                c.weights = Eigen::Vector3d(2 * w[0] - 1, 2 * w[1], 2 * w[2]);  // (a, ab, ca)
            } else if (w[1] >= 0.5) {
                c.face = 4 * p.face + 1;
                c.weights = Eigen::Vector3d(2 * w[0], 2 * w[1] - 1, 2 * w[2]);  // (ab, b, bc)
            } else if (w[2] >= 0.5) {
                c.face = 4 * p.face + 2;
                c.weights = Eigen::Vector3d(2 * w[0], 2 * w[1], 2 * w[2] - 1);  // (ca, bc, c)
            } else {
                c.face = 4 * p.face + 3;
                c.weights = Eigen::Vector3d(1 - 2 * w[2], 1 - 2 * w[0], 1 - 2 * w[1]);  // (ab, bc, ca)
            }
            q.push_back(c);
        }
        Q.neck_line.push_back(q);
    }
    return out;
}

SimSurface extract_surface(const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets, const Eigen::VectorXi& tet_region,
                           const std::vector<std::string>& region_names, const std::vector<int>& row_of_dof) {
    static constexpr int FACES[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // outward for positive tets
    const bool quadratic = tets.cols() == 10;
    struct Seen {
        int count = 0;
        Eigen::Index tet = 0;
        int face = 0;
    };
    std::map<std::array<int, 3>, Seen> seen;
    for (Eigen::Index e = 0; e < tets.rows(); ++e) {
        for (int f = 0; f < 4; ++f) {
            std::array<int, 3> key{tets(e, FACES[f][0]), tets(e, FACES[f][1]), tets(e, FACES[f][2])};
            std::sort(key.begin(), key.end());
            Seen& s = seen[key];
            ++s.count;
            s.tet = e;
            s.face = f;
        }
    }
    auto condensed = [&](int n) {
        for (int a = 0; a < 3; ++a)
            if (row_of_dof[static_cast<size_t>(3 * n + a)] < 0) return false;
        return true;
    };
    std::vector<std::array<int, 3>> tris;  // volume node ids
    std::vector<int> tri_region;
    for (const auto& [key, s] : seen) {
        if (s.count != 1) continue;
        const int* lf = FACES[s.face];
        const int c0 = tets(s.tet, lf[0]), c1 = tets(s.tet, lf[1]), c2 = tets(s.tet, lf[2]);
        if (!(condensed(c0) && condensed(c1) && condensed(c2))) continue;
        const int reg = tet_region.size() ? tet_region[s.tet] : 0;
        if (!quadratic) {
            tris.push_back({c0, c1, c2});
            tri_region.push_back(reg);
            continue;
        }
        const int m01 = tets(s.tet, mid_slot(lf[0], lf[1])), m12 = tets(s.tet, mid_slot(lf[1], lf[2])),
                  m20 = tets(s.tet, mid_slot(lf[2], lf[0]));
        if (!(condensed(m01) || condensed(m12) || condensed(m20))) {  // corners only condensed: the corner triangle
            tris.push_back({c0, c1, c2});
            tri_region.push_back(reg);
            continue;
        }
        if (!(condensed(m01) && condensed(m12) && condensed(m20))) continue;
        for (const auto& t : {std::array<int, 3>{c0, m01, m20}, std::array<int, 3>{m01, c1, m12},
                              std::array<int, 3>{m20, m12, c2}, std::array<int, 3>{m01, m12, m20}}) {
            tris.push_back(t);
            tri_region.push_back(reg);
        }
    }
    SimSurface s;
    std::unordered_map<int, int> local;
    std::vector<int> order;
    for (const auto& t : tris)
        for (int n : t)
            if (local.emplace(n, -1).second) order.push_back(n);
    std::sort(order.begin(), order.end());
    for (size_t i = 0; i < order.size(); ++i) local[order[i]] = static_cast<int>(i);
    const Eigen::Index S = static_cast<Eigen::Index>(order.size());
    s.X.resize(S, 3);
    s.node.resize(S);
    s.row.resize(S, 3);
    for (Eigen::Index i = 0; i < S; ++i) {
        const int n = order[static_cast<size_t>(i)];
        s.node[i] = n;
        s.X.row(i) = nodes.row(n);
        for (int a = 0; a < 3; ++a) s.row(i, a) = row_of_dof[static_cast<size_t>(3 * n + a)];
    }
    s.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
    s.face_region.resize(static_cast<Eigen::Index>(tris.size()));
    for (size_t f = 0; f < tris.size(); ++f) {
        for (int k = 0; k < 3; ++k) s.F(static_cast<Eigen::Index>(f), k) = local.at(tris[f][static_cast<size_t>(k)]);
        s.face_region[static_cast<Eigen::Index>(f)] = tri_region[f];
    }
    s.region_names = region_names.empty() ? std::vector<std::string>{"wall"} : region_names;
    // Normals (area weighted) and one-ring adjacency.
    s.N.setZero(S, 3);
    std::vector<std::vector<int>> nb(static_cast<size_t>(S));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const Eigen::Vector3d a = s.X.row(s.F(f, 0)), b = s.X.row(s.F(f, 1)), c = s.X.row(s.F(f, 2));
        const Eigen::RowVector3d n = (b - a).cross(c - a).transpose();
        for (int k = 0; k < 3; ++k) {
            s.N.row(s.F(f, k)) += n;
            nb[static_cast<size_t>(s.F(f, k))].push_back(s.F(f, (k + 1) % 3));
            nb[static_cast<size_t>(s.F(f, k))].push_back(s.F(f, (k + 2) % 3));
        }
    }
    s.adj_offsets.assign(static_cast<size_t>(S) + 1, 0);
    for (Eigen::Index i = 0; i < S; ++i) {
        const double len = s.N.row(i).norm();
        if (len > 0) s.N.row(i) /= len;
        auto& l = nb[static_cast<size_t>(i)];
        std::sort(l.begin(), l.end());
        l.erase(std::unique(l.begin(), l.end()), l.end());
        s.adj_offsets[static_cast<size_t>(i) + 1] = s.adj_offsets[static_cast<size_t>(i)] + static_cast<int>(l.size());
        s.adj.insert(s.adj.end(), l.begin(), l.end());
    }
    s.neck_loops = neck_loops_of(s.F, s.X, s.face_region, s.region_names);
    return s;
}

SimModel load_model(const std::string& bundle_path, const LoadOptions& opt) {
    const Stopwatch t0;
    BundleParts parts;
    parts.image = parts.surfaces = parts.fem = parts.condensed_W = false;
    Bundle b = read_bundle(bundle_path, parts);
    if (!b.condensed) {
        throw InputError(bundle_path + ": no /condensed group; run `aneuprep condense` to make a case bundle");
    }
    if (!b.volume) throw InputError(bundle_path + ": no /volume group; a case bundle needs the mesh nodes");
    SimModel m;
    m.case_id = b.meta.case_id;
    m.nodes = std::move(b.volume->nodes);
    const CondensedData& c = *b.condensed;
    const Eigen::Index M = c.dof_node.size();
    std::vector<int> row_of_dof(static_cast<size_t>(3 * m.nodes.rows()), -1);
    for (Eigen::Index r = 0; r < M; ++r) {
        const int node = c.dof_node[r], axis = c.dof_axis[r];
        if (node < 0 || node >= m.nodes.rows() || axis < 0 || axis > 2) {
            throw InputError(bundle_path + ": /condensed/dof_node[" + std::to_string(r) + "] = " + std::to_string(node) +
                             ", axis " + std::to_string(axis) + ", but /volume has " + std::to_string(m.nodes.rows()) +
                             " nodes (expected node < #nodes, axis 0..2)");
        }
        row_of_dof[static_cast<size_t>(3 * node + axis)] = static_cast<int>(r);
    }
    // Working region: file rows whose node is inside, in spatial (Morton) order of their nodes, the three axes
    // of a node together: the rows of the nodes near an instrument then form a few contiguous runs, so the
    // per-frame SMVM over them streams memory instead of gathering scattered cache lines.
    std::vector<char> in(static_cast<size_t>(M), 0);
    for (Eigen::Index r = 0; r < M; ++r) {
        const int node = c.dof_node[r];
        if (!opt.region || (m.nodes.row(node).transpose() - opt.region->centre).norm() <= opt.region->radius_mm) {
            in[static_cast<size_t>(r)] = 1;
            m.active.push_back(static_cast<int>(r));
        }
    }
    {
        const Eigen::RowVector3d lo = m.nodes.colwise().minCoeff(), span = (m.nodes.colwise().maxCoeff() - lo).cwiseMax(1e-9);
        auto morton = [&](int node) {
            std::uint64_t code = 0;
            for (int a = 0; a < 3; ++a) {
                const auto q = static_cast<std::uint64_t>(std::clamp((m.nodes(node, a) - lo[a]) / span[a], 0.0, 1.0) * 1023.0);
                for (int b = 0; b < 10; ++b) code |= ((q >> b) & 1u) << (3 * b + a);
            }
            return code;
        };
        std::vector<std::tuple<std::uint64_t, int, int, int>> key;
        key.reserve(m.active.size());
        for (int r : m.active) key.emplace_back(morton(c.dof_node[r]), c.dof_node[r], c.dof_axis[r], r);
        std::sort(key.begin(), key.end());
        for (size_t k = 0; k < key.size(); ++k) m.active[k] = std::get<3>(key[k]);
    }
    if (m.active.empty()) {
        throw InputError(bundle_path + ": the working region (centre " + fmt3(opt.region->centre) + ", radius " +
                         std::to_string(opt.region->radius_mm) + " mm) contains no simulated node");
    }
    // Permutation: active rows first (in the order above), then the rest.
    m.file_row.resize(M);
    Eigen::Index k = 0;
    for (int r : m.active) m.file_row[k++] = r;
    for (Eigen::Index r = 0; r < M; ++r)
        if (!in[static_cast<size_t>(r)]) m.file_row[k++] = static_cast<int>(r);
    m.n_active = static_cast<Eigen::Index>(m.active.size());
    std::vector<int> perm_of_file(static_cast<size_t>(M));
    m.dof_node.resize(M);
    m.dof_axis.resize(M);
    for (Eigen::Index p = 0; p < M; ++p) {
        perm_of_file[static_cast<size_t>(m.file_row[p])] = static_cast<int>(p);
        m.dof_node[p] = c.dof_node[m.file_row[p]];
        m.dof_axis[p] = c.dof_axis[m.file_row[p]];
    }
    for (int& r : row_of_dof)
        if (r >= 0) r = perm_of_file[static_cast<size_t>(r)];

    const bool want_float = opt.working_precision ? *opt.working_precision == Precision::FLOAT32
                                                  : c.precision == Precision::FLOAT32;
    m.precision = want_float ? Precision::FLOAT32 : Precision::FLOAT64;
    auto permute_rows = [&](auto& W) {
        using Mat = std::decay_t<decltype(W)>;
        Mat P(W.rows(), W.cols());
        for (Eigen::Index j = 0; j < W.cols(); ++j)
            for (Eigen::Index p = 0; p < M; ++p) P(p, j) = W(m.file_row[p], j);
        W.swap(P);
    };
    if (opt.geometry_only) {
        // no W
    } else if (want_float) {
        if (c.precision == Precision::FLOAT32) {
            m.Wf = read_condensed_columns_f(bundle_path, m.active);
        } else {
            m.Wf = read_condensed_columns(bundle_path, m.active).cast<float>();
        }
        permute_rows(m.Wf);
    } else {
        m.Wd = read_condensed_columns(bundle_path, m.active);
        permute_rows(m.Wd);
    }
    m.surface = extract_surface(m.nodes, b.volume->tets, b.volume->tet_region, b.volume->region_names, row_of_dof);
    if (m.surface.size() == 0) {
        throw InputError(bundle_path + ": no boundary face of /volume/tets has all its nodes in /condensed (expected the "
                         "outer wall surface to be condensed)");
    }
    const auto inner = b.volume->node_sets.find("inner");
    const Eigen::VectorXi inner_set = inner == b.volume->node_sets.end() ? Eigen::VectorXi() : inner->second;
    m.surface.thickness = wall_thickness(m.surface, m.nodes, b.volume->tets, inner_set);
    m.surface.lumen = extract_lumen(m.surface, m.nodes, b.volume->tets, b.volume->tet_region, inner_set);
    if (const auto fixed = b.volume->node_sets.find("fixed"); fixed != b.volume->node_sets.end()) {
        for (Eigen::Index k = 0; k < fixed->second.size(); ++k)
            if (fixed->second[k] < 0 || fixed->second[k] >= m.nodes.rows())
                throw InputError(bundle_path + ": /volume/node_sets/fixed[" + std::to_string(k) + "] = " + std::to_string(fixed->second[k]) +
                                 ", but /volume has " + std::to_string(m.nodes.rows()) + " nodes (expected 0 <= node < #nodes)");
        m.fixed_nodes = fixed->second;
    }
    m.load_seconds = t0.seconds();
    return m;
}

}  // namespace aneu::sim
