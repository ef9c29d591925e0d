// SPDX-License-Identifier: MIT
// The test programs' main: GoogleTest's, after OpenBLAS's kernels for this CPU are in place (the program executed
// again once where Debian's OpenBLAS fell back to its SSE3 kernels: aneu::reexec_with_blas_kernels), as in the tools.
#include <gtest/gtest.h>

#include "aneu/core/dependency_info.hpp"

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);
    ::testing::InitGoogleTest(&argc, argv);
    return RUN_ALL_TESTS();
}
