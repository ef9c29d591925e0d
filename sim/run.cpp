// SPDX-License-Identifier: MIT
// Running a scene: the deterministic single-thread timeline and the threaded real-time mode, and the
// outputs (per-frame log, haptic log, XDMF + HDF5 surface series, assessment report).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include <unistd.h>

#include <H5Cpp.h>
#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/atomic_file.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/version.hpp"
#include "aneu/sim/simulator.hpp"

namespace aneu::sim {
namespace {

namespace fs = std::filesystem;

std::string g(double x) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", x);
    return b;
}

// A text output written under a temporary name and renamed when complete (AtomicTextFile); off when its path is empty.
class TextOut {
public:
    explicit TextOut(const std::string& path) {
        if (!path.empty()) m_file.emplace(path);
    }
    bool on() const { return m_file.has_value(); }
    std::ofstream& out() { return m_file ? m_file->out() : m_off; }
    void finish() {
        if (m_file) m_file->commit();
    }

private:
    std::optional<AtomicTextFile> m_file;
    std::ofstream m_off;  // never opened: writes to it go nowhere
};

// Deformed surface (and clip jaws) over time: one HDF5 file with a dataset per step, and an XDMF file that
// ParaView opens as a temporal collection.
class Series {
public:
    Series(std::string base, const SimSurface& s) : m_base(std::move(base)), m_S(s.size()) {
        if (m_base.empty()) return;
        m_h5 = m_base + ".h5";
        m_out.emplace(m_h5);
        try {
            m_file = H5::H5File(m_out->tmp(), H5F_ACC_TRUNC);
            std::vector<int> tri(static_cast<size_t>(3 * s.F.rows()));
            for (Eigen::Index f = 0; f < s.F.rows(); ++f)
                for (int k = 0; k < 3; ++k) tri[static_cast<size_t>(3 * f + k)] = s.F(f, k);
            write(m_file, "triangles", tri.data(), {static_cast<hsize_t>(s.F.rows()), 3}, H5::PredType::NATIVE_INT);
            std::vector<int> reg(s.face_region.data(), s.face_region.data() + s.face_region.size());
            write(m_file, "face_region", reg.data(), {reg.size()}, H5::PredType::NATIVE_INT);
            // The volume node of each vertex: `aneuprep flow --series` recovers the whole wall's deformation
            // (and so the lumen's) from these nodes' displacements.
            std::vector<int> node(s.node.data(), s.node.data() + s.node.size());
            write(m_file, "node", node.data(), {node.size()}, H5::PredType::NATIVE_INT);
            m_file.createGroup("/steps");
            m_F = s.F.rows();
        } catch (const H5::Exception& e) {
            throw IoError(m_h5 + ": cannot write the series: " + e.getDetailMsg());
        }
    }
    ~Series() {
        if (m_out && !m_done) {
            try {
                m_file.close();  // before m_out removes the unfinished file
            } catch (const H5::Exception&) {
            }
        }
    }
    bool on() const { return !m_base.empty(); }
    void add(double t, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& rest, const std::vector<Shape>& jaws) {
        const std::string name = "/steps/" + std::to_string(m_steps.size());
        H5::Group grp = m_file.createGroup(name);
        std::vector<float> pts(static_cast<size_t>(3 * m_S)), disp(static_cast<size_t>(3 * m_S));
        for (Eigen::Index v = 0; v < m_S; ++v)
            for (int k = 0; k < 3; ++k) {
                pts[static_cast<size_t>(3 * v + k)] = static_cast<float>(x(v, k));
                disp[static_cast<size_t>(3 * v + k)] = static_cast<float>(x(v, k) - rest(v, k));
            }
        write(grp, "points", pts.data(), {static_cast<hsize_t>(m_S), 3}, H5::PredType::NATIVE_FLOAT);
        write(grp, "displacement", disp.data(), {static_cast<hsize_t>(m_S), 3}, H5::PredType::NATIVE_FLOAT);
        std::vector<float> jp;
        std::vector<int> hex;
        for (const Shape& sh : jaws) {
            if (sh.kind != Shape::Kind::BOX) continue;
            static constexpr int sg[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                             {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
            const int base = static_cast<int>(jp.size() / 3);
            for (const auto& c : sg) {
                Eigen::Vector3d p = sh.centre;
                for (int k = 0; k < 3; ++k) p += c[k] * sh.half[k] * sh.axes.col(k);
                for (int k = 0; k < 3; ++k) jp.push_back(static_cast<float>(p[k]));
            }
            for (int k = 0; k < 8; ++k) hex.push_back(base + k);
        }
        if (!hex.empty()) {
            write(grp, "jaw_points", jp.data(), {jp.size() / 3, 3}, H5::PredType::NATIVE_FLOAT);
            write(grp, "jaw_hexahedra", hex.data(), {hex.size() / 8, 8}, H5::PredType::NATIVE_INT);
        }
        m_steps.push_back({t, hex.size() / 8});
    }
    void finish() {
        if (!on()) return;
        m_file.close();
        m_out->commit();
        m_done = true;
        const std::string h5name = fs::path(m_h5).filename().string();
        TextOut x(m_base + ".xdmf");
        auto& o = x.out();
        o << "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n <Domain>\n";
        o << "  <Grid Name=\"vessel\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
        for (size_t k = 0; k < m_steps.size(); ++k) {
            const std::string st = h5name + ":/steps/" + std::to_string(k);
            o << "   <Grid Name=\"surface\" GridType=\"Uniform\">\n    <Time Value=\"" << g(m_steps[k].t) << "\"/>\n";
            o << "    <Topology TopologyType=\"Triangle\" NumberOfElements=\"" << m_F << "\">\n     <DataItem Dimensions=\""
              << m_F << " 3\" NumberType=\"Int\" Format=\"HDF\">" << h5name << ":/triangles</DataItem>\n    </Topology>\n";
            o << "    <Geometry GeometryType=\"XYZ\">\n     <DataItem Dimensions=\"" << m_S
              << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" << st << "/points</DataItem>\n    </Geometry>\n";
            o << "    <Attribute Name=\"displacement\" AttributeType=\"Vector\" Center=\"Node\">\n     <DataItem Dimensions=\""
              << m_S << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" << st << "/displacement</DataItem>\n    </Attribute>\n";
            o << "    <Attribute Name=\"region\" AttributeType=\"Scalar\" Center=\"Cell\">\n     <DataItem Dimensions=\"" << m_F
              << "\" NumberType=\"Int\" Format=\"HDF\">" << h5name << ":/face_region</DataItem>\n    </Attribute>\n   </Grid>\n";
        }
        o << "  </Grid>\n  <Grid Name=\"clip jaws\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
        for (size_t k = 0; k < m_steps.size(); ++k) {
            const size_t n = m_steps[k].jaws;
            const std::string st = h5name + ":/steps/" + std::to_string(k);
            o << "   <Grid Name=\"jaws\" GridType=\"Uniform\">\n    <Time Value=\"" << g(m_steps[k].t) << "\"/>\n";
            if (n == 0) {
                o << "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"0\"/>\n    <Geometry GeometryType=\"XYZ\">"
                     "\n     <DataItem Dimensions=\"0 3\" Format=\"XML\"></DataItem>\n    </Geometry>\n";
            } else {
                o << "    <Topology TopologyType=\"Hexahedron\" NumberOfElements=\"" << n << "\">\n     <DataItem Dimensions=\""
                  << n << " 8\" NumberType=\"Int\" Format=\"HDF\">" << st << "/jaw_hexahedra</DataItem>\n    </Topology>\n";
                o << "    <Geometry GeometryType=\"XYZ\">\n     <DataItem Dimensions=\"" << 8 * n
                  << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" << st << "/jaw_points</DataItem>\n    </Geometry>\n";
            }
            o << "   </Grid>\n";
        }
        o << "  </Grid>\n </Domain>\n</Xdmf>\n";
        x.finish();
    }

private:
    template <class Loc, class T>
    static void write(Loc& loc, const std::string& name, const T* data, std::vector<hsize_t> dims, const H5::PredType& type) {
        H5::DataSpace sp(static_cast<int>(dims.size()), dims.data());
        H5::DataSet ds = loc.createDataSet(name, type, sp);
        ds.write(data, type);
    }
    struct Step {
        double t;
        size_t jaws;
    };
    std::string m_base, m_h5;
    std::optional<AtomicPath> m_out;  // declared before m_file: the file is closed before its temporary is removed
    Eigen::Index m_S = 0, m_F = 0;
    H5::H5File m_file;
    std::vector<Step> m_steps;
    bool m_done = false;
};

std::vector<Shape> all_jaws(const Simulator& sim) {
    std::vector<Shape> out;
    for (const Clip& c : sim.clips()) {
        if (c.model.empty()) continue;
        const auto j = clip_jaws(sim.scene().clip_models.at(c.model), c.pose, c.opening_deg);
        out.push_back(j[0]);
        out.push_back(j[1]);
    }
    return out;
}

// Log lines; timings only outside deterministic mode (they differ from run to run).
struct Logger {
    TextOut out;
    bool timings;
    const Scene& scene;
    Logger(const Scene& s, bool with_timings) : out(s.log), timings(with_timings), scene(s) {
        if (!out.on()) return;
        auto& o = out.out();
        o << "t_s,contact_nodes,prescribed_nodes,updated_rows,refactored";
        if (timings) o << ",collision_ms,factor_ms,solve_ms,smvm_ms";
        for (const auto& ins : s.instruments) o << ",F_" << ins.name << "_x,F_" << ins.name << "_y,F_" << ins.name << "_z,F_" << ins.name << "_N";
        o << ",clips\n";
    }
    void line(const FrameStats& fs, double t, const std::vector<Eigen::Vector3d>& F, const std::vector<Clip>& clips) {
        if (!out.on()) return;
        auto& o = out.out();
        o << g(t) << ',' << fs.contact_nodes << ',' << fs.prescribed_nodes << ',' << fs.updated_rows << ',' << (fs.refactored ? 1 : 0);
        if (timings) o << ',' << g(1e3 * fs.collision_s) << ',' << g(1e3 * fs.factor_s) << ',' << g(1e3 * fs.solve_s) << ',' << g(1e3 * fs.smvm_s);
        for (const auto& f : F) o << ',' << g(f.x()) << ',' << g(f.y()) << ',' << g(f.z()) << ',' << g(f.norm());
        o << ',';
        for (size_t k = 0; k < clips.size(); ++k) {
            const Clip& c = clips[k];
            if (c.model.empty()) continue;
            o << (k ? " " : "") << "clip" << c.id << ':' << (c.state == Clip::State::HELD ? "held" : "deposited") << ':'
              << g(c.net_force.norm()) << ':' << g(c.grip_force_n) << ':' << g(c.opening_deg);
        }
        o << '\n';
    }
};

struct HapticLog {
    TextOut out;
    explicit HapticLog(const Scene& s) : out(s.haptic_log) {
        if (!out.on()) return;
        out.out() << "t_s";
        for (const auto& ins : s.instruments) out.out() << ",F_" << ins.name << "_x,F_" << ins.name << "_y,F_" << ins.name << "_z";
        out.out() << '\n';
    }
    void line(double t, const std::vector<Eigen::Vector3d>& F) {
        if (!out.on()) return;
        out.out() << g(t);
        for (const auto& f : F) out.out() << ',' << g(f.x()) << ',' << g(f.y()) << ',' << g(f.z());
        out.out() << '\n';
    }
};

int every(double hi, double lo) { return lo > 0 ? std::max(1, static_cast<int>(std::lround(hi / lo))) : 0; }

}  // namespace

Assessment run_scene(Simulator& sim, const RunOptions& opt) {
    const Scene& sc = sim.scene();
    auto message = [&](const std::string& m) {
        if (opt.on_message) opt.on_message(m);
    };
    auto flush_messages = [&] {
        for (const auto& m : sim.take_messages()) message(m);
    };
    Logger log(sc, !opt.deterministic);
    HapticLog hlog(sc);
    Series series(sc.series, sim.model().surface);
    std::vector<FrameStats> frames;
    HapticTiming htime;
    const double H = sc.haptic_hz;
    const int phys_every = every(H, sc.physics_hz), log_every = every(H, sc.log_hz), series_every = every(H, sc.series_hz);
    const int surface_every = every(H, opt.surface_hz);
    const bool have_live = opt.live != nullptr || static_cast<bool>(opt.live_source);
    const auto make_reader = [&] {
        const auto index = [&](const std::string& name) { return sim.instrument_index(name); };
        return opt.live_source ? LiveReader(opt.live_source, index) : LiveReader(*opt.live, index);
    };
    FrameStats last;
    std::vector<Eigen::Vector3d> F(sc.instruments.size(), Eigen::Vector3d::Zero());
    // A stop request (RunOptions::stop) ends the run where it is; the scene time of the last tick is kept.
    double t_last = 0, stop_at = -1;
    const auto stopped = [&] {
        if (stop_at < 0 && opt.stop && opt.stop->load()) stop_at = t_last;
        return stop_at >= 0;
    };

    if (opt.deterministic) {
        long n = 0;
        double t_prev = -1;
        auto tick = [&](double t) {
            t_last = t;
            if (n % phys_every == 0) {
                last = sim.physics_step(t);
                frames.push_back(last);
                if (opt.on_frame) opt.on_frame(last);
            }
            F = sim.haptic_step(t);
            hlog.line(t, F);
            if (opt.on_haptic) opt.on_haptic(t, F);
            if (opt.on_surface && surface_every && n % surface_every == 0) opt.on_surface(t, sim.deformed_surface(), sim.clips(), sim.instrument_poses());
            const Stopwatch to;
            if (n % log_every == 0) log.line(last, t, F, sim.clips());
            if (series.on() && series_every && n % series_every == 0) {
                series.add(t, sim.deformed_surface(), sim.model().surface.X, all_jaws(sim));
                htime.output_s.push_back(to.seconds());
            }
            flush_messages();
            ++n;
        };
        if (!sc.live_input) {
            const long ticks = static_cast<long>(std::floor(sc.duration_s * H + 1e-9));
            for (long k = 0; k <= ticks; ++k) {
                const double t = static_cast<double>(k) / H;
                if (stopped()) break;
                sim.apply_script(t_prev, t);
                t_prev = t;
                tick(t);
            }
        } else {
            if (!have_live) throw InputError(sc.path + ": live_input is set but no pose stream was given");
            LiveReader reader = make_reader();
            const auto skipped = [&](long line, const std::string& why) {
                sim.count_skipped_input();
                message("pose stream line " + std::to_string(line) + " skipped: " + why);
            };
            while (const auto s = reader.next(skipped)) {
                if (stopped()) break;
                // Advance the timeline to the sample's time, then apply it.
                while (static_cast<double>(n) / H + 1e-12 < s->sample.t) tick(static_cast<double>(n) / H);
                sim.set_input(s->instrument, s->sample.key, s->sample.t);
            }
            if (stop_at < 0) tick(static_cast<double>(n) / H);
        }
    } else {
        // Threads: haptic loop at its rate (input sampling + contact-plane force), physics (collision +
        // solve) as often as it can up to its rate, output (log, series) at theirs. Shared state is
        // exchanged under one mutex that the solve never holds.
        std::mutex mx;
        std::atomic<bool> running{true};
        const Stopwatch start;
        auto now = [&] { return start.seconds(); };
        std::vector<std::pair<double, std::vector<Eigen::Vector3d>>> hbuf;
        std::vector<FrameStats> fbuf;
        std::mutex fmx;
        // One core stays with the haptic loop: the SMVM gets the others (on 2 cores, one thread; two took the
        // haptic period's 99th percentile from 2.0 to 3.5 ms on the demo scene).
        sim.set_solver_threads(std::max(1, static_cast<int>(std::thread::hardware_concurrency()) - 1));
        // (The math libraries under a nonlinear patch's frames, CHOLMOD on OpenBLAS and OpenMP's tangents, keep
        // every core: kept to one, the haptic loop's period did no better with the sample's patch active
        // (bench/results/study/patch_realtime.md).) Compliance frames that are refreshed make each refresh on a
        // thread of its own beside the physics thread (sim_patch.cpp): there OpenBLAS is kept to one thread a caller,
        // as its shared pool made the two wait on each other (the tube's refresh: 0.3 s alone, 1.7-2.2 s beside the
        // frames with the pool, 0.26-0.35 s with one thread each).
        const bool one_blas_thread = sc.wall_model == WallModel::PATCH && sc.patch.solver == PatchSpec::Solver::COMPLIANCE && sc.patch.refresh_frames > 0;
        const int blas_threads_before = one_blas_thread ? set_blas_threads(1) : 0;
        std::thread physics([&] {
            const double period = 1.0 / sc.physics_hz;
            double next = 0;
            while (running) {
                const FrameStats fs = sim.physics_step(now(), &mx);
                {
                    std::lock_guard<std::mutex> lk(fmx);
                    fbuf.push_back(fs);
                }
                next += period;
                const double wait = next - now();
                if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
                else next = now();
            }
        });
        std::thread output([&] {
            const double lp = 1.0 / sc.log_hz, sp = sc.series_hz > 0 ? 1.0 / sc.series_hz : 1e300;
            const double up = opt.on_surface && opt.surface_hz > 0 ? 1.0 / opt.surface_hz : 1e300;
            double next_log = 0, next_series = 0, next_surface = 0;
            while (running) {
                const double t = now();
                if (opt.on_surface && t >= next_surface) {
                    Eigen::MatrixX3d x;
                    std::vector<Clip> cl;
                    std::vector<std::optional<Pose>> poses;
                    {
                        std::lock_guard<std::mutex> lk(mx);
                        x = sim.deformed_surface(true);
                        cl = sim.clips();
                        poses = sim.instrument_poses();
                    }
                    opt.on_surface(t, x, cl, poses);
                    next_surface += up;
                    if (next_surface < t) next_surface = t + up;  // a slow consumer skips frames, it does not queue them
                }
                if (t >= next_log) {
                    FrameStats fs;
                    {
                        std::lock_guard<std::mutex> lk(fmx);
                        if (!fbuf.empty()) fs = fbuf.back();
                    }
                    std::vector<Eigen::Vector3d> f;
                    std::vector<Clip> cl;
                    {
                        std::lock_guard<std::mutex> lk(mx);
                        f = F;
                        cl = sim.clips();
                        for (const auto& m : sim.take_messages()) message(m);
                    }
                    log.line(fs, t, f, cl);
                    next_log += lp;
                }
                if (series.on() && t >= next_series) {
                    Eigen::MatrixX3d x;
                    std::vector<Shape> jaws;
                    {
                        std::lock_guard<std::mutex> lk(mx);
                        x = sim.deformed_surface(true);  // region rows: the solver belongs to the physics thread
                        jaws = all_jaws(sim);
                    }
                    const double to = now();
                    series.add(t, x, sim.model().surface.X, jaws);
                    htime.output_s.push_back(now() - to);
                    next_series += sp;
                }
                std::this_thread::sleep_for(std::chrono::microseconds(500));
            }
        });
        // The haptic loop runs on this thread.
        htime.tick_s.reserve(static_cast<size_t>(H * (sc.duration_s + 1)));
        htime.step_s.reserve(htime.tick_s.capacity());
        const double hp = 1.0 / H;
        double t_prev = -1, next = 0;
        std::optional<LiveReader> reader;
        if (sc.live_input && have_live) reader.emplace(make_reader());
        while (true) {
            const double t = now();
            if (!sc.live_input && t > sc.duration_s) break;
            t_last = t;
            if (stopped()) break;
            bool ended = false;
            // Inputs first, then the force, so a tick's force answers the poses that arrived before it (as in the
            // deterministic timeline). A text stream gives one sample per tick at most (a pose device streams at the
            // haptic rate); a device server's source gives what has arrived since the last tick (it keeps one pose
            // per instrument), all applied at the tick's time.
            for (int k = 0; reader && k < (opt.live_source ? 64 : 1); ++k) {
                std::vector<std::pair<long, std::string>> refused;
                const auto s = reader->next([&](long line, const std::string& why) { refused.emplace_back(line, why); });
                std::lock_guard<std::mutex> lk(mx);
                for (const auto& [line, why] : refused) {
                    sim.count_skipped_input();
                    message("pose stream line " + std::to_string(line) + " skipped: " + why);
                }
                if (s) {
                    sim.set_input(s->instrument, s->sample.key, t);
                    continue;
                }
                ended = reader->ended();
                break;
            }
            if (ended) break;
            {
                std::lock_guard<std::mutex> lk(mx);
                if (!sc.live_input) sim.apply_script(t_prev, t);
                F = sim.haptic_step(t);
            }
            htime.tick_s.push_back(t);
            htime.step_s.push_back(now() - t);
            if (hlog.out.on()) hbuf.emplace_back(t, F);
            t_prev = t;
            if (opt.on_haptic) opt.on_haptic(t, F);
            next += hp;
            const double wait = next - now();
            if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
        }
        running = false;
        sim.cancel_physics(true);  // a patch frame in progress stops at its next iteration
        physics.join();
        sim.cancel_physics(false);
        output.join();
        if (one_blas_thread) set_blas_threads(blas_threads_before);  // the process's later work gets its cores back
        for (const auto& [t, f] : hbuf) hlog.line(t, f);
        frames = fbuf;
    }
    flush_messages();
    Assessment a = sim.assess();
    if (stop_at >= 0) {
        a.stopped_at_s = stop_at;
        message("stopped at t=" + std::to_string(stop_at) + " s, before the scene's end (" + std::to_string(sc.duration_s) +
                " s): the outputs and the report are for the time reached");
    }
    log.out.finish();
    hlog.out.finish();
    series.finish();
    ResidualFlow flow;
    if (!sc.flow.empty()) flow = residual_flow(sc);
    if (!sc.report.empty()) write_report(sc.report, sc, sim.model(), a, frames, &htime, sc.flow.empty() ? nullptr : &flow);
    if (!flow.error.empty()) throw Error(flow.error);
    return a;
}

void write_report(const std::string& path, const Scene& scene, const SimModel& model, const Assessment& a,
                  const std::vector<FrameStats>& frames, const HapticTiming* haptic, const ResidualFlow* flow) {
    auto stats = [&](auto get) {
        std::vector<double> v;
        for (const auto& f : frames) v.push_back(get(f) * 1e3);
        nlohmann::json j;
        if (v.empty()) return j;
        std::sort(v.begin(), v.end());
        double sum = 0;
        for (double x : v) sum += x;
        j["mean_ms"] = sum / static_cast<double>(v.size());
        j["p95_ms"] = percentile(v, 0.95);
        j["max_ms"] = v.back();
        return j;
    };
    long refactors = 0;
    for (const auto& f : frames) refactors += f.refactored;
    nlohmann::json j;
    j["tool"] = std::string("aneusim ") + tool_version();
    j["scene"] = scene.path;
    j["bundle"] = scene.bundle;
    j["case_id"] = model.case_id;
    j["deposited_clip_method"] = scene.clip_method == GroupMethod::EXACT ? "exact" : "two-solve";
    j["total_time_s"] = a.total_time_s;
    if (a.stopped_at_s >= 0) j["stopped_at_s"] = a.stopped_at_s;
    j["clips_used"] = a.clips_used;
    j["clips_deposited"] = a.clips_deposited;
    j["repositionings"] = a.repositionings;
    j["force_threshold_n"] = scene.force_threshold_n;
    j["force_exceedances"] = a.force_exceedances;
    j["velocity_threshold_mm_s"] = scene.velocity_threshold_mm_s;
    j["velocity_exceedances"] = a.velocity_exceedances;
    j["peak_force_n"] = a.peak_force_n;
    j["peak_vessel_force_n"] = a.peak_vessel_force_n;
    // the clips' force at their label point (ISO 9713; the tissue's moment on a blade over the label point's arm): the
    // figure a clip model's closing-force range is stated for
    j["peak_clip_label_force_n"] = a.peak_clip_label_force_n;
    j["neck_length_mm"] = a.neck_length_mm;
    j["neck_closed_fraction"] = a.neck_closed_fraction;
    j["neck_gap_mm"] = scene.neck_gap_mm;
    j["neck_measured_on"] = a.neck_on_quadratic_surface ? "quadratic surface" : "corner triangles";
    if (a.neck_min_gap_mm >= 0 || a.neck_interpenetration_mm > 0) j["neck_min_gap_mm"] = a.neck_min_gap_mm;
    j["neck_interpenetration_mm"] = a.neck_interpenetration_mm;
    j["lumen_crossing_mm"] = a.lumen_crossing_mm;  // the lumen through itself anywhere (its deepest vertex behind a face)
    j["lumen_crossing_vertices"] = a.lumen_crossing_vertices;
    if (a.lumen_crossing_vertices > 0) j["lumen_crossing_at"] = {a.lumen_crossing_at.x(), a.lumen_crossing_at.y(), a.lumen_crossing_at.z()};
    // behind a lumen face where a patch holds the tissue, but in none of it (beside or beyond the wall; not counted above)
    j["lumen_beside_tissue_mm"] = a.lumen_beside_tissue_mm;
    j["lumen_beside_tissue_vertices"] = a.lumen_beside_tissue_vertices;
    if (a.patch_nodes_in_other_tissue >= 0) {
        j["patch_nodes_in_other_tissue"] = a.patch_nodes_in_other_tissue;
        j["patch_tissue_overlap_mm"] = a.patch_tissue_overlap_mm;
    }
    j["neck_between_jaws_fraction"] = a.neck_between_jaws_fraction;
    if (std::isfinite(a.neck_in_jaws_fraction)) {
        j["neck_in_jaws_fraction"] = a.neck_in_jaws_fraction;
        j["neck_beside_jaws_mm"] = a.neck_beside_jaws_mm;
    }
    if (std::isfinite(a.neck_channel_mm)) {
        j["neck_channel_mm"] = a.neck_channel_mm;  // the widest channel still joining sac and parent (2: wide open)
        j["neck_channel_at"] = {a.neck_channel_at.x(), a.neck_channel_at.y(), a.neck_channel_at.z()};
        j["neck_sealed"] = a.neck_channel_mm <= scene.neck_gap_mm;
        if (a.neck_cut_off_fraction >= 0) j["neck_cut_off_fraction"] = a.neck_cut_off_fraction;
        if (std::isfinite(a.neck_channel_edge_mm)) j["neck_channel_edge_mm"] = a.neck_channel_edge_mm;
    }
    if (std::isfinite(a.parent_narrowing)) {
        j["parent_channel_mm"] = a.parent_channel_mm;  // the parent's narrowest passage between its ends, deformed
        j["parent_channel_rest_mm"] = a.parent_channel_rest_mm;
        j["parent_narrowing"] = a.parent_narrowing;
        j["parent_channel_at"] = {a.parent_channel_at.x(), a.parent_channel_at.y(), a.parent_channel_at.z()};
    }
    // Where along the neck line it stays open: [x, y, z, gap] per neck vertex in loop order (gap null: no opposite
    // wall within reach).
    j["neck_line"] = nlohmann::json::array();
    for (const auto& q : a.neck_line)
        j["neck_line"].push_back({q.x.x(), q.x.y(), q.x.z(), std::isfinite(q.gap_mm) ? nlohmann::json(q.gap_mm) : nlohmann::json()});
    j["clips"] = nlohmann::json::array();
    for (const auto& c : a.clip_ends) {
        nlohmann::json cj = {{"id", c.id}, {"model", c.model}, {"state", c.deposited ? "deposited" : "held"}, {"opening_deg", c.opening_deg},
                             {"grip_force_n", c.grip_force_n}};
        if (c.spring) {
            cj["spring_torque_nmm"] = c.spring_torque_nmm;
            cj["tissue_moment_nmm"] = c.tissue_moment_nmm;
            cj["label_force_n"] = c.label_force_n;
            cj["spring_placeholder"] = c.placeholder;
        }
        j["clips"].push_back(cj);
    }
    j["wall_model"] = scene.wall_model == WallModel::PATCH ? "patch" : "linear";
    if (scene.wall_model == WallModel::PATCH) {
        j["patches"] = nlohmann::json::array();
        for (const auto& p : a.patches)
            j["patches"].push_back({{"clip", p.clip}, {"more_clips", p.more_clips}, {"tets", p.tets}, {"nodes", p.nodes}, {"interface_nodes", p.interface_nodes},
                                    {"builds", p.builds}, {"setup_s", p.setup_s}, {"frames", p.frames},
                                    {"unconverged_frames", p.unconverged_frames}, {"max_newton_iterations", p.max_iterations},
                                    {"mean_newton_iterations", p.mean_iterations}, {"mean_solve_ms", p.mean_solve_ms},
                                    {"max_solve_ms", p.max_solve_ms}, {"peak_blade_force_n", p.peak_blade_force_n},
                                    {"peak_label_force_n", p.peak_label_force_n},
                                    {"min_wall_distance_mm", std::isfinite(p.min_wall_distance_mm) ? nlohmann::json(p.min_wall_distance_mm) : nlohmann::json()},
                                    {"wall_pairs_touching", p.wall_pairs_touching}, {"wall_resolves", p.wall_resolves},
                                    {"restarts", p.restarts}});
        if (scene.patch.solver == PatchSpec::Solver::COMPLIANCE)
            for (size_t k = 0; k < a.patches.size(); ++k) {
                const auto& p = a.patches[k];
                j["patches"][k]["solver"] = "compliance";
                j["patches"][k]["linearisations"] = p.linearisations;
                j["patches"][k]["linearise_s"] = p.linearise_s;
                j["patches"][k]["linearisations_failed"] = p.linearisations_failed;
                j["patches"][k]["range_refreshes"] = p.range_refreshes;
                j["patches"][k]["linearisations_borrowed"] = p.linearisations_borrowed;
                j["patches"][k]["borrow_fallbacks"] = p.borrow_fallbacks;
                j["patches"][k]["range_earlier_kept"] = p.range_earlier_kept;
                j["patches"][k]["range_hopeless"] = p.range_hopeless;
                j["patches"][k]["range_absurd"] = p.range_absurd;
                j["patches"][k]["walls_absurd"] = p.walls_absurd;
                j["patches"][k]["walls_shortened"] = p.walls_shortened;
                j["patches"][k]["walls_within_start"] = p.walls_within_start;
                j["patches"][k]["walls_newton_frames"] = p.walls_newton_frames;
                j["patches"][k]["walls_newton_failed"] = p.walls_newton_failed;
                j["patches"][k]["newton_frames_loose"] = p.newton_frames_loose;
                j["patches"][k]["max_frame_resolves"] = p.max_frame_resolves;
                j["patches"][k]["range_splits"] = p.range_splits;
                j["patches"][k]["max_frame_splits"] = p.max_frame_splits;
                j["patches"][k]["range_newton_frames"] = p.range_newton_frames;
                j["patches"][k]["range_newton_failed"] = p.range_newton_failed;
                j["patches"][k]["refreshes_stale"] = p.refreshes_stale;
                j["patches"][k]["first_candidates"] = p.first_candidates;
                j["patches"][k]["last_candidates"] = p.last_candidates;
                j["patches"][k]["blade_profile_n"] = p.blade_profile_n;
                j["patches"][k]["blade_profile_across_n"] = p.blade_profile_across_n;
                // How far the frames took the surface from the state they were linearised at, over the wall's thickness
                // (the linear model's measure against linear_limit).
                j["patches"][k]["max_lag_to_thickness"] = p.max_lag_to_thickness;
                j["patches"][k]["max_lag_mm"] = p.max_lag_mm;
                j["patches"][k]["max_lag_thickness_mm"] = p.max_lag_thickness_mm;
                j["patches"][k]["max_lag_t"] = p.max_lag_t;
                j["patches"][k]["max_lag_at"] = {p.max_lag_at.x(), p.max_lag_at.y(), p.max_lag_at.z()};
                j["patches"][k]["end_lag_to_thickness"] = p.end_lag_to_thickness;
            }
    }
    j["skipped_inputs"] = a.skipped_inputs;
    j["physics_frames"] = a.frames;
    j["haptic_ticks"] = a.haptic_ticks;
    j["refactorisations"] = refactors;
    j["wcc_condition_estimate_max"] = a.max_condition_estimate;
    j["linear_limit"] = scene.linear_limit;
    j["max_displacement_to_thickness"] = a.max_displacement_to_thickness;
    j["max_displacement_mm"] = a.max_displacement_mm;
    j["max_displacement_wall_thickness_mm"] = a.max_displacement_thickness_mm;
    j["load_s"] = model.load_seconds;
    j["time_split"] = {{"collision", stats([](const FrameStats& f) { return f.collision_s; })},
                       {"factorisation", stats([](const FrameStats& f) { return f.factor_s; })},
                       {"solve", stats([](const FrameStats& f) { return f.solve_s; })},
                       {"smvm", stats([](const FrameStats& f) { return f.smvm_s; })}};
    if (haptic && !haptic->output_s.empty()) {
        std::vector<double> v;
        for (double x : haptic->output_s) v.push_back(1e3 * x);
        std::sort(v.begin(), v.end());
        double sum = 0;
        for (double x : v) sum += x;
        j["time_split"]["output_series_frame"] = {{"mean_ms", sum / static_cast<double>(v.size())},
                                                  {"p95_ms", percentile(v, 0.95)},
                                                  {"max_ms", v.back()}};
    }
    std::string haptic_line;
    if (haptic && haptic->tick_s.size() > 2) {
        std::vector<double> period, step = haptic->step_s;
        for (size_t k = 1; k < haptic->tick_s.size(); ++k) period.push_back(1e3 * (haptic->tick_s[k] - haptic->tick_s[k - 1]));
        for (double& x : step) x *= 1e3;
        auto pct = [](const std::vector<double>& v, double q) { return percentile(v, q); };
        const double span = haptic->tick_s.back() - haptic->tick_s.front();
        const double rate = span > 0 ? static_cast<double>(haptic->tick_s.size() - 1) / span : 0.0;
        j["haptic_loop"] = {{"target_hz", scene.haptic_hz}, {"rate_hz", rate},
                            {"period_ms", {{"p50", pct(period, 0.5)}, {"p99", pct(period, 0.99)}, {"max", pct(period, 1.0)}}},
                            {"step_ms", {{"p50", pct(step, 0.5)}, {"p99", pct(step, 0.99)}, {"max", pct(step, 1.0)}}}};
        char hb[256];
        std::snprintf(hb, sizeof hb, "  haptic loop                %.0f Hz (target %.0f), period p99 %.2f ms, max %.2f ms\n", rate,
                      scene.haptic_hz, pct(period, 0.99), pct(period, 1.0));
        haptic_line = hb;
        if (a.total_time_s > 0) j["physics_rate_hz"] = static_cast<double>(a.frames) / a.total_time_s;
    }
    std::string flow_line;
    if (flow != nullptr) {
        j["residual_flow"] = {{"file", flow->file}, {"seconds", flow->seconds}};
        if (!flow->error.empty()) {
            j["residual_flow"]["error"] = flow->error;
            flow_line = "  residual sac inflow        not computed: " + flow->error + "\n";
        } else {
            j["residual_flow"]["sac_inflow_ml_s"] = flow->sac_inflow_ml_s;
            j["residual_flow"]["pre_clip_sac_inflow_ml_s"] = flow->pre_clip_sac_inflow_ml_s;
            j["residual_flow"]["sac_volume_reached_mm3"] = flow->sac_volume_mm3;
            j["residual_flow"]["ends_closed_off"] = flow->ends_closed_off;
            if (flow->ratio >= 0) j["residual_flow"]["residual_sac_inflow_ratio"] = flow->ratio;
            j["residual_flow"]["pictures"] = flow->pictures;
            if (!flow->pictures_note.empty()) j["residual_flow"]["pictures_note"] = flow->pictures_note;
            char fb[320];
            if (flow->ratio >= 0)
                std::snprintf(fb, sizeof fb, "  residual sac inflow        %.1f %% of pre-clip (%.3g of %.3g mL/s; sac volume reached %.3g mm3)%s\n", 100 * flow->ratio,
                              flow->sac_inflow_ml_s, flow->pre_clip_sac_inflow_ml_s, flow->sac_volume_mm3,
                              flow->ends_closed_off > 0 ? "; a vessel end closed off" : "");
            else
                std::snprintf(fb, sizeof fb, "  residual sac inflow        no labelled sac to compare\n");
            flow_line = fb;
            for (const auto& pic : flow->pictures) flow_line += "  residual flow picture      " + pic + "\n";
            if (!flow->pictures_note.empty()) flow_line += "  residual flow pictures     " + flow->pictures_note + "\n";
        }
    }
    TextOut js(path);
    js.out() << j.dump(2) << '\n';
    js.finish();
    TextOut tx(path + ".txt");
    auto& o = tx.out();
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "Assessment of %s on %s\n"
                  "  total time                 %.3f s\n"
                  "  clips used                 %d (%d left on the vessel)\n"
                  "  repositionings             %d\n"
                  "  force above %.2f N         %d time(s), peak %.3f N\n"
                  "  speed above %.1f mm/s      %d time(s) while touching\n"
                  "  aneurysm neck closed       %.0f %% of %.1f mm (walls within %.2g mm; %.0f %% between closed jaws)\n",
                  scene.path.c_str(), model.case_id.c_str(), a.total_time_s, a.clips_used, a.clips_deposited,
                  a.repositionings, scene.force_threshold_n, a.force_exceedances, a.peak_force_n,
                  scene.velocity_threshold_mm_s, a.velocity_exceedances, 100.0 * a.neck_closed_fraction, a.neck_length_mm,
                  scene.neck_gap_mm, 100.0 * a.neck_between_jaws_fraction);
    o << buf;
    if (std::isfinite(a.neck_channel_mm)) {
        if (a.neck_channel_mm <= scene.neck_gap_mm)
            std::snprintf(buf, sizeof buf, "  sac sealed off the parent  yes (widest channel left %.3f mm)\n", a.neck_channel_mm);
        else
            std::snprintf(buf, sizeof buf, "  sac sealed off the parent  no: a channel %s%.3f mm wide, narrowest at (%.2f, %.2f, %.2f)\n",
                          a.neck_channel_mm >= 2.0 ? "at least " : "", a.neck_channel_mm, a.neck_channel_at.x(), a.neck_channel_at.y(),
                          a.neck_channel_at.z());
        o << buf;
        if (a.neck_cut_off_fraction >= 0) {
            std::snprintf(buf, sizeof buf, "  neck cut off the parent    %.0f %% of the neck line (the rest still reached by a channel over %.2g mm)\n",
                          100.0 * a.neck_cut_off_fraction, scene.neck_gap_mm);
            o << buf;
        }
    }
    if (std::isfinite(a.parent_narrowing)) {
        std::snprintf(buf, sizeof buf, "  parent artery narrowed     %.0f %% (its narrowest passage %.2f mm, %.2f mm at rest, at (%.2f, %.2f, %.2f))\n",
                      100.0 * a.parent_narrowing, a.parent_channel_mm, a.parent_channel_rest_mm, a.parent_channel_at.x(), a.parent_channel_at.y(),
                      a.parent_channel_at.z());
        o << buf;
    }
    if (std::isfinite(a.neck_in_jaws_fraction)) {
        std::snprintf(buf, sizeof buf, "  neck line in the jaws      %.0f %% (within their width; the farthest beside it %.2f mm)\n", 100.0 * a.neck_in_jaws_fraction,
                      a.neck_beside_jaws_mm);
        o << buf;
    }
    if (a.lumen_crossing_vertices > 0) {
        std::snprintf(buf, sizeof buf, "  lumen through itself       %.3f mm deep at (%.2f, %.2f, %.2f); %d vertices behind a face\n", a.lumen_crossing_mm,
                      a.lumen_crossing_at.x(), a.lumen_crossing_at.y(), a.lumen_crossing_at.z(), a.lumen_crossing_vertices);
        o << buf;
    }
    if (a.patch_nodes_in_other_tissue > 0) {
        std::snprintf(buf, sizeof buf, "  tissue through tissue      %d patch nodes inside an element not their own, %.4f mm deep\n", a.patch_nodes_in_other_tissue,
                      a.patch_tissue_overlap_mm);
        o << buf;
    }
    if (a.lumen_beside_tissue_vertices > 0) {
        std::snprintf(buf, sizeof buf, "  behind a face, not in it   %.3f mm deep; %d vertices in no tissue of the patch (not through it)\n", a.lumen_beside_tissue_mm,
                      a.lumen_beside_tissue_vertices);
        o << buf;
    }
    if (a.skipped_inputs) o << "  pose stream lines skipped  " << a.skipped_inputs << '\n';
    for (const auto& c : a.clip_ends) {
        std::snprintf(buf, sizeof buf, "  clip %-2d %-18s %s, open %.1f deg, grip %.3g N", c.id, c.model.c_str(), c.deposited ? "deposited" : "held",
                      c.opening_deg, c.grip_force_n);
        o << buf;
        if (c.spring) {
            std::snprintf(buf, sizeof buf, "; spring %.3g N mm against the tissue's %.3g N mm (%.3g N at the label point)%s", c.spring_torque_nmm,
                          c.tissue_moment_nmm, c.label_force_n, c.placeholder ? " (placeholder spring values)" : "");
            o << buf;
        }
        o << '\n';
    }
    for (const auto& p : a.patches) {
        std::snprintf(buf, sizeof buf,
                      "  clip %-2d nonlinear patch   %d nodes (%d on the interface), %ld frames (%ld not converged, %ld restarts), %.1f Newton its and "
                      "%.1f ms a frame (max %d, %.1f ms); peak blade force %.3g N (%.3g N at the label point); %s\n",
                      p.clip, p.nodes, p.interface_nodes, p.frames, p.unconverged_frames, p.restarts, p.mean_iterations, p.mean_solve_ms, p.max_iterations,
                      p.max_solve_ms, p.peak_blade_force_n, p.peak_label_force_n,
                      std::isfinite(p.min_wall_distance_mm) ? ("inner walls " + std::to_string(p.min_wall_distance_mm) + " mm apart at the closest").c_str()
                                                            : "no opposite inner walls came near");
        o << buf;
        if (p.max_lag_to_thickness > 0) {
            std::snprintf(buf, sizeof buf, "  clip %-2d frames' reach      %.3g mm from their linearisation on %.3g mm of wall (%.2g x, at the end %.2g x; trusted to %.2g x)%s\n",
                          p.clip, p.max_lag_mm, p.max_lag_thickness_mm, p.max_lag_to_thickness, p.end_lag_to_thickness, scene.linear_limit,
                          scene.linear_limit > 0 && p.max_lag_to_thickness > scene.linear_limit ? "  BEYOND" : "");
            o << buf;
        }
    }
    if (a.max_displacement_to_thickness > 0) {
        std::snprintf(buf, sizeof buf, "  largest push / wall        %.3g mm on %.3g mm (%.2g x; linear model trusted to %.2g x)%s\n",
                      a.max_displacement_mm, a.max_displacement_thickness_mm, a.max_displacement_to_thickness, scene.linear_limit,
                      scene.linear_limit > 0 && a.max_displacement_to_thickness > scene.linear_limit ? "  BEYOND" : "");
        o << buf;
    }
    o << flow_line;
    o << haptic_line;
    tx.finish();
}

}  // namespace aneu::sim
