// SPDX-License-Identifier: MIT
// Contact on a precomputed compliance on a real case's patch (issue #15: physics ≥ 250 Hz with the patch active):
// what a haptic-rate frame costs, what refreshing the linearisation costs, and how far the frames' clip force
// lies from the full nonlinear solve when the linearisation lags.
//
// The case's planned clip (`aneusim plan`: the applier's closing pose and clip model) closes on the bundle's
// nonlinear patch (fem::PatchModel, the simulator's: tetrahedra with a corner within --patch-radius of the jaws'
// wedge, the rest linear and exact). The forceps closes the blades from where they first touch the outer wall to
// --end-deg at the scene's rate (48° in 0.5 s: 0.384° a frame at 250 Hz), then holds them. Each mode runs the same
// frames with fem::solve_compliant_clip_walls (the blades and the inner walls) on a fem::Linearisation that is refreshed at the state the frames reached
// every --refresh frames (0: never; the linearisation at rest), and writes per frame the grip force and the
// frame's time. The reference is the simulator's nonlinear contact solve (fem::ClipBody's barrier, d̂ = 0.01 mm, in
// fem::solve_neo_hookean, θ prescribed, with the inner walls' barrier and crossing check, fem::solve_without_crossings)
// at --checkpoints openings, each solved from the last.
//
// Usage: aneu_bench_compliance FEM.h5 PLAN.json [--end-deg 1.89] [--hold 10] [--refresh 0,10] [--checkpoints 24,16,8,4,1.89]
//                              [--patch-radius 1.5] [--reach 0.05] [--passes 3] [--sweeps 4] [--pivots 200] [--accept 1e-4]
//                              [--friction 0] [--friction-cell 0] [--hold-refresh 0] [--max-frames N] [--out FILE.jsonl]
// --passes: geometry passes per frame (CompliantOptions::geometry_passes); --sweeps, --pivots: the LCP's sweeps before
// pivoting and its pivoting solves at most (max_sweeps, max_pivots); --accept: further sweeps (at most 100) until no gap
// or complementarity is off by more than this [mm] (accept_mm); --friction: the blades' Coulomb friction (blade_friction);
// --friction-cell: its cells [mm] (friction_cell_mm, 0: per node);
// --quadratic-walls: the inner walls' faces split at their mid-edge nodes (aneusim's; default: the corner triangles);
// --wall-one-face: one wall row per vertex (CompliantOptions::wall_one_face);
// --case: the case bundle (same mesh): after each mode's last frame, the neck's occlusion as aneusim measures it;
// --lumen-obj: and the deformed lumen there as PREFIX_<refresh>.obj (bench/render_channel.py);
// --hold-refresh K: while held, refresh every K frames as well (1: a Newton step a frame at the held opening, which
// converges on the nonlinear model's equilibrium with the hard contact);
// --max-frames: stop each mode there (with no
// --checkpoints: no reference), for timing.
// One JSON line per frame and mode, one per checkpoint, a summary line last (stdout, or --out).
#include <algorithm>
#include <malloc.h>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <optional>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/compliance.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/patch.hpp"
#include "aneu/sim/assessment.hpp"
#include "aneu/sim/model.hpp"
#include "bench_util.hpp"

using namespace aneu;
using nlohmann::json;

namespace {

std::vector<double> parse_list(const std::string& s) {
    std::vector<double> v;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) v.push_back(std::stod(item));
    return v;
}

