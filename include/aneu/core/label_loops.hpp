// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Loops of edges on a triangle surface.
#include <array>
#include <vector>

#include <Eigen/Core>

namespace aneu {

/// Chains undirected edges into closed vertex loops (a vertex in two edges at most is expected); loops of fewer
/// than 3 vertices are dropped. Deterministic: loops start at their smallest vertex, in increasing order.
std::vector<std::vector<int>> chain_loops(const std::vector<std::array<int, 2>>& edges);

/// The border of the faces labelled `label`: the edges between one such face and one other face, chained into
/// loops (the neck line when `label` is the aneurysm's). Edges on the surface's own boundary are not border.
std::vector<std::vector<int>> label_border_loops(const Eigen::MatrixX3i& F, const Eigen::VectorXi& labels, int label);

/// The neck line: label_border_loops without the loops round islands, i.e. labelling noise. The faces split into
/// pieces of one side (labelled / not), connected across edges that are not border. Kept are the loops between the
/// largest labelled piece (by area) and an unlabelled piece that reaches the surface's own boundary (the parent
/// vessel runs on past the working region), or on a closed surface the largest unlabelled piece. Dropped: the
/// border of a labelled island out in the rest, and of a hole in the labelled region. Two sacs: the larger one's.
/// If that leaves nothing, all of label_border_loops.
std::vector<std::vector<int>> neck_border_loops(const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& V, const Eigen::VectorXi& labels, int label);

}  // namespace aneu
