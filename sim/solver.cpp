// SPDX-License-Identifier: MIT
#include "aneu/sim/solver.hpp"

#include <algorithm>
#include <chrono>
#include <string>

#include <Eigen/Cholesky>

#include "aneu/core/error.hpp"

namespace aneu::sim {
namespace {

double since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// A factored W_CC for one node set (plus, for groups, the Schur complement S = Bᵀ W⁻¹ B and W⁻¹ B).
template <class T>
struct Factor {
    using Mat = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>;
    std::vector<std::int64_t> key;  // column, group per node
    std::vector<int> cols;          // 3n columns
    Eigen::LLT<Mat> llt;
    Mat WinvB;                      // 3n × 3G
    Eigen::LLT<Mat> schur;          // 3G × 3G
    bool valid = false;
};

}  // namespace

struct ContactSolver::Impl {
    const SimModel& model;
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

    // Makes `fac` the factor of the listed nodes (restricted by `take`), refactoring when the key changed.
    template <class T>
    bool prepare(Factor<T>& fac, const std::vector<Prescribed>& p, const std::vector<int>& take, int n_groups) {
        std::vector<std::int64_t> key;
        key.reserve(take.size() * 2 + 1);
        key.push_back(n_groups);
        for (int i : take) {
            key.push_back(p[static_cast<size_t>(i)].cols[0]);
            key.push_back(p[static_cast<size_t>(i)].group);
        }
        if (fac.valid && key == fac.key) return false;
        fac.valid = false;
        fac.key = std::move(key);
        const Eigen::Index n3 = 3 * static_cast<Eigen::Index>(take.size());
        fac.cols.resize(static_cast<size_t>(n3));
        for (size_t k = 0; k < take.size(); ++k)
            for (int a = 0; a < 3; ++a) {
                const int c = p[static_cast<size_t>(take[k])].cols[a];
                if (c < 0 || c >= model.n_active) {
                    throw InputError("contact solve: column " + std::to_string(c) + " outside the loaded working region (" +
                                     std::to_string(model.n_active) + " columns)");
                }
                fac.cols[3 * k + static_cast<size_t>(a)] = c;
            }
        const auto& Wm = W<T>();
        typename Factor<T>::Mat Wcc(n3, n3);
        for (Eigen::Index j = 0; j < n3; ++j) {
            const T* col = Wm.data() + static_cast<Eigen::Index>(fac.cols[static_cast<size_t>(j)]) * Wm.rows();
            for (Eigen::Index i = 0; i < n3; ++i) Wcc(i, j) = col[fac.cols[static_cast<size_t>(i)]];
        }
        fac.llt.compute(Wcc);
        if (fac.llt.info() != Eigen::Success) {
            throw NumericalError("contact solve: W_CC (" + std::to_string(n3) + " DOFs) is not positive definite in " +
                                 (std::is_same_v<T, float> ? std::string("float32") : std::string("float64")) +
                                 " (a node prescribed twice, or a fixed node?)");
        }
        if (n_groups > 0) {
            typename Factor<T>::Mat B = Factor<T>::Mat::Zero(n3, 3 * n_groups);
            for (size_t k = 0; k < take.size(); ++k) {
                const int g = p[static_cast<size_t>(take[k])].group;
                if (g >= 0)
                    for (int a = 0; a < 3; ++a) B(3 * static_cast<Eigen::Index>(k) + a, 3 * g + a) = T(1);
            }
            fac.WinvB = fac.llt.solve(B);
            typename Factor<T>::Mat S = B.transpose() * fac.WinvB;
            fac.schur.compute(S);
            if (fac.schur.info() != Eigen::Success) {
                throw NumericalError("contact solve: a deposited clip holds no node (singular group system)");
            }
        }
        fac.valid = true;
        return true;
    }

    // f for the nodes `take` with right-hand side u (relative to groups), groups free (exact) or absent.
    template <class T>
    Eigen::Matrix<T, Eigen::Dynamic, 1> forces(const Factor<T>& fac, const Eigen::Matrix<T, Eigen::Dynamic, 1>& u,
                                                int n_groups, std::vector<Eigen::Vector3d>* shift) const {
        using Vec = Eigen::Matrix<T, Eigen::Dynamic, 1>;
        Vec f = fac.llt.solve(u);
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
        return f;
    }

    // d = Σ_j W(:, col_j) f_j on the rows of `ranges` (sorted, disjoint [first, last) pairs); the vector runs
    // from row 0 to the last range's end, zero outside the ranges.
    template <class T>
    Eigen::VectorXd smvm(const std::vector<int>& cols, const Eigen::Matrix<T, Eigen::Dynamic, 1>& f, const RowRanges& ranges) const {
        const auto& Wm = W<T>();
        const Eigen::Index n = ranges.empty() ? 0 : ranges.back().second;
        Eigen::Matrix<T, Eigen::Dynamic, 1> d = Eigen::Matrix<T, Eigen::Dynamic, 1>::Zero(n);
        for (size_t j = 0; j < cols.size(); ++j) {
            const T fj = f[static_cast<Eigen::Index>(j)];
            if (fj == T(0)) continue;
            const auto col = Wm.col(cols[j]);
            for (const auto& [a, b] : ranges) d.segment(a, b - a).noalias() += fj * col.segment(a, b - a);
        }
        return d.template cast<double>();
    }

    template <class T>
    SolveResult run(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, const RowRanges& rows) {
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
        auto t0 = std::chrono::steady_clock::now();
        if (!two) {
            res.refactored = prepare(fac, p, all, n_groups);
            res.factor_s = since(t0);
            t0 = std::chrono::steady_clock::now();
            f = forces(fac, rhs(all, nullptr), n_groups, &res.group_shift);
        } else {
            // Solve 1 without the deposited clips; their nodes' mean displacement shifts each clip.
            Factor<T>& fac1 = facs[1];
            bool r1 = false;
            Vec f1;
            if (!free_only.empty()) {
                r1 = prepare(fac1, p, free_only, 0);
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
            const bool r2 = prepare(fac, p, all, 0);
            res.refactored = r1 || r2;
            res.factor_s = since(t0);
            t0 = std::chrono::steady_clock::now();
            f = forces(fac, rhs(all, &res.group_shift), 0, nullptr);
        }
        res.solve_s = since(t0);
        t0 = std::chrono::steady_clock::now();
        last_cols = fac.cols;
        last_f = f.template cast<double>();
        res.f = last_f;
        res.d = smvm<T>(fac.cols, f, rows);
        res.smvm_s = since(t0);
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
