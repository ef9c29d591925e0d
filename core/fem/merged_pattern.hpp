// SPDX-License-Identifier: MIT
#pragma once
// Private to core/fem: the tangent pattern of a body decorated with extra couplings (wall contact pairs, a clip's
// nodes and opening), built once per decorator, so that its tangent is the body's values scattered into place.
#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/SparseCore>

#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem::detail {

struct MergedPattern {
    Eigen::SparseMatrix<double, Eigen::RowMajor> pattern;  ///< the body's entries and a dense block per group
    std::vector<std::int64_t> body_to_pattern;             ///< where each of the body's stored entries lies in it
    /// Index into pattern's values of entry (r, c), which must be in the pattern.
    std::int64_t position(Eigen::Index r, Eigen::Index c) const {
        const int* cols = pattern.innerIndexPtr() + pattern.outerIndexPtr()[r];
        const int* end = pattern.innerIndexPtr() + pattern.outerIndexPtr()[r + 1];
        return static_cast<std::int64_t>(pattern.outerIndexPtr()[r] + (std::lower_bound(cols, end, static_cast<int>(c)) - cols));
    }
    /// The positions of a group's dense N × N block, row-major.
    template <size_t N>
    std::array<std::int64_t, N * N> block(const std::array<int, N>& dofs) const {
        std::array<std::int64_t, N * N> s{};
        for (size_t i = 0; i < N; ++i)
            for (size_t j = 0; j < N; ++j) s[N * i + j] = position(dofs[i], dofs[j]);
        return s;
    }
};

/// `body`'s pattern on n × n (n ≥ its size) with a dense block over each group of DOFs.
template <size_t N>
MergedPattern merge_pattern(const Eigen::SparseMatrix<double, Eigen::RowMajor>& body, Eigen::Index n, const std::vector<std::array<int, N>>& groups) {
    using RowSparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;
    std::vector<Eigen::Triplet<double>> tp;
    tp.reserve(static_cast<size_t>(body.nonZeros()) + N * N * groups.size());
    for (Eigen::Index r = 0; r < body.outerSize(); ++r)
        for (RowSparse::InnerIterator it(body, r); it; ++it) tp.emplace_back(static_cast<int>(r), static_cast<int>(it.col()), 0.0);
    for (const auto& g : groups)
        for (int i : g)
            for (int j : g) tp.emplace_back(i, j, 0.0);
    MergedPattern m;
    m.pattern.resize(n, n);
    m.pattern.setFromTriplets(tp.begin(), tp.end());
    m.pattern.makeCompressed();
    m.body_to_pattern.reserve(static_cast<size_t>(body.nonZeros()));
    for (Eigen::Index r = 0; r < body.outerSize(); ++r)
        for (RowSparse::InnerIterator it(body, r); it; ++it) m.body_to_pattern.push_back(m.position(r, it.col()));
    return m;
}

/// A contact penalty stiff against the body: 100 × the largest diagonal entry of its tangent at rest [N/mm].
inline double default_penalty(const ElasticBody& body) {
    const Eigen::SparseMatrix<double, Eigen::RowMajor> K0 = body.tangent(Eigen::VectorXd::Zero(body.dofs()));
    double dmax = 0;
    for (Eigen::Index r = 0; r < K0.rows(); ++r) dmax = std::max(dmax, K0.coeff(r, r));
    return 100.0 * dmax;
}

}  // namespace aneu::fem::detail
