// SPDX-License-Identifier: MIT
#include "aneu/fem/element.hpp"

#include <Eigen/LU>
#include <string>

#include "aneu/core/error.hpp"

namespace aneu::fem {

namespace {

/// Strain-displacement matrix rows for one node with shape-function gradient g (Voigt order).
template <int N>
void fill_B(Eigen::Matrix<double, 6, 3 * N>& B, int a, const Eigen::Vector3d& g) {
    const int c = 3 * a;
    B(0, c) = g.x();
    B(1, c + 1) = g.y();
    B(2, c + 2) = g.z();
    B(3, c + 1) = g.z();
    B(3, c + 2) = g.y();
    B(4, c) = g.z();
    B(4, c + 2) = g.x();
    B(5, c) = g.y();
    B(5, c + 1) = g.x();
}

}  // namespace

Eigen::Matrix<double, 10, 3> quadratic_tet_shape_gradients(const Eigen::Vector3d& xi) {
    const double L[4] = {1.0 - xi.sum(), xi[0], xi[1], xi[2]};
    Eigen::Matrix<double, 10, 4> dNdL = Eigen::Matrix<double, 10, 4>::Zero();
    for (int i = 0; i < 4; ++i) dNdL(i, i) = 4.0 * L[i] - 1.0;
    for (int e = 0; e < 6; ++e) {
        const int a = QUADRATIC_TET_EDGES[e][0], b = QUADRATIC_TET_EDGES[e][1];
        dNdL(4 + e, a) = 4.0 * L[b];
        dNdL(4 + e, b) = 4.0 * L[a];
    }
    Eigen::Matrix<double, 10, 3> dNdxi;
    for (int k = 0; k < 3; ++k) dNdxi.col(k) = dNdL.col(k + 1) - dNdL.col(0);  // chain rule through L0
    return dNdxi;
}

Eigen::Matrix<double, 6, 6> elasticity_matrix(double E, double nu) {
    const double lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    const double mu = E / (2.0 * (1.0 + nu));
    Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
    D.topLeftCorner<3, 3>().setConstant(lambda);
    D.topLeftCorner<3, 3>().diagonal().array() += 2.0 * mu;
    D.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
    return D;
}

double tet_volume(const Eigen::Matrix<double, 4, 3>& X) {
    Eigen::Matrix3d J;
    for (int k = 0; k < 3; ++k) J.col(k) = (X.row(k + 1) - X.row(0)).transpose();
    return J.determinant() / 6.0;
}

Eigen::Matrix<double, 12, 12> linear_tet_stiffness(const Eigen::Matrix<double, 4, 3>& X, double E, double nu) {
    Eigen::Matrix3d J;
    for (int k = 0; k < 3; ++k) J.col(k) = (X.row(k + 1) - X.row(0)).transpose();
    const double V = J.determinant() / 6.0;
    if (!(V > 0.0)) throw MeshingError("linear tetrahedron has volume " + std::to_string(V) + " mm^3 (inverted or degenerate)");
    const Eigen::Matrix3d G = J.inverse();  // row k = ∇ξ_k
    Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
    fill_B<4>(B, 0, -(G.row(0) + G.row(1) + G.row(2)).transpose());
    for (int k = 0; k < 3; ++k) fill_B<4>(B, k + 1, G.row(k).transpose());
    return V * B.transpose() * elasticity_matrix(E, nu) * B;
}

Eigen::Matrix<double, 30, 30> quadratic_tet_stiffness(const Eigen::Matrix<double, 10, 3>& X, double E, double nu) {
    const Eigen::Matrix<double, 6, 6> D = elasticity_matrix(E, nu);
    const double w = QUADRATIC_TET_RULE_WEIGHT;
    Eigen::Matrix<double, 30, 30> K = Eigen::Matrix<double, 30, 30>::Zero();
    for (const auto& pt : QUADRATIC_TET_RULE_POINTS) {
        const Eigen::Matrix<double, 10, 3> dNdxi = quadratic_tet_shape_gradients(Eigen::Vector3d(pt[0], pt[1], pt[2]));
        const Eigen::Matrix3d J = X.transpose() * dNdxi;  // J(i,j) = ∂x_i/∂ξ_j
        const double detJ = J.determinant();
        if (!(detJ > 0.0)) {
            throw MeshingError("quadratic tetrahedron has Jacobian " + std::to_string(detJ) +
                               " at an integration point (inverted, degenerate or too strongly curved)");
        }
        const Eigen::Matrix<double, 10, 3> dNdx = dNdxi * J.inverse();  // rows: ∇x N_n
        Eigen::Matrix<double, 6, 30> B = Eigen::Matrix<double, 6, 30>::Zero();
        for (int n = 0; n < 10; ++n) fill_B<10>(B, n, dNdx.row(n).transpose());
        K.noalias() += (w * detJ) * B.transpose() * D * B;
    }
    return K;
}

}  // namespace aneu::fem
