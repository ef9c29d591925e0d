// SPDX-License-Identifier: MIT
// The neo-Hookean reference solid: its tangent at rest is the linear K, its force and tangent are the
// derivatives of its energy, it reproduces a homogeneous large deformation exactly, it tends to the linear
// model at small loads, and it refuses what it cannot solve.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <string>
#include <random>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/structured_mesh.hpp"

namespace {

using namespace aneu;

struct Model {
    Eigen::MatrixX3d V;
    Eigen::MatrixXi T;
    Eigen::VectorXi region;
    std::vector<Material> mats;
};

/// A 1×1.2×2 mm box, two materials (the upper half 5× stiffer); quadratic with curved (moved) mid-edge nodes.
Model box_model(int order, bool curved = true) {
    const fem::StructuredMesh b = fem::box_mesh(1.0, 1.2, 2.0, 2, 2, 3);
    Model m;
    m.V = b.V;
    m.T = b.T;
    if (order == 2) {
        const fem::QuadraticMesh q = fem::quadratic_mesh(b.V, b.T);
        m.V = q.V;
        m.T = q.T;
        if (curved)  // bend the mid-edge nodes a little, as curved boundary elements are
            for (Eigen::Index i = b.V.rows(); i < m.V.rows(); ++i) m.V(i, 0) += 0.03 * std::sin(3 * m.V(i, 2)) * m.V(i, 1);
    }
    m.region.resize(m.T.rows());
    for (Eigen::Index e = 0; e < m.T.rows(); ++e) m.region[e] = m.V(m.T(e, 0), 2) + m.V(m.T(e, 1), 2) + m.V(m.T(e, 2), 2) + m.V(m.T(e, 3), 2) > 4.0 ? 1 : 0;
    m.mats = {{"soft", 1.0, 0.45}, {"stiff", 5.0, 0.3}};
    return m;
}

Eigen::VectorXd smooth_field(const Eigen::MatrixX3d& V, double amp) {
    Eigen::VectorXd u(3 * V.rows());
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
        const double x = V(i, 0), y = V(i, 1), z = V(i, 2);
        u.segment<3>(3 * i) = amp * Eigen::Vector3d(std::sin(1.3 * z + y), 0.5 * x * z - 0.3 * y, std::cos(x + 0.7 * y) * z);
    }
    return u;
}

class NeoHookeanOrder : public ::testing::TestWithParam<int> {};

TEST_P(NeoHookeanOrder, TangentAtRestIsTheLinearStiffness) {
    const Model m = box_model(GetParam());
    const fem::NeoHookeanSolid solid(m.V, m.T, m.region, m.mats);
    const auto K = fem::assemble_stiffness(m.V, m.T, m.region, m.mats);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(solid.dofs());
    const Eigen::MatrixXd diff = Eigen::MatrixXd(solid.tangent(zero)) - Eigen::MatrixXd(K);
    const double scale = Eigen::MatrixXd(K).cwiseAbs().maxCoeff();
    EXPECT_LT(diff.cwiseAbs().maxCoeff(), 1e-12 * scale);
    EXPECT_LT(solid.internal_force(zero).norm(), 1e-14);
    EXPECT_EQ(solid.energy(zero), 0.0);
}

TEST_P(NeoHookeanOrder, ForceAndTangentAreDerivativesOfTheEnergy) {
    const Model m = box_model(GetParam());
    const fem::NeoHookeanSolid solid(m.V, m.T, m.region, m.mats);
    const Eigen::VectorXd u = smooth_field(m.V, 0.15);  // strains of tens of percent
    ASSERT_GT(solid.min_jacobian(u), 0.3);
    const Eigen::VectorXd f = solid.internal_force(u);
    const auto K = solid.tangent(u);
    std::mt19937 rng(7);
    std::normal_distribution<double> nd;
    Eigen::VectorXd v(solid.dofs());
    for (Eigen::Index i = 0; i < v.size(); ++i) v[i] = nd(rng);
    const double h = 1e-6;
    // Directional derivatives by central differences (error O(h²)).
    const double dE = (solid.energy(u + h * v) - solid.energy(u - h * v)) / (2 * h);
    EXPECT_NEAR(dE, f.dot(v), 1e-6 * std::abs(f.dot(v)));
    const Eigen::VectorXd df = (solid.internal_force(u + h * v) - solid.internal_force(u - h * v)) / (2 * h);
    EXPECT_LT((df - K * v).norm(), 1e-6 * df.norm());
    // symmetric
    const Eigen::MatrixXd Kd(K);
    EXPECT_LT((Kd - Kd.transpose()).cwiseAbs().maxCoeff(), 1e-12 * Kd.cwiseAbs().maxCoeff());
    // Under strong compression the tangent is indefinite; the projected one is positive semidefinite.
    const Eigen::VectorXd squash = smooth_field(m.V, 0.15) - 0.35 * Eigen::VectorXd(m.V.transpose().reshaped()).cwiseProduct(
                                       Eigen::Vector3d(0, 0, 1).replicate(m.V.rows(), 1));
    ASSERT_GT(solid.min_jacobian(squash), 0.0);
    const Eigen::MatrixXd Kc(solid.tangent(squash)), Kp(solid.tangent(squash, true));
    const double scale = Kc.cwiseAbs().maxCoeff();
    EXPECT_LT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Kc).eigenvalues().minCoeff(), -1e-6 * scale);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Kp).eigenvalues().minCoeff(), -1e-10 * scale);
    EXPECT_LT((Kp - Kp.transpose()).cwiseAbs().maxCoeff(), 1e-12 * scale);
}

