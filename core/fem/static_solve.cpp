// SPDX-License-Identifier: MIT
#include "aneu/fem/static_solve.hpp"

#include <algorithm>
#include <array>
#include <map>

#include <Eigen/CholmodSupport>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>

#include "aneu/core/error.hpp"
#include "aneu/fem/element.hpp"
#include "aneu/fem/loads.hpp"

namespace aneu::fem {

namespace {

/// Local index (4..9) of the mid-edge node between corners a and b of a 10-node tetrahedron.
int mid_of(int a, int b) {
    for (int k = 0; k < 6; ++k) {
        const int p = QUADRATIC_TET_EDGES[k][0], q = QUADRATIC_TET_EDGES[k][1];
        if ((p == a && q == b) || (p == b && q == a)) return 4 + k;
    }
    return -1;
}

}  // namespace

Eigen::MatrixXi boundary_faces_in_set(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& node_set,
                                      Eigen::VectorXi* face_tet) {
    if (T.cols() != 4 && T.cols() != 10) throw InputError("tetrahedra must have 4 or 10 nodes, not " + std::to_string(T.cols()));
    static constexpr int FACES[4][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
    std::vector<char> in(static_cast<size_t>(V.rows()), 0);
    for (Eigen::Index k = 0; k < node_set.size(); ++k) in.at(static_cast<size_t>(node_set[k])) = 1;
    // A face on the boundary belongs to one tetrahedron only.
    std::map<std::array<int, 3>, std::pair<int, int>> seen;  // sorted corners -> (tet, local face), or tet -1
    for (Eigen::Index t = 0; t < T.rows(); ++t) {
        for (int f = 0; f < 4; ++f) {
            std::array<int, 3> key{T(t, FACES[f][0]), T(t, FACES[f][1]), T(t, FACES[f][2])};
            if (!in[static_cast<size_t>(key[0])] || !in[static_cast<size_t>(key[1])] || !in[static_cast<size_t>(key[2])]) continue;
            std::sort(key.begin(), key.end());
            auto [it, fresh] = seen.emplace(key, std::make_pair(static_cast<int>(t), f));
            if (!fresh) it->second.first = -1;
        }
    }
    std::vector<std::pair<int, int>> faces;
    for (const auto& [key, tf] : seen) {
        if (tf.first >= 0) faces.push_back(tf);
    }
    const bool quadratic = T.cols() == 10;
    Eigen::MatrixXi F(static_cast<Eigen::Index>(faces.size()), quadratic ? 6 : 3);
    if (face_tet) face_tet->resize(static_cast<Eigen::Index>(faces.size()));
    for (size_t i = 0; i < faces.size(); ++i) {
        const auto [t, f] = faces[i];
        std::array<int, 3> l{FACES[f][0], FACES[f][1], FACES[f][2]};
        // Outward: the face normal points away from the tetrahedron's fourth corner.
        const int opposite = 6 - l[0] - l[1] - l[2];
        const Eigen::Vector3d a = V.row(T(t, l[0])), b = V.row(T(t, l[1])), c = V.row(T(t, l[2]));
        const Eigen::Vector3d d = V.row(T(t, opposite));
        if ((b - a).cross(c - a).dot(d - a) > 0) std::swap(l[1], l[2]);
        const auto r = static_cast<Eigen::Index>(i);
        if (face_tet) (*face_tet)[r] = t;
        for (int k = 0; k < 3; ++k) F(r, k) = T(t, l[k]);
        if (quadratic) {
            F(r, 3) = T(t, mid_of(l[0], l[1]));
            F(r, 4) = T(t, mid_of(l[1], l[2]));
            F(r, 5) = T(t, mid_of(l[2], l[0]));
        }
    }
    return F;
}

Eigen::VectorXd set_pressure_loads(const VolumeData& vol, const std::string& set, double p_mpa) {
    auto it = vol.node_sets.find(set);
    if (it == vol.node_sets.end()) throw InputError("node set '" + set + "': not in /volume/node_sets");
    const Eigen::MatrixXi F = boundary_faces_in_set(vol.nodes, vol.tets, it->second);
    if (F.rows() == 0) throw InputError("node set '" + set + "': no boundary face has all its corners in it");
    return pressure_loads(vol.nodes, F, p_mpa);
}

DirichletResult solve_dirichlet(const FemData& fem, const std::vector<std::pair<int, double>>& prescribed, const Eigen::VectorXd* f) {
    const Eigen::Index n = fem.K.rows();
    if (f && f->size() != n) throw InputError("load vector has " + std::to_string(f->size()) + " entries, K " + std::to_string(n) + " rows");
    // Role of each DOF: -1 fixed (u = 0), -2 - k prescribed number k, else its index among the free ones.
    std::vector<int> role(static_cast<size_t>(n), 0);
    for (Eigen::Index k = 0; k < fem.fixed_dofs.size(); ++k) role.at(static_cast<size_t>(fem.fixed_dofs[k])) = -1;
    Eigen::VectorXd up = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(prescribed.size()));
    for (size_t k = 0; k < prescribed.size(); ++k) {
        const auto [dof, value] = prescribed[k];
        if (dof < 0 || dof >= n) throw InputError("prescribed DOF " + std::to_string(dof) + " outside 0.." + std::to_string(n - 1));
        if (role[static_cast<size_t>(dof)] != 0) throw InputError("DOF " + std::to_string(dof) + " is fixed or prescribed twice");
        role[static_cast<size_t>(dof)] = -2 - static_cast<int>(k);
        up[static_cast<Eigen::Index>(k)] = value;
    }
    std::vector<int> dofs;
    for (Eigen::Index i = 0; i < n; ++i) {
        if (role[static_cast<size_t>(i)] == 0) {
            role[static_cast<size_t>(i)] = static_cast<int>(dofs.size());
            dofs.push_back(static_cast<int>(i));
        }
    }
    const auto m = static_cast<Eigen::Index>(dofs.size());
    const auto np = static_cast<Eigen::Index>(prescribed.size());
    // K_ff (upper), K_fp and K_pp; `put` takes one entry (i, j) of the whole K, each exactly once.
    std::vector<Eigen::Triplet<double>> tff, tfp, tpp;
    auto put = [&](Eigen::Index i, Eigen::Index j, double v) {
        const int a = role[static_cast<size_t>(i)], b = role[static_cast<size_t>(j)];
        if (a == -1 || b == -1) return;
        if (a >= 0 && b >= 0) {
            if (a <= b) tff.emplace_back(a, b, v);
        } else if (a >= 0) {
            tfp.emplace_back(a, -2 - b, v);
        } else if (b <= -2) {
            tpp.emplace_back(-2 - a, -2 - b, v);
        }  // a prescribed, b free: K_pf, the transpose of K_fp
    };
    for (Eigen::Index r = 0; r < n; ++r) {
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(fem.K, r); it; ++it) {
            if (fem.K_upper_only) {
                if (it.col() < r) continue;
                put(r, it.col(), it.value());
                if (it.col() != r) put(it.col(), r, it.value());
            } else {
                put(r, it.col(), it.value());
            }
        }
    }
    Eigen::SparseMatrix<double> Kff(m, m), Kfp(m, np), Kpp(np, np);
    Kff.setFromTriplets(tff.begin(), tff.end());
    Kfp.setFromTriplets(tfp.begin(), tfp.end());
    Kpp.setFromTriplets(tpp.begin(), tpp.end());
    Eigen::VectorXd rhs(m);
    for (Eigen::Index i = 0; i < m; ++i) rhs[i] = f ? (*f)[dofs[static_cast<size_t>(i)]] : 0.0;
    if (np > 0) rhs -= Kfp * up;
    Eigen::VectorXd uf(m);
    if (m > 0) {
        Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Upper> llt;
        llt.cholmod().print = 0;  // failures are reported by the exceptions below (Newton probes indefinite tangents)
        llt.compute(Kff);
        if (llt.info() != Eigen::Success) throw NumericalError("K_ff is not positive definite (CHOLMOD factorisation failed)");
        uf = llt.solve(rhs);
        if (llt.info() != Eigen::Success) throw NumericalError("CHOLMOD solve failed");
    }
    DirichletResult out;
    out.u = Eigen::VectorXd::Zero(n);
    for (Eigen::Index i = 0; i < m; ++i) out.u[dofs[static_cast<size_t>(i)]] = uf[i];
    for (size_t k = 0; k < prescribed.size(); ++k) out.u[prescribed[k].first] = prescribed[k].second;
    out.reaction = Eigen::VectorXd::Zero(np);
    if (np > 0) {
        out.reaction = Kfp.transpose() * uf + Kpp * up;
        if (f)
            for (Eigen::Index k = 0; k < np; ++k) out.reaction[k] -= (*f)[prescribed[static_cast<size_t>(k)].first];
    }
    return out;
}

Eigen::VectorXd solve_static(const FemData& fem, const Eigen::VectorXd& f) { return solve_dirichlet(fem, {}, &f).u; }

}  // namespace aneu::fem
