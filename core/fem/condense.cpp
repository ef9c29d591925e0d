// SPDX-License-Identifier: MIT
// W = (K⁻¹)_MM by two routes (REFERENCE.md, "Condensation / inversion"):
//  SPARSE: CHOLMOD supernodal L Lᵀ = P K Pᵀ with a METIS nested-dissection ordering; Y = L⁻¹ P E_M by a
//          forward solve that only touches, for each kept DOF, the supernodes on its elimination-tree path;
//          W = YᵀY accumulated supernode by supernode. Kept DOFs are ordered by pivot, so the kept DOFs
//          below a supernode form one contiguous range and its update W[r,r] += Y_sᵀY_s is a SYRK into a
//          contiguous block of tiles (no scatter).
//  DENSE:  S = K_MM − K_MI K_II⁻¹ K_IM formed densely, then W = S⁻¹ by LAPACK dpotrf + dpotri.
#include "aneu/core/common.hpp"
#include "aneu/fem/condense.hpp"

#include <cblas.h>
#include <cholmod.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>

#include "aneu/core/error.hpp"

extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info);
}

namespace aneu::fem {

namespace {


std::string gb(double bytes) {
    std::ostringstream o;
    o.precision(3);
    o << bytes / 1e9 << " GB";
    return o.str();
}

thread_local std::string g_cholmod_error;
void cholmod_error_handler(int status, const char* file, int line, const char* message) {
    g_cholmod_error = std::string(message ? message : "?") + " (status " + std::to_string(status) + ", " +
                      (file ? file : "?") + ":" + std::to_string(line) + ")";
}

/// RAII owner of a cholmod_common, its factor and its matrices.
struct Cholmod {
    cholmod_common c{};
    cholmod_factor* L = nullptr;
    cholmod_sparse* A = nullptr;
    explicit Cholmod(const std::string& ordering = "metis") {
        cholmod_start(&c);
        c.print = 0;
        c.error_handler = cholmod_error_handler;
        c.supernodal = CHOLMOD_SUPERNODAL;
        c.nmethods = 1;
        c.method[0].ordering = ordering == "amd" ? CHOLMOD_AMD : ordering == "nesdis" ? CHOLMOD_NESDIS : CHOLMOD_METIS;
        c.postorder = 1;
    }
    ~Cholmod() {
        if (L) cholmod_free_factor(&L, &c);
        if (A) cholmod_free_sparse(&A, &c);
        cholmod_finish(&c);
    }
    Cholmod(const Cholmod&) = delete;
    Cholmod& operator=(const Cholmod&) = delete;
};

/// Lower triangle of K restricted to `keep` (old DOF -> new index, −1 dropped) as a CHOLMOD matrix.
cholmod_sparse* lower_csc(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const std::vector<int>& newidx, int n,
                          cholmod_common* c) {
    // K is symmetric, so its CSR rows are CSC columns; entries (i, j ≥ i) of a row are column i's lower part.
    std::int64_t nnz = 0;
    for (Eigen::Index i = 0; i < K.rows(); ++i) {
        if (newidx[static_cast<size_t>(i)] < 0) continue;
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(K, i); it; ++it) {
            const int j = newidx[static_cast<size_t>(it.col())];
            nnz += j >= newidx[static_cast<size_t>(i)];
        }
    }
    cholmod_sparse* A = cholmod_allocate_sparse(static_cast<size_t>(n), static_cast<size_t>(n), static_cast<size_t>(nnz), 1,
                                                1, -1, CHOLMOD_REAL, c);
    if (!A) throw NumericalError("condense: cannot allocate the CHOLMOD matrix (" + g_cholmod_error + ")");
    auto* Ap = static_cast<int*>(A->p);
    auto* Ai = static_cast<int*>(A->i);
    auto* Ax = static_cast<double*>(A->x);
    int k = 0;
    for (Eigen::Index i = 0; i < K.rows(); ++i) {
        const int col = newidx[static_cast<size_t>(i)];
        if (col < 0) continue;
        Ap[col] = k;
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(K, i); it; ++it) {
            const int row = newidx[static_cast<size_t>(it.col())];
            if (row >= col) {
                Ai[k] = row;
                Ax[k++] = it.value();
            }
        }
    }
    Ap[n] = k;
    return A;
}

