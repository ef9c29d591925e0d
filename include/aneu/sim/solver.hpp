// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Prescribed surface displacements → contact forces → deformation, through the condensed compliance W.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"

namespace aneu::sim {

/// One node with a prescribed displacement.
struct Prescribed {
    Eigen::Vector3i cols;      ///< the node's x, y, z columns of W (= permuted rows, < n_active)
    Eigen::Vector3d u;         ///< prescribed displacement [mm]; for a group member, relative to the group's translation
    int group = -1;            ///< ≥ 0: the node belongs to a free rigid group (a deposited clip); see ContactSolver
};

/// How deposited clips (groups) move with the vessel.
enum class GroupMethod {
    EXACT,      ///< each group is a free rigid body translating by r_g with zero net force: one augmented solve
    TWO_SOLVE,  ///< as published: solve without the groups, shift each group by its nodes' mean displacement, solve again
};

/// Result of one solve.
struct SolveResult {
    Eigen::VectorXd f;                    ///< 3n contact forces on the vessel [N], in the order of the prescribed list
    Eigen::VectorXd d;                    ///< displacement of the model's first `rows` rows [mm] (permuted order)
    std::vector<Eigen::Vector3d> group_shift;  ///< translation of each group [mm]
    bool refactored = false;              ///< the Cholesky factor was recomputed (the node set changed)
    double factor_s = 0.0, solve_s = 0.0, smvm_s = 0.0;  ///< time split [s]
};

/// Solves W_CC f = u_C and d = W_{:,C} f on the loaded columns of a SimModel, in the model's precision.
/// The Cholesky factor of W_CC (and of the group Schur complement) is kept and reused while the set of
/// prescribed nodes and their groups do not change; only the right-hand side then changes.
class ContactSolver {
public:
    explicit ContactSolver(const SimModel& model);
    ~ContactSolver();
    ContactSolver(const ContactSolver&) = delete;
    ContactSolver& operator=(const ContactSolver&) = delete;

    /// @param[in] p        prescribed nodes (columns must be distinct and < n_active; groups 0..G-1)
    /// @param[in] n_groups number of groups G
    /// @param[in] rows     how many permuted rows of d to compute (n_active: the working region; #M: all)
    /// @throws NumericalError W_CC is not positive definite (duplicate or degenerate columns)
    SolveResult solve(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, Eigen::Index rows);

    /// d on rows [first, last) for the forces of the last solve (e.g. the rest of the surface at output rate).
    Eigen::VectorXd deformation(Eigen::Index first, Eigen::Index last) const;

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
};

}  // namespace aneu::sim
