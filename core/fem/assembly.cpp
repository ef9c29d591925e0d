// SPDX-License-Identifier: MIT
#include "aneu/fem/assembly.hpp"

#include <algorithm>
#include <array>
#include <limits>
#include <map>
#include <numeric>
#include <string>

#include "aneu/core/error.hpp"
#include "aneu/fem/element.hpp"

namespace aneu::fem {

namespace {

std::string fmt_point(const Eigen::MatrixX3d& V, int n) {
    return "(" + std::to_string(V(n, 0)) + ", " + std::to_string(V(n, 1)) + ", " + std::to_string(V(n, 2)) + ")";
}

/// Sorted unique neighbours (including itself) of every node, as CSR.
void node_graph(const Eigen::MatrixXi& T, Eigen::Index n, std::vector<std::int64_t>& ptr, std::vector<int>& adj) {
    std::vector<std::vector<int>> nb(static_cast<size_t>(n));
    const auto k = T.cols();
    for (Eigen::Index e = 0; e < T.rows(); ++e)
        for (Eigen::Index a = 0; a < k; ++a)
            for (Eigen::Index b = 0; b < k; ++b) nb[static_cast<size_t>(T(e, a))].push_back(T(e, b));
    ptr.assign(static_cast<size_t>(n) + 1, 0);
    for (Eigen::Index i = 0; i < n; ++i) {
        auto& v = nb[static_cast<size_t>(i)];
        std::sort(v.begin(), v.end());
        v.erase(std::unique(v.begin(), v.end()), v.end());
        ptr[static_cast<size_t>(i) + 1] = ptr[static_cast<size_t>(i)] + static_cast<std::int64_t>(v.size());
    }
    adj.resize(static_cast<size_t>(ptr.back()));
    for (Eigen::Index i = 0; i < n; ++i) std::copy(nb[static_cast<size_t>(i)].begin(), nb[static_cast<size_t>(i)].end(), adj.begin() + ptr[static_cast<size_t>(i)]);
}

/// Elements of each node, in increasing element order, as CSR.
void node_elements(const Eigen::MatrixXi& T, Eigen::Index n, std::vector<std::int64_t>& ptr, std::vector<int>& elems) {
    ptr.assign(static_cast<size_t>(n) + 1, 0);
    for (Eigen::Index k = 0; k < T.size(); ++k) ++ptr[static_cast<size_t>(T.data()[k]) + 1];
    for (size_t i = 0; i < static_cast<size_t>(n); ++i) ptr[i + 1] += ptr[i];
    elems.resize(static_cast<size_t>(ptr.back()));
    std::vector<std::int64_t> fill(ptr.begin(), ptr.end() - 1);
    for (Eigen::Index e = 0; e < T.rows(); ++e)
        for (Eigen::Index a = 0; a < T.cols(); ++a) elems[static_cast<size_t>(fill[static_cast<size_t>(T(e, a))]++)] = static_cast<int>(e);
}

/// Two phases per chunk of elements: element matrices in parallel, then every node row gathers its
/// contributions in increasing element order. No atomics, so K is bitwise reproducible, and exactly
/// symmetric because each element matrix is symmetrised and K(i,j), K(j,i) sum the same terms in the
/// same order.
template <int NN>
void assemble_elements(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& region,
                       const std::vector<Material>& mats, const std::vector<std::int64_t>& ptr,
                       const std::vector<int>& adj, std::vector<double>& values) {
    using Ke_t = Eigen::Matrix<double, 3 * NN, 3 * NN>;
    constexpr Eigen::Index CHUNK = 8192;
    const Eigen::Index ne = T.rows(), n = V.rows();
    std::vector<std::int64_t> eptr;
    std::vector<int> elems;
    node_elements(T, n, eptr, elems);
    std::vector<Ke_t, Eigen::aligned_allocator<Ke_t>> Ke(static_cast<size_t>(std::min(CHUNK, ne)));
    std::string failure;
    for (Eigen::Index e0 = 0; e0 < ne; e0 += CHUNK) {
        const Eigen::Index e1 = std::min(ne, e0 + CHUNK);
#pragma omp parallel for schedule(static)
        for (Eigen::Index e = e0; e < e1; ++e) {
            Eigen::Matrix<double, NN, 3> X;
            for (int a = 0; a < NN; ++a) X.row(a) = V.row(T(e, a));
            const Material& m = mats[static_cast<size_t>(region[e])];
            Ke_t& K = Ke[static_cast<size_t>(e - e0)];
            try {
                if constexpr (NN == 4) {
                    K = linear_tet_stiffness(X, m.E_mpa, m.nu);
                } else {
                    K = quadratic_tet_stiffness(X, m.E_mpa, m.nu);
                }
                K = 0.5 * (K + K.transpose()).eval();
            } catch (const MeshingError& err) {
#pragma omp critical
                if (failure.empty()) failure = "element " + std::to_string(e) + ": " + err.what();
                K.setZero();
            }
        }
        if (!failure.empty()) throw MeshingError("assemble: " + failure);
#pragma omp parallel for schedule(dynamic, 512)
        for (Eigen::Index i = 0; i < n; ++i) {
            const auto iu = static_cast<size_t>(i);
            const std::int64_t deg = ptr[iu + 1] - ptr[iu];
            const int* row = adj.data() + ptr[iu];
            const int* eb = elems.data() + eptr[iu];
            const int* ee = elems.data() + eptr[iu + 1];
            for (const int* it = std::lower_bound(eb, ee, static_cast<int>(e0)); it != ee && *it < e1; ++it) {
                const int e = *it;
                int a = 0;
                while (T(e, a) != i) ++a;
                const Ke_t& K = Ke[static_cast<size_t>(e - e0)];
                for (int b = 0; b < NN; ++b) {
                    const std::int64_t pos = std::lower_bound(row, row + deg, T(e, b)) - row;
                    for (int p = 0; p < 3; ++p) {
                        double* dst = values.data() + 9 * ptr[iu] + p * 3 * deg + 3 * pos;
                        for (int q = 0; q < 3; ++q) dst[q] += K(3 * a + p, 3 * b + q);
                    }
                }
            }
        }
    }
}

}  // namespace

void validate_materials(const std::vector<Material>& materials, int n_regions) {
    if (static_cast<int>(materials.size()) < n_regions) {
        throw InputError("materials: " + std::to_string(materials.size()) + " given for " + std::to_string(n_regions) +
                         " regions");
    }
    for (const auto& m : materials) {
        if (!(m.E_mpa > 0.0)) {
            throw InputError("material of region '" + m.region + "': E = " + std::to_string(m.E_mpa) + " MPa, must be > 0");
        }
        if (!(m.nu > -1.0 && m.nu < 0.5)) {
            throw InputError("material of region '" + m.region + "': nu = " + std::to_string(m.nu) +
                             ", must be in (-1, 0.5)");
        }
    }
}

Eigen::SparseMatrix<double, Eigen::RowMajor> assemble_stiffness(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T,
                                                                const Eigen::VectorXi& region,
                                                                const std::vector<Material>& materials, Reporter& rep) {
    if (T.cols() != 4 && T.cols() != 10) {
        throw InputError("assemble: elements have " + std::to_string(T.cols()) + " nodes, expected 4 or 10");
    }
    if (region.size() != T.rows()) throw InputError("assemble: region has " + std::to_string(region.size()) + " entries for " + std::to_string(T.rows()) + " elements");
    const int n_regions = region.size() ? region.maxCoeff() + 1 : 0;
    if (region.size() && region.minCoeff() < 0) throw InputError("assemble: negative region index");
    validate_materials(materials, n_regions);
    if (T.size() && (T.minCoeff() < 0 || T.maxCoeff() >= V.rows())) {
        throw InputError("assemble: element node index outside [0," + std::to_string(V.rows()) + ")");
    }
    const Eigen::Index n = V.rows();
    std::vector<std::int64_t> ptr;
    std::vector<int> adj;
    node_graph(T, n, ptr, adj);
    std::vector<double> values(static_cast<size_t>(9 * ptr.back()), 0.0);
    if (T.cols() == 4) {
        assemble_elements<4>(V, T, region, materials, ptr, adj, values);
    } else {
        assemble_elements<10>(V, T, region, materials, ptr, adj, values);
    }
    // Expand the node graph to DOF-level CSR: row 3i+p holds columns 3j+q for every neighbour j.
    std::vector<int> outer(static_cast<size_t>(3 * n + 1), 0);
    std::vector<int> inner(values.size());
    for (Eigen::Index i = 0; i < n; ++i) {
        const auto iu = static_cast<size_t>(i);
        const std::int64_t deg = ptr[iu + 1] - ptr[iu];
        for (int p = 0; p < 3; ++p) {
            const std::int64_t start = 9 * ptr[iu] + p * 3 * deg;
            outer[3 * iu + static_cast<size_t>(p)] = static_cast<int>(start);
            for (std::int64_t k = 0; k < deg; ++k)
                for (int q = 0; q < 3; ++q) inner[static_cast<size_t>(start + 3 * k + q)] = 3 * adj[static_cast<size_t>(ptr[iu] + k)] + q;
        }
    }
    outer.back() = static_cast<int>(values.size());
    rep.progress("assemble", T.rows(), T.rows());
    return Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>>(3 * n, 3 * n, static_cast<Eigen::Index>(values.size()),
                                                                         outer.data(), inner.data(), values.data());
}

void check_constrained(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& fixed_nodes) {
    const Eigen::Index n = V.rows();
    if (fixed_nodes.size() == 0) {
        throw InputError("stiffness is singular: no fixed node (node set 'fixed' is empty); the mesh would float freely");
    }
    std::vector<int> parent(static_cast<size_t>(n));
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int x) {
        while (parent[static_cast<size_t>(x)] != x) x = parent[static_cast<size_t>(x)] = parent[static_cast<size_t>(parent[static_cast<size_t>(x)])];
        return x;
    };
    std::vector<char> used(static_cast<size_t>(n), 0);
    for (Eigen::Index e = 0; e < T.rows(); ++e) {
        for (Eigen::Index a = 0; a < T.cols(); ++a) {
            used[static_cast<size_t>(T(e, a))] = 1;
            const int r0 = find(T(e, 0)), ra = find(T(e, a));
            if (r0 != ra) parent[static_cast<size_t>(ra)] = r0;
        }
    }
    for (Eigen::Index i = 0; i < n; ++i) {
        if (!used[static_cast<size_t>(i)]) {
            throw InputError("stiffness is singular: node " + std::to_string(i) + " at " + fmt_point(V, static_cast<int>(i)) +
                             " belongs to no element");
        }
    }
    std::vector<char> anchored(static_cast<size_t>(n), 0);
    for (Eigen::Index k = 0; k < fixed_nodes.size(); ++k) anchored[static_cast<size_t>(find(fixed_nodes[k]))] = 1;
    std::map<int, int> free_pieces;  // root -> node count
    int pieces = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
        const int r = find(static_cast<int>(i));
        if (r == i) ++pieces;
        if (!anchored[static_cast<size_t>(r)]) ++free_pieces[r];
    }
    if (!free_pieces.empty()) {
        const auto& [root, count] = *free_pieces.begin();
        throw InputError("stiffness is singular: " + std::to_string(free_pieces.size()) + " of " + std::to_string(pieces) +
                         " connected pieces of the mesh have no fixed node (one has " + std::to_string(count) +
                         " nodes, e.g. node " + std::to_string(root) + " at " + fmt_point(V, root) + ")");
    }
}

