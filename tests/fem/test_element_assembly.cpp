// SPDX-License-Identifier: MIT
// Element kernels and assembly: rigid-body modes, symmetry, patch tests, the Lamé thick-walled tube.
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/element.hpp"
#include "aneu/fem/loads.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "fem_test_util.hpp"

using namespace aneu;
using namespace aneu::fem;
using Sparse = Eigen::SparseMatrix<double, Eigen::RowMajor>;

namespace {

/// Round-off bound of K·r relative to ||K||·||r|| (a few hundred ulps of the assembled sums).
constexpr double ROUND_OFF = 1e-12;
/// Patch tests reproduce a linear field to round-off of the solve.
constexpr double PATCH_TOL = 1e-10;

const std::vector<Material> ONE_MAT{{"artery", 1.0, 0.45}};

/// The 6 rigid-body modes of a node set as columns (3 translations, 3 rotations about the centroid).
Eigen::MatrixXd rigid_modes(const Eigen::MatrixX3d& V) {
    Eigen::MatrixXd R = Eigen::MatrixXd::Zero(3 * V.rows(), 6);
    const Eigen::RowVector3d c = V.colwise().mean();
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
        const Eigen::Vector3d x = (V.row(i) - c).transpose();
        for (int a = 0; a < 3; ++a) R(3 * i + a, a) = 1.0;
        for (int a = 0; a < 3; ++a) R.block<3, 1>(3 * i, 3 + a) = Eigen::Vector3d::Unit(a).cross(x);
    }
    return R;
}

double max_abs_coeff(const Sparse& K) {
    double m = 0;
    for (Eigen::Index k = 0; k < K.nonZeros(); ++k) m = std::max(m, std::abs(K.valuePtr()[k]));
    return m;
}

Eigen::VectorXi all_regions_zero(Eigen::Index n) { return Eigen::VectorXi::Zero(n); }

}  // namespace

TEST(Element, LinearTetMatchesHandComputedEntry) {
    // Unit right tetrahedron, E = 1, ν = 0: K(0,0) = V·(D B)ᵀB entry = (1/6)·(1·1 + 0.5·1 + 0.5·1) = 1/3.
    Eigen::Matrix<double, 4, 3> X;
    X << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
    const auto K = linear_tet_stiffness(X, 1.0, 0.0);
    EXPECT_NEAR(K(0, 0), 1.0 / 3.0, 1e-15);
    EXPECT_NEAR((K - K.transpose()).norm(), 0.0, 1e-15);
    X.row(3) << 0, 0, -1;  // inverted
    EXPECT_THROW(linear_tet_stiffness(X, 1.0, 0.3), MeshingError);
}

TEST(Element, QuadraticWithStraightEdgesHasSameRigidModesAndPositiveEnergy) {
    Eigen::Matrix<double, 4, 3> C;
    C << 0.1, 0, 0, 1.2, 0.1, 0, 0.2, 0.9, 0.1, 0, 0.3, 1.1;
    Eigen::Matrix<double, 10, 3> X;
    X.topRows<4>() = C;
    for (int e = 0; e < 6; ++e) X.row(4 + e) = 0.5 * (C.row(QUADRATIC_TET_EDGES[e][0]) + C.row(QUADRATIC_TET_EDGES[e][1]));
    const auto K = quadratic_tet_stiffness(X, 2.0, 0.3);
    EXPECT_LT((K - K.transpose()).norm(), 1e-13 * K.norm());
    const Eigen::MatrixXd R = rigid_modes(X);
    EXPECT_LT((K * R).norm(), ROUND_OFF * K.norm() * R.norm());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 30, 30>> es(K);
    EXPECT_LT(std::abs(es.eigenvalues()[5]), 1e-10 * es.eigenvalues()[29]);  // exactly 6 zero modes
    EXPECT_GT(es.eigenvalues()[6], 1e-6 * es.eigenvalues()[29]);
}

TEST(Assembly, RigidBodyModesAndSymmetryBothOrders) {
    const StructuredMesh m = tube_mesh(1.5, 1.9, 3.0, 2, 12, 4);
    const Sparse K1 = assemble_stiffness(m.V, m.T, all_regions_zero(m.T.rows()), ONE_MAT);
    const QuadraticMesh q = quadratic_mesh(m.V, m.T);
    const Sparse K2 = assemble_stiffness(q.V, q.T, all_regions_zero(q.T.rows()), ONE_MAT);
    for (const auto* pair : {&K1, &K2}) {
        const Sparse& K = *pair;
        const Eigen::MatrixX3d& V = (&K == &K1) ? m.V : q.V;
        const Eigen::MatrixXd R = rigid_modes(V);
        const Eigen::MatrixXd KR = K * R;
        for (int c = 0; c < 6; ++c) {
            EXPECT_LT(KR.col(c).cwiseAbs().maxCoeff(), ROUND_OFF * max_abs_coeff(K) * R.col(c).cwiseAbs().maxCoeff() * 100)
                << "mode " << c << (&K == &K1 ? " linear" : " quadratic");
        }
        EXPECT_EQ((Sparse(K.transpose()) - K).norm(), 0.0);  // assembled symmetric exactly
    }
    EXPECT_EQ(K1.rows(), 3 * m.V.rows());
    EXPECT_EQ(K2.rows(), 3 * q.V.rows());
}

