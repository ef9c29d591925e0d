// SPDX-License-Identifier: MIT
// One point of the speed/accuracy study (bench/run_study.sh): a clip squeezing the base of the sac, measured on
// one model so that models of other mesh sizes, element orders and precisions can be compared.
//
// The load: an indenter pushes the outer wall in around `--centre` (default: the sac's apex, the outer vertex
// farthest along +x) by `--depth-mm`·(1 − (r/R)²)² within R = `--radius-mm`, along the inward normals. Measured
// with the full FEM (fem::solve_dirichlet on /fem): the indenter force Σ r_v·u_v/depth and the displacement at probe
// points (the closest outer-surface point to 26 fixed points 4 mm around the centre, interpolated in the
// triangle); and, when a case bundle is given, the same through the simulator (W, in its precision) plus the
// bundle's load time and the update rate with 100 and 300 contact nodes.
// Usage: aneu_bench_study FEM.h5 [--case CASE.h5] [--centre x,y,z] [--radius-mm 1.5] [--depth-mm 0.2]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>

#include <Eigen/CholmodSupport>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/sim/model.hpp"
#include "aneu/sim/shapes.hpp"
#include "aneu/sim/solver.hpp"
#include "bench_util.hpp"

using namespace aneu;

namespace {


/// Closest point of triangle abc to p (sim::closest_point_on_triangle), as barycentric weights.
Eigen::Vector3d closest_bary(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d x = sim::closest_point_on_triangle(p, a, b, c);
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double nn = n.squaredNorm();
    if (!(nn > 0)) return {1, 0, 0};
    const double wa = n.dot((c - b).cross(x - b)) / nn, wb = n.dot((a - c).cross(x - c)) / nn;
    return {wa, wb, 1.0 - wa - wb};
}

/// Largest eigenvalue of a symmetric positive (semi)definite operator by power iteration (Rayleigh quotient after
/// `iters` steps, from a fixed start): a lower bound that converges to it.
template <class Apply>
double power_max(Eigen::Index n, Apply&& apply, int iters = 60) {
    Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(n, 1.0, 2.0);
    x.normalize();
    double lam = 0;
    for (int k = 0; k < iters; ++k) {
        const Eigen::VectorXd y = apply(x);
        lam = x.dot(y);
        const double ny = y.norm();
        if (!(ny > 0)) break;
        x = y / ny;
    }
    return lam;
}

struct Probe {
    int face = -1;
    Eigen::Vector3d bary;
};

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s FEM.h5 [--case CASE.h5] [--centre x,y,z] [--radius-mm 1.5] [--depth-mm 0.2]\n", argv[0]);
        return 2;
    }
    std::string case_path;
    double depth = 0.2, radius = 1.5;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    bool have_centre = false;
    for (int a = 2; a + 1 < argc; a += 2) {
        if (!std::strcmp(argv[a], "--case")) case_path = argv[a + 1];
        if (!std::strcmp(argv[a], "--depth-mm")) depth = std::atof(argv[a + 1]);
        if (!std::strcmp(argv[a], "--radius-mm")) radius = std::atof(argv[a + 1]);
        if (!std::strcmp(argv[a], "--centre")) {
            have_centre = std::sscanf(argv[a + 1], "%lf,%lf,%lf", &centre.x(), &centre.y(), &centre.z()) == 3;
        }
    }
    const Bundle b = bench::read_model(argv[1]);
    const VolumeData& vol = *b.volume;
    // The outer surface: every DOF of an outer node gets a "row" (its DOF index) so that extract_surface keeps
    // the faces whose nodes are all outer.
    std::vector<int> row_of_dof(static_cast<size_t>(3 * vol.nodes.rows()), -1);
    const Eigen::VectorXi& outer = vol.node_sets.at("outer");
    for (Eigen::Index k = 0; k < outer.size(); ++k)
        for (int a = 0; a < 3; ++a) row_of_dof[static_cast<size_t>(3 * outer[k] + a)] = 3 * outer[k] + a;
    const sim::SimSurface s = sim::extract_surface(vol.nodes, vol.tets, vol.tet_region, vol.region_names, row_of_dof);
    // The indentation: outer vertices within `radius` of the centre (default: the outer vertex farthest along +x,
    // the sac's apex), pushed along their inward normal by depth·(1 − (r/radius)²)², a bump that fades to zero at
    // its rim so that where a mesh's nodes happen to fall there hardly matters.
    if (!have_centre) {
        Eigen::Index vmax = 0;
        s.X.col(0).maxCoeff(&vmax);
        centre = s.X.row(vmax).transpose();
    }
    std::vector<int> clip;
    std::vector<double> bump;
    for (Eigen::Index v = 0; v < s.size(); ++v) {
        const double r = (s.X.row(v).transpose() - centre).norm();
        if (r < radius) {
            clip.push_back(static_cast<int>(v));
            const double q = 1 - (r / radius) * (r / radius);
            bump.push_back(q * q);
        }
    }
    if (clip.empty()) {
        std::fprintf(stderr, "%s: no outer vertex within %g mm of the centre\n", argv[1], radius);
        return 2;
    }
    // FEM reference of this model.
    std::vector<std::pair<int, double>> pres;
    for (size_t k = 0; k < clip.size(); ++k)
        for (int a = 0; a < 3; ++a) pres.emplace_back(3 * s.node[clip[k]] + a, -depth * bump[k] * s.N(clip[k], a));
    Stopwatch t0;
    const fem::DirichletResult fe = fem::solve_dirichlet(*b.fem, pres);
    const double fem_s = t0.seconds();
    // The indenter's force: the generalised force conjugate to `depth`, Σ r_v · u_v / depth (u_v the prescribed
    // displacement); it converges with the mesh (∫ traction · shape dA), unlike a net force whose radial parts cancel.
    double force = 0;
    for (size_t k = 0; k < clip.size(); ++k) {
        force += fe.reaction.segment<3>(3 * static_cast<Eigen::Index>(k)).dot(-bump[k] * s.N.row(clip[k]).transpose());
    }
    // Probes: closest outer-surface points to 26 points 4 mm around the clip's centre.
    std::vector<Probe> probes;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                if (!i && !j && !k) continue;
                const Eigen::Vector3d q = centre + 4.0 * Eigen::Vector3d(i, j, k).normalized();
                Probe best;
                double bd = 1e300;
                for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
                    const Eigen::Vector3d a = s.X.row(s.F(f, 0)), bb = s.X.row(s.F(f, 1)), c = s.X.row(s.F(f, 2));
                    const Eigen::Vector3d w = closest_bary(q, a, bb, c);
                    const double dd = (w[0] * a + w[1] * bb + w[2] * c - q).squaredNorm();
                    if (dd < bd) {
                        bd = dd;
                        best = {static_cast<int>(f), w};
                    }
                }
                probes.push_back(best);
            }
    auto probe_u = [&](auto&& u_of_vertex) {
        nlohmann::json arr = nlohmann::json::array();
        for (const Probe& pr : probes) {
            Eigen::Vector3d u = Eigen::Vector3d::Zero();
            for (int k = 0; k < 3; ++k) u += pr.bary[k] * u_of_vertex(s.F(pr.face, k));
            arr.push_back({u.x(), u.y(), u.z()});
        }
        return arr;
    };
    nlohmann::json out;
    out["fem"] = argv[1];
    out["nodes"] = vol.nodes.rows();
    out["tets"] = vol.tets.rows();
    out["element_order"] = b.fem->element_order;
    out["dofs"] = b.fem->K.rows();
    out["outer_vertices"] = s.size();
    out["clip_nodes"] = clip.size();
    out["centre"] = {centre.x(), centre.y(), centre.z()};
    out["fem_solve_s"] = fem_s;
    out["force_fem_n"] = force;
    out["probes_fem"] = probe_u([&](int v) -> Eigen::Vector3d { return fe.u.segment<3>(3 * s.node[v]); });
    for (const auto& st : b.meta.stages) out["stage_s"][st.stage] = st.wall_time_s;
    if (!case_path.empty()) {
        const sim::SimModel m = sim::load_model(case_path);
        out["case"] = case_path;
        out["load_s"] = m.load_seconds;
        out["kept_dofs"] = m.dof_node.size();
        out["precision"] = m.is_float() ? "float32" : "float64";
        out["W_bytes"] = static_cast<double>(m.dof_node.size()) * static_cast<double>(m.dof_node.size() + 1) / 2 * (m.is_float() ? 4 : 8);
        out["case_file_bytes"] = std::filesystem::file_size(case_path);
        // node -> permuted rows
        std::vector<int> row_of(static_cast<size_t>(3 * m.nodes.rows()), -1);
        for (Eigen::Index r = 0; r < m.dof_node.size(); ++r) row_of[static_cast<size_t>(3 * m.dof_node[r] + m.dof_axis[r])] = static_cast<int>(r);
        std::vector<sim::Prescribed> p;
        std::vector<size_t> order(clip.size());
        for (size_t k = 0; k < order.size(); ++k) order[k] = k;
        std::sort(order.begin(), order.end(), [&](size_t a, size_t c) { return s.node[clip[a]] < s.node[clip[c]]; });
        // A bundle condensed on the corner nodes of 10-node elements (`condense --nodes corners`) is pushed at its
        // corners only, as the simulator pushes it; the mid-edge nodes follow from K.
        const bool corners_only = b.fem->element_order == 2 && m.surface.size() < s.size();
        for (size_t k : order) {
            const int v = clip[k];
            sim::Prescribed q;
            for (int a = 0; a < 3; ++a) q.cols[a] = row_of[static_cast<size_t>(3 * s.node[v] + a)];
            q.u = -depth * bump[k] * s.N.row(v).transpose();
            if (q.cols.minCoeff() < 0) {
                if (corners_only) continue;
                std::fprintf(stderr, "%s: a clip node is not condensed\n", case_path.c_str());
                return 2;
            }
            p.push_back(q);
        }
        out["pushed_nodes"] = p.size();
        if (p.empty()) {
            std::fprintf(stderr, "%s: no clip node is condensed\n", case_path.c_str());
            return 2;
        }
        sim::ContactSolver solver(m);
        const sim::SolveResult r = solver.solve(p, 0, sim::GroupMethod::EXACT, m.dof_node.size());
        double fw = 0;
        for (size_t k = 0; k < p.size(); ++k) fw += r.f.segment<3>(3 * static_cast<Eigen::Index>(k)).dot(p[k].u) / depth;
        out["force_w_n"] = fw;
        bool probes_condensed = true;  // a working region may leave the probes out: then there is no W-route answer
        for (const Probe& pr : probes)
            for (int k = 0; k < 3; ++k)
                for (int a = 0; a < 3; ++a) probes_condensed = probes_condensed && row_of[static_cast<size_t>(3 * s.node[s.F(pr.face, k)] + a)] >= 0;
        if (probes_condensed) {
            out["probes_w"] = probe_u([&](int v) -> Eigen::Vector3d {
                Eigen::Vector3d u;
                for (int a = 0; a < 3; ++a) u[a] = r.d[row_of[static_cast<size_t>(3 * s.node[v] + a)]];
                return u;
            });
        }
        out["wcc_condition"] = solver.condition_estimate();
        // Condition numbers (2-norm, power iteration) of K on the free DOFs and of the Schur complement S on the
        // condensed DOFs (S = W⁻¹: λmin(S) = 1/λmax(W), λmax(S) by power iteration on S x = K_MM x − K_MI K_II⁻¹ K_IM x).
        {
            const Stopwatch t_cond;
            const FemData& fem = *b.fem;
            const Eigen::Index nd = fem.K.rows();
            std::vector<int> role(static_cast<size_t>(nd), 0);  // 0 interior (free, not kept), 1 kept, -1 fixed
            for (Eigen::Index k = 0; k < fem.fixed_dofs.size(); ++k) role[static_cast<size_t>(fem.fixed_dofs[k])] = -1;
            for (Eigen::Index r = 0; r < m.dof_node.size(); ++r) role[static_cast<size_t>(3 * m.dof_node[r] + m.dof_axis[r])] = 1;
            std::vector<int> idx_f(static_cast<size_t>(nd), -1), idx_i(static_cast<size_t>(nd), -1), idx_m(static_cast<size_t>(nd), -1);
            Eigen::Index nf = 0, ni = 0, nm = 0;
            for (Eigen::Index d = 0; d < nd; ++d) {
                const int rl = role[static_cast<size_t>(d)];
                if (rl < 0) continue;
                idx_f[static_cast<size_t>(d)] = static_cast<int>(nf++);
                if (rl == 0) idx_i[static_cast<size_t>(d)] = static_cast<int>(ni++);
                else idx_m[static_cast<size_t>(d)] = static_cast<int>(nm++);
            }
            std::vector<Eigen::Triplet<double>> tf, ti, tim, tmm;
            auto put = [&](Eigen::Index r, Eigen::Index c, double v) {
                if (idx_f[static_cast<size_t>(r)] < 0 || idx_f[static_cast<size_t>(c)] < 0) return;
                tf.emplace_back(idx_f[static_cast<size_t>(r)], idx_f[static_cast<size_t>(c)], v);
                const int ir = idx_i[static_cast<size_t>(r)], ic = idx_i[static_cast<size_t>(c)];
                const int mr = idx_m[static_cast<size_t>(r)], mc = idx_m[static_cast<size_t>(c)];
                if (ir >= 0 && ic >= 0) ti.emplace_back(ir, ic, v);
                if (ir >= 0 && mc >= 0) tim.emplace_back(ir, mc, v);
                if (mr >= 0 && mc >= 0) tmm.emplace_back(mr, mc, v);
            };
            for (Eigen::Index r = 0; r < nd; ++r)
                for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(fem.K, r); it; ++it) {
                    if (fem.K_upper_only && it.col() < r) continue;
                    put(r, it.col(), it.value());
                    if (fem.K_upper_only && it.col() != r) put(it.col(), r, it.value());
                }
            Eigen::SparseMatrix<double> Kf(nf, nf), Ki(ni, ni), Kim(ni, nm), Kmm(nm, nm);
            Kf.setFromTriplets(tf.begin(), tf.end());
            Ki.setFromTriplets(ti.begin(), ti.end());
            Kim.setFromTriplets(tim.begin(), tim.end());
            Kmm.setFromTriplets(tmm.begin(), tmm.end());
            Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> lf(Kf), li(Ki);
            const double kmax = power_max(nf, [&](const Eigen::VectorXd& x) { return Eigen::VectorXd(Kf * x); });
            const double kinv = power_max(nf, [&](const Eigen::VectorXd& x) { return Eigen::VectorXd(lf.solve(x)); });
            const double smax = power_max(nm, [&](const Eigen::VectorXd& x) {
                return Eigen::VectorXd(Kmm * x - Kim.transpose() * li.solve(Kim * x));
            });
            const double wmax = power_max(nm, [&](const Eigen::VectorXd& x) {
                Eigen::VectorXd y(m.dof_node.size());
                if (m.is_float()) {
                    y = (m.Wf * x.cast<float>()).cast<double>();
                } else {
                    y = m.Wd * x;
                }
                return y;
            });
            out["cond_K_free"] = kmax * kinv;
            out["cond_schur"] = smax * wmax;
            out["cond_s"] = t_cond.seconds();
        }
        // The condensation's own diagnostics: condition of K (CHOLMOD's estimate) and W's residual check.
        for (const auto& [k, v] : read_condensed_header(case_path).diagnostics) {
            if (k == "rcond_estimate_K" || k == "residual_max_rel" || k == "total_s" || k == "peak_rss_bytes") out["condense_" + k] = v;
        }
        // Update rates: patches of 100 and 300 outer vertices nearest the clip centre, all rows of W (the whole
        // working region), factor reused, and with one node swapped each frame.
        std::vector<std::pair<double, int>> near;
        for (Eigen::Index v = 0; v < s.size(); ++v) {
            bool condensed = true;  // a bundle of a working region holds only its nodes
            for (int a = 0; a < 3; ++a) condensed = condensed && row_of[static_cast<size_t>(3 * s.node[v] + a)] >= 0;
            if (condensed) near.emplace_back((s.X.row(v).transpose() - centre).norm(), static_cast<int>(v));
        }
        std::sort(near.begin(), near.end());
        for (int n : {100, 300}) {
            if (n + 1 > static_cast<int>(near.size())) break;
            std::vector<sim::Prescribed> pa, pb;
            for (int k = 0; k <= n; ++k) {
                const int v = near[static_cast<size_t>(k)].second;
                sim::Prescribed q;
                for (int a = 0; a < 3; ++a) q.cols[a] = row_of[static_cast<size_t>(3 * s.node[v] + a)];
                q.u = -0.05 * s.N.row(v).transpose();
                if (k < n) pa.push_back(q);
                if (k != n / 2) pb.push_back(q);
            }
            auto by_col = [](const sim::Prescribed& x, const sim::Prescribed& y) { return x.cols[0] < y.cols[0]; };
            std::sort(pa.begin(), pa.end(), by_col);
            std::sort(pb.begin(), pb.end(), by_col);
            solver.solve(pa, 0, sim::GroupMethod::EXACT, m.dof_node.size());
            const int reps = 400;  // a small model's update takes microseconds: enough repetitions to time it
            t0 = Stopwatch();
            for (int k = 0; k < reps; ++k) solver.solve(pa, 0, sim::GroupMethod::EXACT, m.dof_node.size());
            const double same = t0.seconds() / reps;
            t0 = Stopwatch();
            for (int k = 0; k < reps; ++k) solver.solve(k % 2 ? pa : pb, 0, sim::GroupMethod::EXACT, m.dof_node.size());
            const double changed = t0.seconds() / reps;
            out["update_hz_" + std::to_string(n)] = 1.0 / same;
            out["update_changed_hz_" + std::to_string(n)] = 1.0 / changed;
        }
    }
    std::cout << out.dump() << std::endl;
    return 0;
}
