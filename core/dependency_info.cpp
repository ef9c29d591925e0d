// SPDX-License-Identifier: MIT
#include "aneu/core/dependency_info.hpp"

#include <cholmod.h>
#include <omp.h>

#include <Eigen/Core>
#include <H5public.h>

extern "C" {
char* openblas_get_corename(void);
char* openblas_get_config(void);
int openblas_get_num_threads(void);
}

namespace aneu {

std::string openblas_kernels() { return openblas_get_corename(); }

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
