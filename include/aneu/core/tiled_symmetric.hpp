// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A dense symmetric matrix stored as its lower-triangle square tiles: half the memory of a full matrix,
/// the same layout in memory as in the case bundle (/condensed/W_tiles), and tiles that BLAS can update.
#include <cassert>
#include <vector>

#include <Eigen/Core>

namespace aneu {

/// Symmetric n×n matrix in tiles of b×b. Tile (I,J), I ≥ J, is at index I(I+1)/2 + J and holds rows I·b..
/// and columns J·b.. row-major; entries past n are zero. Diagonal tiles are stored in full (both halves).
template <class T>
class TiledSymmetric {
public:
    using Index = Eigen::Index;
    TiledSymmetric() = default;
    /// Zero matrix of size n in tiles of b.
    TiledSymmetric(Index n, Index b) : m_n(n), m_b(b), m_nb(b > 0 ? (n + b - 1) / b : 0) {
        m_data.assign(static_cast<size_t>(tile_count() * m_b * m_b), T(0));
    }
    Index size() const { return m_n; }
    Index tile_size() const { return m_b; }
    Index tiles_per_side() const { return m_nb; }
    Index tile_count() const { return m_nb * (m_nb + 1) / 2; }
    static Index tile_index(Index I, Index J) { return I * (I + 1) / 2 + J; }

    T* tile(Index I, Index J) { return m_data.data() + tile_index(I, J) * m_b * m_b; }
    const T* tile(Index I, Index J) const { return m_data.data() + tile_index(I, J) * m_b * m_b; }
    std::vector<T>& data() { return m_data; }
    const std::vector<T>& data() const { return m_data; }

    /// Entry (i,j) = (j,i).
    T operator()(Index i, Index j) const {
        if (i < j) std::swap(i, j);
        return tile(i / m_b, j / m_b)[(i % m_b) * m_b + (j % m_b)];
    }
    /// Sets (i,j) and (j,i).
    void set(Index i, Index j, T v) {
        if (i < j) std::swap(i, j);
        T* t = tile(i / m_b, j / m_b);
        t[(i % m_b) * m_b + (j % m_b)] = v;
        if (i / m_b == j / m_b) t[(j % m_b) * m_b + (i % m_b)] = v;
    }

    /// From the lower triangle of a dense matrix.
    template <class Derived>
    static TiledSymmetric from_dense(const Eigen::MatrixBase<Derived>& W, Index b) {
        TiledSymmetric t(W.rows(), b);
        for (Index j = 0; j < W.cols(); ++j)
            for (Index i = j; i < W.rows(); ++i) t.set(i, j, static_cast<T>(W(i, j)));
        return t;
    }
    Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> to_dense() const {
        Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> W(m_n, m_n);
        for (Index j = 0; j < m_n; ++j)
            for (Index i = j; i < m_n; ++i) W(i, j) = W(j, i) = (*this)(i, j);
        return W;
    }
    /// Element-wise conversion (e.g. double → float storage).
    template <class U>
    TiledSymmetric<U> cast() const {
        TiledSymmetric<U> out;
        out.m_n = m_n;
        out.m_b = m_b;
        out.m_nb = m_nb;
        out.m_data.assign(m_data.begin(), m_data.end());
        return out;
    }
    /// Copies the lower half of each diagonal tile into its upper half (after lower-only BLAS updates).
    void symmetrize_diagonal_tiles() {
        for (Index I = 0; I < m_nb; ++I) {
            T* t = tile(I, I);
            for (Index r = 0; r < m_b; ++r)
                for (Index c = r + 1; c < m_b; ++c) t[r * m_b + c] = t[c * m_b + r];
        }
    }
    /// y = W x.
    Eigen::Matrix<T, Eigen::Dynamic, 1> multiply(const Eigen::Matrix<T, Eigen::Dynamic, 1>& x) const;

private:
    template <class>
    friend class TiledSymmetric;
    Index m_n = 0, m_b = 0, m_nb = 0;
    std::vector<T> m_data;
};

template <class T>
Eigen::Matrix<T, Eigen::Dynamic, 1> TiledSymmetric<T>::multiply(const Eigen::Matrix<T, Eigen::Dynamic, 1>& x) const {
    assert(x.size() == m_n);
    Eigen::Matrix<T, Eigen::Dynamic, 1> xp = Eigen::Matrix<T, Eigen::Dynamic, 1>::Zero(m_nb * m_b);
    xp.head(m_n) = x;
    Eigen::Matrix<T, Eigen::Dynamic, 1> y = Eigen::Matrix<T, Eigen::Dynamic, 1>::Zero(m_nb * m_b);
    using Tile = Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
    for (Index I = 0; I < m_nb; ++I) {
        for (Index J = 0; J <= I; ++J) {
            const Tile t(tile(I, J), m_b, m_b);
            y.segment(I * m_b, m_b).noalias() += t * xp.segment(J * m_b, m_b);
            if (I != J) y.segment(J * m_b, m_b).noalias() += t.transpose() * xp.segment(I * m_b, m_b);
        }
    }
    return y.head(m_n);
}

}  // namespace aneu