class PatchTest : public ::testing::TestWithParam<int> {};

TEST_P(PatchTest, LinearFieldIsReproducedInside) {
    const int order = GetParam();
    StructuredMesh m = box_mesh(1.0, 1.3, 0.9, 3, 3, 3);
    // Perturb interior nodes so the patch is irregular.
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
        const Eigen::RowVector3d x = m.V.row(i);
        const bool interior = x.minCoeff() > 1e-9 && x[0] < 1.0 - 1e-9 && x[1] < 1.3 - 1e-9 && x[2] < 0.9 - 1e-9;
        if (interior) m.V.row(i) += 0.07 * Eigen::RowVector3d(std::sin(3.0 * i), std::cos(5.0 * i), std::sin(7.0 * i));
    }
    Eigen::MatrixX3d V = m.V;
    Eigen::MatrixXi T = m.T;
    if (order == 2) {
        const QuadraticMesh q = quadratic_mesh(m.V, m.T);
        V = q.V;
        T = q.T;
    }
    const Sparse K = assemble_stiffness(V, T, all_regions_zero(T.rows()), {{"m", 3.0, 0.3}});
    Eigen::Matrix3d A;
    A << 0.01, -0.02, 0.005, 0.003, 0.02, -0.01, 0.007, 0.001, -0.015;
    const Eigen::Vector3d c(0.1, -0.2, 0.05);
    Eigen::VectorXd exact(3 * V.rows()), zero = Eigen::VectorXd::Zero(3 * V.rows());
    std::vector<char> fixed(static_cast<size_t>(3 * V.rows()), 0);
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
        exact.segment<3>(3 * i) = A * V.row(i).transpose() + c;
        const Eigen::RowVector3d x = V.row(i);
        const bool boundary = x.minCoeff() < 1e-9 || x[0] > 1.0 - 1e-9 || x[1] > 1.3 - 1e-9 || x[2] > 0.9 - 1e-9;
        if (boundary)
            for (int a = 0; a < 3; ++a) fixed[static_cast<size_t>(3 * i + a)] = 1;
    }
    const Eigen::VectorXd u = test::solve_dirichlet(K, zero, fixed, exact);
    EXPECT_LT((u - exact).cwiseAbs().maxCoeff(), PATCH_TOL) << "order " << order;
}
INSTANTIATE_TEST_SUITE_P(BothOrders, PatchTest, ::testing::Values(1, 2));