/// The smallest distance of the nodes from either blade at opening θ, of those not behind it.
double min_distance(const fem::ClipBlades& b, double theta, const Eigen::MatrixX3d& X, const std::vector<int>& nodes) {
    double d = 1e9;
    for (int a : nodes)
        for (int s : {1, -1}) {
            const double ds = fem::blade_distance(b, s, theta, X.row(a).transpose());
            if (ds > -0.02) d = std::min(d, ds);
        }
    return d;
}

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    // As aneusim: the frames' large buffers (the Delassus matrix: megabytes to tens of
    // megabytes, every pass) stay on the heap and are reused, not mapped afresh and page-faulted in at each use
    // (without this, one frame in two took 100-250 ms more on the sample's pressed walls).
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
    if (argc < 3) {
        std::fprintf(stderr, "usage: aneu_bench_compliance FEM.h5 PLAN.json [--end-deg 1.89] [--hold 10] [--refresh 0,10] "
                             "[--checkpoints 24,16,8,4,1.89] [--patch-radius 1.5] [--reach 0.05] [--passes 3] [--sweeps 4] [--pivots 200] [--accept 1e-4] "
                             "[--friction 0] [--friction-cell 0] [--hold-refresh 0] [--max-frames N] [--quadratic-walls] [--wall-one-face] [--case CASE.h5 [--lumen-obj PREFIX]] [--out FILE.jsonl]\n");
        return 2;
    }
    double end_deg = 1.89, patch_radius = 1.5, reach = 0.05, accept = 1e-4, friction = 0, friction_cell = 0;
    int hold = 10, max_frames = 0, passes = 3, sweeps = 4, pivots = 200, hold_refresh = 0;
    bool quadratic_walls = false, wall_one_face = false;
    std::vector<double> refresh{0, 10}, checkpoints{24, 16, 8, 4, 1.89};
    std::string out_path, case_path, lumen_obj;
    for (int i = 3; i < argc; i += 2) {
        const std::string k = argv[i];
        if (k == "--quadratic-walls" || k == "--wall-one-face") {
            (k == "--quadratic-walls" ? quadratic_walls : wall_one_face) = true;
            --i;
            continue;
        }
        if (i + 1 >= argc) {
            std::fprintf(stderr, "aneu_bench_compliance: %s needs a value\n", k.c_str());
            return 2;
        }
        const std::string v = argv[i + 1];
        if (k == "--end-deg") end_deg = std::stod(v);
        else if (k == "--hold") hold = std::stoi(v);
        else if (k == "--hold-refresh") hold_refresh = std::stoi(v);
        else if (k == "--refresh") refresh = parse_list(v);
        else if (k == "--checkpoints") checkpoints = parse_list(v);
        else if (k == "--patch-radius") patch_radius = std::stod(v);
        else if (k == "--reach") reach = std::stod(v);
        else if (k == "--out") out_path = v;
        else if (k == "--max-frames") max_frames = std::stoi(v);
        else if (k == "--passes") passes = std::stoi(v);
        else if (k == "--sweeps") sweeps = std::stoi(v);
        else if (k == "--pivots") pivots = std::stoi(v);
        else if (k == "--accept") accept = std::stod(v);
        else if (k == "--friction") friction = std::stod(v);
        else if (k == "--friction-cell") friction_cell = std::stod(v);
        else if (k == "--case") case_path = v;
        else if (k == "--lumen-obj") lumen_obj = v;
        else {
            std::fprintf(stderr, "aneu_bench_compliance: unknown option %s\n", k.c_str());
            return 2;
        }
    }
    std::FILE* out = out_path.empty() ? stdout : std::fopen(out_path.c_str(), "w");
    if (!out) {
        std::fprintf(stderr, "%s: cannot write\n", out_path.c_str());
        return 1;
    }
    auto emit = [&](const json& j) {
        std::fprintf(out, "%s\n", j.dump().c_str());
        std::fflush(out);
    };

    // The plan: its clip model and the applier's closing pose (the keyframe where the opening starts to close).
    std::ifstream pf(argv[2]);
    if (!pf) {
        std::fprintf(stderr, "%s: cannot read\n", argv[2]);
        return 2;
    }
    std::string text, line;
    while (std::getline(pf, line))
        if (line.rfind("//", 0) != 0) text += line + "\n";
    const json plan = json::parse(text);
    const json& app = plan.at("instruments").at(0);
    const json& kf = app.at("keyframes");
    const json& model = plan.at("clip_models").at(kf.at(0).at("load").get<std::string>());
    fem::ClipBlades blades;
    auto vec = [](const json& a) { return Eigen::Vector3d(a.at(0).get<double>(), a.at(1).get<double>(), a.at(2).get<double>()); };
    blades.axis = vec(kf.at(0).at("axis")).normalized();
    blades.up = vec(kf.at(0).at("up"));
    blades.up = (blades.up - blades.up.dot(blades.axis) * blades.axis).normalized();
    blades.hinge = vec(kf.at(1).at("position"));
    blades.length_mm = model.at("jaw_length_mm").get<double>();
    blades.width_mm = model.at("jaw_width_mm").get<double>();
    blades.thickness_mm = model.at("jaw_thickness_mm").get<double>();
    blades.closed_gap_mm = model.at("closed_gap_mm").get<double>();
    const double open = kf.at(1).at("opening_deg").get<double>() * DEG;
    const json& sp = model.at("spring");
    const double rl = 2.0 / 3.0 * blades.length_mm;
    const fem::ClipSpring spring =
        fem::ClipSpring::from_forces(rl, fem::opening_angle(rl, 1.0, blades.closed_gap_mm), sp.at("label_force_n").get<double>(),
                                     model.at("max_opening_deg").get<double>() * DEG, sp.at("open_force_n").get<double>());

    const Bundle b = bench::read_model(argv[1]);
    const VolumeData& vol = *b.volume;
    const FemData& fem = *b.fem;
    const Eigen::VectorXi& outer = vol.node_sets.at("outer");
    std::vector<int> outer_list(outer.data(), outer.data() + outer.size());
    // Where the blades first come within 1 mm of the outer wall (the simulator's trigger), then touch it.
    double theta_build = open;
    while (theta_build > 0 && min_distance(blades, theta_build, vol.nodes, outer_list) > 1.0) theta_build -= 0.25 * DEG;
    std::vector<int> tets;
    for (Eigen::Index t = 0; t < vol.tets.rows(); ++t)
        for (int k = 0; k < 4; ++k)
            if (blades.near_wedge(theta_build, vol.nodes.row(vol.tets(t, k)).transpose(), patch_radius)) {
                tets.push_back(static_cast<int>(t));
                break;
            }
    Stopwatch sw;
    const fem::PatchModel pm(vol, fem, tets);
    const double patch_s = sw.lap();
    const auto np = static_cast<Eigen::Index>(pm.nodes().size());
    Eigen::MatrixX3d X(np, 3);
    for (Eigen::Index a = 0; a < np; ++a) X.row(a) = vol.nodes.row(pm.nodes()[static_cast<size_t>(a)]);
    std::vector<char> is_outer(static_cast<size_t>(vol.nodes.rows()), 0);
    for (int o : outer_list) is_outer[static_cast<size_t>(o)] = 1;
    // The inner walls: the lumen's faces in the patch (the simulator's), and for the frames those whose corners lie
    // within 0.3 mm of the wedge (where the blades flatten the lumen), their corners candidates too.
    const Eigen::MatrixXi F6 = fem::boundary_faces_in_set(vol.nodes, vol.tets, vol.node_sets.at("inner"));
    // --quadratic-walls (10-node elements): each face split in four at its mid-edge nodes, as aneusim's patch pairs
    // them (on the corner triangles alone the quadratic surface between them bulges through the opposite wall). On the
    // sample's planned clip with friction 0.3 (session 33) the frames were solved exactly to frame 98 (up to 1,041 wall
    // rows, 2.5 s a frame) and then broke down: at 1.89° 116 wall crossings, pivoting unfinished, 26 s and more a frame.
    // With --wall-one-face they hold through full closure (2-4 s a frame; compliance.md, session 33).
    Eigen::MatrixX3i Fin;
    if (quadratic_walls && F6.cols() == 6) {
        Fin.resize(4 * F6.rows(), 3);
        for (Eigen::Index f = 0; f < F6.rows(); ++f) {
            const int c0 = F6(f, 0), c1 = F6(f, 1), c2 = F6(f, 2), m01 = F6(f, 3), m12 = F6(f, 4), m20 = F6(f, 5);
            Fin.row(4 * f) << c0, m01, m20;
            Fin.row(4 * f + 1) << m01, c1, m12;
            Fin.row(4 * f + 2) << m20, m12, c2;
            Fin.row(4 * f + 3) << m01, m12, m20;
        }
    } else {
        Fin = F6.leftCols(3);
    }
    std::vector<Eigen::Vector3i> inner_p;
    for (Eigen::Index f = 0; f < Fin.rows(); ++f) {
        const int a = pm.local(Fin(f, 0)), b2 = pm.local(Fin(f, 1)), c = pm.local(Fin(f, 2));
        if (a < 0 || b2 < 0 || c < 0) continue;
        inner_p.emplace_back(a, b2, c);
    }
    Eigen::MatrixX3i inner(static_cast<Eigen::Index>(inner_p.size()), 3);
    for (size_t f = 0; f < inner_p.size(); ++f) inner.row(static_cast<Eigen::Index>(f)) = inner_p[f].transpose();
    // The candidates: the outer nodes of the patch within 0.1 mm of the open jaws' wedge, then the corners of the
    // inner faces within 0.3 mm of it (fem::compliant_setup, as aneusim's patch).
    std::vector<int> outer_p;
    for (Eigen::Index a = 0; a < np; ++a)
        if (is_outer[static_cast<size_t>(pm.nodes()[static_cast<size_t>(a)])]) outer_p.push_back(static_cast<int>(a));
    fem::CompliantSetup setup = fem::compliant_setup(blades, theta_build, X, outer_p, inner);
    std::vector<int> cand = std::move(setup.candidates);
    const size_t blade_cand = setup.blade_candidates;
    const Eigen::MatrixX3i faces_c = std::move(setup.faces);
    Eigen::MatrixX3d Xc(static_cast<Eigen::Index>(cand.size()), 3);
    for (size_t k = 0; k < cand.size(); ++k) Xc.row(static_cast<Eigen::Index>(k)) = X.row(cand[k]);
    std::vector<int> blade_nodes(cand.begin(), cand.begin() + static_cast<std::ptrdiff_t>(blade_cand));
    double theta_touch = theta_build;
    while (theta_touch > 0 && min_distance(blades, theta_touch, X, blade_nodes) > 0) theta_touch -= 0.01 * DEG;
    const double step = 48.0 * DEG / (0.5 * 250.0);
    std::vector<double> frames;
    for (double th = theta_touch; th > end_deg * DEG; th -= step) frames.push_back(th);
    for (int k = 0; k <= hold; ++k) frames.push_back(end_deg * DEG);
    emit({{"case", argv[1]},
          {"patch_tets", tets.size()},
          {"patch_nodes", np},
          {"patch_dofs", pm.dofs()},
          {"interface_nodes", pm.interface_nodes()},
          {"patch_setup_s", patch_s},
          {"candidates", cand.size()},
          {"blade_candidates", blade_cand},
          {"wall_faces", faces_c.rows()},
          {"patch_inner_faces", inner.rows()},
          {"theta_build_deg", theta_build / DEG},
          {"theta_touch_deg", theta_touch / DEG},
          {"frames", frames.size()},
          {"step_deg", step / DEG}});

    // --case: the case bundle's lumen, split at its mid-edge nodes (aneusim's measure with a 10-node patch).
    std::optional<sim::SplitLumen> split;
    int sac_region = -1;
    if (!case_path.empty()) {
        sim::LoadOptions lo;
        lo.geometry_only = true;
        const sim::SimModel sm = sim::load_model(case_path, lo);
        if (sm.nodes.rows() != vol.nodes.rows()) {
            std::fprintf(stderr, "%s: %lld nodes, the FEM bundle %lld: not the same mesh\n", case_path.c_str(), static_cast<long long>(sm.nodes.rows()),
                         static_cast<long long>(vol.nodes.rows()));
            return 2;
        }
        const fem::MidEdgeNodes mid(vol.tets);
        split = vol.tets.cols() == 10 ? sim::split_lumen(sm.surface.lumen, [&](int a, int b) { return mid(a, b); }, vol.nodes)
                                      : sim::SplitLumen{sm.surface.lumen, Eigen::MatrixX2i(0, 2)};
        const auto& names = sm.surface.region_names;
        const auto it = std::find(names.begin(), names.end(), "aneurysm");
        sac_region = it == names.end() ? -1 : static_cast<int>(it - names.begin());
    }
    std::vector<size_t> check_frames;
    for (double cd : checkpoints) {
        size_t fi = 0;
        while (fi + 1 < frames.size() && frames[fi] > cd * DEG + 1e-12) ++fi;
        check_frames.push_back(fi);
    }
    // Per mode and checkpoint frame: the frames' mean grip force and the candidates' displacement.
    std::map<int, std::map<size_t, std::pair<double, Eigen::VectorXd>>> at_check;
    json summary = {{"summary", true}};
    if (checkpoints.empty() && max_frames > 0) check_frames.clear();
    for (double rf : refresh) {
        const int R = static_cast<int>(rf);
        Eigen::VectorXd u = Eigen::VectorXd::Zero(pm.dofs());
        std::unique_ptr<fem::Linearisation> lin;
        fem::CompliantFrame f;
        f.theta = theta_touch;
        std::vector<double> frame_ms, refresh_s;
        int since = 0;
        fem::CompliantOptions co;
        co.reach_mm = reach;
        co.geometry_passes = passes;
        co.max_sweeps = sweeps;
        co.max_pivots = pivots;
        co.accept_mm = accept;
        co.blade_friction = friction;
        co.friction_cell_mm = friction_cell;
        co.wall_one_face = wall_one_face;
        fem::CompliantWallSearch cp;  // the walls' pair search, close vertices and crossings carried from frame to frame
        int refresh_failed = 0;
        for (size_t fi = 0; fi < frames.size(); ++fi) {
            if (max_frames > 0 && static_cast<int>(fi) >= max_frames) break;
            const bool held_frame = fi + static_cast<size_t>(hold) + 1 >= frames.size();
            if (!lin || (R > 0 && since >= R) || (held_frame && hold_refresh > 0 && since >= hold_refresh)) {
                // The state the frames reached (one back substitution), linearised there. A state the lagging
                // frames took past an element's inversion cannot be: the frames go on with the old linearisation.
                const Eigen::VectorXd un = lin ? lin->displacement(f.candidate_forces) : u;
                sw.lap();
                try {
                    auto fresh = std::make_unique<fem::Linearisation>(pm, X, pm.fixed_dofs(), un, cand);
                    lin = std::move(fresh);
                    u = un;
                    refresh_s.push_back(sw.lap());
                    emit({{"mode_refresh", R}, {"refresh_at", fi}, {"seconds", refresh_s.back()}, {"tangent_s", lin->tangent_s},
                          {"factorise_s", lin->factorise_s}, {"compliance_s", lin->compliance_s}});
                } catch (const NumericalError& e) {
                    ++refresh_failed;
                    emit({{"mode_refresh", R}, {"refresh_failed_at", fi}, {"error", e.what()}, {"seconds", sw.lap()}});
                }
                since = 0;
            }
            const fem::CompliantFrame prev = f;
            f = fem::solve_compliant_clip_walls(*lin, Xc, faces_c, cp, blades, spring, frames[fi], prev.theta, fi ? &prev : nullptr, co);
            ++since;
            frame_ms.push_back(1e3 * f.seconds);
            json line = {{"mode_refresh", R}, {"frame", fi}, {"theta_deg", frames[fi] / DEG}, {"force_n", {f.loads.force_n[0], f.loads.force_n[1]}},
                         {"contacts", {f.loads.contacts[0], f.loads.contacts[1]}}, {"rows", f.lambda.size()}, {"sweeps", f.sweeps},
                         {"pivots", f.pivots}, {"single_pivots", f.single_pivots}, {"passes", f.passes}, {"complementarity_mm", f.complementarity_mm}, {"walls", {f.wall_rows, f.wall_contacts}},
                         {"wall_force_n", f.wall_force_n}, {"friction_n", {f.loads.friction_n[0], f.loads.friction_n[1]}}, {"sliding", {f.loads.sliding[0], f.loads.sliding[1]}}, {"wall_crossings", f.wall_crossings}, {"ms", frame_ms.back()},
                         {"split_ms", {1e3 * f.rows_s, 1e3 * f.delassus_s, 1e3 * f.lcp_s, 1e3 * f.search_s}}, {"pair_nodes", f.pair_nodes}, {"refactors", f.refactors}};
            if (std::find(check_frames.begin(), check_frames.end(), fi) != check_frames.end())
                at_check[R][fi] = {0.5 * (f.loads.force_n[0] + f.loads.force_n[1]), f.candidate_u};
            emit(line);
        }
        if (!case_path.empty() && lin) {
            // The neck's occlusion where the frames ended, measured as aneusim measures it (the quadratic lumen, the
            // scene's 0.05 mm gap), every lumen vertex at its own node's displacement: the patch's, and the exterior's
            // from the interface (PatchModel::full_displacement).
            const Eigen::VectorXd full = pm.full_displacement(lin->displacement(f.candidate_forces));
            const sim::SimLumen& Q = split->lumen;
            Eigen::MatrixX3d y(Q.X.rows(), 3);
            for (Eigen::Index l = 0; l < Q.X.rows(); ++l) y.row(l) = Q.X.row(l) + full.segment<3>(3 * Q.node[l]).transpose();
            const sim::NeckOcclusion occ = sim::neck_occlusion(Q, y, 0.05, Q.wall_mm);
            const sim::NeckChannel ch = sim::neck_channel(Q, y, sac_region);
            emit({{"mode_refresh", R}, {"occlusion", {{"theta_deg", f.theta / DEG}, {"neck_closed_fraction", occ.fraction}, {"neck_length_mm", occ.length_mm},
                                                      {"min_gap_mm", occ.min_gap_mm}, {"max_interpenetration_mm", occ.max_interpenetration_mm},
                                                      {"channel_mm", ch.width_mm}, {"cut_off_fraction", sim::neck_cut_off_fraction(occ, ch, 0.05)}}}});
            if (!lumen_obj.empty() && !sim::write_lumen_obj(lumen_obj + "_" + std::to_string(R) + ".obj", Q, y, occ, ch))
                std::fprintf(stderr, "%s_%d.obj: cannot write\n", lumen_obj.c_str(), R);
        }
        summary["refresh_" + std::to_string(R)] = {{"frame_ms_p50", percentile(frame_ms, 0.5)},
                                                   {"frame_ms_p99", percentile(frame_ms, 0.99)},
                                                   {"frame_ms_max", *std::max_element(frame_ms.begin(), frame_ms.end())},
                                                   {"refresh_s_mean", std::accumulate(refresh_s.begin(), refresh_s.end(), 0.0) / static_cast<double>(refresh_s.size())},
                                                   {"refreshes", refresh_s.size()},
                                                   {"refreshes_failed", refresh_failed}};
    }
    // Reference: the barrier solve at the checkpoints, each from the last.
    {
        Eigen::VectorXd v = Eigen::VectorXd::Zero(pm.dofs() + 1);
        v[pm.dofs()] = theta_touch;
        std::vector<int> ref_close;
        for (size_t fi : check_frames) {
            fem::NewtonOptions no;
            no.keep_going = true;
            no.max_iterations = 60;
            fem::ContactParams cp;
            cp.search_mm = std::max(cp.search_mm, 0.2 + 2.0 * std::abs(v[pm.dofs()] - frames[fi]) * blades.length_mm);
            cp.close_vertices = ref_close;
            fem::BladeLoads L;
            sw.lap();
            const fem::CrossingFreeSolve cs = fem::solve_without_crossings(pm, X, inner, v, cp, [&](const fem::ContactBody& wall) {
                const fem::ClipBody cb(wall, X, blade_nodes, v, blades, spring);
                fem::NewtonResult rr = fem::solve_neo_hookean(cb, pm.fixed_dofs(), {{static_cast<int>(cb.theta_dof()), frames[fi]}}, v, no);
                L = cb.loads(rr.u);
                return rr;
            });
            const double s = sw.lap();
            const fem::NewtonResult& r = cs.result;
            ref_close = cs.close_vertices;
            v = r.u;
            emit({{"reference", fi}, {"theta_deg", frames[fi] / DEG}, {"force_n", {L.force_n[0], L.force_n[1]}}, {"converged", r.converged},
                  {"contacts", {L.contacts[0], L.contacts[1]}}, {"iterations", r.iterations}, {"seconds", s}, {"wall_resolves", cs.rounds},
                  {"deepest_mm", cs.deepest_mm}});
            // Each mode's frame there against it: the mean grip force, the candidates' displacement (RMS).
            const double Fr = 0.5 * (L.force_n[0] + L.force_n[1]);
            for (auto& [R, per] : at_check) {
                const auto it = per.find(fi);
                if (it == per.end()) continue;
                double num = 0, den = 0;
                for (size_t k = 0; k < cand.size(); ++k)
                    for (int ax = 0; ax < 3; ++ax) {
                        const double a = it->second.second[static_cast<Eigen::Index>(3 * k) + ax], rr = r.u[3 * cand[k] + ax];
                        num += (a - rr) * (a - rr);
                        den += rr * rr;
                    }
                const json e = {{"theta_deg", frames[fi] / DEG}, {"force_n", it->second.first}, {"ref_force_n", Fr},
                                {"force_error", Fr > 0 ? (it->second.first - Fr) / Fr : 0.0}, {"displacement_error", den > 0 ? std::sqrt(num / den) : 0.0}};
                emit({{"mode_refresh", R}, {"checkpoint", e}});
                summary["refresh_" + std::to_string(R)]["errors"].push_back(e);
            }
        }
    }

    emit(summary);
    if (out != stdout) std::fclose(out);
    return 0;
}
