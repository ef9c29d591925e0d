// SPDX-License-Identifier: MIT
#pragma once
// Private to core/fem: the tangent pattern of a body decorated with extra couplings (wall contact pairs, a clip's
// nodes and opening), built once per decorator, so that its tangent is the body's values scattered into place.
#include <algorithm>
#include <array>
#include <cstdint>
#include <iterator>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/SparseCore>

#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem::detail {

/// The free block's upper triangle (CSC, rows sorted) of a row-major symmetric matrix K, from the entries on and right
/// of the diagonal of each row: fi maps a DOF to its free index (−1: fixed), m free DOFs. Two linear passes (a count,
/// then a fill row by row), no sort. where (non-null): for each stored entry of K, its index in the result's values
/// (−1: not in the free upper block).
inline Eigen::SparseMatrix<double> free_upper(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const std::vector<int>& fi, Eigen::Index m,
                                              std::vector<std::int64_t>* where = nullptr) {
    std::vector<std::int64_t> next(static_cast<size_t>(m) + 1, 0);
    for (Eigen::Index r = 0; r < K.rows(); ++r) {
        const int a = fi[static_cast<size_t>(r)];
        if (a < 0) continue;
        for (std::int64_t p = K.outerIndexPtr()[r]; p < K.outerIndexPtr()[r + 1]; ++p) {
            const int b = fi[static_cast<size_t>(K.innerIndexPtr()[p])];
            if (b >= a) ++next[static_cast<size_t>(b) + 1];
        }
    }
    for (Eigen::Index b = 0; b < m; ++b) next[static_cast<size_t>(b) + 1] += next[static_cast<size_t>(b)];
    Eigen::SparseMatrix<double> U(m, m);
    U.resizeNonZeros(static_cast<Eigen::Index>(next.back()));
    for (Eigen::Index b = 0; b <= m; ++b) U.outerIndexPtr()[b] = static_cast<int>(next[static_cast<size_t>(b)]);
    if (where) where->assign(static_cast<size_t>(K.nonZeros()), -1);
    for (Eigen::Index r = 0; r < K.rows(); ++r) {
        const int a = fi[static_cast<size_t>(r)];
        if (a < 0) continue;
        for (std::int64_t p = K.outerIndexPtr()[r]; p < K.outerIndexPtr()[r + 1]; ++p) {
            const int b = fi[static_cast<size_t>(K.innerIndexPtr()[p])];
            if (b < a) continue;
            const std::int64_t pos = next[static_cast<size_t>(b)]++;
            U.innerIndexPtr()[pos] = a;
            U.valuePtr()[pos] = K.valuePtr()[p];
            if (where) (*where)[static_cast<size_t>(p)] = pos;
        }
    }
    return U;
}

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

/// The entries (row, column) of a dense block over each group of DOFs: sorted, unique.
template <size_t N>
std::vector<std::pair<int, int>> group_entries(const std::vector<std::array<int, N>>& groups) {
    std::vector<std::pair<int, int>> extra;
    extra.reserve(N * N * groups.size());
    for (const auto& g : groups)
        for (int i : g)
            for (int j : g) extra.emplace_back(i, j);
    std::sort(extra.begin(), extra.end());
    extra.erase(std::unique(extra.begin(), extra.end()), extra.end());
    return extra;
}

/// `body`'s pattern on n × n (n ≥ its size) with the entries `extra` (sorted, unique) added. Built row by row in
/// compressed form: a row without extra entries is the body's row as it is; a row with some merges its sorted
/// extra columns into the body's (a patch's tangent has ~10⁷ entries, its dense exterior block most of them,
/// against a few thousand from the groups). Written straight into the result's storage, which is made once: Eigen
/// 3.4's SparseMatrix has no move constructor, so a pattern returned or assigned by value is copied, and a Map
/// assigned to it is appended entry by entry (on the C0024 corpus case the clip's pattern build, these copies and
/// their page faults most of it, took 29 % of a profiled 90 s of patch frames; on the sample's 1.1 × 10⁷-entry
/// pattern a merge went from 2.3-2.6 s to 0.73-0.80 s).
inline std::shared_ptr<const MergedPattern> merge_entries(const Eigen::SparseMatrix<double, Eigen::RowMajor>& body, Eigen::Index n,
                                                          const std::vector<std::pair<int, int>>& extra) {
    const Eigen::Index body_rows = body.outerSize();
    const int* bo = body.outerIndexPtr();
    const int* bi = body.innerIndexPtr();
    const bool compressed = body.isCompressed();
    const int* bnz = body.innerNonZeroPtr();
    auto row_begin = [&](Eigen::Index r) { return r < body_rows ? bo[r] : 0; };
    auto row_end = [&](Eigen::Index r) { return r < body_rows ? (compressed ? bo[r + 1] : bo[r] + bnz[r]) : 0; };
    auto m = std::make_shared<MergedPattern>();
    m->pattern.resize(n, n);
    m->pattern.resizeNonZeros(static_cast<Eigen::Index>(body.nonZeros()) + static_cast<Eigen::Index>(extra.size()));  // at most
    int* outer = m->pattern.outerIndexPtr();
    int* inner = m->pattern.innerIndexPtr();
    m->body_to_pattern.resize(static_cast<size_t>(body.nonZeros()));
    size_t e = 0;
    int count = 0;
    std::int64_t body_k = 0;  // running index over the body's stored entries, in row order
    outer[0] = 0;
    for (Eigen::Index r = 0; r < n; ++r) {
        int k = row_begin(r);
        const int end = row_end(r);
        while (k < end || (e < extra.size() && extra[e].first == r)) {
            const bool take_body = k < end && (e >= extra.size() || extra[e].first != r || bi[k] <= extra[e].second);
            if (take_body) {
                if (e < extra.size() && extra[e].first == r && extra[e].second == bi[k]) ++e;  // the same entry
                m->body_to_pattern[static_cast<size_t>(body_k++)] = count;
                inner[count++] = bi[k++];
            } else {
                inner[count++] = extra[e++].second;
            }
        }
        outer[r + 1] = count;
    }
    m->pattern.data().resize(count);  // shrinks the size only: the storage stays
    std::fill(m->pattern.valuePtr(), m->pattern.valuePtr() + count, 0.0);
    return m;
}