namespace {

/// Lamé: radial displacement of a thick tube under internal pressure p, plane strain (REFERENCE.md).
double lame_ur(double r, double a, double b, double E, double nu, double p) {
    const double A = p * a * a / (b * b - a * a), B = p * a * a * b * b / (b * b - a * a);
    return (1 + nu) / E * ((1 - 2 * nu) * A * r + B / r);
}

struct LameError {
    double inner, outer;
};

/// Quarter tube (symmetry planes x = 0, y = 0), u_z = 0 everywhere (plane strain), pressure inside.
LameError lame_errors(int order, int n_r, int n_theta, bool curved, double nu = 0.45, double thickness = 0.4) {
    const double a = 1.5, b = a + thickness, E = 1.0, p = 0.01, L = 0.8;
    const StructuredMesh m = tube_mesh(a, b, L, n_r, n_theta, 2, M_PI / 2);
    Eigen::MatrixX3d V = m.V;
    Eigen::MatrixXi T = m.T;
    Eigen::MatrixXi F = boundary_faces(m.T);
    Eigen::VectorXi inner_set = m.inner, outer_set = m.outer;
    if (order == 2) {
        const QuadraticMesh q = quadratic_mesh(m.V, m.T);
        V = q.V;
        T = q.T;
        if (curved) {  // mid-edge nodes on the exact cylinders: midpoint in (r, θ, z)
            for (Eigen::Index k = 0; k < q.edge_of_mid.rows(); ++k) {
                const Eigen::Vector3d x0 = m.V.row(q.edge_of_mid(k, 0)), x1 = m.V.row(q.edge_of_mid(k, 1));
                const double r = 0.5 * (x0.head<2>().norm() + x1.head<2>().norm());
                const double th = 0.5 * (std::atan2(x0.y(), x0.x()) + std::atan2(x1.y(), x1.x()));
                V.row(m.V.rows() + k) << r * std::cos(th), r * std::sin(th), 0.5 * (x0.z() + x1.z());
            }
        }
        F = quadratic_faces(q, static_cast<int>(m.V.rows()), F);
        inner_set = quadratic_node_set(q, m.T, static_cast<int>(m.V.rows()), m.inner);
        outer_set = quadratic_node_set(q, m.T, static_cast<int>(m.V.rows()), m.outer);
    }
    // Pressure on the faces of the inner surface only.
    std::vector<char> is_inner(static_cast<size_t>(V.rows()), 0);
    for (Eigen::Index k = 0; k < inner_set.size(); ++k) is_inner[static_cast<size_t>(inner_set[k])] = 1;
    std::vector<int> keep;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (is_inner[static_cast<size_t>(F(f, 0))] && is_inner[static_cast<size_t>(F(f, 1))] && is_inner[static_cast<size_t>(F(f, 2))])
            keep.push_back(static_cast<int>(f));
    Eigen::MatrixXi Fin(static_cast<Eigen::Index>(keep.size()), F.cols());
    for (size_t k = 0; k < keep.size(); ++k) Fin.row(static_cast<Eigen::Index>(k)) = F.row(keep[k]);
    const Eigen::VectorXd f = pressure_loads(V, Fin, p);
    const Sparse K = assemble_stiffness(V, T, Eigen::VectorXi::Zero(T.rows()), {{"wall", E, nu}});
    std::vector<char> fixed(static_cast<size_t>(3 * V.rows()), 0);
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
        fixed[static_cast<size_t>(3 * i + 2)] = 1;                                // plane strain
        if (std::abs(V(i, 1)) < 1e-12) fixed[static_cast<size_t>(3 * i + 1)] = 1;  // y = 0 plane
        if (std::abs(V(i, 0)) < 1e-12) fixed[static_cast<size_t>(3 * i)] = 1;      // x = 0 plane
    }
    const Eigen::VectorXd u = test::solve_dirichlet(K, f, fixed, Eigen::VectorXd::Zero(3 * V.rows()));
    auto mean_ur = [&](const Eigen::VectorXi& set) {
        double s = 0;
        for (Eigen::Index k = 0; k < set.size(); ++k) {
            const Eigen::Vector3d x = V.row(set[k]);
            s += u.segment<3>(3 * set[k]).head<2>().dot(x.head<2>().normalized());
        }
        return s / set.size();
    };
    return {mean_ur(inner_set) / lame_ur(a, a, b, E, nu, p) - 1.0, mean_ur(outer_set) / lame_ur(b, a, b, E, nu, p) - 1.0};
}

}  // namespace

TEST(Lame, AnalyticValuesOfReference) {
    EXPECT_NEAR(lame_ur(1.5, 1.5, 1.9, 1.0, 0.45, 0.01), 0.0613318, 5e-8);
    EXPECT_NEAR(lame_ur(1.9, 1.5, 1.9, 1.0, 0.45, 0.01), 0.0501369, 5e-8);
}

TEST(Lame, LinearTetsConvergeAndCurvedQuadraticTetsAreWithinOnePercent) {
    // h ≈ 0.4, 0.2, 0.1 mm through the 0.4 mm wall and along the circumference (θ span π/2 at r ≈ 1.7).
    const LameError l1 = lame_errors(1, 1, 7, false), l2 = lame_errors(1, 2, 14, false), l3 = lame_errors(1, 4, 27, false);
    RecordProperty("linear_h0.4_inner", std::to_string(l1.inner));
    RecordProperty("linear_h0.2_inner", std::to_string(l2.inner));
    RecordProperty("linear_h0.1_inner", std::to_string(l3.inner));
    EXPECT_GT(std::abs(l1.inner), std::abs(l2.inner));
    EXPECT_GT(std::abs(l2.inner), std::abs(l3.inner));
    EXPECT_GT(std::abs(l1.outer), std::abs(l2.outer));
    EXPECT_GT(std::abs(l2.outer), std::abs(l3.outer));
    EXPECT_LT(std::abs(l3.inner), 0.05);
    const LameError q = lame_errors(2, 1, 7, true);  // quadratic, curved, h ≈ 0.4 mm: a practical size
    RecordProperty("quadratic_curved_h0.4_inner", std::to_string(q.inner));
    EXPECT_LT(std::abs(q.inner), 0.01);
    EXPECT_LT(std::abs(q.outer), 0.01);
    std::printf("Lame u_r error inner/outer: linear h0.4 %.4f/%.4f  h0.2 %.4f/%.4f  h0.1 %.4f/%.4f  quadratic curved h0.4 %.5f/%.5f\n",
                l1.inner, l1.outer, l2.inner, l2.outer, l3.inner, l3.outer, q.inner, q.outer);
}