/// With METIS and the free DOFs in node triples (3k, 3k+1, 3k+2 belong to one node), the ordering is computed on
/// the node graph and expanded to the DOFs: the same nested dissection on a graph with a ninth of the edges
/// (the C0001 real case, 445 k DOFs of 10-node elements: analysis 15 s -> a few seconds).
cholmod_factor* analyze_by_nodes(Cholmod& ch) {
    const cholmod_sparse* A = ch.A;
    const auto n = static_cast<std::int64_t>(A->nrow);
    if (n % 3 != 0 || n == 0) return nullptr;
    const std::int64_t nn = n / 3;
    const auto* Ap = static_cast<const int*>(A->p);
    const auto* Ai = static_cast<const int*>(A->i);
    // Lower node pattern, column by column (rows ≥ column), without duplicates.
    std::vector<int> mark(static_cast<size_t>(nn), -1), cp(static_cast<size_t>(nn) + 1, 0), ci;
    ci.reserve(static_cast<size_t>(Ap[n] / 6 + nn));
    for (std::int64_t J = 0; J < nn; ++J) {
        for (std::int64_t j = 3 * J; j < 3 * J + 3; ++j)
            for (int k = Ap[j]; k < Ap[j + 1]; ++k) {
                const int I = Ai[k] / 3;
                if (I >= J && mark[static_cast<size_t>(I)] != static_cast<int>(J)) {
                    mark[static_cast<size_t>(I)] = static_cast<int>(J);
                    ci.push_back(I);
                }
            }
        cp[static_cast<size_t>(J) + 1] = static_cast<int>(ci.size());
    }
    cholmod_sparse* G = cholmod_allocate_sparse(static_cast<size_t>(nn), static_cast<size_t>(nn), ci.size(), 0, 1, -1, CHOLMOD_PATTERN, &ch.c);
    if (!G) return nullptr;
    std::copy(cp.begin(), cp.end(), static_cast<int*>(G->p));
    std::copy(ci.begin(), ci.end(), static_cast<int*>(G->i));
    std::vector<int> node_perm(static_cast<size_t>(nn));
    const int ok = cholmod_metis(G, nullptr, 0, 1, node_perm.data(), &ch.c);
    cholmod_free_sparse(&G, &ch.c);
    if (!ok) return nullptr;
    std::vector<int> perm(static_cast<size_t>(n));
    for (std::int64_t k = 0; k < nn; ++k)
        for (int a = 0; a < 3; ++a) perm[static_cast<size_t>(3 * k + a)] = 3 * node_perm[static_cast<size_t>(k)] + a;
    const int saved = ch.c.method[0].ordering;
    ch.c.method[0].ordering = CHOLMOD_GIVEN;
    cholmod_factor* L = cholmod_analyze_p(ch.A, perm.data(), nullptr, 0, &ch.c);
    ch.c.method[0].ordering = saved;
    return L;
}

void factorize(Cholmod& ch, const std::string& what, bool node_triples = false) {
    if (node_triples && ch.c.method[0].ordering == CHOLMOD_METIS) ch.L = analyze_by_nodes(ch);
    if (!ch.L) ch.L = cholmod_analyze(ch.A, &ch.c);
    if (!ch.L) throw NumericalError("condense: CHOLMOD analysis of " + what + " failed: " + g_cholmod_error);
}

void factorize_numeric(Cholmod& ch, const std::string& what) {
    cholmod_factorize(ch.A, ch.L, &ch.c);
    if (ch.c.status == CHOLMOD_NOT_POSDEF) {
        throw NumericalError("condense: " + what + " is not positive definite (CHOLMOD failed at column " +
                             std::to_string(ch.L->minor) + " of " + std::to_string(ch.L->n) +
                             "): check the fixed nodes and the materials");
    }
    if (ch.c.status < CHOLMOD_OK) throw NumericalError("condense: CHOLMOD factorization of " + what + " failed: " + g_cholmod_error);
}

/// Supernodal structure of the factor, with its elimination tree and subtree column ranges.
struct Supernodes {
    int nsuper = 0;
    const int *super = nullptr, *pi = nullptr, *px = nullptr, *s = nullptr;
    const double* x = nullptr;
    std::vector<int> super_of;  ///< supernode of each pivot column
    std::vector<int> first;     ///< first pivot column of each supernode's subtree
    explicit Supernodes(const cholmod_factor* L) {
        nsuper = static_cast<int>(L->nsuper);
        super = static_cast<const int*>(L->super);
        pi = static_cast<const int*>(L->pi);
        px = static_cast<const int*>(L->px);
        s = static_cast<const int*>(L->s);
        x = static_cast<const double*>(L->x);
        super_of.resize(L->n);
        first.resize(static_cast<size_t>(nsuper));
        for (int k = 0; k < nsuper; ++k) {
            for (int c = super[k]; c < super[k + 1]; ++c) super_of[static_cast<size_t>(c)] = k;
            first[static_cast<size_t>(k)] = super[k];
        }
        for (int k = 0; k < nsuper; ++k) {  // children precede parents: propagate subtree starts upward
            const int p = parent(k);
            if (p >= 0) first[static_cast<size_t>(p)] = std::min(first[static_cast<size_t>(p)], first[static_cast<size_t>(k)]);
        }
    }
    int ncols(int k) const { return super[k + 1] - super[k]; }
    int nrows(int k) const { return pi[k + 1] - pi[k]; }
    int parent(int k) const { return nrows(k) > ncols(k) ? super_of[static_cast<size_t>(s[pi[k] + ncols(k)])] : -1; }
};

