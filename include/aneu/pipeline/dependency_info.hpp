// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Versions of the libraries the offline pipeline links: ITK, GDCM, VTK, CGAL, TetGen, Netgen.
#include <string>
#include <utility>
#include <vector>

namespace aneu::pipeline {

/// (library, version) pairs. Also proves at run time that each library is loaded and callable.
std::vector<std::pair<std::string, std::string>> pipeline_dependency_versions();

}  // namespace aneu::pipeline
