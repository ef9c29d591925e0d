// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Measures of a clipping's result on the deformed vessel (sim/assessment.cpp).
#include <vector>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"

namespace aneu::sim {

/// How much of the aneurysm's neck is occluded.
struct NeckOcclusion {
    double length_mm = 0.0;            ///< deformed length of the neck line on the lumen (the inner wall)
    double closed_mm = 0.0;            ///< of which the opposite inner walls touch or lie within the tolerance
    double fraction = 0.0;             ///< closed_mm / length_mm (0 when there is no neck)
    double min_gap_mm = 0.0;           ///< smallest lumen gap found across the neck line (negative: interpenetration)
    double max_interpenetration_mm = 0.0;  ///< largest depth of one inner wall through the opposite one (0: none)
    /// Per neck loop, per vertex in loop order: the lumen gap there (+inf: no opposite wall within reach), so a
    /// report can say where along the neck line it stays open.
    std::vector<std::vector<double>> gap_mm;
};

/// Neck occlusion on the deformed lumen `y` (#L×3, SimLumen::deformed). The neck line is the sac's border on
/// the lumen (SimLumen::neck_loops). At each of its vertices the lumen gap is the distance across the lumen
/// (against the vertex's deformed normal) to the nearest opposite wall — faces whose deformed normal turns more
/// than 120° from the vertex's, not its own or its one ring's — negative when that wall lies behind the vertex
/// within its own wall (`wall_mm` per vertex: the walls pass through each other). A neck edge is closed when the
/// gaps at both its ends are at most `gap_tol_mm`; at a vertex with no opposite wall within 12 mm the gap is
/// infinite. Lengths are the deformed
/// lumen's: where a clip flattens the neck, its two folds collapse to almost no length. A clip across the neck
/// that presses the walls together closes nearly all of it; a clip beside the neck closes none.
NeckOcclusion neck_occlusion(const SimLumen& lumen, const Eigen::MatrixX3d& y, double gap_tol_mm, const Eigen::VectorXd& wall_mm);

}  // namespace aneu::sim
