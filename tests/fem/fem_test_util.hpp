// SPDX-License-Identifier: MIT
#pragma once
// Helpers of the FEM tests: reference sparse solves with Dirichlet conditions.
#include <vector>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

namespace aneu::test {

/// Solves K u = f with u[d] = g[d] prescribed on `fixed` DOFs (dense flags), by elimination; returns u.
inline Eigen::VectorXd solve_dirichlet(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const Eigen::VectorXd& f,
                                       const std::vector<char>& fixed, const Eigen::VectorXd& g) {
    const Eigen::Index n = K.rows();
    std::vector<int> idx(static_cast<size_t>(n), -1);
    int nf = 0;
    for (Eigen::Index i = 0; i < n; ++i)
        if (!fixed[static_cast<size_t>(i)]) idx[static_cast<size_t>(i)] = nf++;
    std::vector<Eigen::Triplet<double>> trip;
    Eigen::VectorXd rhs(nf);
    for (Eigen::Index i = 0; i < n; ++i) {
        const int r = idx[static_cast<size_t>(i)];
        if (r < 0) continue;
        rhs[r] = f[i];
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(K, i); it; ++it) {
            const int c = idx[static_cast<size_t>(it.col())];
            if (c >= 0) {
                trip.emplace_back(r, c, it.value());
            } else {
                rhs[r] -= it.value() * g[it.col()];
            }
        }
    }
    Eigen::SparseMatrix<double> Kff(nf, nf);
    Kff.setFromTriplets(trip.begin(), trip.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(Kff);
    const Eigen::VectorXd x = ldlt.solve(rhs);
    Eigen::VectorXd u = g;
    for (Eigen::Index i = 0; i < n; ++i)
        if (idx[static_cast<size_t>(i)] >= 0) u[i] = x[idx[static_cast<size_t>(i)]];
    return u;
}

}  // namespace aneu::test