TEST_P(NeoHookeanOrder, HomogeneousLargeDeformationIsReproducedExactly) {
    // The boundary follows x = F X (40 % stretch, 20 % compression, shears); the interior, free, must follow
    // it too, and the boundary forces must carry the analytic stress: Σ f_a ⊗ X_a = P(F) · volume.
    Model m = box_model(GetParam(), false);
    m.mats = {{"a", 2.0, 0.45}, {"b", 2.0, 0.45}};
    const fem::NeoHookeanSolid solid(m.V, m.T, m.region, m.mats);
    Eigen::Matrix3d F;
    F << 1.4, 0.2, 0.0, 0.0, 0.8, 0.1, 0.05, 0.0, 1.1;
    std::vector<std::pair<int, double>> pres;
    std::vector<char> interior(static_cast<size_t>(m.V.rows()), 1);
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
        const Eigen::Vector3d X = m.V.row(i);
        const bool on_boundary = X.x() < 1e-9 || X.x() > 1 - 1e-9 || X.y() < 1e-9 || X.y() > 1.2 - 1e-9 || X.z() < 1e-9 || X.z() > 2 - 1e-9;
        if (!on_boundary) continue;
        interior[static_cast<size_t>(i)] = 0;
        const Eigen::Vector3d u = (F - Eigen::Matrix3d::Identity()) * X;
        for (int k = 0; k < 3; ++k) pres.emplace_back(static_cast<int>(3 * i + k), u[k]);
    }
    const fem::NewtonResult r = fem::solve_neo_hookean(solid, Eigen::VectorXi(), pres, Eigen::VectorXd::Zero(solid.dofs()));
    double err = 0;
    int n_interior = 0;
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
        if (!interior[static_cast<size_t>(i)]) continue;
        ++n_interior;
        const Eigen::Vector3d X = m.V.row(i);
        err = std::max(err, (r.u.segment<3>(3 * i) - (F - Eigen::Matrix3d::Identity()) * X).norm());
    }
    ASSERT_GT(n_interior, 0);
    EXPECT_LT(err, 1e-9);
    const double mu = 2.0 / (2 * 1.45), lambda = 2.0 * 0.45 / (1.45 * 0.1), J = F.determinant();
    const Eigen::Matrix3d FinvT = F.inverse().transpose();
    const Eigen::Matrix3d P = mu * (F - FinvT) + lambda * std::log(J) * FinvT;
    Eigen::Matrix3d virial = Eigen::Matrix3d::Zero();
    for (size_t k = 0; k < pres.size(); ++k) {
        const int node = pres[k].first / 3, axis = pres[k].first % 3;
        virial.row(axis) += r.reaction[static_cast<Eigen::Index>(k)] * m.V.row(node);
    }
    const double vol = 1.0 * 1.2 * 2.0;
    EXPECT_LT((virial - P * vol).norm(), 1e-8 * P.norm() * vol) << "virial\n" << virial << "\nP V\n" << P * vol;
    const double psi = 0.5 * mu * (F.squaredNorm() - 3) - mu * std::log(J) + 0.5 * lambda * std::log(J) * std::log(J);
    EXPECT_NEAR(solid.energy(r.u), psi * vol, 1e-10 * psi * vol);
    EXPECT_NEAR(r.min_J, J, 1e-9);
    EXPECT_LT(r.residual, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(Orders, NeoHookeanOrder, ::testing::Values(1, 2), [](const auto& i) {
    return i.param == 1 ? std::string("Linear") : std::string("Quadratic");
});

TEST(NeoHookean, SmallLoadsGiveTheLinearModelAndLargeOnesDoNot) {
    // A tube wall held at both ends, a patch of its outer surface pushed in radially. The difference to the
    // linear model is a large-deformation effect: it vanishes with the load, in proportion to it.
    const fem::StructuredMesh t = fem::tube_mesh(1.5, 1.9, 6.0, 2, 20, 10);
    const fem::QuadraticMesh q = fem::quadratic_mesh(t.V, t.T);
    const Eigen::VectorXi region = Eigen::VectorXi::Zero(q.T.rows());
    const std::vector<Material> mats = {{"wall", 1.0, 0.45}};
    const fem::NeoHookeanSolid solid(q.V, q.T, region, mats);
    std::vector<int> fd;
    for (Eigen::Index i = 0; i < q.V.rows(); ++i)
        if (q.V(i, 2) < 1e-9 || q.V(i, 2) > 6 - 1e-9)
            for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
    const Eigen::VectorXi fixed_dofs = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    FemData linear;
    linear.K = fem::assemble_stiffness(q.V, q.T, region, mats);
    linear.K_upper_only = false;
    linear.fixed_dofs = fixed_dofs;
    std::vector<int> patch;
    for (Eigen::Index i = 0; i < q.V.rows(); ++i) {
        const Eigen::Vector3d X = q.V.row(i);
        if (std::hypot(X.x(), X.y()) > 1.9 - 1e-6 && X.x() > 1.6 && std::abs(X.z() - 3) < 1.0) patch.push_back(static_cast<int>(i));
    }
    ASSERT_GT(patch.size(), 4u);
    auto compare = [&](double depth) {
        std::vector<std::pair<int, double>> pres;
        for (int v : patch)
            for (int k = 0; k < 3; ++k) pres.emplace_back(3 * v + k, k == 0 ? -depth : 0.0);
        const Eigen::VectorXd ul = fem::solve_dirichlet(linear, pres).u;
        const fem::NewtonResult r = fem::solve_neo_hookean(solid, fixed_dofs, pres, Eigen::VectorXd::Zero(solid.dofs()));
        EXPECT_LT(r.residual, 1e-9);
        return (r.u - ul).norm() / ul.norm();
    };
    const double small = compare(1e-4), larger = compare(1e-2);
    EXPECT_LT(small, 1e-4);
    EXPECT_GT(larger / small, 30.0);   // about 100: the deviation grows with the load
    EXPECT_LT(larger / small, 300.0);
    // and at 0.4 mm (a fifth of the wall's radius) it is a real difference
    EXPECT_GT(compare(0.4), 0.02);
}

TEST(NeoHookean, CompressedColumnPastBucklingIsSolvedWithProjectedTangents) {
    // A slender column clamped at both ends and shortened by 8 %, far beyond its Euler strain (~0.3 %): the
    // straight state's tangent is indefinite. Newton uses the projected element tangents there, and the solve
    // still ends in equilibrium with no element inverted.
    const fem::StructuredMesh b = fem::box_mesh(0.3, 0.3, 6.0, 1, 1, 30);
    const Eigen::VectorXi region = Eigen::VectorXi::Zero(b.T.rows());
    const fem::NeoHookeanSolid solid(b.V, b.T, region, {{"col", 1.0, 0.3}});
    std::vector<int> fd;
    std::vector<std::pair<int, double>> pres;
    for (Eigen::Index i = 0; i < b.V.rows(); ++i) {
        if (b.V(i, 2) < 1e-9) {
            for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
        } else if (b.V(i, 2) > 6 - 1e-9) {
            pres.emplace_back(static_cast<int>(3 * i), 0.0);
            pres.emplace_back(static_cast<int>(3 * i + 1), 0.0);
            pres.emplace_back(static_cast<int>(3 * i + 2), -0.48);
        }
    }
    const Eigen::VectorXi fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    // A tiny lateral imperfection lets it leave the straight path.
    Eigen::VectorXd u0 = Eigen::VectorXd::Zero(solid.dofs());
    for (Eigen::Index i = 0; i < b.V.rows(); ++i) u0[3 * i] = 1e-4 * std::sin(M_PI * b.V(i, 2) / 6.0);
    const fem::NewtonResult r = fem::solve_neo_hookean(solid, fixed, pres, u0);
    EXPECT_GT(r.shifted, 0);
    EXPECT_LT(r.residual, 1e-9);
    EXPECT_GT(r.min_J, 0.0);
    double lateral = 0;
    for (Eigen::Index i = 0; i < b.V.rows(); ++i) lateral = std::max(lateral, std::abs(r.u[3 * i]));
    EXPECT_GT(lateral, 0.3);  // it buckled sideways (a straight column would only shorten)
}

TEST(NeoHookean, RefusesWhatItCannotSolve) {
    Eigen::MatrixX3d V(4, 3);
    V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
    Eigen::MatrixXi T(1, 4);
    T << 0, 1, 2, 3;
    const Eigen::VectorXi region = Eigen::VectorXi::Zero(1);
    const fem::NeoHookeanSolid solid(V, T, region, {{"r", 1.0, 0.3}});
    Eigen::VectorXi fixed(9);
    for (int k = 0; k < 9; ++k) fixed[k] = k;
    // The apex pushed through the opposite face: every path crosses J = 0.
    const std::vector<std::pair<int, double>> through = {{9, 0.0}, {10, 0.0}, {11, -1.5}};
    try {
        fem::solve_neo_hookean(solid, fixed, through, Eigen::VectorXd::Zero(12));
        FAIL() << "expected NumericalError";
    } catch (const NumericalError& e) {
        EXPECT_NE(std::string(e.what()).find("no convergence at load fraction"), std::string::npos) << e.what();
    }
    // With keep_going (the simulator's frames) the same solve returns where it got and says why it stopped.
    fem::NewtonOptions go;
    go.keep_going = true;
    const fem::NewtonResult r = fem::solve_neo_hookean(solid, fixed, through, Eigen::VectorXd::Zero(12), go);
    EXPECT_FALSE(r.converged);
    EXPECT_LT(r.load_fraction, 1.0);
    EXPECT_GT(r.min_J, 0.0);
    EXPECT_FALSE(r.failure.empty());
    EXPECT_TRUE(r.failure.find("inverts elements") != std::string::npos || r.failure.find("line search") != std::string::npos ||
                r.failure.find("no convergence") != std::string::npos)
        << r.failure;
    const fem::NewtonResult ok = fem::solve_neo_hookean(solid, fixed, {{11, -0.1}}, Eigen::VectorXd::Zero(12), go);
    EXPECT_TRUE(ok.converged);
    EXPECT_TRUE(ok.failure.empty());
    EXPECT_THROW(fem::solve_neo_hookean(solid, fixed, {{12, 0.1}}, Eigen::VectorXd::Zero(12)), InputError);
    EXPECT_THROW(fem::solve_neo_hookean(solid, fixed, {{3, 0.1}}, Eigen::VectorXd::Zero(12)), InputError);
    Eigen::VectorXd inverted = Eigen::VectorXd::Zero(12);
    inverted[11] = -1.5;
    EXPECT_TRUE(std::isinf(solid.energy(inverted)));
    EXPECT_THROW(solid.internal_force(inverted), NumericalError);
    EXPECT_THROW(fem::NeoHookeanSolid(V, T, region, {{"r", 1.0, 0.5}}), InputError);
}

/// The 2 mm box (box_model(2)) clamped at its base, as the Newton workspace, dump and chord tests use it: its fixed
/// DOFs, its top's z DOFs, and those moved down by d (`pressed`).
struct ClampedBox {
    Model m = box_model(2);
    fem::NeoHookeanSolid solid{m.V, m.T, m.region, m.mats};
    Eigen::VectorXi fixed;
    std::vector<int> top;
    ClampedBox() {
        std::vector<int> fd;
        for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
            if (m.V(i, 2) < 1e-9)
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
            if (m.V(i, 2) > 2 - 1e-9) top.push_back(static_cast<int>(3 * i + 2));
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    }
    std::vector<std::pair<int, double>> pressed(double d) const {
        std::vector<std::pair<int, double>> p;
        for (const int dof : top) p.emplace_back(dof, -d);
        return p;
    }
};

TEST(NeoHookean, AWorkspaceKeepsTheAnalysisWhileThePatternStaysAndAMoveInEquilibriumNeedsNoSolve) {
    // The box clamped at its base, its top pressed down 0.2 mm (10 %): three calls in a row as a simulator's frames
    // make them, on one workspace.
    const ClampedBox box;
    const fem::NeoHookeanSolid& solid = box.solid;
    const Eigen::VectorXi& fixed = box.fixed;
    const std::vector<int>& top = box.top;
    auto pressed = [&](double d) { return box.pressed(d); };
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(solid.dofs());
    fem::NewtonOptions o;
    o.workspace = fem::make_newton_workspace();
    const fem::NewtonResult fresh = fem::solve_neo_hookean(solid, fixed, pressed(0.2), zero);
    const fem::NewtonResult first = fem::solve_neo_hookean(solid, fixed, pressed(0.2), zero, o);
    EXPECT_FALSE(first.analysis_reused);
    EXPECT_GT(first.factorisations, 0);
    // Same pattern, same free DOFs: the analysis is reused and the answer is the fresh solve's, bit for bit.
    const fem::NewtonResult again = fem::solve_neo_hookean(solid, fixed, pressed(0.2), zero, o);
    EXPECT_TRUE(again.analysis_reused);
    EXPECT_EQ(again.iterations, fresh.iterations);
    EXPECT_EQ((again.u - fresh.u).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_EQ((first.u - fresh.u).cwiseAbs().maxCoeff(), 0.0);
    // From the converged state, the top moved by 1e-13 mm: in equilibrium as it stands, no linear solve.
    const fem::NewtonResult nudged = fem::solve_neo_hookean(solid, fixed, pressed(0.2 + 1e-13), first.u, o);
    EXPECT_TRUE(nudged.converged);
    EXPECT_EQ(nudged.unsolved_substeps, 1);
    EXPECT_EQ(nudged.factorisations, 0);
    EXPECT_LE(nudged.residual, 1e-9);
    for (Eigen::Index i = 0; i < solid.dofs(); ++i) {
        if (std::find(top.begin(), top.end(), static_cast<int>(i)) == top.end()) {
            EXPECT_EQ(nudged.u[i], first.u[i]) << i;
        }
    }
    for (const int dof : top) EXPECT_DOUBLE_EQ(nudged.u[dof], -0.2 - 1e-13);
    // Pressed 0.01 mm further: not in equilibrium without a solve; the reused analysis gives the fresh answer.
    const fem::NewtonResult further = fem::solve_neo_hookean(solid, fixed, pressed(0.21), first.u, o);
    EXPECT_EQ(further.unsolved_substeps, 0);
    EXPECT_GT(further.factorisations, 0);
    EXPECT_TRUE(further.analysis_reused);
    const fem::NewtonResult further_fresh = fem::solve_neo_hookean(solid, fixed, pressed(0.21), first.u);
    EXPECT_EQ((further.u - further_fresh.u).cwiseAbs().maxCoeff(), 0.0);
    // Other free DOFs (the top's sideways DOFs held too): analysed again, and right.
    auto held = pressed(0.2);
    for (const int dof : top) held.emplace_back(dof - 1, 0.0);
    const fem::NewtonResult other = fem::solve_neo_hookean(solid, fixed, held, zero, o);
    EXPECT_FALSE(other.analysis_reused);
    const fem::NewtonResult other_fresh = fem::solve_neo_hookean(solid, fixed, held, zero);
    EXPECT_EQ((other.u - other_fresh.u).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_GT((other.u - first.u).cwiseAbs().maxCoeff(), 1e-4);  // a different problem
}

TEST(NeoHookean, TheFirstFactorisedTangentCanBeWrittenAsASymmetricMatrixMarketFile) {
    // The diagnostic behind bench/bench_factor.cpp: the box clamped at its base, its top pressed 0.2 mm; the first
    // factorised free tangent is written once, as the lower triangle of a symmetric m x m matrix (m free DOFs),
    // every diagonal entry positive, and nothing left under the temporary name.
    const ClampedBox box;
    const std::vector<std::pair<int, double>> pressed = box.pressed(0.2);
    const std::string path = ::testing::TempDir() + "aneu_free_tangent.mtx";
    std::remove(path.c_str());
    fem::NewtonOptions o;
    o.dump_free_tangent = path;
    const fem::NewtonResult r = fem::solve_neo_hookean(box.solid, box.fixed, pressed, Eigen::VectorXd::Zero(box.solid.dofs()), o);
    ASSERT_TRUE(r.converged);
    ASSERT_GT(r.factorisations, 1);
    FILE* f = std::fopen(path.c_str(), "r");
    ASSERT_NE(f, nullptr);
    char header[128] = {};
    ASSERT_NE(std::fgets(header, sizeof header, f), nullptr);
    EXPECT_EQ(std::string(header), "%%MatrixMarket matrix coordinate real symmetric\n");
    long rows = 0, cols = 0, nnz = 0;
    ASSERT_EQ(std::fscanf(f, "%ld %ld %ld", &rows, &cols, &nnz), 3);
    const long free = box.solid.dofs() - static_cast<long>(box.fixed.size()) - static_cast<long>(pressed.size());
    EXPECT_EQ(rows, free);
    EXPECT_EQ(cols, free);
    long read = 0, upper = 0, positive_diagonal = 0;
    long i = 0, j = 0;
    double v = 0;
    while (std::fscanf(f, "%ld %ld %lf", &i, &j, &v) == 3) {
        ++read;
        if (i < j || i < 1 || j < 1 || i > rows) ++upper;
        if (i == j && v > 0) ++positive_diagonal;
    }
    std::fclose(f);
    EXPECT_EQ(read, nnz);
    EXPECT_EQ(upper, 0);
    EXPECT_EQ(positive_diagonal, free);
    FILE* part = std::fopen((path + ".part").c_str(), "r");
    EXPECT_EQ(part, nullptr);
    if (part) std::fclose(part);
    std::remove(path.c_str());
}

TEST(NeoHookean, ChordStepsReachTheSameEquilibriumWithFewerFactorisations) {
    // The box pressed 0.4 mm (20 %) in one load step: with chord steps (an iteration whose residual fell to a tenth
    // of the last one's solves with the last factorisation) the solve ends at the Newton solve's equilibrium within
    // the tolerance, with fewer factorisations; with the chords off none is taken.
    const ClampedBox box;
    const fem::NeoHookeanSolid& solid = box.solid;
    const Eigen::VectorXi& fixed = box.fixed;
    const std::vector<std::pair<int, double>> top = box.pressed(0.4);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(solid.dofs());
    fem::NewtonOptions o;
    o.tolerance = 1e-10;
    const fem::NewtonResult newton = fem::solve_neo_hookean(solid, fixed, top, zero, o);
    EXPECT_EQ(newton.chord_steps, 0);
    o.chord_ratio = 0.1;
    const fem::NewtonResult chords = fem::solve_neo_hookean(solid, fixed, top, zero, o);
    std::printf("pressed 20 %%: Newton %d iterations, %d factorisations; with chords %d iterations (%d chord steps), %d factorisations\n",
                newton.iterations, newton.factorisations, chords.iterations, chords.chord_steps, chords.factorisations);
    ASSERT_TRUE(chords.converged);
    EXPECT_GT(chords.chord_steps, 0);
    EXPECT_LT(chords.factorisations, newton.factorisations);
    EXPECT_LE(chords.residual, 1e-10);
    EXPECT_LT((chords.u - newton.u).cwiseAbs().maxCoeff(), 1e-8);
    EXPECT_LT((chords.reaction - newton.reaction).cwiseAbs().maxCoeff(), 1e-8 * newton.reaction.cwiseAbs().maxCoeff());
}

}  // namespace

TEST(NeoHookean, ACancelledSolveStopsBeforeItsNextIteration) {
    // A real-time run that ends sets the flag from another thread: with keep_going the solve returns its last
    // accepted state, not converged and marked cancelled; without, it throws aneu::Cancelled. Cleared, the same
    // call converges.
    const ClampedBox box;
    std::atomic<bool> stop{true};
    fem::NewtonOptions o;
    o.keep_going = true;
    o.cancel = &stop;
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(box.solid.dofs());
    const fem::NewtonResult r = fem::solve_neo_hookean(box.solid, box.fixed, box.pressed(0.2), zero, o);
    EXPECT_TRUE(r.cancelled);
    EXPECT_FALSE(r.converged);
    EXPECT_EQ(r.failure, "cancelled");
    EXPECT_EQ(r.iterations, 0);
    o.keep_going = false;
    EXPECT_THROW(fem::solve_neo_hookean(box.solid, box.fixed, box.pressed(0.2), zero, o), Cancelled);
    stop = false;
    const fem::NewtonResult c = fem::solve_neo_hookean(box.solid, box.fixed, box.pressed(0.2), zero, o);
    EXPECT_TRUE(c.converged);
    EXPECT_FALSE(c.cancelled);
    EXPECT_GT(c.iterations, 0);
}
