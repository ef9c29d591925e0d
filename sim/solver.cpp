// SPDX-License-Identifier: MIT
#include "aneu/core/common.hpp"
#include "aneu/sim/solver.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include <Eigen/Cholesky>

#include "aneu/core/error.hpp"

namespace aneu::sim {
namespace {


// A factored W_CC for one node set (plus, for groups, the Schur complement S = Bᵀ W⁻¹ B and W⁻¹ B). The factor
// keeps its own node order: when the set changes by a few nodes it is updated instead of recomputed (a removed
// node: rank-3 update of the trailing block; added nodes: appended block), O(n²) instead of O(n³).
template <class T>
struct Factor {
    using Mat = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>;
    using Vec = Eigen::Matrix<T, Eigen::Dynamic, 1>;
    std::vector<std::int64_t> key;  // n_groups, then column and group per node, in the order of the list
    std::vector<int> cols;          // 3n columns in the order of the list
    std::vector<int> node_col;      // per factor position: the node's first column
    std::vector<int> order;         // per factor position: the node's index in the list
    Mat L;                          // lower Cholesky factor of W_CC in factor order
    int updates = 0;                // nodes added or removed since the last full factorisation
    Mat WinvB;                      // 3n × 3G, factor order
    Eigen::LLT<Mat> schur;          // 3G × 3G
    bool valid = false;

    Vec solve(const Vec& b) const {
        Vec x = L.template triangularView<Eigen::Lower>().solve(b);
        L.template triangularView<Eigen::Lower>().transpose().solveInPlace(x);
        return x;
    }
    Mat solve(const Mat& b) const {
        Mat x = L.template triangularView<Eigen::Lower>().solve(b);
        L.template triangularView<Eigen::Lower>().transpose().solveInPlace(x);
        return x;
    }
};

// L L^T + w w^T on a lower factor, in place (Givens-like sweep; stable: it only adds).
template <class Mat, class Vec>
void rank1_update(Eigen::Block<Mat> L, Vec w) {
    using T = typename Mat::Scalar;
    const Eigen::Index m = L.rows();
    for (Eigen::Index k = 0; k < m; ++k) {
        const T lkk = L(k, k), wk = w[k];
        const T r = std::sqrt(lkk * lkk + wk * wk);
        const T c = r / lkk, sn = wk / lkk;
        L(k, k) = r;
        if (k + 1 < m) {
            auto lk = L.col(k).tail(m - k - 1);
            auto wt = w.tail(m - k - 1);
            lk = (lk + sn * wt) / c;
            wt = c * wt - sn * lk;
        }
    }
}

}  // namespace

struct ContactSolver::Impl {
    /// Nodes added or removed by updates before the factor is recomputed from scratch anyway (a backstop: the
    /// residual check of every solve recomputes it when it drifts).
    static constexpr int MAX_UPDATES = 4096;
    const SimModel& model;
    int threads = 2;  // of the SMVM
    Factor<float> ff[2];
    Factor<double> fd[2];
    // Last forces, for deformation(): columns and values.
    std::vector<int> last_cols;
    Eigen::VectorXd last_f;

    explicit Impl(const SimModel& m) : model(m) {}

    template <class T>
    const Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>& W() const {
        if constexpr (std::is_same_v<T, float>) {
            return model.Wf;
        } else {
            return model.Wd;
        }
    }

    template <class T>
    T w_at(int i, int j) const {
        const auto& Wm = W<T>();
        return Wm.data()[static_cast<Eigen::Index>(j) * Wm.rows() + i];
    }

    template <class T>
    [[noreturn]] void not_positive_definite(Eigen::Index n3) const {
        throw NumericalError("contact solve: W_CC (" + std::to_string(n3) + " DOFs) is not positive definite in " +
                             (std::is_same_v<T, float> ? std::string("float32") : std::string("float64")) +
                             " (a node prescribed twice, or a fixed node?)");
    }

