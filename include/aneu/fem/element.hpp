// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Isotropic linear-elastic element kernels for 4-node and 10-node tetrahedra (small strain).
/// 10-node ordering (as VTK_QUADRATIC_TETRA and Abaqus C3D10): corners 0–3, then mid-edge nodes
/// 4:(0,1) 5:(1,2) 6:(2,0) 7:(0,3) 8:(1,3) 9:(2,3). DOF order within an element: node-major, x y z.
#include <Eigen/Core>

namespace aneu::fem {

/// 6×6 isotropic elasticity matrix in Voigt order (xx, yy, zz, yz, xz, xy), engineering shear strains.
/// @param[in] E_mpa Young's modulus [MPa], nu Poisson's ratio
Eigen::Matrix<double, 6, 6> elasticity_matrix(double E_mpa, double nu);

/// Signed volume of a tetrahedron [mm³]; positive when (x1−x0, x2−x0, x3−x0) is right-handed.
double tet_volume(const Eigen::Matrix<double, 4, 3>& X);

/// Stiffness of a 4-node tetrahedron [N/mm], 12×12.
/// @param[in] X  node coordinates [mm], one row per node
/// @throws MeshingError if the tetrahedron is inverted or degenerate (volume ≤ 0)
Eigen::Matrix<double, 12, 12> linear_tet_stiffness(const Eigen::Matrix<double, 4, 3>& X, double E_mpa, double nu);

/// Stiffness of a 10-node tetrahedron [N/mm], 30×30, by the 4-point Gauss rule (exact for straight
/// edges; the rule CalculiX uses for C3D10). Mid-edge nodes may be off the straight edge (curved element).
/// @throws MeshingError if the Jacobian is not positive at an integration point
Eigen::Matrix<double, 30, 30> quadratic_tet_stiffness(const Eigen::Matrix<double, 10, 3>& X, double E_mpa,
                                                      double nu);

/// ∂N/∂ξ (10×3) of the 10-node tetrahedron's shape functions at reference point ξ (barycentric L1, L2, L3;
/// L0 = 1 − ΣLk).
Eigen::Matrix<double, 10, 3> quadratic_tet_shape_gradients(const Eigen::Vector3d& xi);

/// The 4-point, degree-2 Gauss rule on the reference tetrahedron (points ξ; each weight 1/24, a quarter of
/// the reference volume): the rule of quadratic_tet_stiffness.
inline constexpr double QUADRATIC_TET_RULE_A = 0.5854101966249685, QUADRATIC_TET_RULE_B = 0.1381966011250105;
inline constexpr double QUADRATIC_TET_RULE_POINTS[4][3] = {{QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_B},
                                                           {QUADRATIC_TET_RULE_A, QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_B},
                                                           {QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_A, QUADRATIC_TET_RULE_B},
                                                           {QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_B, QUADRATIC_TET_RULE_A}};
inline constexpr double QUADRATIC_TET_RULE_WEIGHT = 1.0 / 24.0;

/// The (a,b) corner pair of each mid-edge node 4..9 of a 10-node tetrahedron.
inline constexpr int QUADRATIC_TET_EDGES[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};

}  // namespace aneu::fem
