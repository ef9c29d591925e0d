// SPDX-License-Identifier: MIT
// Condensation: W against full sparse solves, the two routes against each other, SPD, working regions,
// refusals.
#include <gtest/gtest.h>

#include <map>

#include <Eigen/Cholesky>

#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/condense.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "fem_test_util.hpp"

using namespace aneu;
using namespace aneu::fem;
using Sparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;

namespace {

/// Acceptance bounds (FEM issue): W f equals the full solve to 1e-10 in double, 1e-4 in float32.
constexpr double DOUBLE_TOL = 1e-10;
constexpr double FLOAT_TOL = 1e-4;

struct Problem {
    StructuredMesh m;
    Sparse K;
    Eigen::VectorXi fixed, kept;
};

/// A thin tube wall (one element through 0.3 mm), both end rings fixed, kept = outer nodes not fixed.
Problem tube_problem(int n_theta = 16, int n_z = 10) {
    Problem p;
    p.m = tube_mesh(1.5, 1.8, 4.0, 1, n_theta, n_z);
    p.K = assemble_stiffness(p.m.V, p.m.T, Eigen::VectorXi::Zero(p.m.T.rows()), {{"wall", 1.0, 0.45}});
    const WallDofSets d = wall_dof_sets(p.m);
    p.fixed = d.fixed;
    p.kept = d.kept;
    return p;
}

/// W as a dense matrix in the order of `kept` (undoing the row order of the result).
Eigen::MatrixXd dense_in_kept_order(const CondensedData& c, const Eigen::VectorXi& kept) {
    std::map<int, int> pos;
    for (Eigen::Index i = 0; i < kept.size(); ++i) pos[kept[i]] = static_cast<int>(i);
    const Eigen::Index m = c.size();
    std::vector<int> to(static_cast<size_t>(m));
    for (Eigen::Index r = 0; r < m; ++r) to[static_cast<size_t>(r)] = pos.at(3 * c.dof_node[r] + c.dof_axis[r]);
    Eigen::MatrixXd W(m, m);
    for (Eigen::Index j = 0; j < m; ++j)
        for (Eigen::Index i = 0; i < m; ++i)
            W(to[static_cast<size_t>(i)], to[static_cast<size_t>(j)]) =
                c.precision == Precision::FLOAT32 ? double(c.W32(i, j)) : c.W64(i, j);
    return W;
}

/// Full sparse solve of K u = f (f on kept DOFs only), u restricted to kept.
Eigen::VectorXd full_solve_kept(const Problem& p, const Eigen::VectorXd& f_kept) {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(p.K.rows());
    for (Eigen::Index i = 0; i < p.kept.size(); ++i) f[p.kept[i]] = f_kept[i];
    std::vector<char> fixed(static_cast<size_t>(p.K.rows()), 0);
    for (Eigen::Index i = 0; i < p.fixed.size(); ++i) fixed[static_cast<size_t>(p.fixed[i])] = 1;
    const Eigen::VectorXd u = test::solve_dirichlet(p.K, f, fixed, Eigen::VectorXd::Zero(p.K.rows()));
    Eigen::VectorXd out(p.kept.size());
    for (Eigen::Index i = 0; i < p.kept.size(); ++i) out[i] = u[p.kept[i]];
    return out;
}

CondenseParams params(CondenseMethod m, Precision pr, int tile = 32) {
    CondenseParams c;
    c.method = m;
    c.precision = pr;
    c.tile_size = tile;
    return c;
}

double diag(const CondensedData& c, const std::string& k) {
    for (const auto& [n, v] : c.diagnostics)
        if (n == k) return v;
    ADD_FAILURE() << "no diagnostic " << k;
    return 0;
}

}  // namespace

class CondenseRoute : public ::testing::TestWithParam<CondenseMethod> {};

TEST_P(CondenseRoute, WTimesLoadEqualsFullSolveDouble) {
    const Problem p = tube_problem();
    const CondensedData c = condense(p.K, p.fixed, p.kept, params(GetParam(), Precision::FLOAT64));
    ASSERT_EQ(c.size(), p.kept.size());
    const Eigen::MatrixXd W = dense_in_kept_order(c, p.kept);
    for (unsigned seed = 1; seed <= 3; ++seed) {
        std::srand(seed);
        const Eigen::VectorXd f = Eigen::VectorXd::Random(p.kept.size());
        const Eigen::VectorXd u_full = full_solve_kept(p, f);
        EXPECT_LT((W * f - u_full).norm() / u_full.norm(), DOUBLE_TOL);
    }
    EXPECT_LT(diag(c, "residual_max_rel"), DOUBLE_TOL);
    EXPECT_EQ((W - W.transpose()).norm(), 0.0);
    EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(W).info(), Eigen::Success);  // SPD
}

TEST_P(CondenseRoute, WTimesLoadEqualsFullSolveFloat32) {
    const Problem p = tube_problem();
    const CondensedData c = condense(p.K, p.fixed, p.kept, params(GetParam(), Precision::FLOAT32));
    EXPECT_EQ(c.W64.size(), 0);
    const Eigen::MatrixXd W = dense_in_kept_order(c, p.kept);
    std::srand(5);
    const Eigen::VectorXd f = Eigen::VectorXd::Random(p.kept.size());
    const Eigen::VectorXd u_full = full_solve_kept(p, f);
    EXPECT_LT((W * f - u_full).norm() / u_full.norm(), FLOAT_TOL);
}
INSTANTIATE_TEST_SUITE_P(Routes, CondenseRoute, ::testing::Values(CondenseMethod::SPARSE, CondenseMethod::DENSE));