    // L of W_CC for fac.node_col, from scratch.
    template <class T>
    void full_factor(Factor<T>& fac) const {
        const Eigen::Index n3 = 3 * static_cast<Eigen::Index>(fac.node_col.size());
        typename Factor<T>::Mat Wcc(n3, n3);
        for (Eigen::Index j = 0; j < n3; ++j)
            for (Eigen::Index i = 0; i < n3; ++i)
                Wcc(i, j) = w_at<T>(fac.node_col[static_cast<size_t>(i / 3)] + static_cast<int>(i % 3),
                                    fac.node_col[static_cast<size_t>(j / 3)] + static_cast<int>(j % 3));
        Eigen::LLT<typename Factor<T>::Mat> llt(Wcc);
        if (llt.info() != Eigen::Success) not_positive_definite<T>(n3);
        fac.L = llt.matrixL();
        fac.updates = 0;
    }

    // Removes the nodes at factor positions `gone` (ascending): for each, L33' L33'ᵀ = L33 L33ᵀ + L32 L32ᵀ on the
    // block after it (in place, later removed nodes included), then one compaction drops their rows and columns.
    template <class T>
    void remove_nodes(Factor<T>& fac, const std::vector<Eigen::Index>& gone) const {
        using Mat = typename Factor<T>::Mat;
        if (gone.empty()) return;
        Mat& L = fac.L;
        const Eigen::Index n3 = L.rows();
        for (Eigen::Index k : gone) {
            const Eigen::Index a = 3 * k, m = n3 - a - 3;
            for (int c = 0; c < 3 && m > 0; ++c) {
                typename Factor<T>::Vec w = L.col(a + c).tail(m);
                rank1_update<Mat>(L.block(a + 3, a + 3, m, m), w);
            }
        }
        std::vector<char> dead(fac.node_col.size(), 0);
        for (Eigen::Index k : gone) dead[static_cast<size_t>(k)] = 1;
        std::vector<Eigen::Index> keep;
        std::vector<int> cols;
        for (size_t k = 0; k < dead.size(); ++k) {
            if (dead[k]) continue;
            for (int c = 0; c < 3; ++c) keep.push_back(3 * static_cast<Eigen::Index>(k) + c);
            cols.push_back(fac.node_col[k]);
        }
        const auto m = static_cast<Eigen::Index>(keep.size());
        Mat Lk = Mat::Zero(m, m);
        for (Eigen::Index j = 0; j < m; ++j)
            for (Eigen::Index i = j; i < m; ++i) Lk(i, j) = L(keep[static_cast<size_t>(i)], keep[static_cast<size_t>(j)]);
        L.swap(Lk);
        fac.node_col = std::move(cols);
    }

    // Appends nodes (first columns `add`): L21 = (L11⁻¹ W_12)ᵀ, L22 = chol(W_22 − L21 L21ᵀ).
    template <class T>
    bool append_nodes(Factor<T>& fac, const std::vector<int>& add) const {
        using Mat = typename Factor<T>::Mat;
        const Eigen::Index n3 = fac.L.rows(), k3 = 3 * static_cast<Eigen::Index>(add.size());
        auto col_of = [&](Eigen::Index i) {
            return i < n3 ? fac.node_col[static_cast<size_t>(i / 3)] + static_cast<int>(i % 3)
                          : add[static_cast<size_t>((i - n3) / 3)] + static_cast<int>((i - n3) % 3);
        };
        Mat B(n3, k3), D(k3, k3);
        for (Eigen::Index j = 0; j < k3; ++j) {
            for (Eigen::Index i = 0; i < n3; ++i) B(i, j) = w_at<T>(col_of(i), col_of(n3 + j));
            for (Eigen::Index i = 0; i < k3; ++i) D(i, j) = w_at<T>(col_of(n3 + i), col_of(n3 + j));
        }
        if (n3 > 0) fac.L.template triangularView<Eigen::Lower>().solveInPlace(B);  // B = L11⁻¹ W_12
        Eigen::LLT<Mat> llt(D - B.transpose() * B);
        if (llt.info() != Eigen::Success) return false;
        fac.L.conservativeResize(n3 + k3, n3 + k3);
        fac.L.topRightCorner(n3, k3).setZero();
        fac.L.bottomLeftCorner(k3, n3) = B.transpose();
        fac.L.bottomRightCorner(k3, k3) = llt.matrixL();
        fac.node_col.insert(fac.node_col.end(), add.begin(), add.end());
        return true;
    }

