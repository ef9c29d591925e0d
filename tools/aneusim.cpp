// SPDX-License-Identifier: MIT
// aneusim: the real-time clipping simulator. Links aneu_sim + aneu_core only (no offline stack).
#include <malloc.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/atomic_file.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/version.hpp"
#include "aneu/sim/model.hpp"
#include "aneu/sim/plan.hpp"
#include "aneu/sim/serve.hpp"
#include "aneu/sim/simulator.hpp"
#include "cli_common.hpp"

namespace {
std::atomic<bool> run_stop{false};
std::atomic<int> stop_signal{0};
static_assert(std::atomic<bool>::is_always_lock_free && std::atomic<int>::is_always_lock_free, "set from a signal handler");
// `aneusim run`: the first SIGINT/SIGTERM asks the run to stop where it is (its outputs and report written, exit
// status 128 + the signal, as a shell reports a signal); the second ends the process (the default action).
void on_stop_signal(int sig) {
    if (run_stop.load()) {
        std::signal(sig, SIG_DFL);
        std::raise(sig);
        return;
    }
    stop_signal.store(sig);
    run_stop.store(true);
}
}  // namespace

int main(int argc, char** argv) {
    using namespace aneu::tools;
    reexec_for_this_machine(argv, false);  // OpenBLAS's kernels for this CPU (dependency_info.hpp)
    // The nonlinear patch's physics frames allocate and free tangents of ~10⁶ entries (tens of MB) many times a
    // second. Above glibc's mmap threshold each would be a fresh mapping, page-faulted in on first touch and
    // unmapped when freed; keeping them on the heap, never trimmed, reuses the same pages (measured on the study
    // artery: a frame's blade set-up 70–100 ms → 9 ms, a frame 0.8–1.0 s → 0.5–0.7 s; bench/results/study/patch_sim_notes.md).
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
    CLI::App app{"aneuclip real-time clipping simulator", "aneusim"};
    app.set_version_flag("--version", std::string("aneusim ") + aneu::tool_version() + " (" + aneu::git_revision() + "), OpenBLAS kernels " + aneu::openblas_kernels());
    app.require_subcommand(1);
    app.fallthrough();  // logging options after the subcommand too (`aneusim run SCENE -q`)
    LoggingOptions log;
    add_logging_options(app, log);

    // aneusim load BUNDLE: load figures only.
    auto* load = app.add_subcommand("load", "load a case bundle (only the working region's columns of W) and report");
    std::string bundle;
    std::vector<double> sphere;
    load->add_option("bundle", bundle, "case bundle (.h5) made by `aneuprep condense`")->required();
    load->add_option("--region-sphere", sphere, "working region x,y,z,radius [mm]: load only W's columns there")
        ->delimiter(',')
        ->expected(4);

    // aneusim run SCENE: simulate.
    auto* run = app.add_subcommand("run", "run a scene (configs/scenes/*.json): scripted keyframes or live poses on stdin");
    std::string scene_path, bundle_override, log_out, report_out, series_out, haptic_out, method;
    bool deterministic = false, live = false;
    run->add_option("scene", scene_path, "scene file (JSON)")->required();  // a missing file is bad input (exit 2), said by read_scene
    run->add_flag("--deterministic", deterministic,
                  "single thread on a fixed timeline (tests, replays): the same scene gives the same log, bit for bit");
    run->add_flag("--live", live, "read poses from standard input (`t name px py pz ax ay az ux uy uz opening button [action]`)");
    run->add_option("--bundle", bundle_override, "case bundle instead of the scene's");
    run->add_option("--log", log_out, "per-frame log (CSV) instead of the scene's");
    run->add_option("--haptic-log", haptic_out, "haptic force at every haptic tick (CSV)");
    run->add_option("--series", series_out, "deformed surface series (writes BASE.xdmf + BASE.h5)");
    run->add_option("--report", report_out, "assessment report (JSON; a readable summary goes to REPORT.txt)");
    run->add_option("--clip-method", method, "deposited clips: exact or two-solve (the published method)")
        ->check(CLI::IsMember({"exact", "two-solve"}));

    // aneusim plan BUNDLE -o SCENE: a scene with a clip across the detected neck.
    auto* plan = app.add_subcommand("plan", "write a scene for a case bundle: a straight clip approaching and closing across the detected neck, "
                                            "a suction tube parked nearby");
    std::string plan_bundle, plan_out;
    plan->add_option("bundle", plan_bundle, "case bundle (.h5) made by `aneuprep condense`")->required();
    plan->add_option("-o,--output", plan_out, "scene file to write (JSON); its outputs are named after it")->required();
    bool plan_flow = false;
    double plan_min_cover = aneu::sim::PlanOptions{}.min_cover;
    plan->add_option("--min-cover", plan_min_cover, "least share of the neck's border the jaws must cover (0-1); a case whose only clear way is beside the neck is refused below it")
        ->check(CLI::Range(0.0, 1.0))
        ->capture_default_str();
    bool plan_tandem = aneu::sim::PlanOptions{}.tandem;
    plan->add_flag("--tandem", plan_tandem,
                   "tandem clips: a second clip (straight, the same model) beside the first, a jaw's width and 0.1 mm across the blades, on the side "
                   "where more of the neck line lies beside the first's jaws (none: the parent's side)");
    double plan_fulcrum = aneu::sim::PlanOptions{}.fulcrum_mm;
    double plan_curve = aneu::sim::PlanOptions{}.curve_radius_mm;
    plan->add_option("--fulcrum-mm", plan_fulcrum, "the planned clip's blades turn about a fulcrum this far behind their heel (the model's fulcrum_mm; 0: about the heel)")
        ->check(CLI::Range(0.0, 60.0))
        ->capture_default_str();
    plan->add_option("--curve-radius-mm", plan_curve,
                     "a curved clip: its blades bend from the heel on a circle of this radius, towards the sac or away from it as covers more of the neck "
                     "(the model's jaw_curve_radius_mm; 0: straight)")
        ->check(CLI::Range(0.0, 1000.0))
        ->capture_default_str();
    bool plan_whole_band = aneu::sim::PlanOptions{}.parent_whole_band;
    plan->add_flag("--parent-whole-band", plan_whole_band,
                   "a pose is clear only with no lumen vertex of the parent anywhere across the open jaws' width (default: in the half towards the sac; "
                   "the parent's top may graze the other half)");
    plan->add_flag("--flow", plan_flow, "the scene's outputs include the residual blood flow after the session (aneuprep flow, OpenFOAM: about a minute for the sample)");

    // aneusim serve SCENE: the simulator behind an OpenIGTLink server.
    auto* serve = app.add_subcommand("serve", "run a scene with poses from OpenIGTLink clients (a device bridge, a viewer, 3D Slicer) and send them "
                                              "forces, the deformed surface, clip poses and events (docs/openigtlink.md)");
    std::string serve_scene_path, serve_bundle, serve_report, serve_log, serve_series;
    aneu::sim::ServeOptions sopt;
    serve->add_option("scene", serve_scene_path, "scene file (JSON); served as live input")->required();
    serve->add_option("--port", sopt.port, "TCP port (0: any free port, said in the log)")->check(CLI::Range(0, 65535))->capture_default_str();
    serve->add_flag("--deterministic", sopt.deterministic,
                    "lockstep: the timeline follows the messages' time stamps (tests, replays; forces as `run --deterministic --live` gives them)");
    serve->add_option("--max-seconds", sopt.max_seconds, "stop after this long (0: no limit; a client stops the session with STRING aneusim=stop)")
        ->check(CLI::NonNegativeNumber);
    serve->add_option("--idle-seconds", sopt.idle_seconds, "stop after this long without any client (0: never)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    serve->add_option("--polydata-hz", sopt.polydata_hz, "deformed surface to the clients [Hz]")->check(CLI::PositiveNumber)->capture_default_str();
    serve->add_flag("--ras", sopt.ras, "coordinates to and from the clients in RAS (3D Slicer) instead of the bundle's LPS: x and y negated");
    serve->add_option("--bundle", serve_bundle, "case bundle instead of the scene's");
    serve->add_option("--report", serve_report, "assessment report (JSON; a readable summary goes to REPORT.txt)");
    serve->add_option("--log", serve_log, "per-frame log (CSV) instead of the scene's");
    serve->add_option("--series", serve_series, "deformed surface series (writes BASE.xdmf + BASE.h5)");

    CLI11_PARSE(app, argc, argv);
    apply_logging_options(log);
    if (load->parsed()) {
        return run_guarded("aneusim load", [&] {
            std::optional<aneu::sim::RegionSphere> region;
            if (!sphere.empty()) {
                if (!(sphere[3] > 0)) throw aneu::InputError("--region-sphere: radius = " + std::to_string(sphere[3]) + ", must be > 0");
                region = aneu::sim::RegionSphere{{sphere[0], sphere[1], sphere[2]}, sphere[3]};
            }
            const auto m = aneu::sim::load_model(bundle, region);
            const bool f32 = m.is_float();
            logger().info("loaded {}: {} nodes, W {} rows x {} of {} columns ({}) in {:.3f} s", bundle, m.nodes.rows(),
                          m.dof_node.size(), m.active.size(), m.dof_node.size(), f32 ? "float32" : "float64", m.load_seconds);
            fmt::print("bundle {}\nnodes {}\nsurface_vertices {}\nsurface_triangles {}\nneck_loops {}\nW_rows {}\n"
                       "W_columns_loaded {}\nprecision {}\nload_seconds {:.3f}\n",
                       bundle, m.nodes.rows(), m.surface.size(), m.surface.F.rows(), m.surface.neck_loops.size(),
                       m.dof_node.size(), m.active.size(), f32 ? "float32" : "float64", m.load_seconds);
        });
    }
    if (plan->parsed()) {
        return run_guarded("aneusim plan", [&] {
            namespace fs = std::filesystem;
            aneu::sim::LoadOptions lo;
            lo.geometry_only = true;
            const auto m = aneu::sim::load_model(plan_bundle, lo);
            const fs::path out = fs::absolute(plan_out);
            const std::string ref = fs::relative(fs::absolute(plan_bundle), out.parent_path()).string();
            aneu::sim::PlanOptions po;
            po.flow = plan_flow;
            po.min_cover = plan_min_cover;
            po.fulcrum_mm = plan_fulcrum;
            po.curve_radius_mm = plan_curve;
            po.tandem = plan_tandem;
            po.parent_whole_band = plan_whole_band;
            const std::string text = aneu::sim::plan_scene(m, ref, out.stem().string(), po);
            aneu::AtomicTextFile f(plan_out);
            f.out() << text;
            f.commit();
            const aneu::sim::NeckFrame nf = aneu::sim::neck_frame(m);
            logger().info("planned {}: neck {:.2f} x {:.2f} mm at ({:.2f}, {:.2f}, {:.2f}); run it with `aneusim run {}`", plan_out, nf.length_mm,
                          nf.width_mm, nf.centre.x(), nf.centre.y(), nf.centre.z(), plan_out);
        });
    }
    if (serve->parsed()) {
        return run_guarded("aneusim serve", [&] {
            aneu::sim::Scene scene = aneu::sim::read_scene(serve_scene_path);
            if (!serve_bundle.empty()) scene.bundle = serve_bundle;
            if (!serve_report.empty()) scene.report = serve_report;
            if (!serve_log.empty()) scene.log = serve_log;
            if (!serve_series.empty()) scene.series = serve_series;
            scene.live_input = true;
            aneu::sim::LoadOptions lo;
            lo.region = scene.region;
            lo.working_precision = scene.working_precision;
            aneu::sim::SimModel model = aneu::sim::load_model(scene.bundle, lo);
            aneu::sim::Simulator sim(std::move(scene), std::move(model));
            sopt.on_listening = [](int port) { logger().info("serving OpenIGTLink on port {}", port); };
            sopt.on_message = [](const std::string& m) { logger().warn("{}", m); };
            aneu::sim::ServeCounters c;
            const aneu::sim::Assessment a = aneu::sim::serve_scene(sim, sopt, &c);
            fmt::print("time_s {:.3f}\nclips_used {}\nclips_deposited {}\npeak_force_n {:.4f}\nneck_closed_fraction {:.3f}\nskipped_inputs {}\n"
                       "haptic_ticks {}\nclients_connected {}\nclients_refused {}\nmessages {}\nposes {}\nposes_coalesced {}\n"
                       "dropped_unknown {}\ndropped_malformed {}\ndropped_oversize {}\ndropped_garbage {}\nforces_sent {}\nforces_skipped {}\n"
                       "polydata_sent {}\ntransforms_sent {}\nstatus_sent {}\n",
                       a.total_time_s, a.clips_used, a.clips_deposited, a.peak_force_n, a.neck_closed_fraction, a.skipped_inputs, a.haptic_ticks,
                       c.clients_connected, c.clients_refused, c.messages, c.poses, c.poses_coalesced, c.dropped_unknown, c.dropped_malformed,
                       c.dropped_oversize, c.dropped_garbage, c.forces_sent, c.forces_skipped, c.polydata_sent, c.transforms_sent, c.status_sent);
        });
    }
    const int rc = run_guarded("aneusim run", [&] {
        // SIGINT/SIGTERM (Ctrl-C, a batch system's time limit) end the run at the next tick (while loading: before
        // the first) with its outputs and report written for the time reached; a second signal ends the process.
        std::signal(SIGINT, on_stop_signal);
        std::signal(SIGTERM, on_stop_signal);
        aneu::sim::Scene scene = aneu::sim::read_scene(scene_path);
        if (!bundle_override.empty()) scene.bundle = bundle_override;
        if (!log_out.empty()) scene.log = log_out;
        if (!report_out.empty()) scene.report = report_out;
        if (!series_out.empty()) scene.series = series_out;
        if (!haptic_out.empty()) scene.haptic_log = haptic_out;
        if (method == "exact") scene.clip_method = aneu::sim::GroupMethod::EXACT;
        if (method == "two-solve") scene.clip_method = aneu::sim::GroupMethod::TWO_SOLVE;
        if (live) scene.live_input = true;
        aneu::sim::LoadOptions lo;
        lo.region = scene.region;
        lo.working_precision = scene.working_precision;
        aneu::sim::SimModel model = aneu::sim::load_model(scene.bundle, lo);
        logger().info("loaded {} in {:.3f} s: {} surface vertices, {} of {} columns of W ({})", scene.bundle,
                      model.load_seconds, model.surface.size(), model.n_active, model.dof_node.size(),
                      model.is_float() ? "float32" : "float64");
        aneu::sim::Simulator sim(std::move(scene), std::move(model));
        aneu::sim::RunOptions opt;
        opt.deterministic = deterministic;
        opt.live = &std::cin;
        opt.stop = &run_stop;
        opt.on_message = [](const std::string& m) { logger().warn("{}", m); };
        const aneu::sim::Assessment a = aneu::sim::run_scene(sim, opt);
        fmt::print("time_s {:.3f}\nclips_used {}\nclips_deposited {}\nrepositionings {}\nforce_exceedances {}\n"
                   "velocity_exceedances {}\npeak_force_n {:.4f}\npeak_vessel_force_n {:.4f}\nneck_closed_fraction {:.3f}\n"
                   "skipped_inputs {}\nphysics_frames {}\nhaptic_ticks {}\n",
                   a.total_time_s, a.clips_used, a.clips_deposited, a.repositionings, a.force_exceedances,
                   a.velocity_exceedances, a.peak_force_n, a.peak_vessel_force_n, a.neck_closed_fraction, a.skipped_inputs,
                   a.frames, a.haptic_ticks);
        if (a.stopped_at_s >= 0) fmt::print("stopped_at_s {:.4f}\n", a.stopped_at_s);
    });
    return rc == 0 && run_stop.load() ? 128 + stop_signal.load() : rc;
}
