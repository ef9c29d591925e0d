// SPDX-License-Identifier: MIT
// Simulator speed on a case bundle: load time, and per contact-set size the time split of one deformation
// update (W_CC gather + Cholesky, triangular solves, SMVM over the working region's rows and over all rows),
// with the factor reused (contact set unchanged) and recomputed (set changed), and with the SMVM on the rows a
// physics frame updates (within 3 mm of the contact patch, update_margin_mm) instead of the whole region. One JSON object per line on stdout.
// Usage: aneu_bench_sim BUNDLE [--region x,y,z,r] [--margin MM] [--reps N]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/sim/model.hpp"
#include "aneu/sim/solver.hpp"

using namespace aneu;


int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s BUNDLE [--region x,y,z,r] [--margin MM] [--reps N]\n", argv[0]);
        return 2;
    }
    sim::LoadOptions lo;
    int reps = 200;
    double margin = 1.2;
    for (int a = 2; a + 1 < argc; a += 2) {
        if (!std::strcmp(argv[a], "--region")) {
            double x, y, z, r;
            if (std::sscanf(argv[a + 1], "%lf,%lf,%lf,%lf", &x, &y, &z, &r) != 4) return 2;
            lo.region = sim::RegionSphere{{x, y, z}, r};
        } else if (!std::strcmp(argv[a], "--margin")) {
            margin = std::atof(argv[a + 1]);
        } else if (!std::strcmp(argv[a], "--reps")) {
            reps = std::atoi(argv[a + 1]);
        }
    }
    const sim::SimModel m = sim::load_model(argv[1], lo);
    const auto& s = m.surface;
    nlohmann::json head{{"bundle", argv[1]},
                        {"precision", m.is_float() ? "float32" : "float64"},
                        {"W_rows", m.dof_node.size()},
                        {"W_columns_loaded", m.n_active},
                        {"surface_vertices", s.size()},
                        {"load_s", m.load_seconds}};
    std::cout << head.dump() << std::endl;
    sim::ContactSolver solver(m);
    // Contact patches: the n region vertices nearest a vertex near the region's centre.
    Eigen::Vector3d c = lo.region ? lo.region->centre : Eigen::Vector3d(s.X.colwise().mean().transpose());
    Eigen::Index v0 = 0;
    (s.X.rowwise() - c.transpose()).rowwise().squaredNorm().minCoeff(&v0);
    std::vector<std::pair<double, int>> order;
    for (Eigen::Index v = 0; v < s.size(); ++v)
        if (s.row.row(v).maxCoeff() < m.n_active) order.emplace_back((s.X.row(v) - s.X.row(v0)).norm(), static_cast<int>(v));
    std::sort(order.begin(), order.end());
    for (int n : {10, 50, 100, 200, 300, 500}) {
        if (n > static_cast<int>(order.size())) break;
        std::vector<sim::Prescribed> p;
        for (int k = 0; k < n; ++k) {
            sim::Prescribed q;
            q.cols = s.row.row(order[static_cast<size_t>(k)].second).transpose();
            q.u = -0.05 * s.N.row(order[static_cast<size_t>(k)].second).transpose();
            p.push_back(q);
        }
        double f_ref = 0, s_ref = 0, mv_ref = 0, mv_all = 0, t_re = 0, f_new = 0, mv_near = 0, s_near = 0;
        // What a physics frame updates: the region vertices within the update margin (--margin, default 1.2 mm:
        // the effective default on this mesh) of the contact patch's bounding box (the instrument is about
        // there), as 16-row blocks.
        Eigen::RowVector3d lo = s.X.row(order[0].second), hi = lo;
        for (int k = 0; k < n; ++k) {
            lo = lo.cwiseMin(s.X.row(order[static_cast<size_t>(k)].second));
            hi = hi.cwiseMax(s.X.row(order[static_cast<size_t>(k)].second));
        }
        std::vector<int> near;
        for (const auto& [dist, v] : order) {
            const Eigen::RowVector3d x = s.X.row(v);
            if ((x.array() >= lo.array() - margin).all() && (x.array() <= hi.array() + margin).all()) near.push_back(v);
        }
        const sim::RowRanges near_rows = sim::rows_of_vertices(m, near);
        Eigen::Index n_near_rows = 0;
        for (const auto& [a, b] : near_rows) n_near_rows += b - a;
        const int r_new = std::max(20, reps / 5);
        // Set changed every frame by one node (alternating two sets): the factor is updated (a node removed,
        // one appended), the near rows computed, as a physics frame of a sliding contact does.
        std::vector<sim::Prescribed> p2 = p;
        p2[static_cast<size_t>(n / 2)].cols = s.row.row(order[static_cast<size_t>(n)].second).transpose();
        std::sort(p2.begin(), p2.end(), [](const sim::Prescribed& a, const sim::Prescribed& b) { return a.cols[0] < b.cols[0]; });
        solver.solve(p, 0, sim::GroupMethod::EXACT, near_rows);
        for (int r = 0; r < r_new; ++r) {
            const Stopwatch t0;
            const auto res = solver.solve(r % 2 ? p : p2, 0, sim::GroupMethod::EXACT, near_rows);
            t_re += t0.seconds();
            f_new += res.factor_s;
        }
        // The factor recomputed from scratch (a new solver each time).
        double f_full = 0;
        for (int r = 0; r < std::max(3, r_new / 4); ++r) {
            sim::ContactSolver fresh(m);
            f_full += fresh.solve(p, 0, sim::GroupMethod::EXACT, near_rows).factor_s;
        }
        f_full /= std::max(3, r_new / 4);
        // Set unchanged: the factor is reused, only the right-hand side changes.
        solver.solve(p, 0, sim::GroupMethod::EXACT, m.n_active);
        for (int r = 0; r < reps; ++r) {
            for (auto& q : p) q.u *= -1.0;
            const auto res = solver.solve(p, 0, sim::GroupMethod::EXACT, m.n_active);
            f_ref += res.factor_s;
            s_ref += res.solve_s;
            mv_ref += res.smvm_s;
        }
        for (int r = 0; r < reps; ++r) {
            for (auto& q : p) q.u *= -1.0;
            const auto res = solver.solve(p, 0, sim::GroupMethod::EXACT, near_rows);
            s_near += res.factor_s + res.solve_s;
            mv_near += res.smvm_s;
        }
        for (int r = 0; r < std::max(5, reps / 20); ++r) {
            const Stopwatch t0;
            solver.deformation(m.n_active, m.dof_node.size());
            mv_all += t0.seconds();
        }
        const double upd_reuse = (f_ref + s_ref + mv_ref) / reps;
        nlohmann::json j{{"contact_nodes", n},
                         {"reuse_update_ms", 1e3 * upd_reuse},
                         {"reuse_update_hz", 1.0 / upd_reuse},
                         {"reuse_solve_ms", 1e3 * s_ref / reps},
                         {"reuse_smvm_region_ms", 1e3 * mv_ref / reps},
                         {"near_rows", n_near_rows},
                         {"near_smvm_ms", 1e3 * mv_near / reps},
                         {"near_update_hz", reps / (s_near + mv_near)},
                         {"changed_update_ms", 1e3 * t_re / r_new},
                         {"changed_update_hz", r_new / t_re},
                         {"factor_update_ms", 1e3 * f_new / r_new},
                         {"full_factor_ms", 1e3 * f_full},
                         {"smvm_rest_of_surface_ms", 1e3 * mv_all / std::max(5, reps / 20)}};
        std::cout << j.dump() << std::endl;
    }
    return 0;
}