    // Makes `fac` the factor of the listed nodes (restricted by `take`). Returns whether the factor changed;
    // *updated says it was updated rather than recomputed.
    template <class T>
    bool prepare(bool* updated, Factor<T>& fac, const std::vector<Prescribed>& p, const std::vector<int>& take, int n_groups) {
        std::vector<std::int64_t> key;
        key.reserve(take.size() * 2 + 1);
        key.push_back(n_groups);
        for (int i : take) {
            key.push_back(p[static_cast<size_t>(i)].cols[0]);
            key.push_back(p[static_cast<size_t>(i)].group);
        }
        if (fac.valid && key == fac.key) return false;
        const Eigen::Index n3 = 3 * static_cast<Eigen::Index>(take.size());
        std::vector<int> cols(static_cast<size_t>(n3));
        for (size_t k = 0; k < take.size(); ++k)
            for (int a = 0; a < 3; ++a) {
                const int c = p[static_cast<size_t>(take[k])].cols[a];
                if (c < 0 || c >= model.n_active) {
                    throw InputError("contact solve: column " + std::to_string(c) + " outside the loaded working region (" +
                                     std::to_string(model.n_active) + " columns)");
                }
                if (a > 0 && c != cols[3 * k] + a) {
                    throw InputError("contact solve: a node's columns must be consecutive (x, y, z), got " +
                                     std::to_string(cols[3 * k]) + ", " + std::to_string(c));
                }
                cols[3 * k + static_cast<size_t>(a)] = c;
            }
        // Update or recompute the factor: update when a few nodes came or went since a full factorisation.
        std::map<int, int> wanted;  // first column -> index in take
        for (size_t k = 0; k < take.size(); ++k) wanted[cols[3 * k]] = static_cast<int>(k);
        bool done = false;
        if (fac.valid) {
            std::vector<Eigen::Index> gone;
            std::map<int, int> have;
            for (size_t k = 0; k < fac.node_col.size(); ++k) {
                have[fac.node_col[k]] = static_cast<int>(k);
                if (!wanted.count(fac.node_col[k])) gone.push_back(static_cast<Eigen::Index>(k));
            }
            std::vector<int> add;
            for (const auto& [c, k] : wanted)
                if (!have.count(c)) add.push_back(c);
            const size_t changes = gone.size() + add.size();
            // Time estimates: from scratch, gather and (3n)³/3 flops at level-3 speed; update: three rank-1
            // updates of the trailing block per removed node (level-2 speed), the appended block, one compaction.
            const double n_new = 3.0 * static_cast<double>(take.size()), kept = n_new - 3.0 * static_cast<double>(add.size());
            const double k3 = 3.0 * static_cast<double>(add.size());
            double update_flops = 4.0 * (kept * kept * k3 + k3 * k3 * kept + k3 * k3 * k3 / 3.0) + 2.0 * kept * kept;
            for (Eigen::Index g : gone) {
                const double m = 3.0 * static_cast<double>(fac.node_col.size() - static_cast<size_t>(g) - 1);
                update_flops += 4.0 * 4.5 * m * m;  // level 2: about 4 times slower per flop
            }
            if (update_flops <= n_new * n_new * n_new / 3.0 + 4.0 * n_new * n_new &&
                fac.updates + static_cast<int>(changes) <= MAX_UPDATES) {
                remove_nodes(fac, gone);
                done = add.empty() || append_nodes(fac, add);
                if (done) fac.updates += static_cast<int>(changes);
            }
        }
        fac.valid = false;
        if (updated) *updated = done;
        if (!done) {
            fac.node_col.clear();
            for (size_t k = 0; k < take.size(); ++k) fac.node_col.push_back(cols[3 * k]);
            full_factor(fac);
        }
        fac.key = std::move(key);
        fac.cols = std::move(cols);
        fac.order.resize(fac.node_col.size());
        for (size_t k = 0; k < fac.node_col.size(); ++k) fac.order[k] = wanted.at(fac.node_col[k]);
        if (n_groups > 0) {
            typename Factor<T>::Mat B = Factor<T>::Mat::Zero(n3, 3 * n_groups);
            for (size_t k = 0; k < fac.order.size(); ++k) {
                const int g = p[static_cast<size_t>(take[static_cast<size_t>(fac.order[k])])].group;
                if (g >= 0)
                    for (int a = 0; a < 3; ++a) B(3 * static_cast<Eigen::Index>(k) + a, 3 * g + a) = T(1);
            }
            fac.WinvB = fac.solve(B);
            typename Factor<T>::Mat S = B.transpose() * fac.WinvB;
            fac.schur.compute(S);
            if (fac.schur.info() != Eigen::Success) {
                throw NumericalError("contact solve: a deposited clip holds no node (singular group system)");
            }
        }
        fac.valid = true;
        return true;
    }

