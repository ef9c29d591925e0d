// SPDX-License-Identifier: MIT
#include "aneu/fem/hyperelastic.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/element.hpp"
#include "merged_pattern.hpp"

namespace aneu::fem {

namespace {

using Mat3 = Eigen::Matrix3d;

/// A symmetric matrix's upper triangle (CSC) as a Matrix Market file, written under path + ".part" and renamed.
void write_upper_market(const Eigen::SparseMatrix<double>& U, const std::string& path) {
    const std::string part = path + ".part";
    FILE* f = std::fopen(part.c_str(), "w");
    if (!f) throw IoError("cannot write the free tangent to " + part);
    std::fprintf(f, "%%%%MatrixMarket matrix coordinate real symmetric\n%ld %ld %ld\n", static_cast<long>(U.rows()), static_cast<long>(U.cols()),
                 static_cast<long>(U.nonZeros()));
    for (Eigen::Index c = 0; c < U.outerSize(); ++c)  // (row, column) of the lower triangle, as the format wants
        for (Eigen::SparseMatrix<double>::InnerIterator it(U, c); it; ++it)
            std::fprintf(f, "%ld %ld %.17g\n", static_cast<long>(c) + 1, static_cast<long>(it.row()) + 1, it.value());
    const bool ok = std::fclose(f) == 0;
    if (!ok || std::rename(part.c_str(), path.c_str()) != 0) {
        std::remove(part.c_str());
        throw IoError("cannot write the free tangent to " + path);
    }
}

/// Quantities of one integration point at deformation gradient F.
struct PointState {
    double J = 1, logJ = 0;
    Mat3 Finv = Mat3::Identity();
};

bool point_state(const Mat3& F, PointState& s) {
    s.J = F.determinant();
    if (!(s.J > 0.0)) return false;
    s.logJ = std::log(s.J);
    s.Finv = F.inverse();
    return true;
}

/// Ψ from the displacement gradient H = F − I, without the cancellations of the textbook form (½|F|² − 3/2 and
/// ln J computed from H directly), so that energy differences near equilibrium stay above rounding and the line
/// search can see them. Returns false if inverted.
bool energy_density(const Mat3& H, double mu, double lambda, double& psi) {
    const double tr = H.trace();
    const double Jm1 = tr + 0.5 * (tr * tr - (H * H).trace()) + H.determinant();  // det(I + H) − 1, exactly
    if (!(Jm1 > -1.0)) return false;
    const double logJ = std::log1p(Jm1);
    psi = mu * (tr + 0.5 * H.squaredNorm() - logJ) + 0.5 * lambda * logJ * logJ;
    return true;
}

/// First Piola–Kirchhoff stress.
Mat3 piola(const Mat3& F, const PointState& s, double mu, double lambda) {
    const Mat3 FinvT = s.Finv.transpose();
    return mu * (F - FinvT) + lambda * s.logJ * FinvT;
}

/// The first inverted element a parallel loop meets, reported after the loop.
struct FirstInverted {
    Eigen::Index element = -1;
    double J = 0;
    void note(Eigen::Index e, double j) {
#pragma omp critical(aneu_first_inverted)
        if (element < 0) {
            element = e;
            J = j;
        }
    }
    void raise_if_any(const char* what) const {
        if (element >= 0)
            throw NumericalError(std::string(what) + ": element " + std::to_string(element) + " is inverted (det F = " +
                                 std::to_string(J) + " at an integration point)");
    }
};

}  // namespace

template <int NN>
void NeoHookeanSolid::init(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T) {
    const Eigen::Index ne = T.rows();
    points_per_element_ = NN == 4 ? 1 : 4;
    w_.resize(static_cast<size_t>(ne * points_per_element_));
    dN_.resize(static_cast<size_t>(ne * points_per_element_ * NN * 3));
    std::string failure;
#pragma omp parallel for schedule(static)
    for (Eigen::Index e = 0; e < ne; ++e) {
        Eigen::Matrix<double, NN, 3> X;
        for (int a = 0; a < NN; ++a) X.row(a) = V.row(T(e, a));
        for (int q = 0; q < points_per_element_; ++q) {
            Eigen::Matrix<double, NN, 3> dNdxi;
            double weight = 1.0 / 6.0;
            if constexpr (NN == 4) {
                dNdxi << -1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1;
            } else {
                const auto& pt = QUADRATIC_TET_RULE_POINTS[q];
                dNdxi = quadratic_tet_shape_gradients(Eigen::Vector3d(pt[0], pt[1], pt[2]));
                weight = QUADRATIC_TET_RULE_WEIGHT;
            }
            const Mat3 J0 = X.transpose() * dNdxi;
            const double det = J0.determinant();
            if (!(det > 0.0)) {
#pragma omp critical
                if (failure.empty()) failure = "element " + std::to_string(e) + " has reference Jacobian " + std::to_string(det);
                continue;
            }
            const Eigen::Matrix<double, NN, 3> dNdX = dNdxi * J0.inverse();
            const auto k = static_cast<size_t>(e * points_per_element_ + q);
            w_[k] = weight * det;
            for (int a = 0; a < NN; ++a)
                for (int j = 0; j < 3; ++j) dN_[(k * NN + static_cast<size_t>(a)) * 3 + static_cast<size_t>(j)] = dNdX(a, j);
        }
    }
    if (!failure.empty()) throw MeshingError("neo-Hookean solid: " + failure + " (inverted or degenerate)");
}

NeoHookeanSolid::NeoHookeanSolid(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& region,
                                 const std::vector<Material>& materials)
    : n_nodes_(V.rows()), nn_(static_cast<int>(T.cols())), T_(T) {
    if (nn_ != 4 && nn_ != 10) throw InputError("neo-Hookean solid: elements have " + std::to_string(nn_) + " nodes, expected 4 or 10");
    if (region.size() != T.rows()) throw InputError("neo-Hookean solid: " + std::to_string(region.size()) + " regions for " + std::to_string(T.rows()) + " elements");
    if (T.size() && (T.minCoeff() < 0 || T.maxCoeff() >= V.rows())) throw InputError("neo-Hookean solid: element node index outside the nodes");
    if (region.size() && region.minCoeff() < 0) throw InputError("neo-Hookean solid: negative region index");
    validate_materials(materials, region.size() ? region.maxCoeff() + 1 : 0);
    mu_.resize(static_cast<size_t>(T.rows()));
    lambda_.resize(static_cast<size_t>(T.rows()));
    for (Eigen::Index e = 0; e < T.rows(); ++e) {
        const Material& m = materials[static_cast<size_t>(region[e])];
        mu_[static_cast<size_t>(e)] = m.E_mpa / (2.0 * (1.0 + m.nu));
        lambda_[static_cast<size_t>(e)] = m.E_mpa * m.nu / ((1.0 + m.nu) * (1.0 - 2.0 * m.nu));
    }
    if (nn_ == 4) {
        init<4>(V, T);
    } else {
        init<10>(V, T);
    }
    // Tangent pattern from the node graph: row 3i+p holds columns 3j+q for every neighbour j of i.
    std::vector<std::vector<int>> nb(static_cast<size_t>(n_nodes_));
    for (Eigen::Index e = 0; e < T.rows(); ++e)
        for (int a = 0; a < nn_; ++a)
            for (int b = 0; b < nn_; ++b) nb[static_cast<size_t>(T(e, a))].push_back(T(e, b));
    std::vector<std::int64_t> row_start(static_cast<size_t>(3 * n_nodes_ + 1), 0);
    std::int64_t nnz = 0;
    for (Eigen::Index i = 0; i < n_nodes_; ++i) {
        auto& v = nb[static_cast<size_t>(i)];
        std::sort(v.begin(), v.end());
        v.erase(std::unique(v.begin(), v.end()), v.end());
        for (int p = 0; p < 3; ++p) {
            row_start[static_cast<size_t>(3 * i + p)] = nnz;
            nnz += 3 * static_cast<std::int64_t>(v.size());
        }
    }
    row_start.back() = nnz;
    pattern_.resize(3 * n_nodes_, 3 * n_nodes_);
    pattern_.resizeNonZeros(nnz);
    for (Eigen::Index r = 0; r <= 3 * n_nodes_; ++r) pattern_.outerIndexPtr()[r] = static_cast<int>(row_start[static_cast<size_t>(r)]);
    for (Eigen::Index i = 0; i < n_nodes_; ++i) {
        const auto& v = nb[static_cast<size_t>(i)];
        for (int p = 0; p < 3; ++p) {
            int* cols = pattern_.innerIndexPtr() + row_start[static_cast<size_t>(3 * i + p)];
            for (size_t k = 0; k < v.size(); ++k)
                for (int q = 0; q < 3; ++q) cols[3 * k + static_cast<size_t>(q)] = 3 * v[k] + q;
        }
    }
    std::fill(pattern_.valuePtr(), pattern_.valuePtr() + nnz, 0.0);
    // slot_: for element e and local nodes (a, b), the value index of entry (3T(e,a), 3T(e,b)); the entry
    // (3T(e,a)+p, 3T(e,b)+q) is at slot + p·(row length) + q (every row of a node has the same length).
    slot_.resize(static_cast<size_t>(T.rows() * nn_ * nn_));
    for (Eigen::Index e = 0; e < T.rows(); ++e)
        for (int a = 0; a < nn_; ++a) {
            const auto& v = nb[static_cast<size_t>(T(e, a))];
            for (int b = 0; b < nn_; ++b) {
                const auto pos = std::lower_bound(v.begin(), v.end(), T(e, b)) - v.begin();
                slot_[static_cast<size_t>((e * nn_ + a) * nn_ + b)] = row_start[static_cast<size_t>(3 * T(e, a))] + 3 * pos;
            }
        }
}

Eigen::Matrix3d NeoHookeanSolid::displacement_gradient(const Eigen::VectorXd& u, Eigen::Index e, const double* g) const {
    Mat3 H = Mat3::Zero();
    for (int a = 0; a < nn_; ++a) H += u.segment<3>(3 * T_(e, a)) * Eigen::RowVector3d(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
    return H;
}

double NeoHookeanSolid::energy(const Eigen::VectorXd& u) const {
    if (u.size() != dofs()) throw InputError("neo-Hookean energy: u has " + std::to_string(u.size()) + " entries, expected " + std::to_string(dofs()));
    const Eigen::Index ne = T_.rows();
    double total = 0;
    bool inverted = false;
#pragma omp parallel for schedule(static) reduction(+ : total) reduction(|| : inverted)
    for (Eigen::Index e = 0; e < ne; ++e) {
        for (int q = 0; q < points_per_element_; ++q) {
            const auto k = static_cast<size_t>(e * points_per_element_ + q);
            const double* g = dN_.data() + k * static_cast<size_t>(nn_) * 3;
            const Mat3 H = displacement_gradient(u, e, g);
            double psi = 0;
            if (!energy_density(H, mu_[static_cast<size_t>(e)], lambda_[static_cast<size_t>(e)], psi)) {
                inverted = true;
                continue;
            }
            total += w_[k] * psi;
        }
    }
    return inverted ? std::numeric_limits<double>::infinity() : total;
}

double NeoHookeanSolid::min_jacobian(const Eigen::VectorXd& u) const {
    const Eigen::Index ne = T_.rows();
    double mj = std::numeric_limits<double>::infinity();
#pragma omp parallel for schedule(static) reduction(min : mj)
    for (Eigen::Index e = 0; e < ne; ++e) {
        for (int q = 0; q < points_per_element_; ++q) {
            const auto k = static_cast<size_t>(e * points_per_element_ + q);
            const double* g = dN_.data() + k * static_cast<size_t>(nn_) * 3;
            const Mat3 F = Mat3::Identity() + displacement_gradient(u, e, g);
            mj = std::min(mj, F.determinant());
        }
    }
    return mj;
}

Eigen::VectorXd NeoHookeanSolid::internal_force(const Eigen::VectorXd& u) const {
    if (u.size() != dofs()) throw InputError("neo-Hookean force: u has " + std::to_string(u.size()) + " entries, expected " + std::to_string(dofs()));
    const Eigen::Index ne = T_.rows();
    // Element forces in parallel, gathered in element order (reproducible sums).
    Eigen::MatrixXd fe(3 * nn_, ne);
    FirstInverted inverted;
#pragma omp parallel for schedule(static)
    for (Eigen::Index e = 0; e < ne; ++e) {
        fe.col(e).setZero();
        for (int q = 0; q < points_per_element_; ++q) {
            const auto k = static_cast<size_t>(e * points_per_element_ + q);
            const double* g = dN_.data() + k * static_cast<size_t>(nn_) * 3;
            PointState s;
            const Mat3 F = Mat3::Identity() + displacement_gradient(u, e, g);
            if (!point_state(F, s)) {
                inverted.note(e, s.J);
                continue;
            }
            const Mat3 P = w_[k] * piola(F, s, mu_[static_cast<size_t>(e)], lambda_[static_cast<size_t>(e)]);
            for (int a = 0; a < nn_; ++a) fe.col(e).segment<3>(3 * a) += P * Eigen::Vector3d(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
        }
    }
    inverted.raise_if_any("neo-Hookean force");
    Eigen::VectorXd f = Eigen::VectorXd::Zero(dofs());
    for (Eigen::Index e = 0; e < ne; ++e)
        for (int a = 0; a < nn_; ++a) f.segment<3>(3 * T_(e, a)) += fe.col(e).segment<3>(3 * a);
    return f;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> NeoHookeanSolid::tangent(const Eigen::VectorXd& u, bool project) const {
    if (u.size() != dofs()) throw InputError("neo-Hookean tangent: u has " + std::to_string(u.size()) + " entries, expected " + std::to_string(dofs()));
    Eigen::SparseMatrix<double, Eigen::RowMajor> K = pattern_;
    double* val = K.valuePtr();
    const Eigen::Index ne = T_.rows();
    const int m = 3 * nn_;
    constexpr Eigen::Index CHUNK = 4096;
    Eigen::MatrixXd Ke(m, m * std::min(CHUNK, std::max<Eigen::Index>(ne, 1)));
    FirstInverted inverted;
    for (Eigen::Index e0 = 0; e0 < ne; e0 += CHUNK) {
        const Eigen::Index e1 = std::min(ne, e0 + CHUNK);
#pragma omp parallel for schedule(static)
        for (Eigen::Index e = e0; e < e1; ++e) {
            auto Kb = Ke.middleCols(m * (e - e0), m);
            Kb.setZero();
            const double mu = mu_[static_cast<size_t>(e)], lambda = lambda_[static_cast<size_t>(e)];
            for (int q = 0; q < points_per_element_; ++q) {
                const auto k = static_cast<size_t>(e * points_per_element_ + q);
                const double* g = dN_.data() + k * static_cast<size_t>(nn_) * 3;
                PointState s;
                if (!point_state(Mat3::Identity() + displacement_gradient(u, e, g), s)) {
                    inverted.note(e, s.J);
                    continue;
                }
                // A_iJkL = μ δik δJL + (μ − λ ln J) F⁻¹_Li F⁻¹_Jk + λ F⁻¹_Ji F⁻¹_Lk, contracted with ∇₀N_a (J) and
                // ∇₀N_b (L): with G = ∇₀N and the spatial gradients g = F⁻ᵀ G,
                // K_ab(i,k) = w [μ (G_a·G_b) δik + (μ − λ ln J) g_b,i g_a,k + λ g_a,i g_b,k].
                const double w = w_[k], c2 = mu - lambda * s.logJ;
                Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, 10> G(3, nn_), gs(3, nn_);
                for (int a = 0; a < nn_; ++a) G.col(a) = Eigen::Vector3d(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
                gs.noalias() = s.Finv.transpose() * G;
                for (int a = 0; a < nn_; ++a)
                    for (int b = a; b < nn_; ++b) {
                        Mat3 Kab = (w * c2) * gs.col(b) * gs.col(a).transpose() + (w * lambda) * gs.col(a) * gs.col(b).transpose();
                        Kab.diagonal().array() += w * mu * G.col(a).dot(G.col(b));
                        Kb.block<3, 3>(3 * a, 3 * b) += Kab;
                    }
            }
            for (int a = 0; a < nn_; ++a)
                for (int b = 0; b < a; ++b) Kb.block<3, 3>(3 * a, 3 * b) = Kb.block<3, 3>(3 * b, 3 * a).transpose();
            if (project) {
                // Projected Newton (Teran et al. 2005): the element's tangent with its negative eigenvalues set to
                // zero, so the sum is positive semidefinite and every Newton step goes downhill in energy.
                Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Kb);
                const Eigen::VectorXd lam = es.eigenvalues().cwiseMax(0.0);
                Kb = es.eigenvectors() * lam.asDiagonal() * es.eigenvectors().transpose();
                for (int a = 0; a < m; ++a)
                    for (int b = 0; b < a; ++b) Kb(a, b) = Kb(b, a);
            }
        }
        inverted.raise_if_any("neo-Hookean tangent");
        for (Eigen::Index e = e0; e < e1; ++e) {
            const auto Kb = Ke.middleCols(m * (e - e0), m);
            for (int a = 0; a < nn_; ++a) {
                const int row = 3 * T_(e, a);
                const std::int64_t len = K.outerIndexPtr()[row + 1] - K.outerIndexPtr()[row];
                for (int b = 0; b < nn_; ++b) {
                    const std::int64_t s0 = slot_[static_cast<size_t>((e * nn_ + a) * nn_ + b)];
                    for (int p = 0; p < 3; ++p)
                        for (int q = 0; q < 3; ++q) val[s0 + p * len + q] += Kb(3 * a + p, 3 * b + q);
                }
            }
        }
    }
    return K;
}

struct NewtonWorkspace {
    using Index = Eigen::SparseMatrix<double, Eigen::RowMajor>::StorageIndex;
    bool valid = false;                  // analysed for the pattern below
    std::vector<Index> outer, inner;     // the body's tangent pattern it was analysed for
    std::vector<int> free_index;         // and its free DOFs (−1: fixed or prescribed)
    Eigen::SparseMatrix<double> Kff;     // the free block's upper triangle
    std::vector<std::int64_t> to_ff;     // tangent entry → Kff entry (−1: not free)
    std::vector<Eigen::Index> diag_pos;  // Kff's diagonal entries
    // The body adds its tangent straight into `acc` (ElasticBody::add_tangent): tangent entry p goes to
    // acc[where[p]]: Kff's entries first (to_ff), then the entries of free rows in constrained columns (K_fp, in
    // row order: (fp_row, fp_col)), then one slot that takes everything else (fixed rows, the free lower triangle).
    // No full tangent is made per iteration (a patch's has ~10⁷ entries, its dense exterior block: allocating and
    // copying it was a third of a frame).
    std::vector<std::int64_t> where;
    std::vector<int> fp_row, fp_col;     // free index of the row, DOF of the column
    std::vector<double> acc;
    Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Upper> llt;
    NewtonWorkspace() { llt.cholmod().print = 0; }  // a tangent that is not positive definite is expected (buckling)
};

std::shared_ptr<NewtonWorkspace> make_newton_workspace() { return std::make_shared<NewtonWorkspace>(); }

NewtonResult solve_neo_hookean(const ElasticBody& solid, const Eigen::VectorXi& fixed_dofs,
                               const std::vector<std::pair<int, double>>& prescribed, const Eigen::VectorXd& u0,
                               const NewtonOptions& opt) {
    const Eigen::Index n = solid.dofs();
    if (u0.size() != n) throw InputError("neo-Hookean solve: u0 has " + std::to_string(u0.size()) + " entries, expected " + std::to_string(n));
    std::vector<char> constrained(static_cast<size_t>(n), 0);
    for (Eigen::Index k = 0; k < fixed_dofs.size(); ++k) {
        if (fixed_dofs[k] < 0 || fixed_dofs[k] >= n) throw InputError("neo-Hookean solve: fixed DOF " + std::to_string(fixed_dofs[k]) + " outside the model");
        constrained[static_cast<size_t>(fixed_dofs[k])] = 1;
    }
    for (const auto& [dof, v] : prescribed) {
        (void)v;
        if (dof < 0 || dof >= n) throw InputError("neo-Hookean solve: prescribed DOF " + std::to_string(dof) + " outside the model");
        if (constrained[static_cast<size_t>(dof)]) throw InputError("neo-Hookean solve: DOF " + std::to_string(dof) + " is fixed or prescribed twice");
        constrained[static_cast<size_t>(dof)] = 1;
    }
    auto free_norm = [&](const Eigen::VectorXd& g) {
        double s = 0;
        for (Eigen::Index i = 0; i < n; ++i)
            if (!constrained[static_cast<size_t>(i)]) s += g[i] * g[i];
        return std::sqrt(s);
    };
    // The free block of the tangent: its pattern (upper triangle) and where each tangent entry goes, built once,
    // so that CHOLMOD orders and analyses it once per call (or once for many calls: NewtonOptions::workspace) and
    // only refactorises in the iterations. Built at the first linearised solve: a call that starts converged (a
    // simulator frame where nothing moved) needs none of it (on the sample's patch, its dense interface block makes
    // it 2.7-3.6 s).
    std::vector<int> free_index(static_cast<size_t>(n), -1);
    Eigen::Index m = 0;
    for (Eigen::Index i = 0; i < n; ++i)
        if (!constrained[static_cast<size_t>(i)]) free_index[static_cast<size_t>(i)] = static_cast<int>(m++);
    const std::shared_ptr<NewtonWorkspace> ws = opt.workspace ? opt.workspace : make_newton_workspace();
    Eigen::SparseMatrix<double>& Kff = ws->Kff;
    std::vector<std::int64_t>& to_ff = ws->to_ff;
    std::vector<Eigen::Index>& diag_pos = ws->diag_pos;
    auto& llt = ws->llt;
    NewtonResult out;
    bool analysed = false;
    auto analyse = [&] {
        const Stopwatch sw;
        const Eigen::SparseMatrix<double, Eigen::RowMajor>& P = solid.pattern();
        const auto* po = P.outerIndexPtr();
        const auto* pi = P.innerIndexPtr();
        const size_t nnz = static_cast<size_t>(P.nonZeros());
        // The last call's analysis holds when the free tangent's pattern is the same: the body's pattern and the
        // free DOFs (a compressed pattern compared entry by entry: milliseconds against seconds of analysis).
        const bool same = ws->valid && P.isCompressed() && ws->free_index == free_index && ws->outer.size() == static_cast<size_t>(P.outerSize()) + 1 &&
                          ws->inner.size() == nnz && std::equal(ws->outer.begin(), ws->outer.end(), po) && std::equal(ws->inner.begin(), ws->inner.end(), pi);
        if (same) {
            out.analysis_reused = true;
        } else {
            ws->valid = false;
            // Kff's upper triangle from the rows' entries right of the diagonal (as they are assembled; the tangent's
            // two triangles need not agree to the last bit), scattered into columns: a count, then a fill row by row
            // (ascending rows: each column's row indices come out sorted). Two linear passes, no sort.
            Kff = detail::free_upper(P, free_index, m, &to_ff);
            diag_pos.assign(static_cast<size_t>(m), 0);
            for (Eigen::Index b = 0; b < m; ++b) {  // a column's rows ascend to its diagonal
                const std::int64_t last = static_cast<std::int64_t>(Kff.outerIndexPtr()[b + 1]) - 1;
                if (last >= Kff.outerIndexPtr()[b] && Kff.innerIndexPtr()[last] == b) diag_pos[static_cast<size_t>(b)] = last;
            }
            // Where each tangent entry goes in acc (see NewtonWorkspace).
            const auto nff = static_cast<std::int64_t>(Kff.nonZeros());
            ws->where.assign(nnz, -1);
            ws->fp_row.clear();
            ws->fp_col.clear();
            for (Eigen::Index r = 0; r < P.outerSize(); ++r) {
                const int a = free_index[static_cast<size_t>(r)];
                if (a < 0) continue;
                const std::int64_t end = P.isCompressed() ? po[r + 1] : po[r] + P.innerNonZeroPtr()[r];
                for (std::int64_t p = po[r]; p < end; ++p) {
                    if (to_ff[static_cast<size_t>(p)] >= 0) {
                        ws->where[static_cast<size_t>(p)] = to_ff[static_cast<size_t>(p)];
                    } else if (free_index[static_cast<size_t>(pi[p])] < 0) {
                        ws->where[static_cast<size_t>(p)] = nff + static_cast<std::int64_t>(ws->fp_row.size());
                        ws->fp_row.push_back(a);
                        ws->fp_col.push_back(pi[p]);
                    }
                }
            }
            const std::int64_t rest = nff + static_cast<std::int64_t>(ws->fp_row.size());
            for (std::int64_t& w : ws->where)
                if (w < 0) w = rest;
            ws->acc.assign(static_cast<size_t>(rest) + 1, 0.0);
            if (m > 0) llt.analyzePattern(Kff);
            if (P.isCompressed()) {
                ws->outer.assign(po, po + P.outerSize() + 1);
                ws->inner.assign(pi, pi + nnz);
                ws->free_index = free_index;
                ws->valid = true;
            }
        }
        analysed = true;
        out.setup_s += sw.seconds();
    };
    // −g on the free DOFs (the right-hand side's residual part), and a free solution back on all DOFs.
    auto free_rhs = [&](const Eigen::VectorXd& g) {
        Eigen::VectorXd rhs(m);
        for (Eigen::Index r = 0; r < n; ++r) {
            const int a = free_index[static_cast<size_t>(r)];
            if (a >= 0) rhs[a] = -g[r];
        }
        return rhs;
    };
    auto put_free = [&](const Eigen::VectorXd& x, Eigen::VectorXd& du) {
        for (Eigen::Index r = 0; r < n; ++r)
            if (free_index[static_cast<size_t>(r)] >= 0) du[r] = x[free_index[static_cast<size_t>(r)]];
    };
    auto newton_step = [&](const Eigen::VectorXd& u, const Eigen::VectorXd& g, const Eigen::VectorXd* dp) {
        if (!analysed) analyse();
        Stopwatch sw;
        std::vector<double>& acc = ws->acc;
        const auto nff = static_cast<size_t>(Kff.nonZeros());
        // The body's tangent at u into acc, its free upper block into Kff.
        auto assemble = [&](bool project) {
            std::fill(acc.begin(), acc.end(), 0.0);
            solid.add_tangent(u, project, acc.data(), ws->where.data());
            std::copy(acc.begin(), acc.begin() + static_cast<std::ptrdiff_t>(nff), Kff.valuePtr());
        };
        assemble(false);
        Eigen::VectorXd du = Eigen::VectorXd::Zero(n);
        if (dp) du = *dp;
        Eigen::VectorXd rhs = free_rhs(g);
        if (dp)  // − K_fp Δp, each row's terms in column order
            for (size_t k = 0; k < ws->fp_row.size(); ++k) rhs[ws->fp_row[k]] -= acc[nff + k] * (*dp)[ws->fp_col[k]];
        out.tangent_s += sw.lap();
        if (m == 0) return du;
        if (!opt.dump_free_tangent.empty() && out.factorisations == 0) write_upper_market(Kff, opt.dump_free_tangent);
        llt.factorize(Kff);
        ++out.factorisations;
        bool factored = llt.info() == Eigen::Success;
        if (!factored) {
            // Not positive definite (buckling, strong compression): project the element tangents instead.
            // The predictor keeps the true tangent's K_fp in its right-hand side, computed above.
            ++out.shifted;
            ++out.failed_factorisations;
            const double failed = sw.lap();
            out.factorise_s += failed;
            out.failed_factorise_s += failed;
            assemble(true);
            out.tangent_s += sw.lap();
        }
        Eigen::VectorXd diag(m);
        for (Eigen::Index a = 0; a < m; ++a) diag[a] = Kff.valuePtr()[diag_pos[static_cast<size_t>(a)]];
        for (double tau = 0; !factored;) {
            const Stopwatch attempt;
            llt.factorize(Kff);
            ++out.factorisations;
            if (llt.info() == Eigen::Success) break;
            ++out.failed_factorisations;
            out.failed_factorise_s += attempt.seconds();
            if (tau > 1e4) throw NumericalError("neo-Hookean solve: the tangent stays indefinite with a shift of 1e4 times its diagonal");
            const double next = tau == 0 ? 1e-8 : 10 * tau;
            for (Eigen::Index a = 0; a < m; ++a) Kff.valuePtr()[diag_pos[static_cast<size_t>(a)]] += (next - tau) * diag[a];
            tau = next;
        }
        out.factorise_s += sw.lap();
        put_free(llt.solve(rhs), du);
        out.back_solve_s += sw.lap();
        return du;
    };
    // A chord step: the last factorisation (of this call) against the residual g.
    auto chord_step = [&](const Eigen::VectorXd& g) {
        Stopwatch sw;
        Eigen::VectorXd du = Eigen::VectorXd::Zero(n);
        put_free(llt.solve(free_rhs(g)), du);
        out.back_solve_s += sw.lap();
        ++out.chord_steps;
        return du;
    };
    Eigen::VectorXd u = u0;
    for (Eigen::Index k = 0; k < fixed_dofs.size(); ++k) u[fixed_dofs[k]] = 0;
    Eigen::VectorXd start(static_cast<Eigen::Index>(prescribed.size())), target(start.size());
    for (size_t k = 0; k < prescribed.size(); ++k) {
        start[static_cast<Eigen::Index>(k)] = u[prescribed[k].first];
        target[static_cast<Eigen::Index>(k)] = prescribed[k].second;
    }
    double s = 0, ds = 1;
    const bool trace = std::getenv("ANEU_NEWTON_TRACE") != nullptr;
    std::string last_failure = "no iteration";
    bool budget_spent = false;  // keep_going: the iteration budget ran out (u is the last accepted iterate)
    // NewtonOptions::cancel set: true with keep_going (the caller returns the last accepted state), else throws.
    auto stop_asked = [&] {
        if (!opt.cancel || !opt.cancel->load(std::memory_order_relaxed)) return false;
        if (!opt.keep_going) throw Cancelled("neo-Hookean solve: cancelled");
        return true;
    };
    // Tries to reach load fraction s1 from the converged state u (at s); true on convergence (u updated).
    // (s1 may come back smaller: a contact that stops the prescribed DOFs' own move short makes the step shorter.)
    auto substep = [&](double& s1) {
        Eigen::VectorXd dp = Eigen::VectorXd::Zero(n);
        for (size_t k = 0; k < prescribed.size(); ++k) {
            const auto kk = static_cast<Eigen::Index>(k);
            dp[prescribed[k].first] = start[kk] + s1 * (target[kk] - start[kk]) - u[prescribed[k].first];
        }
        Eigen::VectorXd g = solid.internal_force(u);
        // Predictor: moves the prescribed DOFs. Without a prescribed increment (a load that is all free: a
        // released clip's spring) it would be a full Newton step without the line search, which can jump
        // through a contact; the corrector's line-searched iterations start from u instead.
        const bool moves = dp.cwiseAbs().maxCoeff() > 0;
        bool shortened = false;  // by a contact: a way point, solved loosely (below)
        Eigen::VectorXd v = u;
        if (moves && solid.max_step(u, dp) >= 1) {
            // The prescribed DOFs moved alone, the free ones where they are: already in equilibrium when the move is
            // small enough (a held clip's opening moved by less than the trace's 0.001°: the sample's held frames each
            // analysed and factorised the patch's tangent for a predictor that moved nothing, 6 s a frame). No
            // linear solve then; a contact the move would pass (max_step < 1) or a residual above the tolerance
            // takes the predictor below.
            const Eigen::VectorXd w = u + dp;
            if (std::isfinite(solid.energy(w))) {
                const Eigen::VectorXd gw = solid.internal_force(w);
                const double r = free_norm(gw), scale = std::max(gw.norm(), opt.force_scale);
                if (r <= opt.tolerance * scale + 1e-14) {
                    out.residual = scale > 0 ? r / scale : 0;
                    ++out.unsolved_substeps;
                    u = w;
                    return true;
                }
            }
        }
        if (moves) {
            // A contact may cut the predictor short (max_step): the prescribed DOFs still move all the way, the
            // free ones as far as admitted. Where that still runs into a contact (a prescribed DOF that moves
            // the contact itself: a clip's opening, a node pressed on a blade), the whole step goes as far as
            // admitted: a shorter load step, to s + a (s1 − s).
            const Eigen::VectorXd step = newton_step(u, g, &dp);
            const double a = solid.max_step(u, step);
            v += step;
            if (a < 1) {
                for (Eigen::Index r = 0; r < n; ++r)
                    if (free_index[static_cast<size_t>(r)] >= 0) v[r] = u[r] + a * step[r];
                if (solid.max_step(u, v - u) < 1) {
                    if (!(a > 1e-3)) {
                        last_failure = "the predictor runs into a contact";
                        return false;
                    }
                    v = u + a * step;
                    s1 = s + a * (s1 - s);
                    shortened = true;
                }
            }
        }
        double E = solid.energy(v);
        if (!std::isfinite(E)) {
            last_failure = "the predictor inverts elements";
            return false;
        }
        double r_last = -1;        // the last iteration's residual, when its step was taken in full (α = 1)
        for (int it = 0; it < opt.max_iterations; ++it) {
            g = solid.internal_force(v);
            const double r = free_norm(g), scale = std::max(g.norm(), opt.force_scale);
            out.residual = scale > 0 ? r / scale : 0;
            // A load step a contact shortened is a way point (a barrier's force, extrapolated linearly, lets
            // the pressed nodes come nearer than they do: the next predictor starts from here and corrects what
            // is left of the residual): 1 % of the force is enough there; the end of the load is solved to the
            // tolerance.
            const double tol = shortened && s1 < 1 ? std::max(opt.tolerance, 1e-2) : opt.tolerance;
            if (r <= tol * scale + 1e-14) {
                u = v;
                return true;
            }
            if (stop_asked()) {
                u = v;
                budget_spent = out.cancelled = true;
                return true;
            }
            if (opt.max_total_iterations > 0 && out.iterations >= opt.max_total_iterations) {
                if (opt.keep_going) {
                    u = v;
                    budget_spent = true;
                    return true;
                }
                throw NumericalError("neo-Hookean solve: " + std::to_string(out.iterations) + " Newton iterations (the limit) reached at load fraction " +
                                     std::to_string(s1) + ", residual " + std::to_string(out.residual));
            }
            ++out.iterations;
            // A chord step while the residual falls fast enough with full steps; a fresh tangent otherwise (and
            // always after a chord step that did not: the old factorisation has done what it can).
            const bool chord = opt.chord_ratio > 0 && out.factorisations > 0 && m > 0 && r_last > 0 && r <= opt.chord_ratio * r_last;
            const Eigen::VectorXd du = chord ? chord_step(g) : newton_step(v, g, nullptr);
            const double slope = g.dot(du);
            if (trace) {
                Eigen::Index worst = 0;
                du.cwiseAbs().maxCoeff(&worst);
                std::fprintf(stderr, "newton s %.4g it %d residual %.3e / %.3e energy %.12e slope %.3e |du| %.3e (largest at DOF %lld: %.3e; projected tangents so far %d)\n", s1,
                             it, r, scale, E, slope, du.norm(), static_cast<long long>(worst), du[worst], out.shifted);
            }
            double alpha = solid.max_step(v, du);  // 1 unless a contact stops the step short
            bool accepted = false;
            for (int ls = 0; ls < 40; ++ls, alpha *= 0.5) {
                const Eigen::VectorXd trial = v + alpha * du;
                const double Et = solid.energy(trial);
                if (!std::isfinite(Et)) continue;
                // Armijo on the energy. Near convergence the energy change drowns in rounding: a step whose
                // energy change is at that level is taken when it lowers the residual.
                bool ok = Et <= E + 1e-4 * alpha * slope;
                if (!ok && Et - E <= 1e-11 * std::abs(E)) ok = free_norm(solid.internal_force(trial)) < r;
                if (ok) {
                    if (trace) std::fprintf(stderr, "  alpha %g energy %.15e\n", alpha, Et);
                    v = trial;
                    E = Et;
                    accepted = true;
                    r_last = alpha == 1 ? r : -1;
                    break;
                }
            }
            if (!accepted && chord) {  // the old factorisation's direction led nowhere: a fresh tangent next
                r_last = -1;
                continue;
            }
            if (!accepted) {
                last_failure = "the line search found no decrease of the energy";
                return false;
            }
        }
        last_failure = "no convergence in " + std::to_string(opt.max_iterations) + " iterations (residual " + std::to_string(out.residual) + ")";
        return false;
    };
    while (s < 1.0) {
        // (Also between substeps: a frame whose predictors keep failing and halving never reaches an iteration.)
        if (stop_asked()) {
            out.converged = false;
            out.cancelled = true;
            out.load_fraction = s;
            out.failure = "cancelled";
            break;
        }
        double s1 = std::min(1.0, s + ds);
        if (substep(s1)) {
            if (budget_spent) {
                out.converged = false;
                out.load_fraction = s1;
                out.failure = out.cancelled ? std::string("cancelled") : "the iteration budget (" + std::to_string(opt.max_total_iterations) + ") ran out";
                break;
            }
            s = s1;
            ++out.substeps;
            ds = std::min(2 * ds, 1.0);
        } else {
            if (ds < std::ldexp(1.0, -opt.max_halvings)) {
                if (opt.keep_going) {
                    out.converged = false;
                    out.load_fraction = s;
                    out.failure = last_failure;
                    break;
                }
                throw NumericalError("neo-Hookean solve: no convergence at load fraction " + std::to_string(s1) + " with the step " +
                                     "halved " + std::to_string(opt.max_halvings) + " times: " + last_failure +
                                     "; smallest det F " + std::to_string(solid.min_jacobian(u)));
            }
            ds *= 0.5;
        }
    }
    const Eigen::VectorXd g = solid.internal_force(u);
    out.reaction.resize(static_cast<Eigen::Index>(prescribed.size()));
    for (size_t k = 0; k < prescribed.size(); ++k) out.reaction[static_cast<Eigen::Index>(k)] = g[prescribed[k].first];
    out.min_J = solid.min_jacobian(u);
    out.u = std::move(u);
    return out;
}

}  // namespace aneu::fem