/// Range [lo, hi) of kept-DOF positions (sorted by pivot) whose pivot lies in [a, b).
std::pair<int, int> kept_range(const std::vector<int>& pivots_sorted, int a, int b) {
    const auto lo = std::lower_bound(pivots_sorted.begin(), pivots_sorted.end(), a) - pivots_sorted.begin();
    const auto hi = std::lower_bound(pivots_sorted.begin(), pivots_sorted.end(), b) - pivots_sorted.begin();
    return {static_cast<int>(lo), static_cast<int>(hi)};
}

/// Peak bytes of the live Y blocks and GEMM buffer of the forward solve, from the symbolic structure.
double predict_y_peak(const Supernodes& sn, const std::vector<int>& piv) {
    std::vector<char> alive(static_cast<size_t>(sn.nsuper), 0);
    double live = 0, peak = 0;
    auto block = [&](int t) {
        const auto [lo, hi] = kept_range(piv, sn.first[static_cast<size_t>(t)], sn.super[t + 1]);
        return 8.0 * sn.ncols(t) * (hi - lo);
    };
    for (int k = 0; k < sn.nsuper; ++k) {
        const auto [lo, hi] = kept_range(piv, sn.first[static_cast<size_t>(k)], sn.super[k + 1]);
        if (hi == lo) continue;
        if (!alive[static_cast<size_t>(k)]) {
            alive[static_cast<size_t>(k)] = 1;
            live += block(k);
        }
        for (int r = sn.pi[k] + sn.ncols(k); r < sn.pi[k + 1]; ++r) {
            const int t = sn.super_of[static_cast<size_t>(sn.s[r])];
            if (!alive[static_cast<size_t>(t)]) {
                alive[static_cast<size_t>(t)] = 1;
                live += block(t);
            }
        }
        peak = std::max(peak, live + 8.0 * (sn.nrows(k) - sn.ncols(k)) * (hi - lo));
        live -= block(k);
    }
    return peak;
}

void syrk(int n, int k, const double* A, int lda, double* C, int ldc) {
    cblas_dsyrk(CblasColMajor, CblasUpper, CblasTrans, n, k, 1.0, A, lda, 1.0, C, ldc);
}
void syrk(int n, int k, const float* A, int lda, float* C, int ldc) {
    cblas_ssyrk(CblasColMajor, CblasUpper, CblasTrans, n, k, 1.0f, A, lda, 1.0f, C, ldc);
}
void gemm_tn(int m, int n, int k, const double* A, const double* B, int ld, double* C, int ldc) {
    cblas_dgemm(CblasColMajor, CblasTrans, CblasNoTrans, m, n, k, 1.0, A, ld, B, ld, 1.0, C, ldc);
}
void gemm_tn(int m, int n, int k, const float* A, const float* B, int ld, float* C, int ldc) {
    cblas_sgemm(CblasColMajor, CblasTrans, CblasNoTrans, m, n, k, 1.0f, A, ld, B, ld, 1.0f, C, ldc);
}

/// W[lo:hi, lo:hi] += AᵀA for A = ns×(hi−lo) column-major (ld ns), into the tiles of W. Returns flops.
template <class T>
double syrk_into_tiles(TiledSymmetric<T>& W, int lo, int hi, int ns, const T* A) {
    const int b = static_cast<int>(W.tile_size());
    double flops = 0;
    for (int I = lo / b; I <= (hi - 1) / b; ++I) {
        const int r0 = std::max(lo, I * b) - I * b, r1 = std::min(hi, I * b + b) - I * b;
        const int cI = I * b + r0 - lo;
        for (int J = lo / b; J <= I; ++J) {
            const int c0 = std::max(lo, J * b) - J * b, c1 = std::min(hi, J * b + b) - J * b;
            const int cJ = J * b + c0 - lo;
            T* C = W.tile(I, J);
            if (I == J) {  // column-major view of the row-major tile: its upper part is the tile's lower part
                syrk(r1 - r0, ns, A + static_cast<std::int64_t>(cI) * ns, ns, C + r0 * b + r0, b);
                flops += 1.0 * (r1 - r0) * (r1 - r0 + 1) * ns;
            } else {
                gemm_tn(c1 - c0, r1 - r0, ns, A + static_cast<std::int64_t>(cJ) * ns, A + static_cast<std::int64_t>(cI) * ns, ns,
                        C + r0 * b + c0, b);
                flops += 2.0 * (c1 - c0) * (r1 - r0) * ns;
            }
        }
    }
    return flops;
}