    // f for the nodes `take` with right-hand side u (relative to groups), groups free (exact) or absent. u and f
    // are in the order of the list; the factor works in its own order.
    template <class T>
    Eigen::Matrix<T, Eigen::Dynamic, 1> forces(const Factor<T>& fac, const Eigen::Matrix<T, Eigen::Dynamic, 1>& u_list,
                                                int n_groups, std::vector<Eigen::Vector3d>* shift) const {
        using Vec = Eigen::Matrix<T, Eigen::Dynamic, 1>;
        Vec u(u_list.size());
        for (size_t k = 0; k < fac.order.size(); ++k)
            u.template segment<3>(3 * static_cast<Eigen::Index>(k)) = u_list.template segment<3>(3 * static_cast<Eigen::Index>(fac.order[k]));
        Vec f = fac.solve(u);
        if (n_groups > 0) {
            // W f = u + B r, Bᵀ f = 0  →  r = −S⁻¹ Bᵀ W⁻¹ u, f = W⁻¹ u + W⁻¹ B r.
            const Vec r = -fac.schur.solve(fac.WinvB.transpose() * u);
            f += fac.WinvB * r;
            if (shift) {
                shift->assign(static_cast<size_t>(n_groups), Eigen::Vector3d::Zero());
                for (int g = 0; g < n_groups; ++g)
                    (*shift)[static_cast<size_t>(g)] = r.template segment<3>(3 * g).template cast<double>();
            }
        }
        Vec f_list(f.size());
        for (size_t k = 0; k < fac.order.size(); ++k)
            f_list.template segment<3>(3 * static_cast<Eigen::Index>(fac.order[k])) = f.template segment<3>(3 * static_cast<Eigen::Index>(k));
        return f_list;
    }