/// A decorator's body's tangent at u added into `values` through the merged pattern mp: the body's p-th entry at
/// where[mp.body_to_pattern[p]] (where null: at mp.body_to_pattern[p]). The composed places go into `compose`, a
/// buffer the decorator keeps (no allocation per call), under its mutex.
inline void add_body_tangent(const ElasticBody& body, const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where,
                             const MergedPattern& mp, std::vector<std::int64_t>& compose, std::mutex& compose_mutex) {
    if (!where) {
        body.add_tangent(u, project, values, mp.body_to_pattern.data());
        return;
    }
    const std::lock_guard<std::mutex> lock(compose_mutex);
    compose.resize(mp.body_to_pattern.size());
    for (size_t p = 0; p < compose.size(); ++p) compose[p] = where[mp.body_to_pattern[p]];
    body.add_tangent(u, project, values, compose.data());
}

}  // namespace aneu::fem::detail

namespace aneu::fem {

/// See hyperelastic.hpp (make_pattern_cache): the last merged pattern, the body pattern it was merged over and the
/// extra entries it holds.
struct PatternCache {
    std::mutex mutex;
    Eigen::Index n = -1;
    std::vector<int> body_outer, body_inner;
    std::vector<std::pair<int, int>> extra;
    std::shared_ptr<const detail::MergedPattern> merged;
    int builds = 0, reuses = 0;
};

}  // namespace aneu::fem

namespace aneu::fem::detail {

/// The groups' entries merged into the body's pattern (merge_entries) through a cache kept between decorators of
/// successive solves: the cached pattern serves when it was merged over the same body pattern (compared entry by
/// entry: milliseconds) and holds every entry the groups need; else a new one is merged with the cached entries
/// and the new ones (while the union stays within a few times what is needed now), so that pairs that come and go
/// between frames leave the pattern, and with it the Newton workspace's analysis, as it is. cache null: merged
/// afresh.
template <size_t N>
std::shared_ptr<const MergedPattern> merge_pattern_cached(PatternCache* cache, const Eigen::SparseMatrix<double, Eigen::RowMajor>& body, Eigen::Index n,
                                                          const std::vector<std::array<int, N>>& groups) {
    std::vector<std::pair<int, int>> extra = group_entries(groups);
    if (!cache || !body.isCompressed()) return merge_entries(body, n, extra);
    const std::lock_guard<std::mutex> lock(cache->mutex);
    const int* bo = body.outerIndexPtr();
    const int* bi = body.innerIndexPtr();
    const size_t nnz = static_cast<size_t>(body.nonZeros());
    const bool same_body = cache->merged && cache->n == n && cache->body_outer.size() == static_cast<size_t>(body.outerSize()) + 1 &&
                           cache->body_inner.size() == nnz && std::equal(cache->body_outer.begin(), cache->body_outer.end(), bo) &&
                           std::equal(cache->body_inner.begin(), cache->body_inner.end(), bi);
    if (same_body && std::includes(cache->extra.begin(), cache->extra.end(), extra.begin(), extra.end())) {
        ++cache->reuses;
        return cache->merged;
    }
    if (same_body) {
        std::vector<std::pair<int, int>> all;
        all.reserve(cache->extra.size() + extra.size());
        std::set_union(cache->extra.begin(), cache->extra.end(), extra.begin(), extra.end(), std::back_inserter(all));
        if (all.size() <= 4 * extra.size() + 20000) extra = std::move(all);
    }
    cache->merged = merge_entries(body, n, extra);
    cache->extra = std::move(extra);
    cache->n = n;
    cache->body_outer.assign(bo, bo + body.outerSize() + 1);
    cache->body_inner.assign(bi, bi + nnz);
    ++cache->builds;
    return cache->merged;
}

/// The largest diagonal entry of the body's tangent at rest [N/mm]: the stiffest node's own stiffness.
inline double max_diagonal(const ElasticBody& body) {
    const Eigen::SparseMatrix<double, Eigen::RowMajor> K0 = body.tangent(Eigen::VectorXd::Zero(body.dofs()));
    double dmax = 0;
    for (Eigen::Index r = 0; r < K0.rows(); ++r) dmax = std::max(dmax, K0.coeff(r, r));
    return dmax;
}

}  // namespace aneu::fem::detail
