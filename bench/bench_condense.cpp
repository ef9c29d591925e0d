// SPDX-License-Identifier: MIT
// Condensation benchmark on the size of the largest published case: a tube wall with one tetrahedron
// through a 0.3 mm wall (11,128 nodes, 33,072 linear tets), both end rings fixed, condensed onto its
// 16,380 outer DOFs (REFERENCE.md measured its routes on 11,176 nodes / 33,371 tets / 16,452 DOFs).
// One configuration per process, so the peak RSS is that configuration's:
//   aneu_bench_condense --method sparse|dense --precision float32|float64 --threads N [--n-theta 52 --n-z 106]
// prints one JSON line. bench/run_condense_bench.sh runs the set and writes bench/results/condense.md.
#include <cblas.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <nlohmann/json.hpp>

#include "aneu/core/common.hpp"
#include "aneu/core/dependency_info.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/condense.hpp"
#include "aneu/fem/structured_mesh.hpp"

extern "C" void openblas_set_num_threads(int);

namespace {

/// dgemm rate on 2048² matrices: the machine's practical GEMM peak with the current thread count.
double dgemm_gflops() {
    const int n = 2048;
    std::vector<double> A(static_cast<size_t>(n) * n, 1.0), B(A), C(A.size(), 0.0);
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, n, n, n, 1.0, A.data(), n, B.data(), n, 0.0, C.data(), n);
    const aneu::Stopwatch t0;
    const int reps = 3;
    for (int r = 0; r < reps; ++r)
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, n, n, n, 1.0, A.data(), n, B.data(), n, 0.0, C.data(), n);
    const double s = t0.seconds();
    return reps * 2.0 * n * n * double(n) / s / 1e9;
}

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    std::string method = "sparse", precision = "float64";
    int threads = 2, n_theta = 52, n_z = 106;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string k = argv[i], v = argv[i + 1];
        if (k == "--method") method = v;
        else if (k == "--precision") precision = v;
        else if (k == "--threads") threads = std::stoi(v);
        else if (k == "--n-theta") n_theta = std::stoi(v);
        else if (k == "--n-z") n_z = std::stoi(v);
        else {
            std::fprintf(stderr, "aneu_bench_condense: unknown option %s\n", k.c_str());
            return 2;
        }
    }
    openblas_set_num_threads(threads);
    using namespace aneu::fem;
    const aneu::Stopwatch t0;
    const StructuredMesh m = tube_mesh(1.7, 2.0, 25.6, 1, n_theta, n_z);
    const auto K = assemble_stiffness(m.V, m.T, Eigen::VectorXi::Zero(m.T.rows()), {{"wall", 1.0, 0.45}});
    const double assemble_s = t0.seconds();
    const WallDofSets dofs = wall_dof_sets(m);
    CondenseParams p;
    p.method = method == "dense" ? CondenseMethod::DENSE : CondenseMethod::SPARSE;
    if (const char* ts = std::getenv("ANEU_BENCH_TILE")) p.tile_size = std::stoi(ts);
    if (const char* o = std::getenv("ANEU_BENCH_ORDERING")) p.ordering = o;
    p.precision = precision == "float32" ? aneu::Precision::FLOAT32 : aneu::Precision::FLOAT64;
    const double peak = dgemm_gflops();
    const auto c = condense(K, dofs.fixed, dofs.kept, p);
    nlohmann::json j{{"method", method}, {"precision", precision}, {"threads", threads}, {"nodes", m.V.rows()},
                     {"tets", m.T.rows()}, {"nnz_K", K.nonZeros()}, {"assemble_s", assemble_s},
                     {"dgemm_peak_gflops", peak}, {"blas_kernels", aneu::openblas_kernels()}};
    for (const auto& [k, v] : c.diagnostics) j[k] = v;
    std::printf("%s\n", j.dump().c_str());
    return 0;
}