    // d = Σ_j W(:, col_j) f_j on the rows of `ranges` (sorted, disjoint [first, last) pairs); the vector runs
    // from row 0 to the last range's end, zero outside the ranges. Memory-bound: with `threads` > 1 and enough
    // work the rows are split between threads at 16-row boundaries (each row's sum is the same either way).
    template <class T>
    Eigen::VectorXd smvm(const std::vector<int>& cols, const Eigen::Matrix<T, Eigen::Dynamic, 1>& f, const RowRanges& ranges) const {
        const auto& Wm = W<T>();
        const Eigen::Index n = ranges.empty() ? 0 : ranges.back().second;
        Eigen::Matrix<T, Eigen::Dynamic, 1> d = Eigen::Matrix<T, Eigen::Dynamic, 1>::Zero(n);
        Eigen::Index total = 0;
        for (const auto& [a, b] : ranges) total += b - a;
        std::vector<RowRanges> parts(1, ranges);
        const int nt = total * static_cast<Eigen::Index>(cols.size()) >= 200000 ? std::max(1, threads) : 1;
        if (nt > 1) {  // split the rows into nt parts of about equal size
            parts.assign(static_cast<size_t>(nt), {});
            const Eigen::Index share = (total + nt - 1) / nt;
            Eigen::Index filled = 0;
            size_t t = 0;
            for (auto [a, b] : ranges) {
                while (a < b) {
                    Eigen::Index take = std::min(b - a, share - filled);
                    if (a + take < b && t + 1 < parts.size()) take = std::max<Eigen::Index>(16, (a + take) / 16 * 16 - a);
                    take = std::min(take, b - a);
                    parts[t].emplace_back(a, a + take);
                    filled += take;
                    a += take;
                    if (filled >= share && t + 1 < parts.size()) {
                        ++t;
                        filled = 0;
                    }
                }
            }
        }
#pragma omp parallel for num_threads(nt) schedule(static, 1) if (nt > 1)
        for (int t = 0; t < static_cast<int>(parts.size()); ++t) {
            for (size_t j = 0; j < cols.size(); ++j) {
                const T fj = f[static_cast<Eigen::Index>(j)];
                if (fj == T(0)) continue;
                const auto col = Wm.col(cols[j]);
                for (const auto& [a, b] : parts[static_cast<size_t>(t)]) d.segment(a, b - a).noalias() += fj * col.segment(a, b - a);
            }
        }
        return d.template cast<double>();
    }