struct Timing {
    double factor_s = 0, solve_s = 0, flops = 0;
};

/// The kept DOFs sorted by their pivot (elimination) position in the factor: `order` = positions into
/// kept_free, `piv` = their pivots, ascending. Needs only the symbolic factor.
void pivot_order(const cholmod_factor* L, const std::vector<int>& kept_free, std::vector<int>& order, std::vector<int>& piv) {
    const int* Perm = static_cast<const int*>(L->Perm);
    std::vector<int> inv(L->n);
    for (size_t k = 0; k < L->n; ++k) inv[static_cast<size_t>(Perm[k])] = static_cast<int>(k);
    order.resize(kept_free.size());
    std::iota(order.begin(), order.end(), 0);
    auto pivot = [&](int q) { return inv[static_cast<size_t>(kept_free[static_cast<size_t>(q)])]; };
    std::sort(order.begin(), order.end(), [&](int a, int b) { return pivot(a) < pivot(b); });
    piv.resize(order.size());
    for (size_t q = 0; q < order.size(); ++q) piv[q] = pivot(order[q]);
}

/// SPARSE route: W with rows in the order of `piv` (pivot_order). The factor and Y are double; the final
/// accumulation YᵀY runs in T (float32 storage: SSYRK on Y rounded to float, which keeps W's relative
/// error near float32 rounding because every term is well scaled).
template <class T>
TiledSymmetric<T> sparse_w(Cholmod& ch, const std::vector<int>& piv, int tile, Timing& tm, Reporter& rep) {
    const Supernodes sn(ch.L);  // after the numeric factorization: its values are set
    const Stopwatch t0;
    const int m = static_cast<int>(piv.size());
    TiledSymmetric<T> W(m, tile);
    std::vector<std::vector<double>> Y(static_cast<size_t>(sn.nsuper));
    std::vector<double> U;
    std::vector<T> Bt_buf;
    auto block = [&](int t, int& lo, int& hi) -> std::vector<double>& {
        std::tie(lo, hi) = kept_range(piv, sn.first[static_cast<size_t>(t)], sn.super[t + 1]);
        auto& B = Y[static_cast<size_t>(t)];
        if (B.empty()) B.assign(static_cast<size_t>(sn.ncols(t)) * static_cast<size_t>(hi - lo), 0.0);
        return B;
    };
    for (int k = 0; k < sn.nsuper; ++k) {
        int lo = 0, hi = 0;
        std::tie(lo, hi) = kept_range(piv, sn.first[static_cast<size_t>(k)], sn.super[k + 1]);
        if (hi == lo) continue;
        const int ns = sn.ncols(k), nsrow = sn.nrows(k), nrb = nsrow - ns, mk = hi - lo;
        std::vector<double>& B = block(k, lo, hi);
        // Right-hand side: the unit entries of the kept DOFs whose pivot is in this supernode.
        for (int q = kept_range(piv, sn.super[k], sn.super[k + 1]).first; q < hi; ++q) {
            B[static_cast<size_t>(piv[static_cast<size_t>(q)] - sn.super[k]) + static_cast<size_t>(q - lo) * ns] += 1.0;
        }
        const double* Lk = sn.x + sn.px[k];
        cblas_dtrsm(CblasColMajor, CblasLeft, CblasLower, CblasNoTrans, CblasNonUnit, ns, mk, 1.0, Lk, nsrow, B.data(), ns);
        tm.flops += 1.0 * ns * ns * mk;
        if (nrb > 0) {
            U.resize(static_cast<size_t>(nrb) * static_cast<size_t>(mk));
            cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, nrb, mk, ns, 1.0, Lk + ns, nsrow, B.data(), ns, 0.0,
                        U.data(), nrb);
            tm.flops += 2.0 * nrb * ns * mk;
            // Scatter −U into the ancestors' blocks, one run of rows per ancestor supernode.
            const int* rows = sn.s + sn.pi[k] + ns;
            for (int r = 0; r < nrb;) {
                const int t = sn.super_of[static_cast<size_t>(rows[r])];
                int r_end = r;
                while (r_end < nrb && rows[r_end] < sn.super[t + 1]) ++r_end;
                int tlo = 0, thi = 0;
                std::vector<double>& Bt = block(t, tlo, thi);
                const int nst = sn.ncols(t), off = lo - tlo;
                for (int c = 0; c < mk; ++c) {
                    double* dst = Bt.data() + static_cast<size_t>(c + off) * nst - sn.super[t];
                    const double* src = U.data() + static_cast<size_t>(c) * nrb;
                    for (int rr = r; rr < r_end; ++rr) dst[rows[rr]] -= src[rr];
                }
                r = r_end;
            }
        }
        if constexpr (std::is_same_v<T, double>) {
            tm.flops += syrk_into_tiles(W, lo, hi, ns, B.data());
        } else {
            Bt_buf.assign(B.begin(), B.end());
            tm.flops += syrk_into_tiles(W, lo, hi, ns, Bt_buf.data());
        }
        std::vector<double>().swap(B);
        if (k % 64 == 0) rep.progress("condense", k, sn.nsuper);
    }
    W.symmetrize_diagonal_tiles();
    tm.solve_s = t0.seconds();
    rep.progress("condense", sn.nsuper, sn.nsuper);
    return W;
}

