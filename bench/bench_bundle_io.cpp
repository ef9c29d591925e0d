// SPDX-License-Identifier: MIT
// Speed of the case bundle's W storage: writing W, loading all of it, and loading the columns of a
// working region, for the sizes of real cases (up to M = 16,452 kept DOFs, the largest published mesh).
// Run on purpose (not a test):  build/bench/aneu_bench_bundle_io --benchmark_out=bench/results/bundle_io.json
#include <filesystem>
#include <map>
#include <numeric>

#include <benchmark/benchmark.h>
#include <unistd.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/dependency_info.hpp"

namespace {

namespace fs = std::filesystem;

std::string bundle_path(long n) {
    return (fs::temp_directory_path() / ("aneu-bench-W" + std::to_string(n) + "-" + std::to_string(::getpid()) + ".h5"))
        .string();
}

aneu::Bundle make_bundle(long n) {
    aneu::Bundle b;
    b.meta.case_id = "bench";
    aneu::CondensedData c;
    c.dof_node.resize(n);
    c.dof_axis.resize(n);
    for (long i = 0; i < n; ++i) {
        c.dof_node[i] = static_cast<int>(i / 3);
        c.dof_axis[i] = static_cast<int>(i % 3);
    }
    c.precision = aneu::Precision::FLOAT32;
    c.W32 = aneu::TiledSymmetric<float>(n, 128);
    float v = 0.f;
    for (auto& x : c.W32.data()) x = (v += 1e-3f);  // values do not matter for I/O speed
    c.method = "benchmark";
    b.condensed = std::move(c);
    return b;
}

/// Writes the bundle once per n and keeps it for the read benchmarks.
const std::string& bundle_for(long n) {
    static std::map<long, std::string> files;
    auto it = files.find(n);
    if (it == files.end()) {
        const std::string p = bundle_path(n);
        aneu::write_bundle(p, make_bundle(n));
        it = files.emplace(n, p).first;
        std::atexit([] {
            for (const auto& [k, f] : files) fs::remove(f);
        });
    }
    return it->second;
}

void BM_WriteW(benchmark::State& st) {
    const long n = st.range(0);
    const aneu::Bundle b = make_bundle(n);
    const std::string p = bundle_path(n) + ".w";
    for (auto _ : st) aneu::write_bundle(p, b);
    fs::remove(p);
    st.counters["W_MB"] = static_cast<double>(n) * (n + 1) / 2.0 * 4.0 / 1e6;  // packed float32 size
    st.SetBytesProcessed(static_cast<int64_t>(st.iterations()) * n * n * 2);
}

void BM_LoadAllColumns(benchmark::State& st) {
    const long n = st.range(0);
    const std::string& p = bundle_for(n);
    std::vector<int> cols(static_cast<size_t>(n));
    std::iota(cols.begin(), cols.end(), 0);
    for (auto _ : st) benchmark::DoNotOptimize(aneu::read_condensed_columns_f(p, cols));
    st.SetBytesProcessed(static_cast<int64_t>(st.iterations()) * n * n * 4);
}

void BM_LoadRegionColumns(benchmark::State& st) {
    const long n = st.range(0), k = st.range(1);
    const std::string& p = bundle_for(n);
    std::vector<int> cols(static_cast<size_t>(k));
    std::iota(cols.begin(), cols.end(), static_cast<int>(n / 3));  // a contiguous working region
    for (auto _ : st) benchmark::DoNotOptimize(aneu::read_condensed_columns_f(p, cols));
    st.SetBytesProcessed(static_cast<int64_t>(st.iterations()) * n * k * 4);
}

}  // namespace

BENCHMARK(BM_WriteW)->Arg(2048)->Arg(8192)->Arg(16452)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_LoadAllColumns)->Arg(2048)->Arg(8192)->Arg(16452)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_LoadRegionColumns)->Args({16452, 300})->Args({16452, 1500})->Args({16452, 4500})
    ->Unit(benchmark::kMillisecond)->Iterations(3);

int main(int argc, char** argv) {
    for (const auto& [k, v] : aneu::core_dependency_versions()) benchmark::AddCustomContext(k, v);
    benchmark::Initialize(&argc, argv);
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
