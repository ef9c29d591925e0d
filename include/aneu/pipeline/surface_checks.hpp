// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Geometric checks of triangle surfaces (CGAL Polygon Mesh Processing behind standard types).
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"

namespace aneu::pipeline {

/// Pairs of faces of `s` that intersect (other than sharing a vertex or edge), at most `max_pairs`.
std::vector<std::pair<int, int>> self_intersections(const SurfaceData& s, std::size_t max_pairs = 16);

}  // namespace aneu::pipeline