/// DENSE route: S = K_MM − K_MI K_II⁻¹ K_IM, W = S⁻¹ (LAPACK), in the order of kept_free.
TiledSymmetric<double> dense_w(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const std::vector<int>& free_dofs,
                               const std::vector<int>& kept_free, int tile, Timing& tm, Reporter& rep) {
    const int nf = static_cast<int>(free_dofs.size()), m = static_cast<int>(kept_free.size());
    std::vector<int> kpos(static_cast<size_t>(nf), -1), ipos(static_cast<size_t>(nf), -1);
    for (int q = 0; q < m; ++q) kpos[static_cast<size_t>(kept_free[static_cast<size_t>(q)])] = q;
    int ni = 0;
    for (int f = 0; f < nf; ++f)
        if (kpos[static_cast<size_t>(f)] < 0) ipos[static_cast<size_t>(f)] = ni++;
    // Old DOF -> interior index, and old DOF -> kept index.
    std::vector<int> to_i(static_cast<size_t>(K.rows()), -1), to_m(static_cast<size_t>(K.rows()), -1);
    for (int f = 0; f < nf; ++f) {
        to_i[static_cast<size_t>(free_dofs[static_cast<size_t>(f)])] = ipos[static_cast<size_t>(f)];
        to_m[static_cast<size_t>(free_dofs[static_cast<size_t>(f)])] = kpos[static_cast<size_t>(f)];
    }
    const Stopwatch t0;
    // K_MM dense (it becomes S, then W); K_IM sparse: only its nonzeros enter the products.
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m, m);
    std::vector<Eigen::Triplet<double>> kim;
    for (Eigen::Index r = 0; r < K.rows(); ++r) {
        const int rm = to_m[static_cast<size_t>(r)], ri = to_i[static_cast<size_t>(r)];
        if (rm < 0 && ri < 0) continue;
        for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(K, r); it; ++it) {
            const int cm = to_m[static_cast<size_t>(it.col())];
            if (cm < 0) continue;
            if (rm >= 0) S(rm, cm) = it.value();
            if (ri >= 0) kim.emplace_back(ri, cm, it.value());
        }
    }
    Eigen::SparseMatrix<double> KIM(ni, m);  // column-major: column blocks are contiguous
    KIM.setFromTriplets(kim.begin(), kim.end());
    if (ni > 0) {
        Cholmod ch;
        ch.A = lower_csc(K, to_i, ni, &ch.c);
        factorize(ch, "K_II");
        factorize_numeric(ch, "K_II (the interior block)");
        tm.factor_s += t0.seconds();
        constexpr int BLOCK = 256;
        for (int c0 = 0; c0 < m; c0 += BLOCK) {
            const int nc = std::min(BLOCK, m - c0);
            cholmod_dense* Bd = cholmod_zeros(static_cast<size_t>(ni), static_cast<size_t>(nc), CHOLMOD_REAL, &ch.c);
            Eigen::Map<Eigen::MatrixXd>(static_cast<double*>(Bd->x), ni, nc) = KIM.middleCols(c0, nc);
            cholmod_dense* X = cholmod_solve(CHOLMOD_A, ch.L, Bd, &ch.c);
            const Eigen::Map<const Eigen::MatrixXd> Xm(static_cast<const double*>(X->x), ni, nc);
            S.middleCols(c0, nc).noalias() -= KIM.transpose() * Xm;  // sparse × dense
            cholmod_free_dense(&X, &ch.c);
            cholmod_free_dense(&Bd, &ch.c);
            rep.progress("condense (Schur complement)", c0 + nc, m);
        }
        tm.flops += 2.0 * static_cast<double>(KIM.nonZeros()) * m + 4.0 * ch.c.lnz * m;
    }
    int info = 0;
    dpotrf_("L", &m, S.data(), &m, &info);
    if (info != 0) throw NumericalError("condense: the Schur complement is not positive definite (dpotrf info " + std::to_string(info) + ")");
    dpotri_("L", &m, S.data(), &m, &info);
    if (info != 0) throw NumericalError("condense: dpotri failed (info " + std::to_string(info) + ")");
    tm.flops += 1.0 * m * m * m;  // potrf m³/3 + potri 2m³/3
    tm.solve_s = t0.seconds() - tm.factor_s;
    return TiledSymmetric<double>::from_dense(S, tile);  // reads the lower triangle dpotri wrote
}

}  // namespace

