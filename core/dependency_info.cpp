// SPDX-License-Identifier: MIT
#include "aneu/core/dependency_info.hpp"

#include <strings.h>
#include <unistd.h>

#include <cstdlib>

#include <cholmod.h>
#include <omp.h>

#include <Eigen/Core>
#include <H5public.h>

extern "C" {
char* openblas_get_corename(void);
char* openblas_get_config(void);
int openblas_get_num_threads(void);
void openblas_set_num_threads(int);
}

namespace aneu {

std::string openblas_kernels() { return openblas_get_corename(); }

int set_blas_threads(int n) {
    const int before = openblas_get_num_threads();
    openblas_set_num_threads(n);
    return before;
}

std::string blas_kernels_for_this_cpu() {
    if (std::getenv("OPENBLAS_CORETYPE") != nullptr) return "";  // the user's choice (or ours, already applied)
    const char* core = openblas_get_corename();
    if (core == nullptr || strcasecmp(core, "Prescott") != 0) return "";
    __builtin_cpu_init();  // (libgcc's checks include the OS's support of the AVX and AVX-512 states)
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512bw") &&
        __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl"))
        return "SkylakeX";
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
    if (__builtin_cpu_supports("avx")) return "Sandybridge";
    return "";
}

bool set_blas_kernels_env() {
    const std::string k = blas_kernels_for_this_cpu();
    return !k.empty() && ::setenv("OPENBLAS_CORETYPE", k.c_str(), 1) == 0;
}

void reexec_with_blas_kernels(char** argv) {
    if (set_blas_kernels_env()) ::execv("/proc/self/exe", argv);
    // exec failed (or nothing to change): go on with the kernels OpenBLAS chose; children still get the variable
}

std::vector<std::pair<std::string, std::string>> core_dependency_versions() {
    unsigned maj = 0, min = 0, rel = 0;
    H5get_libversion(&maj, &min, &rel);
    int cv[3] = {0, 0, 0};
    cholmod_version(cv);
    return {
        {"Eigen", std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "." +
                      std::to_string(EIGEN_MINOR_VERSION)},
        {"HDF5", std::to_string(maj) + "." + std::to_string(min) + "." + std::to_string(rel)},
        {"CHOLMOD", std::to_string(cv[0]) + "." + std::to_string(cv[1]) + "." + std::to_string(cv[2])},
        {"OpenBLAS", openblas_get_config()},
        {"OpenBLAS kernels", openblas_kernels()},
        {"OpenBLAS threads", std::to_string(openblas_get_num_threads())},
        {"OpenMP threads", std::to_string(omp_get_max_threads())},
    };
}

}  // namespace aneu
