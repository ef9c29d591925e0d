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
    std::vector<std::vector<Eigen::Vector3d>> points;  ///< the neck line's points on the deformed lumen, per loop
};

/// Neck occlusion on the deformed lumen `y` (#L×3, SimLumen::deformed). The neck line is the sac's border on
/// the lumen (SimLumen::neck_loops), smoothed (smoothed_neck_line; SimLumen::neck_line when set, else smoothed
/// here). At each of its points the lumen gap is the distance across the lumen (against the deformed normal
/// interpolated there) to the nearest opposite wall — faces whose deformed normal turns more than 120° from it,
/// not those round its face's corners or their one ring — negative when that wall lies behind the point within
/// its own wall (`wall_mm` per vertex: the walls pass through each other). A segment of the line is closed when
/// the gaps at both its ends are at most `gap_tol_mm`; where no opposite wall lies within 12 mm the gap is
/// infinite. Lengths are the deformed lumen's: where a clip flattens the neck, its two folds collapse to almost
/// no length. A clip across the neck that presses the walls together closes nearly all of it; a clip beside the
/// neck closes none.
NeckOcclusion neck_occlusion(const SimLumen& lumen, const Eigen::MatrixX3d& y, double gap_tol_mm, const Eigen::VectorXd& wall_mm);

}  // namespace aneu::sim
