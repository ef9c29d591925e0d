// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Versions and run-time configuration of the libraries aneu_core links (for `--version` output and
/// benchmark reports): Eigen, HDF5, CHOLMOD, OpenBLAS (with the CPU kernels it selected), OpenMP.
#include <string>
#include <utility>
#include <vector>

namespace aneu {

/// (library, version or setting) pairs, e.g. ("OpenBLAS kernels", "SkylakeX").
std::vector<std::pair<std::string, std::string>> core_dependency_versions();

/// The CPU kernel set OpenBLAS selected at load time, e.g. "Haswell", "SkylakeX", "Prescott".
/// "Prescott" on a modern Xeon means OpenBLAS 0.3.21 did not recognise the CPU (REFERENCE.md): set
/// OPENBLAS_CORETYPE before the process starts.
std::string openblas_kernels();

}  // namespace aneu