    template <class T>
    SolveResult run(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, const RowRanges& rows, bool retried = false) {
        using Vec = Eigen::Matrix<T, Eigen::Dynamic, 1>;
        SolveResult res;
        Factor<T>* facs = nullptr;
        if constexpr (std::is_same_v<T, float>) {
            facs = ff;
        } else {
            facs = fd;
        }
        std::vector<int> all(p.size()), free_only;
        for (size_t i = 0; i < p.size(); ++i) {
            all[i] = static_cast<int>(i);
            if (p[i].group < 0) free_only.push_back(static_cast<int>(i));
            if (p[i].group >= n_groups) {
                throw InputError("contact solve: node group " + std::to_string(p[i].group) + " but " +
                                 std::to_string(n_groups) + " groups");
            }
        }
        auto rhs = [&](const std::vector<int>& take, const std::vector<Eigen::Vector3d>* add) {
            Vec u(3 * static_cast<Eigen::Index>(take.size()));
            for (size_t k = 0; k < take.size(); ++k) {
                const Prescribed& q = p[static_cast<size_t>(take[k])];
                Eigen::Vector3d v = q.u;
                if (add && q.group >= 0) v += (*add)[static_cast<size_t>(q.group)];
                u.template segment<3>(3 * static_cast<Eigen::Index>(k)) = v.cast<T>();
            }
            return u;
        };
        res.group_shift.assign(static_cast<size_t>(n_groups), Eigen::Vector3d::Zero());
        const bool two = method == GroupMethod::TWO_SOLVE && n_groups > 0;
        Factor<T>& fac = facs[0];
        Vec f;
        Stopwatch t0;
        if (!two) {
            res.refactored = prepare(&res.factor_updated, fac, p, all, n_groups);
            res.factor_s = t0.seconds();
            t0 = Stopwatch();
            f = forces(fac, rhs(all, nullptr), n_groups, &res.group_shift);
        } else {
            // Solve 1 without the deposited clips; their nodes' mean displacement shifts each clip.
            Factor<T>& fac1 = facs[1];
            bool r1 = false;
            Vec f1;
            if (!free_only.empty()) {
                r1 = prepare(nullptr, fac1, p, free_only, 0);
                f1 = forces(fac1, rhs(free_only, nullptr), 0, nullptr);
            }
            std::vector<int> count(static_cast<size_t>(n_groups), 0);
            const auto& Wm = W<T>();
            for (const Prescribed& q : p) {
                if (q.group < 0) continue;
                ++count[static_cast<size_t>(q.group)];
                for (int a = 0; a < 3; ++a) {
                    double da = 0;
                    for (size_t k = 0; k < free_only.size(); ++k)
                        for (int b = 0; b < 3; ++b)
                            da += static_cast<double>(Wm(q.cols[a], p[static_cast<size_t>(free_only[k])].cols[b])) *
                                  static_cast<double>(f1[3 * static_cast<Eigen::Index>(k) + b]);
                    res.group_shift[static_cast<size_t>(q.group)][a] += da;
                }
            }
            for (int g = 0; g < n_groups; ++g)
                if (count[static_cast<size_t>(g)]) res.group_shift[static_cast<size_t>(g)] /= count[static_cast<size_t>(g)];
            const bool r2 = prepare(&res.factor_updated, fac, p, all, 0);
            res.refactored = r1 || r2;
            res.factor_s = t0.seconds();
            t0 = Stopwatch();
            f = forces(fac, rhs(all, &res.group_shift), 0, nullptr);
        }
        res.solve_s = t0.seconds();
        t0 = Stopwatch();
        last_cols = fac.cols;
        last_f = f.template cast<double>();
        res.f = last_f;
        res.d = smvm<T>(fac.cols, f, rows);
        res.smvm_s = t0.seconds();
        // The prescribed rows of d must reproduce u (W_CC f = u): a free residual check when they were computed.
        // An updated factor that drifted past the tolerance is recomputed and the frame solved again.
        double r_max = 0, u_max = 0;
        bool all_in = true;
        for (size_t i = 0; i < p.size() && all_in; ++i) {
            const Prescribed& q = p[i];
            Eigen::Vector3d u = q.u;
            if (q.group >= 0) u += res.group_shift[static_cast<size_t>(q.group)];
            for (int a = 0; a < 3; ++a) {
                const Eigen::Index row = q.cols[a];
                const auto it = std::upper_bound(rows.begin(), rows.end(), row, [](Eigen::Index v, const auto& r) { return v < r.second; });
                if (it == rows.end() || row < it->first) {
                    all_in = false;
                    break;
                }
                r_max = std::max(r_max, std::abs(res.d[row] - u[a]));
                u_max = std::max(u_max, std::abs(u[a]));
            }
        }
        res.residual = all_in && u_max > 0 ? r_max / u_max : -1.0;
        const double tol = std::is_same_v<T, float> ? 1e-3 : 1e-9;
        if (res.residual > tol && !retried && fac.updates > 0) {
            fac.valid = false;  // recompute from scratch, then this frame again
            if (method == GroupMethod::TWO_SOLVE) facs[1].valid = false;
            SolveResult again = run<T>(p, n_groups, method, rows, true);
            again.factor_s += res.factor_s + res.solve_s + res.smvm_s;
            again.recomputed_for_residual = true;
            return again;
        }
        return res;
    }
};

RowRanges rows_of_vertices(const SimModel& model, const std::vector<int>& vertices) {
    std::vector<Eigen::Index> r;
    r.reserve(3 * vertices.size());
    for (int v : vertices)
        for (int ax = 0; ax < 3; ++ax) r.push_back(model.surface.row(v, ax));
    std::sort(r.begin(), r.end());
    RowRanges rows;
    for (Eigen::Index q : r) {
        const Eigen::Index a = q / 16 * 16, b = std::min<Eigen::Index>(a + 16, model.n_active);
        if (!rows.empty() && a <= rows.back().second) {
            rows.back().second = std::max(rows.back().second, b);
        } else {
            rows.emplace_back(a, b);
        }
    }
    return rows;
}

ContactSolver::ContactSolver(const SimModel& model) : m_impl(std::make_unique<Impl>(model)) {}
ContactSolver::~ContactSolver() = default;

void ContactSolver::set_threads(int n) { m_impl->threads = std::max(1, n); }

double ContactSolver::condition_estimate() const {
    auto est = [&](const auto& fac, const auto& Wm) -> double {
        using Fac = std::decay_t<decltype(fac)>;
        using Vec = typename Fac::Vec;
        const Eigen::Index n = fac.L.rows();
        if (!fac.valid || n == 0) return 1.0;
        // ‖W_CC‖₁ from W itself (the factor is in its own node order; the norm does not depend on it).
        double norm = 0;
        for (Eigen::Index j = 0; j < n; ++j) {
            const int cj = fac.node_col[static_cast<size_t>(j / 3)] + static_cast<int>(j % 3);
            double col = 0;
            for (Eigen::Index i = 0; i < n; ++i) {
                const int ci = fac.node_col[static_cast<size_t>(i / 3)] + static_cast<int>(i % 3);
                col += std::abs(static_cast<double>(Wm.data()[static_cast<Eigen::Index>(cj) * Wm.rows() + ci]));
            }
            norm = std::max(norm, col);
        }
        // ‖W_CC⁻¹‖₁ by Hager's estimator (W_CC⁻¹ is symmetric: its transpose solve is the same solve).
        Vec x = Vec::Constant(n, typename Vec::Scalar(1.0 / static_cast<double>(n)));
        double inv = 0;
        for (int it = 0; it < 5; ++it) {
            const Vec y = fac.solve(x);
            inv = static_cast<double>(y.cwiseAbs().sum());
            Vec xi = y.unaryExpr([](auto v) { return v >= 0 ? decltype(v)(1) : decltype(v)(-1); });
            const Vec z = fac.solve(xi);
            Eigen::Index jmax = 0;
            const double zmax = static_cast<double>(z.cwiseAbs().maxCoeff(&jmax));
            if (zmax <= static_cast<double>(z.dot(x))) break;
            x.setZero();
            x[jmax] = 1;
        }
        return norm * inv;
    };
    if (m_impl->model.is_float()) return est(m_impl->ff[0], m_impl->model.Wf);
    return est(m_impl->fd[0], m_impl->model.Wd);
}

SolveResult ContactSolver::solve(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, Eigen::Index rows) {
    const Eigen::Index M = m_impl->model.dof_node.size();
    if (rows < 0 || rows > M) rows = M;
    return solve(p, n_groups, method, RowRanges{{0, rows}});
}

SolveResult ContactSolver::solve(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, const RowRanges& rows) {
    const Eigen::Index M = m_impl->model.dof_node.size();
    Eigen::Index end = 0;
    for (const auto& [a, b] : rows) {
        if (a < end || b < a || b > M) {
            throw InputError("contact solve: row ranges must be sorted, disjoint and within 0.." + std::to_string(M));
        }
        end = b;
    }
    if (p.empty()) {
        SolveResult r;
        r.d = Eigen::VectorXd::Zero(end);
        r.group_shift.assign(static_cast<size_t>(n_groups), Eigen::Vector3d::Zero());
        m_impl->last_cols.clear();
        m_impl->last_f.resize(0);
        return r;
    }
    if (m_impl->model.is_float()) return m_impl->run<float>(p, n_groups, method, rows);
    return m_impl->run<double>(p, n_groups, method, rows);
}

Eigen::VectorXd ContactSolver::deformation(const RowRanges& rows) const {
    if (m_impl->last_cols.empty()) return Eigen::VectorXd::Zero(rows.empty() ? 0 : rows.back().second);
    if (m_impl->model.is_float()) return m_impl->smvm<float>(m_impl->last_cols, m_impl->last_f.cast<float>(), rows);
    return m_impl->smvm<double>(m_impl->last_cols, m_impl->last_f, rows);
}

Eigen::VectorXd ContactSolver::deformation(Eigen::Index first, Eigen::Index last) const {
    if (m_impl->model.is_float()) {
        return m_impl->smvm<float>(m_impl->last_cols, m_impl->last_f.cast<float>(), {{first, last}}).tail(last - first);
    }
    return m_impl->smvm<double>(m_impl->last_cols, m_impl->last_f, {{first, last}}).tail(last - first);
}

}  // namespace aneu::sim