TEST(Lame, NearIncompressibleLinearTetsLockQuadraticTetsDoNot) {
    // Stability at the extremes: ν from 0.3 to 0.4999. Linear tetrahedra lock (too stiff: the displacement error
    // grows as ν → 0.5); curved quadratic tetrahedra stay within 1 % of Lamé at the same node spacing.
    std::vector<double> lin, quad;
    for (double nu : {0.3, 0.45, 0.49, 0.499, 0.4999}) {
        const LameError l = lame_errors(1, 2, 14, false, nu), q = lame_errors(2, 1, 7, true, nu);
        lin.push_back(std::abs(l.inner));
        quad.push_back(std::abs(q.inner));
        std::printf("nu %.4f: linear h0.2 u_r error %.4f, quadratic curved h0.4 %.5f\n", nu, l.inner, q.inner);
        RecordProperty("linear_nu" + std::to_string(nu), std::to_string(l.inner));
        RecordProperty("quadratic_nu" + std::to_string(nu), std::to_string(q.inner));
        EXPECT_LT(std::abs(q.inner), 0.01) << "nu " << nu;
        EXPECT_LT(std::abs(q.outer), 0.01) << "nu " << nu;
    }
    EXPECT_GT(lin.back(), 3.0 * lin.front());  // locking
    EXPECT_GT(lin.back(), 10.0 * quad.back());
}

TEST(Lame, VeryThinWallWithOneElementThroughTheThickness) {
    // Stability at the extremes: a 0.05 mm wall (a/t = 30), one element through the thickness, elements 8 times
    // longer than thick. Under pressure the wall works as a membrane: both orders stay close to Lamé (measured:
    // linear −10.7 % at 0.4 mm, −1.3 % at 0.1, −0.6 % at 0.05; quadratic ≤ 0.05 %). In bending (the study's
    // indenter on the 0.1 mm sac wall) linear tetrahedra lock instead: see bench/results/study.
    for (double t : {0.4, 0.1, 0.05}) {
        const LameError l = lame_errors(1, 1, 14, false, 0.45, t), q = lame_errors(2, 1, 14, true, 0.45, t);
        std::printf("wall %.2f mm, one element through it: linear u_r error %.4f, quadratic curved %.5f\n", t, l.inner, q.inner);
        RecordProperty("thin_linear_t" + std::to_string(t), std::to_string(l.inner));
        RecordProperty("thin_quadratic_t" + std::to_string(t), std::to_string(q.inner));
        EXPECT_LT(std::abs(q.inner), 0.01) << "t " << t;
        EXPECT_LT(std::abs(l.inner), t < 0.2 ? 0.02 : 0.12) << "t " << t;  // thick: the through-thickness gradient
    }
}

TEST(Assembly, BadMaterialsAndSingularMeshesAreRefusedWithNames) {
    const StructuredMesh m = box_mesh(1, 1, 1, 1, 1, 1);
    const Eigen::VectorXi r = all_regions_zero(m.T.rows());
    auto msg = [&](auto&& f) {
        try {
            f();
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("no InputError");
    };
    EXPECT_NE(msg([&] { assemble_stiffness(m.V, m.T, r, {{"sac", 0.0, 0.45}}); }).find("region 'sac': E = 0"), std::string::npos);
    EXPECT_NE(msg([&] { assemble_stiffness(m.V, m.T, r, {{"sac", 1.0, 0.5}}); }).find("nu = 0.5"), std::string::npos);
    EXPECT_NE(msg([&] { assemble_stiffness(m.V, m.T, r, {{"sac", 1.0, -1.0}}); }).find("must be in (-1, 0.5)"), std::string::npos);
    EXPECT_NE(msg([&] { check_constrained(m.V, m.T, Eigen::VectorXi()); }).find("no fixed node"), std::string::npos);
    // Two separate boxes, only the first held.
    const StructuredMesh b = box_mesh(1, 1, 1, 1, 1, 1);
    Eigen::MatrixX3d V(2 * b.V.rows(), 3);
    V << b.V, (b.V.rowwise() + Eigen::RowVector3d(5, 0, 0));
    Eigen::MatrixXi T(2 * b.T.rows(), 4);
    T << b.T, (b.T.array() + static_cast<int>(b.V.rows())).matrix();
    EXPECT_NE(msg([&] { check_constrained(V, T, b.inner); }).find("1 of 2 connected pieces of the mesh have no fixed node"),
              std::string::npos);
    EXPECT_EQ(msg([&] { check_constrained(V, T, (Eigen::VectorXi(2) << 0, 9).finished()); }), "no InputError");
}
