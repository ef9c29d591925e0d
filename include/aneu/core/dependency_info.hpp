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
/// "Prescott" on a modern Xeon means OpenBLAS 0.3.21 did not recognise the CPU (REFERENCE.md; OpenBLAS issue
/// #4267, fixed in 0.3.25): set OPENBLAS_CORETYPE before the process starts (set_blas_kernels_env).
std::string openblas_kernels();

/// OpenBLAS's threads for every call from now on, in every thread of the process (its pool is shared: two threads
/// calling it at once, each with a pool of every core, wait on each other; the real-time mode's refreshes on the second
/// core do: sim/run.cpp). Returns the count before, to set it back.
int set_blas_threads(int n);

/// The kernel set this CPU can run where OpenBLAS fell back to its SSE3 "Prescott" kernels without being told to
/// (OPENBLAS_CORETYPE unset): "SkylakeX" with AVX-512 (F, CD, BW, DQ, VL), else "Haswell" with AVX2 and FMA, else
/// "Sandybridge" with AVX; "" where OpenBLAS chose something else, the user set OPENBLAS_CORETYPE, or the CPU
/// has none of these. (On this project's Xeon, 1500 x 1500 dgemm on one core: Prescott 12.9 GFLOP/s, SkylakeX 65.)
std::string blas_kernels_for_this_cpu();

/// OPENBLAS_CORETYPE set to blas_kernels_for_this_cpu() where that is not ""; true if it was set. OpenBLAS reads
/// it when it is loaded, so it counts for this process only once the program runs again (the tools execute
/// themselves again at start: tools/cli_common.hpp, reexec_for_this_machine), and for its children.
bool set_blas_kernels_env();

/// set_blas_kernels_env(), and where it set the variable the program executed again (/proc/self/exe, the same
/// argv) before anything else runs: the benchmarks' first call. Returns where nothing changed or exec failed.
void reexec_with_blas_kernels(char** argv);

}  // namespace aneu