TEST(Condense, SparseAndDenseRoutesAgree) {
    const Problem p = tube_problem(20, 12);
    const Eigen::MatrixXd Ws = dense_in_kept_order(condense(p.K, p.fixed, p.kept, params(CondenseMethod::SPARSE, Precision::FLOAT64, 64)), p.kept);
    const Eigen::MatrixXd Wd = dense_in_kept_order(condense(p.K, p.fixed, p.kept, params(CondenseMethod::DENSE, Precision::FLOAT64, 16)), p.kept);
    EXPECT_LT((Ws - Wd).norm() / Wd.norm(), DOUBLE_TOL);
}

TEST(Condense, TheKeptFactorSolvesTheFreeBlockAndAgreesWithW) {
    // The factor condense made for W, kept (fem::Linearisation's free step and frames use it): K_ff x = b to rounding,
    // and x at the kept DOFs for a unit load on one of them is W's column.
    const Problem p = tube_problem(20, 12);
    std::unique_ptr<CondenseFactor> factor;
    const CondensedData cd = condense(p.K, p.fixed, p.kept, params(CondenseMethod::SPARSE, Precision::FLOAT64, 64), null_reporter(), &factor);
    ASSERT_TRUE(factor);
    const Eigen::MatrixXd W = dense_in_kept_order(cd, p.kept);
    std::vector<int> free_index(static_cast<size_t>(p.K.rows()), 0);
    for (Eigen::Index k = 0; k < p.fixed.size(); ++k) free_index[static_cast<size_t>(p.fixed[k])] = -1;
    std::vector<int> free_dofs;
    for (Eigen::Index d = 0; d < p.K.rows(); ++d)
        if (free_index[static_cast<size_t>(d)] >= 0) {
            free_index[static_cast<size_t>(d)] = static_cast<int>(free_dofs.size());
            free_dofs.push_back(static_cast<int>(d));
        }
    const Eigen::Index nf = static_cast<Eigen::Index>(free_dofs.size());
    Eigen::MatrixXd Kff(nf, nf);
    const Eigen::MatrixXd Kd(p.K);
    for (Eigen::Index a = 0; a < nf; ++a)
        for (Eigen::Index b = 0; b < nf; ++b) Kff(a, b) = Kd(free_dofs[static_cast<size_t>(a)], free_dofs[static_cast<size_t>(b)]);
    const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(nf, -1.0, 2.0);
    const Eigen::VectorXd x = factor->solve(b);
    EXPECT_LT((Kff * x - b).norm() / b.norm(), 1e-10);
    for (Eigen::Index j : {Eigen::Index(0), p.kept.size() / 2}) {
        Eigen::VectorXd e = Eigen::VectorXd::Zero(nf);
        e[free_index[static_cast<size_t>(p.kept[j])]] = 1.0;
        const Eigen::VectorXd col = factor->solve(e);
        for (Eigen::Index i = 0; i < p.kept.size(); ++i) EXPECT_NEAR(col[free_index[static_cast<size_t>(p.kept[i])]], W(i, j), DOUBLE_TOL * W.norm());
    }
    EXPECT_THROW(factor->solve(Eigen::VectorXd::Zero(nf + 1)), InputError);
    // The dense route keeps none.
    condense(p.K, p.fixed, p.kept, params(CondenseMethod::DENSE, Precision::FLOAT64, 16), null_reporter(), &factor);
    EXPECT_FALSE(factor);
}

TEST(Condense, WorkingRegionIsTheSubBlockOfTheFullW) {
    const Problem p = tube_problem();
    const Eigen::MatrixXd W = dense_in_kept_order(condense(p.K, p.fixed, p.kept, params(CondenseMethod::SPARSE, Precision::FLOAT64)), p.kept);
    // Region: kept DOFs of nodes within 1.5 mm of a point on the outer surface.
    const Eigen::Vector3d centre(1.8, 0.0, 2.0);
    std::vector<int> region, where;
    for (Eigen::Index i = 0; i < p.kept.size(); ++i) {
        if ((p.m.V.row(p.kept[i] / 3).transpose() - centre).norm() <= 1.5) {
            region.push_back(p.kept[i]);
            where.push_back(static_cast<int>(i));
        }
    }
    ASSERT_GT(region.size(), 9u);
    ASSERT_LT(region.size(), static_cast<size_t>(p.kept.size()) / 2);
    const Eigen::VectorXi kr = Eigen::Map<Eigen::VectorXi>(region.data(), static_cast<Eigen::Index>(region.size()));
    const Eigen::MatrixXd Wr = dense_in_kept_order(condense(p.K, p.fixed, kr, params(CondenseMethod::SPARSE, Precision::FLOAT64)), kr);
    for (size_t a = 0; a < where.size(); ++a)
        for (size_t b = 0; b < where.size(); ++b)
            EXPECT_NEAR(Wr(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)), W(where[a], where[b]), DOUBLE_TOL * W.norm());
}

TEST(Condense, RefusesWhatDoesNotFitAndBadDofSets) {
    const Problem p = tube_problem();
    CondenseParams small = params(CondenseMethod::SPARSE, Precision::FLOAT64);
    small.memory_limit_gb = 1e-6;
    try {
        condense(p.K, p.fixed, p.kept, small);
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("needs about"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("but the limit is 1e-06 GB"), std::string::npos) << e.what();
    }
    EXPECT_THROW(condense(p.K, p.fixed, Eigen::VectorXi(), params(CondenseMethod::SPARSE, Precision::FLOAT64)), InputError);
    EXPECT_THROW(condense(p.K, p.fixed, p.fixed.head(3), params(CondenseMethod::SPARSE, Precision::FLOAT64)), InputError);
    // Nothing fixed: K is singular, CHOLMOD says so.
    EXPECT_THROW(condense(p.K, Eigen::VectorXi(), p.kept, params(CondenseMethod::SPARSE, Precision::FLOAT64)), NumericalError);
}
