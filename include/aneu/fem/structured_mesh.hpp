// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Structured tetrahedral meshes of simple solids with known solutions (tube walls, boxes), for analytic
/// tests, benchmarks and the trade study. Every hexahedral cell is split into 6 tetrahedra along its main
/// diagonal (Kuhn subdivision), which conforms across cells; every tetrahedron is positively oriented.
#include <Eigen/Core>

namespace aneu::fem {

/// A tetrahedral mesh with the node sets of a tube wall.
struct StructuredMesh {
    Eigen::MatrixX3d V;      ///< #N×3 [mm]
    Eigen::MatrixXi T;       ///< #T×4
    Eigen::VectorXi inner;   ///< nodes on the inner surface (tube) / the x = 0 face (box)
    Eigen::VectorXi outer;   ///< nodes on the outer surface (tube) / the x = size face (box)
    Eigen::VectorXi ends;    ///< nodes on the end planes z = 0 and z = length
};

/// Wall of a tube around the z axis: radii r_in..r_out, z in [0, length], angle θ in [0, theta_span]
/// (2π: closed ring), with n_r × n_theta × n_z cells. Nodes lie exactly on the circles.
StructuredMesh tube_mesh(double r_in, double r_out, double length, int n_r, int n_theta, int n_z,
                         double theta_span = 6.283185307179586);

/// DOF sets of a tube wall held at both ends: fixed = every DOF of the end nodes, kept = every DOF of the
/// outer nodes that are not at an end (the simulated surface), both sorted.
struct WallDofSets {
    Eigen::VectorXi fixed, kept;
};
WallDofSets wall_dof_sets(const StructuredMesh& m);

/// The box [0,sx]×[0,sy]×[0,sz] with nx × ny × nz cells.
StructuredMesh box_mesh(double sx, double sy, double sz, int nx, int ny, int nz);

}  // namespace aneu::fem