std::uint64_t available_memory_bytes() {
    std::ifstream in("/proc/meminfo");
    std::string key;
    std::uint64_t kb = 0;
    std::string unit;
    while (in >> key >> kb >> unit) {
        if (key == "MemAvailable:") return kb * 1024;
    }
    return 0;
}

std::uint64_t peak_memory_bytes() {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
    }
    return 0;
}


struct CondenseFactor::Impl {
    std::unique_ptr<Cholmod> ch;
    int n = 0;
};
CondenseFactor::CondenseFactor() : m(std::make_unique<Impl>()) {}
CondenseFactor::~CondenseFactor() = default;

Eigen::VectorXd CondenseFactor::solve(const Eigen::VectorXd& b) const {
    if (b.size() != m->n) throw InputError("condense factor: a right-hand side of " + std::to_string(b.size()) + " entries, expected " + std::to_string(m->n));
    Eigen::VectorXd x(m->n);
    if (m->n == 0) return x;
    Cholmod& ch = *m->ch;
    cholmod_dense B{};
    B.nrow = B.d = static_cast<size_t>(m->n);
    B.ncol = 1;
    B.nzmax = static_cast<size_t>(m->n);
    B.x = const_cast<double*>(b.data());
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    cholmod_dense* X = cholmod_solve(CHOLMOD_A, ch.L, &B, &ch.c);
    if (!X) throw NumericalError("condense factor: CHOLMOD solve failed: " + g_cholmod_error);
    std::copy_n(static_cast<const double*>(X->x), m->n, x.data());
    cholmod_free_dense(&X, &ch.c);
    return x;
}

Eigen::MatrixXd CondenseFactor::solve_columns(const Eigen::MatrixXd& b) const {
    if (b.rows() != m->n) throw InputError("condense factor: right-hand sides of " + std::to_string(b.rows()) + " entries, expected " + std::to_string(m->n));
    Eigen::MatrixXd x(m->n, b.cols());
    if (m->n == 0 || b.cols() == 0) return x;
    Cholmod& ch = *m->ch;
    cholmod_dense B{};
    B.nrow = B.d = static_cast<size_t>(m->n);
    B.ncol = static_cast<size_t>(b.cols());
    B.nzmax = static_cast<size_t>(m->n) * static_cast<size_t>(b.cols());
    B.x = const_cast<double*>(b.data());
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    cholmod_dense* X = cholmod_solve(CHOLMOD_A, ch.L, &B, &ch.c);
    if (!X) throw NumericalError("condense factor: CHOLMOD solve failed: " + g_cholmod_error);
    std::copy_n(static_cast<const double*>(X->x), x.size(), x.data());
    cholmod_free_dense(&X, &ch.c);
    return x;
}

