// SPDX-License-Identifier: MIT
// What one factorisation of a patch's free tangent costs, and what it could cost (issue #15, the physics rate).
// Input: a free tangent written by the simulator (ANEU_DUMP_TANGENT=FILE: the first patch tangent factorised, its
// upper triangle as symmetric Matrix Market). For each fill-reducing ordering CHOLMOD offers (AMD, METIS, NESDIS),
// and for the interface's DOFs ordered last (the columns denser than --dense: the exterior's dense block) with the
// interior by METIS or AMD: analysis time, factorisation time (best of --repeat), nonzeros of L, flops and the rate.
// Then the floor: a dense Cholesky (LAPACK dpotrf) of an SPD matrix the size of that interface block, which any
// factorisation of the coupled system must at least do.
// usage: aneu_bench_factor TANGENT.mtx [--dense 1500] [--repeat 2] [--out results.jsonl]
// Threads: OpenBLAS's own (OPENBLAS_NUM_THREADS); the simulator's patch runs use 1.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <cholmod.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

extern "C" void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Run {
    std::string name;
    double analyse_s = 0, factorise_s = 0, lnz = 0, flops = 0;
    bool positive_definite = false;
};

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"aneu_bench_factor: orderings and the dense floor for a patch's free tangent"};
    std::string path, out;
    int dense = 1500, repeat = 2;
    app.add_option("tangent", path, "the free tangent (symmetric Matrix Market, from ANEU_DUMP_TANGENT)")->required();
    app.add_option("--dense", dense, "a column with more entries than this belongs to the interface's dense block");
    app.add_option("--repeat", repeat, "factorisations per ordering (the best is kept)")->check(CLI::PositiveNumber);
    app.add_option("--out", out, "append one JSON line per ordering here");
    CLI11_PARSE(app, argc, argv);

    cholmod_common c;
    cholmod_start(&c);
    c.print = 0;
    FILE* f = std::fopen(path.c_str(), "r");
    if (!f) {
        std::fprintf(stderr, "aneu_bench_factor: error: cannot open %s\n", path.c_str());
        return 2;
    }
    cholmod_sparse* A = cholmod_read_sparse(f, &c);
    std::fclose(f);
    if (!A || A->stype == 0 || A->nrow != A->ncol) {
        std::fprintf(stderr, "aneu_bench_factor: error: %s is not a symmetric Matrix Market matrix\n", path.c_str());
        return 2;
    }
    const int n = static_cast<int>(A->nrow);
    // The interface: columns of the full pattern with more than `dense` entries.
    cholmod_sparse* F = cholmod_copy(A, 0, 0, &c);
    const int* Fp = static_cast<const int*>(F->p);
    std::vector<int> interior, interface;
    for (int j = 0; j < n; ++j) (Fp[j + 1] - Fp[j] > dense ? interface : interior).push_back(j);
    const long anz = static_cast<long>(cholmod_nnz(A, &c));
    std::printf("%s: %d DOFs, %ld stored entries (upper), %zu interface DOFs (columns with > %d entries)\n", path.c_str(), n, anz, interface.size(), dense);

    std::vector<Run> runs;
    auto measure = [&](const std::string& name, const std::vector<int>* perm, int ordering, double ordering_s = 0) {
        c.supernodal = CHOLMOD_SUPERNODAL;
        c.final_asis = 1;
        c.nmethods = 1;
        c.postorder = 1;
        c.method[0].ordering = perm ? CHOLMOD_GIVEN : ordering;
        const auto t0 = Clock::now();
        cholmod_factor* L = perm ? cholmod_analyze_p(A, const_cast<int*>(perm->data()), nullptr, 0, &c) : cholmod_analyze(A, &c);
        Run r;
        r.name = name;
        r.analyse_s = ordering_s + since(t0);  // a given permutation: the time that made it, then CHOLMOD's analysis
        r.factorise_s = 1e300;
        for (int k = 0; k < repeat; ++k) {
            const auto t1 = Clock::now();
            cholmod_factorize(A, L, &c);
            r.factorise_s = std::min(r.factorise_s, since(t1));
        }
        r.lnz = c.lnz;
        r.flops = c.fl;
        r.positive_definite = L->minor == L->n;
        cholmod_free_factor(&L, &c);
        runs.push_back(r);
    };
    measure("AMD", nullptr, CHOLMOD_AMD);
    measure("METIS", nullptr, CHOLMOD_METIS);
    measure("NESDIS", nullptr, CHOLMOD_NESDIS);
    for (const int ordering : {CHOLMOD_METIS, CHOLMOD_AMD}) {
        // The interior by itself (its full pattern), then the interface.
        const auto t0 = Clock::now();
        cholmod_sparse* S = cholmod_submatrix(F, interior.data(), static_cast<long>(interior.size()), interior.data(), static_cast<long>(interior.size()), 1, 1, &c);
        std::vector<int> p(interior.size());
        if (ordering == CHOLMOD_METIS) {
            cholmod_metis(S, nullptr, 0, 1, p.data(), &c);
        } else {
            S->stype = 0;
            cholmod_sparse* U = cholmod_copy(S, 1, 1, &c);  // AMD takes the upper triangle
            cholmod_amd(U, nullptr, 0, p.data(), &c);
            cholmod_free_sparse(&U, &c);
        }
        cholmod_free_sparse(&S, &c);
        std::vector<int> perm;
        for (int k : p) perm.push_back(interior[static_cast<size_t>(k)]);
        perm.insert(perm.end(), interface.begin(), interface.end());
        measure(std::string("interior ") + (ordering == CHOLMOD_METIS ? "METIS" : "AMD") + ", interface last", &perm, 0, since(t0));
    }
    // The floor: a dense SPD matrix the interface's size.
    const int m = static_cast<int>(interface.size());
    if (m > 0) {
        std::vector<double> D(static_cast<size_t>(m) * m, 0.0);  // lower triangle: entries in [−1, 1], diagonal m (SPD: dominant)
        std::mt19937 g(1);
        std::uniform_real_distribution<double> u(-1, 1);
        for (int j = 0; j < m; ++j)
            for (int i = j; i < m; ++i) D[static_cast<size_t>(j) * m + i] = i == j ? m : u(g);
        Run r;
        r.name = "dense interface block alone (dpotrf)";
        r.factorise_s = 1e300;
        for (int k = 0; k < repeat; ++k) {
            std::vector<double> W = D;
            int info = 0;
            const auto t1 = Clock::now();
            dpotrf_("L", &m, W.data(), &m, &info);
            r.factorise_s = std::min(r.factorise_s, since(t1));
            r.positive_definite = info == 0;
        }
        r.lnz = 0.5 * m * (m + 1.0);
        r.flops = static_cast<double>(m) * m * m / 3.0;
        runs.push_back(r);
    }
    std::printf("| ordering | analyse [s] | factorise [s] | nonzeros of L | flops | GFlop/s | positive definite |\n|---|---|---|---|---|---|---|\n");
    for (const Run& r : runs)
        std::printf("| %s | %.2f | %.3f | %.3g | %.3g | %.1f | %s |\n", r.name.c_str(), r.analyse_s, r.factorise_s, r.lnz, r.flops, r.flops / r.factorise_s / 1e9,
                    r.positive_definite ? "yes" : "no");
    if (!out.empty()) {
        FILE* o = std::fopen(out.c_str(), "a");
        if (!o) {
            std::fprintf(stderr, "aneu_bench_factor: error: cannot append to %s\n", out.c_str());
            return 1;
        }
        for (const Run& r : runs)
            std::fprintf(o, "%s\n", nlohmann::json{{"tangent", path}, {"dofs", n}, {"interface_dofs", m}, {"ordering", r.name}, {"analyse_s", r.analyse_s},
                                                   {"factorise_s", r.factorise_s}, {"lnz", r.lnz}, {"flops", r.flops}, {"positive_definite", r.positive_definite}}
                                        .dump()
                                        .c_str());
        std::fclose(o);
    }
    cholmod_free_sparse(&F, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return 0;
}
