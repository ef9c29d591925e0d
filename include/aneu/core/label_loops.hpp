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

}  // namespace aneu
