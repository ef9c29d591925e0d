// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Prescribed surface displacements → contact forces → deformation, through the condensed compliance W.
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"

namespace aneu::sim {

/// Sorted, disjoint [first, last) ranges of permuted rows.
using RowRanges = std::vector<std::pair<Eigen::Index, Eigen::Index>>;

/// The rows of surface vertices (all in the working region) as runs of whole 16-row blocks (a 64-byte line of
/// floats): memory is read by lines anyway, and each row then goes through the same (vectorised or not)
/// arithmetic as in a whole-region update, so rows computed this way are bit-identical to it.
RowRanges rows_of_vertices(const SimModel& model, const std::vector<int>& vertices);

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
    Eigen::VectorXd d;                    ///< displacement [mm] of the rows asked for (permuted order; zero between ranges)
    std::vector<Eigen::Vector3d> group_shift;  ///< translation of each group [mm]
    bool refactored = false;              ///< the Cholesky factor changed (the node set changed)
    bool factor_updated = false;          ///< it was updated for the nodes that came and went, not recomputed
    /// max |d − u| / max |u| over the prescribed rows (W_CC f = u), when d covers them; −1 otherwise
    double residual = -1.0;
    bool recomputed_for_residual = false; ///< an updated factor had drifted: recomputed and solved again
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
    /// Same, computing d only on `rows` (e.g. the nodes near the instruments; the SMVM is the cost of a frame).
    SolveResult solve(const std::vector<Prescribed>& p, int n_groups, GroupMethod method, const RowRanges& rows);

    /// Estimate of cond₁(W_CC) of the last solve's node set (Hager's estimator with the factor, ‖W_CC‖₁ from W):
    /// the forces lose about log10 of it digits of the working precision (float32 has 7). O(n²): call it at a
    /// low rate.
    double condition_estimate() const;
    /// Threads of the SMVM [2]: it is bound by memory bandwidth, which one core does not saturate here.
    void set_threads(int n);
    /// d on rows [first, last) for the forces of the last solve (e.g. the rest of the surface at output rate).
    Eigen::VectorXd deformation(Eigen::Index first, Eigen::Index last) const;
    /// d on `rows` for the forces of the last solve (vector up to the last range's end, zero between ranges).
    Eigen::VectorXd deformation(const RowRanges& rows) const;

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
};

}  // namespace aneu::sim
