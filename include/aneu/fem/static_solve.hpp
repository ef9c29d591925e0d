// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A static linear solve of the assembled model (K u = f with u = 0 on the fixed DOFs), the faces of a node
/// set on the mesh boundary, and the loads of a uniform pressure on them: the model checked on its own
/// (`aneuprep solve`) and against another FEM code (`aneuprep export --format inp`).
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "aneu/core/bundle.hpp"

namespace aneu::fem {

/// Boundary faces of the tetrahedra `T` (#T×4 or #T×10) whose corners all lie in `node_set`, oriented
/// outward from their tetrahedron: #F×3 for 4-node tets, #F×6 for 10-node tets (corners, then the mid-edge
/// nodes of (0,1), (1,2), (2,0)), as pressure_loads takes them. `face_tet`, when given, receives each face's tetrahedron.
Eigen::MatrixXi boundary_faces_in_set(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& node_set,
                                      Eigen::VectorXi* face_tet = nullptr);

/// Consistent nodal forces [N] (3#N) of a pressure p [MPa] on the faces of node set `set` ("inner": blood
/// pressure). @throws InputError when the set is missing or has no boundary face
Eigen::VectorXd set_pressure_loads(const VolumeData& vol, const std::string& set, double p_mpa);

/// Displacement and the reactions at the prescribed DOFs.
struct DirichletResult {
    Eigen::VectorXd u;         ///< 3#N [mm]
    Eigen::VectorXd reaction;  ///< per prescribed DOF, in its order: K u − f there [N] (the force the constraint applies)
};
/// u with K u = f (f = 0 when null) on the free DOFs, u = 0 on fem.fixed_dofs and u = value on each prescribed
/// (DOF, value) (CHOLMOD supernodal Cholesky): the reference of the simulator's contact solve.
/// @throws InputError a DOF outside K or given twice; NumericalError K_ff is not positive definite
DirichletResult solve_dirichlet(const FemData& fem, const std::vector<std::pair<int, double>>& prescribed,
                                const Eigen::VectorXd* f = nullptr);

/// u (3#N) with K u = f on the free DOFs and u = 0 on fem.fixed_dofs (CHOLMOD supernodal Cholesky).
/// @throws NumericalError when K_ff is not positive definite
Eigen::VectorXd solve_static(const FemData& fem, const Eigen::VectorXd& f);

}  // namespace aneu::fem
