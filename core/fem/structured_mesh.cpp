// SPDX-License-Identifier: MIT
#include "aneu/core/common.hpp"
#include "aneu/fem/structured_mesh.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <vector>

#include "aneu/core/error.hpp"
#include "aneu/fem/element.hpp"

namespace aneu::fem {

namespace {

/// Splits an (n0 × n1 × n2)-cell grid into tetrahedra; node(i,j,k) gives the node index of a grid point.
Eigen::MatrixXi kuhn_tets(int n0, int n1, int n2, const std::function<int(int, int, int)>& node,
                          const Eigen::MatrixX3d& V) {
    // The 6 monotone paths from corner 000 to 111, one per permutation of the axes.
    static constexpr int PERM[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    Eigen::MatrixXi T(6 * n0 * n1 * n2, 4);
    int t = 0;
    for (int k = 0; k < n2; ++k)
        for (int j = 0; j < n1; ++j)
            for (int i = 0; i < n0; ++i)
                for (const auto& p : PERM) {
                    std::array<int, 3> c{i, j, k};
                    T(t, 0) = node(c[0], c[1], c[2]);
                    for (int s = 0; s < 3; ++s) {
                        ++c[static_cast<size_t>(p[s])];
                        T(t, s + 1) = node(c[0], c[1], c[2]);
                    }
                    Eigen::Matrix<double, 4, 3> X;
                    for (int a = 0; a < 4; ++a) X.row(a) = V.row(T(t, a));
                    if (tet_volume(X) < 0) std::swap(T(t, 2), T(t, 3));
                    ++t;
                }
    return T;
}

Eigen::VectorXi to_vec(const std::vector<int>& v) { return Eigen::Map<const Eigen::VectorXi>(v.data(), static_cast<Eigen::Index>(v.size())); }

}  // namespace

StructuredMesh tube_mesh(double r_in, double r_out, double length, int n_r, int n_theta, int n_z, double theta_span) {
    if (!(r_in > 0 && r_out > r_in && length > 0 && n_r >= 1 && n_theta >= 3 && n_z >= 1 && theta_span > 0)) {
        throw InputError("tube_mesh: need 0 < r_in < r_out, length > 0, n_r >= 1, n_theta >= 3, n_z >= 1");
    }
    const bool closed = std::abs(theta_span - 2.0 * PI) < 1e-12;
    const int nt_nodes = closed ? n_theta : n_theta + 1;
    StructuredMesh m;
    m.V.resize((n_r + 1) * nt_nodes * (n_z + 1), 3);
    auto id = [&](int i, int j, int k) { return i + (n_r + 1) * ((j % nt_nodes) + nt_nodes * k); };
    std::vector<int> inner, outer, ends;
    for (int k = 0; k <= n_z; ++k)
        for (int j = 0; j < nt_nodes; ++j)
            for (int i = 0; i <= n_r; ++i) {
                const double r = r_in + (r_out - r_in) * i / n_r, th = theta_span * j / n_theta;
                const int v = id(i, j, k);
                m.V.row(v) << r * std::cos(th), r * std::sin(th), length * k / n_z;
                if (i == 0) inner.push_back(v);
                if (i == n_r) outer.push_back(v);
                if (k == 0 || k == n_z) ends.push_back(v);
            }
    m.T = kuhn_tets(n_r, n_theta, n_z, id, m.V);
    m.inner = to_vec(inner);
    m.outer = to_vec(outer);
    m.ends = to_vec(ends);
    return m;
}

WallDofSets wall_dof_sets(const StructuredMesh& m) {
    std::vector<char> is_end(static_cast<size_t>(m.V.rows()), 0);
    for (Eigen::Index k = 0; k < m.ends.size(); ++k) is_end[static_cast<size_t>(m.ends[k])] = 1;
    std::vector<int> fixed, kept;
    for (Eigen::Index k = 0; k < m.ends.size(); ++k)
        for (int a = 0; a < 3; ++a) fixed.push_back(3 * m.ends[k] + a);
    for (Eigen::Index k = 0; k < m.outer.size(); ++k)
        if (!is_end[static_cast<size_t>(m.outer[k])])
            for (int a = 0; a < 3; ++a) kept.push_back(3 * m.outer[k] + a);
    std::sort(fixed.begin(), fixed.end());
    std::sort(kept.begin(), kept.end());
    return {to_vec(fixed), to_vec(kept)};
}

StructuredMesh box_mesh(double sx, double sy, double sz, int nx, int ny, int nz) {
    if (!(sx > 0 && sy > 0 && sz > 0 && nx >= 1 && ny >= 1 && nz >= 1)) throw InputError("box_mesh: sizes and cell counts must be positive");
    StructuredMesh m;
    m.V.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
    auto id = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };
    std::vector<int> inner, outer, ends;
    for (int k = 0; k <= nz; ++k)
        for (int j = 0; j <= ny; ++j)
            for (int i = 0; i <= nx; ++i) {
                const int v = id(i, j, k);
                m.V.row(v) << sx * i / nx, sy * j / ny, sz * k / nz;
                if (i == 0) inner.push_back(v);
                if (i == nx) outer.push_back(v);
                if (k == 0 || k == nz) ends.push_back(v);
            }
    m.T = kuhn_tets(nx, ny, nz, id, m.V);
    m.inner = to_vec(inner);
    m.outer = to_vec(outer);
    m.ends = to_vec(ends);
    return m;
}

}  // namespace aneu::fem