Eigen::MatrixX3i boundary_faces(const Eigen::MatrixXi& T4) {
    static constexpr int FACES[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // outward for positive tets
    std::map<std::array<int, 3>, std::pair<int, std::array<int, 3>>> seen;  // sorted key -> (count, oriented)
    for (Eigen::Index e = 0; e < T4.rows(); ++e) {
        for (const auto& f : FACES) {
            const std::array<int, 3> o{T4(e, f[0]), T4(e, f[1]), T4(e, f[2])};
            std::array<int, 3> key = o;
            std::sort(key.begin(), key.end());
            auto& s = seen[key];
            ++s.first;
            s.second = o;
        }
    }
    std::vector<std::array<int, 3>> out;
    for (const auto& [k, v] : seen)
        if (v.first == 1) out.push_back(v.second);
    Eigen::MatrixX3i F(static_cast<Eigen::Index>(out.size()), 3);
    for (size_t i = 0; i < out.size(); ++i) F.row(static_cast<Eigen::Index>(i)) << out[i][0], out[i][1], out[i][2];
    return F;
}

QuadraticMesh quadratic_mesh(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T4) {
    if (T4.cols() != 4) throw InputError("quadratic_mesh: expected a 4-node mesh, got " + std::to_string(T4.cols()) + " nodes per element");
    std::map<std::pair<int, int>, int> mid;
    QuadraticMesh q;
    q.T.resize(T4.rows(), 10);
    std::vector<std::pair<int, int>> edges;
    const int n0 = static_cast<int>(V.rows());
    for (Eigen::Index e = 0; e < T4.rows(); ++e) {
        for (int a = 0; a < 4; ++a) q.T(e, a) = T4(e, a);
        for (int k = 0; k < 6; ++k) {
            int a = T4(e, QUADRATIC_TET_EDGES[k][0]), b = T4(e, QUADRATIC_TET_EDGES[k][1]);
            const auto key = std::minmax(a, b);
            auto it = mid.find(key);
            if (it == mid.end()) {
                it = mid.emplace(key, n0 + static_cast<int>(edges.size())).first;
                edges.push_back(key);
            }
            q.T(e, 4 + k) = it->second;
        }
    }
    q.V.resize(n0 + static_cast<Eigen::Index>(edges.size()), 3);
    q.V.topRows(n0) = V;
    q.edge_of_mid.resize(static_cast<Eigen::Index>(edges.size()), 2);
    for (size_t k = 0; k < edges.size(); ++k) {
        const auto r = static_cast<Eigen::Index>(k);
        q.V.row(n0 + r) = 0.5 * (V.row(edges[k].first) + V.row(edges[k].second));
        q.edge_of_mid.row(r) << edges[k].first, edges[k].second;
    }
    return q;
}

Eigen::MatrixXi quadratic_faces(const QuadraticMesh& q, int n_linear_nodes, const Eigen::MatrixX3i& F3) {
    std::map<std::pair<int, int>, int> mid;
    for (Eigen::Index k = 0; k < q.edge_of_mid.rows(); ++k) mid[{q.edge_of_mid(k, 0), q.edge_of_mid(k, 1)}] = n_linear_nodes + static_cast<int>(k);
    Eigen::MatrixXi F6(F3.rows(), 6);
    for (Eigen::Index f = 0; f < F3.rows(); ++f) {
        for (int k = 0; k < 3; ++k) {
            F6(f, k) = F3(f, k);
            const auto it = mid.find(std::minmax(F3(f, k), F3(f, (k + 1) % 3)));
            if (it == mid.end()) throw InputError("quadratic_faces: face " + std::to_string(f) + " is not a face of the mesh");
            F6(f, 3 + k) = it->second;
        }
    }
    return F6;
}

MidEdgeNodes::MidEdgeNodes(const Eigen::MatrixXi& T10, const std::vector<int>& tets) {
    if (T10.cols() != 10) throw InputError("MidEdgeNodes: the elements must have 10 nodes, not " + std::to_string(T10.cols()));
    auto add = [&](Eigen::Index t) {
        if (t < 0 || t >= T10.rows()) throw InputError("MidEdgeNodes: element " + std::to_string(t) + " is outside the mesh");
        for (int e = 0; e < 6; ++e) {
            const auto [a, b] = std::minmax(T10(t, QUADRATIC_TET_EDGES[e][0]), T10(t, QUADRATIC_TET_EDGES[e][1]));
            m_sorted.emplace_back((static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) | static_cast<std::uint32_t>(b), T10(t, 4 + e));
        }
    };
    if (tets.empty())
        for (Eigen::Index t = 0; t < T10.rows(); ++t) add(t);
    else
        for (int t : tets) add(t);
    std::sort(m_sorted.begin(), m_sorted.end());
    m_sorted.erase(std::unique(m_sorted.begin(), m_sorted.end()), m_sorted.end());
}

int MidEdgeNodes::operator()(int a, int b) const {
    const auto [lo, hi] = std::minmax(a, b);
    const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(lo)) << 32) | static_cast<std::uint32_t>(hi);
    const auto it = std::lower_bound(m_sorted.begin(), m_sorted.end(), std::make_pair(key, std::numeric_limits<int>::min()));
    return it != m_sorted.end() && it->first == key ? it->second : -1;
}

