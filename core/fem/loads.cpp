// SPDX-License-Identifier: MIT
#include "aneu/fem/loads.hpp"

#include <Eigen/Geometry>

#include "aneu/core/error.hpp"

namespace aneu::fem {

Eigen::VectorXd pressure_loads(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& F, double p) {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * V.rows());
    if (F.cols() == 3) {
        for (Eigen::Index e = 0; e < F.rows(); ++e) {
            const Eigen::Vector3d a = V.row(F(e, 0)), b = V.row(F(e, 1)), c = V.row(F(e, 2));
            const Eigen::Vector3d area_normal = 0.5 * (b - a).cross(c - a);  // |.| = area, outward
            for (int k = 0; k < 3; ++k) f.segment<3>(3 * F(e, k)) -= p * area_normal / 3.0;
        }
        return f;
    }
    if (F.cols() != 6) throw InputError("pressure_loads: faces must have 3 or 6 nodes");
    // Degree-4 rule on the triangle (Dunavant, 6 points): N_a (degree 2) times the area element of a
    // quadratic face (degree 2) is integrated exactly.
    static constexpr double PTS[6][3] = {{0.445948490915965, 0.445948490915965, 0.223381589678011},
                                         {0.445948490915965, 0.108103018168070, 0.223381589678011},
                                         {0.108103018168070, 0.445948490915965, 0.223381589678011},
                                         {0.091576213509771, 0.091576213509771, 0.109951743655322},
                                         {0.091576213509771, 0.816847572980459, 0.109951743655322},
                                         {0.816847572980459, 0.091576213509771, 0.109951743655322}};
    for (Eigen::Index e = 0; e < F.rows(); ++e) {
        Eigen::Matrix<double, 6, 3> X;
        for (int k = 0; k < 6; ++k) X.row(k) = V.row(F(e, k));
        for (const auto& q : PTS) {
            const double s = q[0], t = q[1], L0 = 1.0 - s - t, L[3] = {L0, s, t};
            double N[6];
            Eigen::Matrix<double, 6, 2> dN;  // ∂N/∂s, ∂N/∂t
            for (int k = 0; k < 3; ++k) N[k] = L[k] * (2 * L[k] - 1);
            N[3] = 4 * L0 * s;
            N[4] = 4 * s * t;
            N[5] = 4 * t * L0;
            dN << -(4 * L0 - 1), -(4 * L0 - 1),  //
                4 * s - 1, 0,                    //
                0, 4 * t - 1,                    //
                4 * (L0 - s), -4 * s,            //
                4 * t, 4 * s,                    //
                -4 * t, 4 * (L0 - t);
            const Eigen::Vector3d xs = X.transpose() * dN.col(0), xt = X.transpose() * dN.col(1);
            const Eigen::Vector3d dA = xs.cross(xt) * (0.5 * q[2]);  // reference area 1/2
            for (int k = 0; k < 6; ++k) f.segment<3>(3 * F(e, k)) -= p * N[k] * dA;
        }
    }
    return f;
}

}  // namespace aneu::fem
