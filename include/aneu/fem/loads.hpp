// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Consistent nodal loads of surface tractions.
#include <Eigen/Core>

namespace aneu::fem {

/// Consistent nodal forces [N] of a uniform pressure p [MPa] on boundary faces, as a vector of 3#N DOFs.
/// @param[in] F  #F×3 (linear) or #F×6 (quadratic: corners, then mid-edges (0,1), (1,2), (2,0)) faces,
///               oriented with the outward normal of the solid; the pressure pushes against that normal
Eigen::VectorXd pressure_loads(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& F, double p_mpa);

}  // namespace aneu::fem