Eigen::MatrixX3i quadratic_surface_triangles(const MidEdgeNodes& mid, const Eigen::MatrixX3i& F3) {
    Eigen::MatrixX3i out(4 * F3.rows(), 3);
    for (Eigen::Index f = 0; f < F3.rows(); ++f) {
        const int a = F3(f, 0), b = F3(f, 1), c = F3(f, 2);
        const int ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
        if (ab < 0 || bc < 0 || ca < 0)
            throw InputError("quadratic_surface_triangles: triangle " + std::to_string(f) + " (" + std::to_string(a) + ", " + std::to_string(b) + ", " +
                             std::to_string(c) + ") has an edge with no mid-edge node");
        out.row(4 * f) << a, ab, ca;
        out.row(4 * f + 1) << ab, b, bc;
        out.row(4 * f + 2) << ca, bc, c;
        out.row(4 * f + 3) << ab, bc, ca;
    }
    return out;
}

Eigen::VectorXi quadratic_node_set(const QuadraticMesh& q, const Eigen::MatrixXi& T4, int n_linear_nodes,
                                   const Eigen::VectorXi& corner_set) {
    std::vector<char> in(static_cast<size_t>(n_linear_nodes), 0);
    for (Eigen::Index k = 0; k < corner_set.size(); ++k) in[static_cast<size_t>(corner_set[k])] = 1;
    std::map<std::pair<int, int>, int> mid;
    for (Eigen::Index k = 0; k < q.edge_of_mid.rows(); ++k) mid[{q.edge_of_mid(k, 0), q.edge_of_mid(k, 1)}] = n_linear_nodes + static_cast<int>(k);
    std::vector<int> out(corner_set.data(), corner_set.data() + corner_set.size());
    const Eigen::MatrixX3i F = boundary_faces(T4);
    std::vector<char> added(static_cast<size_t>(q.V.rows()), 0);
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
        if (!(in[static_cast<size_t>(F(f, 0))] && in[static_cast<size_t>(F(f, 1))] && in[static_cast<size_t>(F(f, 2))])) continue;
        for (int k = 0; k < 3; ++k) {
            const int m = mid.at(std::minmax(F(f, k), F(f, (k + 1) % 3)));
            if (!added[static_cast<size_t>(m)]) {
                added[static_cast<size_t>(m)] = 1;
                out.push_back(m);
            }
        }
    }
    std::sort(out.begin(), out.end());
    return Eigen::Map<Eigen::VectorXi>(out.data(), static_cast<Eigen::Index>(out.size()));
}

}  // namespace aneu::fem