CondensedData condense(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const Eigen::VectorXi& fixed_dofs,
                       const Eigen::VectorXi& kept_dofs, const CondenseParams& p, Reporter& rep, std::unique_ptr<CondenseFactor>* factor) {
    validate(p);
    if (factor) factor->reset();  // none unless this condensation succeeds
    const Stopwatch t_all;
    const Eigen::Index n = K.rows();
    if (K.cols() != n) throw InputError("condense: K is not square");
    std::vector<int> state(static_cast<size_t>(n), 0);  // 0 free, 1 fixed, 2 kept
    for (Eigen::Index i = 0; i < fixed_dofs.size(); ++i) {
        const int d = fixed_dofs[i];
        if (d < 0 || d >= n) throw InputError("condense: fixed DOF " + std::to_string(d) + " outside [0," + std::to_string(n) + ")");
        state[static_cast<size_t>(d)] = 1;
    }
    if (kept_dofs.size() == 0) throw InputError("condense: the kept DOF set is empty (no simulated node in the region?)");
    for (Eigen::Index i = 0; i < kept_dofs.size(); ++i) {
        const int d = kept_dofs[i];
        if (d < 0 || d >= n) throw InputError("condense: kept DOF " + std::to_string(d) + " outside [0," + std::to_string(n) + ")");
        if (state[static_cast<size_t>(d)] == 1) throw InputError("condense: kept DOF " + std::to_string(d) + " is fixed");
        if (state[static_cast<size_t>(d)] == 2) throw InputError("condense: kept DOF " + std::to_string(d) + " given twice");
        state[static_cast<size_t>(d)] = 2;
    }
    std::vector<int> free_dofs, newidx(static_cast<size_t>(n), -1);
    for (Eigen::Index d = 0; d < n; ++d) {
        if (state[static_cast<size_t>(d)] != 1) {
            newidx[static_cast<size_t>(d)] = static_cast<int>(free_dofs.size());
            free_dofs.push_back(static_cast<int>(d));
        }
    }
    std::vector<int> kept_free(static_cast<size_t>(kept_dofs.size()));
    for (Eigen::Index i = 0; i < kept_dofs.size(); ++i) kept_free[static_cast<size_t>(i)] = newidx[static_cast<size_t>(kept_dofs[i])];
    const int nf = static_cast<int>(free_dofs.size()), m = static_cast<int>(kept_free.size());

    // Factor of K_ff: the SPARSE route's engine, and both routes' independent residual check.
    auto chp = std::make_unique<Cholmod>(p.ordering);
    Cholmod& ch = *chp;
    ch.A = lower_csc(K, newidx, nf, &ch.c);
    Stopwatch t0;
    bool triples = nf % 3 == 0;  // every node's three DOFs free together, in order
    for (int k = 0; k < nf && triples; k += 3)
        triples = free_dofs[static_cast<size_t>(k)] % 3 == 0 && free_dofs[static_cast<size_t>(k) + 1] == free_dofs[static_cast<size_t>(k)] + 1 &&
                  free_dofs[static_cast<size_t>(k) + 2] == free_dofs[static_cast<size_t>(k)] + 2;
    factorize(ch, "K", triples);
    const double analyze_s = t0.seconds();
    Timing tm;
    const double nb = std::ceil(static_cast<double>(m) / p.tile_size);
    const double w_bytes = (p.precision == Precision::FLOAT32 ? 4.0 : 8.0) * nb * (nb + 1) / 2 * p.tile_size * p.tile_size;
    // The DENSE route forms W in double and converts it.
    const double w_out_bytes = p.method == CondenseMethod::DENSE && p.precision == Precision::FLOAT32 ? 2.0 * w_bytes : 0.0;
    double predicted = 8.0 * static_cast<double>(ch.L->xsize > 0 ? ch.L->xsize : 0) + w_bytes + w_out_bytes;
    std::vector<int> order, piv;
    double y_peak = 0;
    if (p.method == CondenseMethod::SPARSE) {
        // The symbolic analysis fixes the supernodes, so the forward solve's peak can be predicted exactly.
        pivot_order(ch.L, kept_free, order, piv);
        y_peak = predict_y_peak(Supernodes(ch.L), piv);
        predicted += y_peak;
    } else {
        predicted += 8.0 * m * static_cast<double>(m) + 2.0 * 8.0 * (nf - m) * 256.0;  // S and one block of solves
    }
    const double avail = static_cast<double>(available_memory_bytes());
    const double limit = p.memory_limit_gb > 0 ? p.memory_limit_gb * 1e9 : 0.9 * avail;
    if (limit > 0 && predicted > limit) {
        throw InputError("condense: W for " + std::to_string(m) + " kept DOFs needs about " + gb(predicted) +
                         " (W " + gb(w_bytes) + ", the factor and work space) but the limit is " +
                         gb(limit) + "; condense a smaller working region, or raise --memory-limit-gb");
    }
    rep.info("condense: " + std::to_string(nf) + " free DOFs, " + std::to_string(m) + " kept; predicted peak " + gb(predicted));
    factorize_numeric(ch, "K (free DOFs)");
    tm.factor_s = t0.seconds();
    // nnz(L) and its flops, for the report.
    const double nnzL = static_cast<double>(ch.c.lnz);
    const double fl_factor = ch.c.fl;

    CondensedData out;
    out.precision = p.precision;
    std::vector<int> row_kept;  // position in kept_dofs of each row of W
    const bool f32 = p.precision == Precision::FLOAT32;
    if (p.method == CondenseMethod::SPARSE) {
        if (f32) {
            out.W32 = sparse_w<float>(ch, piv, p.tile_size, tm, rep);
        } else {
            out.W64 = sparse_w<double>(ch, piv, p.tile_size, tm, rep);
        }
        row_kept = order;
    } else {
        TiledSymmetric<double> W = dense_w(K, free_dofs, kept_free, p.tile_size, tm, rep);
        if (f32) {
            out.W32 = W.cast<float>();
        } else {
            out.W64 = std::move(W);
        }
        row_kept.resize(static_cast<size_t>(m));
        std::iota(row_kept.begin(), row_kept.end(), 0);
    }
    auto Wat = [&](int r, int c) { return f32 ? static_cast<double>(out.W32(r, c)) : out.W64(r, c); };

    // Residual check: columns of W against independent sparse solves K_ff x = e_j.
    double max_rel = 0;
    if (p.residual_columns > 0) {
        const int ns = std::min(p.residual_columns, m);
        cholmod_dense* B = cholmod_zeros(static_cast<size_t>(nf), static_cast<size_t>(ns), CHOLMOD_REAL, &ch.c);
        std::vector<int> rows(static_cast<size_t>(ns));
        for (int j = 0; j < ns; ++j) {
            rows[static_cast<size_t>(j)] = static_cast<int>((static_cast<std::int64_t>(j) * m) / ns + (m / ns) / 2) % m;
            static_cast<double*>(B->x)[static_cast<std::int64_t>(j) * nf + kept_free[static_cast<size_t>(row_kept[static_cast<size_t>(rows[static_cast<size_t>(j)])])]] = 1.0;
        }
        cholmod_dense* X = cholmod_solve(CHOLMOD_A, ch.L, B, &ch.c);
        const auto* xv = static_cast<const double*>(X->x);
        for (int j = 0; j < ns; ++j) {
            double num = 0, den = 0;
            for (int r = 0; r < m; ++r) {
                const double exact = xv[static_cast<std::int64_t>(j) * nf + kept_free[static_cast<size_t>(row_kept[static_cast<size_t>(r)])]];
                const double d = Wat(r, rows[static_cast<size_t>(j)]) - exact;
                num += d * d;
                den += exact * exact;
            }
            max_rel = std::max(max_rel, std::sqrt(num / den));
        }
        cholmod_free_dense(&X, &ch.c);
        cholmod_free_dense(&B, &ch.c);
    }
    const double rcond = cholmod_rcond(ch.L, &ch.c);

    out.dof_node.resize(m);
    out.dof_axis.resize(m);
    for (int r = 0; r < m; ++r) {
        const int d = kept_dofs[row_kept[static_cast<size_t>(r)]];
        out.dof_node[r] = d / 3;
        out.dof_axis[r] = d % 3;
    }
    out.method = p.method == CondenseMethod::SPARSE ? "sparse: CHOLMOD supernodal LL^T (METIS), forward solve, SYRK per supernode"
                                                    : "dense: Schur complement, LAPACK dpotrf + dpotri";
    const double total = t_all.seconds();
    out.diagnostics = {{"n_free_dofs", nf},
                       {"n_kept_dofs", m},
                       {"nnz_K_free_lower", static_cast<double>(static_cast<const int*>(ch.A->p)[nf])},
                       {"nnz_L", nnzL},
                       {"factor_flops", fl_factor},
                       {"factor_s", tm.factor_s},
                       {"analyze_s", analyze_s},
                       {"w_s", tm.solve_s},
                       {"w_flops", tm.flops},
                       {"w_gflops_per_s", tm.solve_s > 0 ? tm.flops / tm.solve_s / 1e9 : 0.0},
                       {"total_s", total},
                       {"predicted_peak_bytes", predicted},
                       {"peak_rss_bytes", static_cast<double>(peak_memory_bytes())},
                       {"y_peak_bytes", y_peak},
                       {"residual_max_rel", max_rel},
                       {"residual_columns", static_cast<double>(std::min(p.residual_columns, m))},
                       {"rcond_estimate_K", rcond},
                       {"tile_size", p.tile_size}};
    if (factor && p.method == CondenseMethod::SPARSE) {
        cholmod_free_sparse(&ch.A, &ch.c);  // the matrix is not needed for solves
        *factor = std::make_unique<CondenseFactor>();
        (*factor)->m->n = nf;
        (*factor)->m->ch = std::move(chp);
    }
    return out;
}

}  // namespace aneu::fem
