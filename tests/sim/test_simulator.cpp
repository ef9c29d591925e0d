// SPDX-License-Identifier: MIT
// Scenes on the small tube case: clips placed, released, repositioned; deterministic replay; the
// contact-plane haptic force over a slide on the curved wall; suction sticking and relaxing; obstacles;
// bad scenes and pose streams.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <H5Cpp.h>
#include <nlohmann/json.hpp>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/sim/scene.hpp"
#include "aneu/sim/simulator.hpp"
#include "sim_fixtures.hpp"
#include "test_bundles.hpp"

using namespace aneu;
using nlohmann::json;

namespace {

std::string slurp(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void put(const std::string& p, const std::string& s) { std::ofstream(p, std::ios::binary) << s; }

// The bundle is shared by the tests (writing it is the slow part).
const std::string& tube_bundle(Precision prec) {
    static std::map<Precision, std::unique_ptr<test::TempDir>> dirs;
    static std::map<Precision, std::string> files;
    if (!files.count(prec)) {
        dirs[prec] = std::make_unique<test::TempDir>(prec == Precision::FLOAT64 ? "simcase64" : "simcase32");
        files[prec] = dirs[prec]->file("tube.h5");
        write_bundle(files[prec], test::tube_case(prec, 32, 20, 1.0, 0.5).bundle);
    }
    return files[prec];
}

json key(double t, std::array<double, 3> pos, std::array<double, 3> axis, std::array<double, 3> up, double opening) {
    return json{{"t", t}, {"position", pos}, {"axis", axis}, {"up", up}, {"opening_deg", opening}};
}

// Two clips across the sac side of the tube (jaws spread along z, closing on the wall at x ≈ 1.9), the
// first released, the second placed lower, then the first picked up and moved 0.6 mm along z.
json two_clip_scene(const std::string& bundle, const std::string& method) {
    json keys = json::array();
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 0, 1};
    auto k = [&](double t, double x, double z, double open) { return key(t, {x, 0, z}, ax, up, open); };
    json k0 = k(0.00, 5.0, 4.0, 40);
    k0["load"] = "straight";
    keys.push_back(k0);
    keys.push_back(k(0.05, 2.6, 4.0, 40));
    keys.push_back(k(0.10, 2.6, 4.0, 0));
    json r1 = k(0.14, 2.6, 4.0, 0);
    r1["release"] = true;
    keys.push_back(r1);
    keys.push_back(k(0.18, 5.0, 4.0, 0));
    json l2 = k(0.20, 5.0, 2.2, 40);
    l2["load"] = "straight";
    keys.push_back(l2);
    keys.push_back(k(0.24, 2.6, 2.2, 40));
    keys.push_back(k(0.28, 2.6, 2.2, 0));
    json r2 = k(0.32, 2.6, 2.2, 0);
    r2["release"] = true;
    keys.push_back(r2);
    keys.push_back(k(0.36, 5.0, 2.2, 0));
    json g1 = k(0.40, 2.6 + 0.0, 4.0, 0);  // at the first clip's hinge (it moved little with the vessel)
    keys.push_back(g1);
    json g2 = k(0.41, 2.6, 4.0, 0);
    g2["grasp"] = true;
    keys.push_back(g2);
    keys.push_back(k(0.44, 2.6, 4.0, 30));
    keys.push_back(k(0.48, 2.6, 4.6, 30));
    keys.push_back(k(0.52, 2.6, 4.6, 0));
    json r3 = k(0.56, 2.6, 4.6, 0);
    r3["release"] = true;
    keys.push_back(r3);
    keys.push_back(k(0.60, 5.0, 4.6, 0));
    return json{{"bundle", bundle},
                {"clip_models", {{"straight", {{"jaw_length_mm", 4.0}, {"jaw_width_mm", 1.2}, {"jaw_thickness_mm", 0.5},
                                               {"closed_gap_mm", 0.0}, {"max_opening_deg", 45}}}}},
                {"contact", {{"deposited_clips", method}}},
                {"rates_hz", {{"haptic", 1000}, {"physics", 250}, {"log", 250}, {"series", 50}}},
                {"assessment", {{"force_threshold_n", 0.05}, {"velocity_threshold_mm_s", 30}}},
                {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}, {"keyframes", keys}}})}};
}

sim::Simulator make(const json& j, const std::string& dir, const std::string& name = "scene.json") {
    const std::string p = dir + "/" + name;
    put(p, j.dump(2));
    sim::Scene sc = sim::read_scene(p);
    sim::LoadOptions lo;
    lo.region = sc.region;
    lo.working_precision = sc.working_precision;
    sim::SimModel m = sim::load_model(sc.bundle, lo);
    return sim::Simulator(std::move(sc), std::move(m));
}

}  // namespace

TEST(Simulator, TwoClipsReleasedAndOneRepositioned) {
    test::TempDir d("clips");
    json j = two_clip_scene(tube_bundle(Precision::FLOAT64), "exact");
    j["outputs"] = {{"log", "log.csv"}, {"report", "report.json"}, {"series", "series"}};
    sim::Simulator sim = make(j, d.file(""));
    std::vector<std::string> msgs;
    double worst_ratio = 0;
    int deposited_frames = 0;
    sim::RunOptions opt;
    opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
    opt.on_frame = [&](const sim::FrameStats&) {
        for (const sim::Clip& c : sim.clips())
            if (c.state == sim::Clip::State::DEPOSITED && c.n_nodes > 0 && c.grip_force_n > 0) {
                worst_ratio = std::max(worst_ratio, c.net_force.norm() / c.grip_force_n);
                ++deposited_frames;
            }
    };
    const sim::Assessment a = sim::run_scene(sim, opt);
    // Closed clips squeeze the 0.4 mm wall by half its thickness: past the linear model's range, said once.
    ASSERT_EQ(msgs.size(), 1u);
    EXPECT_NE(msgs[0].find("beyond the linear model's range"), std::string::npos) << msgs[0];
    EXPECT_NE(msgs[0].find("local wall thickness (0.4 mm)"), std::string::npos) << msgs[0];
    EXPECT_GT(a.max_displacement_to_thickness, sim.scene().linear_limit);
    EXPECT_NEAR(a.max_displacement_thickness_mm, 0.4, 1e-6);
    EXPECT_NEAR(a.max_displacement_to_thickness, a.max_displacement_mm / a.max_displacement_thickness_mm, 1e-12);
    EXPECT_EQ(a.clips_used, 2);
    EXPECT_EQ(a.repositionings, 1);
    EXPECT_EQ(a.clips_deposited, 2);
    EXPECT_GT(deposited_frames, 50);
    // Exact method: a deposited clip is a free body, the vessel's forces on it sum to zero.
    EXPECT_LT(worst_ratio, 1e-8);
    EXPECT_GT(a.peak_vessel_force_n, 0.0);
    EXPECT_GE(a.neck_closed_fraction, 0.0);
    EXPECT_LE(a.neck_closed_fraction, 1.0);
    // Outputs exist under their final names (and no temporary is left).
    const json rep = json::parse(slurp(d.file("report.json")));
    EXPECT_EQ(rep["clips_used"], 2);
    EXPECT_EQ(rep["repositionings"], 1);
    EXPECT_NE(slurp(d.file("report.json.txt")).find("repositionings             1"), std::string::npos);
    EXPECT_NE(slurp(d.file("report.json.txt")).find("BEYOND"), std::string::npos);
    EXPECT_DOUBLE_EQ(rep["max_displacement_to_thickness"].get<double>(), a.max_displacement_to_thickness);
    EXPECT_NE(slurp(d.file("series.xdmf")).find("CollectionType=\"Temporal\""), std::string::npos);
    EXPECT_GT(slurp(d.file("series.h5")).size(), 1000u);
    const std::string log = slurp(d.file("log.csv"));
    EXPECT_EQ(log.rfind("t_s,contact_nodes,prescribed_nodes,updated_rows,refactored,F_applier_x", 0), 0u);
    EXPECT_NE(log.find("clip1:deposited"), std::string::npos);
    for (const auto& e : std::filesystem::directory_iterator(d.file("")))
        EXPECT_EQ(e.path().string().find(".part-"), std::string::npos) << e.path();

    // The published two-solve method leaves a net force on the deposited clips.
    json j2 = two_clip_scene(tube_bundle(Precision::FLOAT64), "two-solve");
    sim::Simulator sim2 = make(j2, d.file(""), "two.json");
    double ratio2 = 0;
    opt.on_frame = [&](const sim::FrameStats&) {
        for (const sim::Clip& c : sim2.clips())
            if (c.state == sim::Clip::State::DEPOSITED && c.n_nodes > 0 && c.grip_force_n > 0)
                ratio2 = std::max(ratio2, c.net_force.norm() / c.grip_force_n);
    };
    const sim::Assessment a2 = sim::run_scene(sim2, opt);
    EXPECT_EQ(a2.clips_used, 2);
    EXPECT_EQ(a2.repositionings, 1);
    EXPECT_GT(ratio2, 1e-3);
    std::printf("net/grip force on deposited clips: exact %.2e, two-solve %.2e\n", worst_ratio, ratio2);
    std::printf("largest prescribed displacement %.3f mm on a %.3f mm wall: %.2f wall thicknesses (linear_limit %.2f): warned\n",
                a.max_displacement_mm, a.max_displacement_thickness_mm, a.max_displacement_to_thickness, sim.scene().linear_limit);
}

TEST(Simulator, DeterministicModeGivesBitIdenticalLogs) {
    test::TempDir d("det");
    for (const char* run : {"a", "b"}) {
        json j = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
        j["outputs"] = {{"log", std::string("log_") + run + ".csv"}, {"haptic_log", std::string("hap_") + run + ".csv"}};
        sim::Simulator sim = make(j, d.file(""), std::string("s_") + run + ".json");
        sim::run_scene(sim, {});
    }
    const std::string a = slurp(d.file("log_a.csv")), b = slurp(d.file("log_b.csv"));
    ASSERT_GT(a.size(), 1000u);
    EXPECT_EQ(a, b);
    EXPECT_EQ(slurp(d.file("hap_a.csv")), slurp(d.file("hap_b.csv")));
}

TEST(Simulator, AStopRequestEndsTheRunWhereItIsAndItsLogIsTheFullRunsBeginning) {
    // RunOptions::stop (aneusim run's SIGINT/SIGTERM) set after the frame at t = 0.1 s: the run ends at the next
    // tick, the report says where (stopped_at_s) and its figures are for the time reached, and the log is the first
    // part of the whole run's log, line for line.
    test::TempDir d("stop");
    std::string logs[2];
    sim::Assessment as[2];
    for (int run = 0; run < 2; ++run) {
        json j = two_clip_scene(tube_bundle(Precision::FLOAT64), "exact");
        j["outputs"] = {{"log", "log" + std::to_string(run) + ".csv"}, {"report", "report" + std::to_string(run) + ".json"}};
        sim::Simulator sim = make(j, d.file(""), "stop" + std::to_string(run) + ".json");
        std::atomic<bool> stop{false};
        sim::RunOptions opt;
        std::vector<std::string> msgs;
        opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
        if (run == 1) {
            opt.stop = &stop;
            opt.on_frame = [&](const sim::FrameStats& f) {
                if (f.t >= 0.1 - 1e-12) stop = true;
            };
        }
        as[run] = sim::run_scene(sim, opt);
        logs[run] = slurp(d.file("log" + std::to_string(run) + ".csv"));
        const json rep = json::parse(slurp(d.file("report" + std::to_string(run) + ".json")));
        if (run == 0) {
            EXPECT_LT(as[0].stopped_at_s, 0);
            EXPECT_FALSE(rep.contains("stopped_at_s"));
        } else {
            EXPECT_NEAR(as[1].stopped_at_s, 0.1, 1e-9);
            EXPECT_NEAR(rep["stopped_at_s"].get<double>(), 0.1, 1e-9);
            EXPECT_NEAR(rep["total_time_s"].get<double>(), 0.1, 1e-3);
            EXPECT_TRUE(std::any_of(msgs.begin(), msgs.end(), [](const std::string& m) { return m.find("stopped at t=0.1") != std::string::npos; }));
        }
    }
    EXPECT_GT(as[0].total_time_s, 0.5);
    ASSERT_GT(logs[1].size(), 200u);
    ASSERT_LT(logs[1].size(), logs[0].size());
    EXPECT_EQ(logs[0].compare(0, logs[1].size(), logs[1]), 0) << "the stopped run's log is not the whole run's beginning";
}

TEST(Simulator, NearRowUpdateGivesTheSameContactsAndForcesAsTheWholeRegion) {
    // Each frame updates only the rows of the nodes within update_margin_mm of the jaws (and the prescribed
    // ones), the whole region at rates_hz.region: contacts, forces and haptics must be those of updating the
    // whole region every frame, bit for bit (the SMVM adds the same terms in the same order per row).
    test::TempDir d("near");
    for (const char* run : {"whole", "near"}) {
        json j = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
        j["contact"]["update_margin_mm"] = std::string(run) == "whole" ? 0.0 : 1.5;
        j["rates_hz"]["region"] = 50;
        j["outputs"] = {{"log", std::string("log_") + run + ".csv"}, {"haptic_log", std::string("hap_") + run + ".csv"}};
        sim::Simulator sim = make(j, d.file(""), std::string("s_") + run + ".json");
        sim::run_scene(sim, {});
    }
    EXPECT_TRUE(slurp(d.file("hap_whole.csv")) == slurp(d.file("hap_near.csv"))) << "haptic logs differ";
    // Frame logs: equal but for the updated_rows column (the 4th).
    auto split = [](const std::string& text, std::vector<long>& rows) {
        std::istringstream in(text);
        std::string line, out;
        while (std::getline(in, line)) {
            std::vector<std::string> c;
            std::string cell;
            std::istringstream ls(line);
            while (std::getline(ls, cell, ',')) c.push_back(cell);
            if (c.size() > 4 && c[0] != "t_s") rows.push_back(std::stol(c[3]));
            if (c.size() > 4) c.erase(c.begin() + 3);
            for (const auto& x : c) out += x + ",";
            out += "\n";
        }
        return out;
    };
    std::vector<long> whole_rows, near_rows;
    const std::string a = split(slurp(d.file("log_whole.csv")), whole_rows), b = split(slurp(d.file("log_near.csv")), near_rows);
    ASSERT_GT(a.size(), 1000u);
    EXPECT_TRUE(a == b) << "frame logs differ";
    ASSERT_EQ(whole_rows.size(), near_rows.size());
    // The near update is in use: most frames update fewer rows than the whole region, every 5th the whole.
    size_t fewer = 0;
    for (size_t k = 0; k < near_rows.size(); ++k) {
        EXPECT_LE(near_rows[k], whole_rows[k]);
        fewer += near_rows[k] < whole_rows[k];
    }
    EXPECT_GT(fewer, near_rows.size() / 2);
    EXPECT_LT(fewer, near_rows.size());
    RecordProperty("frames_with_fewer_rows", std::to_string(fewer) + " of " + std::to_string(near_rows.size()));
}

TEST(Simulator, ContactPlaneForceIsContinuousAndFrictionOpposesMotion) {
    // The suction tip, pointing at the axis, 0.15 mm inside the outer wall (r = 1.9), slides 120° around it.
    test::TempDir d("slide");
    json keys = json::array();
    const double z = 4.0, r_in = 1.9 - 0.15;
    auto at = [&](double t, double ang, double r) {
        const double c = std::cos(ang), s = std::sin(ang);
        return key(t, {r * c, r * s, z}, {-c, -s, 0}, {0, 0, 1}, 0);
    };
    keys.push_back(at(0.0, -M_PI / 3, 2.6));
    keys.push_back(at(0.1, -M_PI / 3, r_in));
    for (int k = 1; k <= 8; ++k) keys.push_back(at(0.1 + 0.1 * k, -M_PI / 3 + k * (2 * M_PI / 3) / 8, r_in));
    keys.push_back(at(1.0, M_PI / 3, 2.6));
    json j{{"bundle", tube_bundle(Precision::FLOAT64)},
           {"haptic", {{"plane_stiffness_n_per_mm", 0.3}, {"friction_n_s_per_mm", 0.002}}},
           {"rates_hz", {{"haptic", 1000}, {"physics", 250}}},
           {"instruments", json::array({{{"name", "suction"}, {"kind", "suction"}, {"radius_mm", 0.5}, {"keyframes", keys}}})}};
    sim::Simulator sim = make(j, d.file(""));
    const int H = 1000, every = 4;
    double peak = 0, jump = 0, fric_checked = 0, fric_bad = 0, step = 0;
    Eigen::Vector3d prev = Eigen::Vector3d::Zero();
    Eigen::Vector3d prev_pos = sim::sample(sim.scene().instruments[0], 0).pose.position;
    for (int n = 0; n <= H * 1; ++n) {
        const double t = static_cast<double>(n) / H;
        sim.apply_script(n ? static_cast<double>(n - 1) / H : -1, t);
        if (n % every == 0) sim.physics_step(t);
        const Eigen::Vector3d F = sim.haptic_step(t)[0];
        peak = std::max(peak, F.norm());
        if (n) jump = std::max(jump, (F - prev).norm());
        prev = F;
        // While sliding (0.15 < t < 0.85) the force pushes outward and its tangential part opposes the motion.
        const Eigen::Vector3d pos = sim::sample(sim.scene().instruments[0], t).pose.position;
        if (t > 0.15 && t < 0.85 && F.norm() > 0) {
            const Eigen::Vector3d radial = Eigen::Vector3d(pos.x(), pos.y(), 0).normalized();
            EXPECT_GT(F.dot(radial), 0) << "t=" << t;
            Eigen::Vector3d v = (pos - prev_pos) * H;
            v -= v.dot(radial) * radial;
            const Eigen::Vector3d Ft = F - F.dot(radial) * radial;
            if (v.norm() > 1.0) {
                ++fric_checked;
                if (Ft.dot(v) >= 0) ++fric_bad;
            }
        }
        step = std::max(step, (pos - prev_pos).norm());
        prev_pos = pos;
    }
    // Continuous: no step larger than what a spring of the plane's stiffness gives at the tool's largest
    // speed over one haptic tick (a force that switched on at first node contact would step by k × depth).
    const double k = 0.3, bound = 1.5 * k * step;
    std::printf("slide: peak %.4f N, largest step between haptic ticks %.5f N (%.2f %% of peak), k·v·dt %.5f N\n", peak,
                jump, 100 * jump / peak, k * step);
    EXPECT_GT(peak, 0.02);
    EXPECT_LT(jump, bound);
    EXPECT_GT(fric_checked, 400);
    EXPECT_LT(fric_bad, 0.02 * fric_checked);
}

TEST(Simulator, SuctionSticksPullsAndReleasedAreaRelaxes) {
    test::TempDir d("suction");
    json keys = json::array();
    auto at = [&](double t, double x, bool button) {
        json k = key(t, {x, 0, 4.0}, {-1, 0, 0}, {0, 0, 1}, 0);
        k["button"] = button;
        return k;
    };
    keys.push_back(at(0.0, 2.5, false));
    keys.push_back(at(0.1, 1.8, false));
    keys.push_back(at(0.15, 1.8, true));
    keys.push_back(at(0.3, 2.6, true));   // pulls the wall out by ~0.8 mm
    keys.push_back(at(0.35, 2.6, false));  // released
    keys.push_back(at(0.8, 2.6, false));
    json j{{"bundle", tube_bundle(Precision::FLOAT64)},
           {"contact", {{"relax_time_s", 0.05}}},
           {"rates_hz", {{"haptic", 1000}, {"physics", 250}}},
           {"instruments", json::array({{{"name", "suction"}, {"kind", "suction"}, {"radius_mm", 0.6}, {"keyframes", keys}}})}};
    sim::Simulator sim = make(j, d.file(""));
    const auto& X = sim.model().surface.X;
    auto outward = [&] {
        const Eigen::MatrixX3d x = sim.deformed_surface();
        double best = -1e9;
        for (Eigen::Index v = 0; v < X.rows(); ++v) best = std::max(best, x(v, 0) - X(v, 0));
        return best;
    };
    double pulled = 0, after = 1e9, prev_after = 1e9;
    bool monotone = true;
    for (int n = 0; n <= 800; ++n) {
        const double t = n / 1000.0;
        sim.apply_script(n ? (n - 1) / 1000.0 : -1, t);
        if (n % 4 == 0) {
            sim.physics_step(t);
            if (std::abs(t - 0.30) < 1e-9) pulled = outward();
            if (t > 0.36) {
                after = outward();
                if (after > prev_after + 1e-9) monotone = false;
                prev_after = after;
            }
        }
        sim.haptic_step(t);
    }
    EXPECT_GT(pulled, 0.5) << "the stuck wall follows the tube out";
    EXPECT_TRUE(monotone) << "released area relaxes back monotonically";
    EXPECT_LT(after, 0.01) << "and reaches rest after many time constants";
}

TEST(Simulator, RigidObstaclePushesTheInstrumentOut) {
    test::TempDir d("obst");
    // A cube obstacle x ∈ [4,6], y,z ∈ [-1,1] (+4 in z), as ASCII STL, outward triangles.
    const double c[8][3] = {{4, -1, 3}, {6, -1, 3}, {6, 1, 3}, {4, 1, 3}, {4, -1, 5}, {6, -1, 5}, {6, 1, 5}, {4, 1, 5}};
    const int f[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                          {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
    std::ostringstream stl;
    stl << "solid box\n";
    for (const auto& t : f) {
        stl << " facet normal 0 0 0\n  outer loop\n";
        for (int k : t) stl << "   vertex " << c[k][0] << ' ' << c[k][1] << ' ' << c[k][2] << '\n';
        stl << "  endloop\n endfacet\n";
    }
    stl << "endsolid box\n";
    put(d.file("box.stl"), stl.str());
    json keys = json::array({key(0.0, {7.0, 0, 4}, {-1, 0, 0}, {0, 0, 1}, 0), key(0.2, {5.8, 0, 4}, {-1, 0, 0}, {0, 0, 1}, 0)});
    json j{{"bundle", tube_bundle(Precision::FLOAT64)},
           {"obstacles", json::array({{{"name", "bone"}, {"mesh", "box.stl"}}})},
           {"haptic", {{"obstacle_stiffness_n_per_mm", 2.0}}},
           {"instruments", json::array({{{"name", "suction"}, {"kind", "suction"}, {"keyframes", keys}}})}};
    sim::Simulator sim = make(j, d.file(""));
    sim.apply_script(-1, 0.2);
    sim.physics_step(0.2);
    const Eigen::Vector3d F = sim.haptic_step(0.2)[0];
    // Tip 0.2 mm inside the face x = 6: pushed back along +x with 2 N/mm · 0.2 mm.
    EXPECT_NEAR(F.x(), 0.4, 1e-6);
    EXPECT_NEAR(F.y(), 0.0, 1e-9);
    EXPECT_NEAR(F.z(), 0.0, 1e-9);
}

TEST(SimulatorInput, BadScenesAreClearErrors) {
    test::TempDir d("badscene");
    auto expect_error = [&](const json& j, const std::string& needle) {
        put(d.file("s.json"), j.dump());
        try {
            sim::read_scene(d.file("s.json"));
            ADD_FAILURE() << "expected InputError containing " << needle;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
        }
    };
    json good = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
    json j = good;
    j["instruments"][0]["keyframes"][0]["load"] = "fenestrated";
    expect_error(j, "names clip model \"fenestrated\", which clip_models does not define");
    j = good;
    j["contact"]["deposited_clips"] = "magic";
    expect_error(j, "expected exact or two-solve");
    j = good;
    j["haptc"] = json::object();
    expect_error(j, "unknown key \"haptc\"");
    j = good;
    j["instruments"][0]["keyframes"][1]["t"] = 0.0;
    expect_error(j, "must be after the previous keyframe");
    j = good;
    j["clip_models"]["straight"]["jaw_mesh"] = "missing_jaw.stl";
    expect_error(j, "missing_jaw.stl: cannot open");
    j = good;
    j["clip_models"]["straight"]["spring"] = {{"label_force_n", 2.0}, {"open_force_n", 1.0}};
    expect_error(j, "clip_models.straight: spring: clip spring: need two closing forces 0 < f1 < f2");
    j = good;
    j["clip_models"]["straight"]["spring"] = {{"label_force_n", 1.0}, {"open_force_n", 2.0}, {"stiffness", 3}};
    expect_error(j, "clip_models.straight.spring: unknown key \"stiffness\"");
    j = good;
    j["clip_models"]["straight"] = {{"file", "no_such_clip.json"}};
    expect_error(j, "no_such_clip.json: cannot open the clip file");
    j = good;
    j["model"] = {{"wall", "patch"}, {"patch_solver", "compliance"}, {"friction_cell_mm", -0.5}};
    expect_error(j, "friction_cell_mm");
    j["model"]["friction_cell_mm"] = 0.5;
    put(d.file("s.json"), j.dump());
    EXPECT_EQ(sim::read_scene(d.file("s.json")).patch.friction_cell_mm, 0.5);
    put(d.file("broken.json"), "{ \"bundle\": ");
    EXPECT_THROW(sim::read_scene(d.file("broken.json")), InputError);

    // A bundle of another schema version.
    const std::string other = d.file("other.h5");
    std::filesystem::copy_file(tube_bundle(Precision::FLOAT32), other);
    {
        H5::H5File f(other, H5F_ACC_RDWR);
        H5::Group meta = f.openGroup("/meta");
        meta.removeAttr("schema_version");
        const int v = 99;
        meta.createAttribute("schema_version", H5::PredType::NATIVE_INT, H5::DataSpace()).write(H5::PredType::NATIVE_INT, &v);
    }
    try {
        sim::load_model(other);
        ADD_FAILURE() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("schema"), std::string::npos) << e.what();
    }
}

TEST(SimulatorInput, PoseStreamSkipsGarbageAndNaN) {
    // One reader for both run modes: the deterministic timeline and the threaded real-time loop refuse the same
    // lines for the same reasons, and pass over blank lines and comments alike.
    for (const bool deterministic : {true, false}) {
        SCOPED_TRACE(deterministic ? "deterministic" : "threaded");
        test::TempDir d("live");
        json j{{"bundle", tube_bundle(Precision::FLOAT64)},
               {"live_input", true},
               {"contact", {{"linear_limit", 0}}},  // only the stream's messages here
               {"clip_models", {{"straight", json::object()}}},
               {"rates_hz", {{"haptic", 1000}, {"physics", 250}}},
               {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}}})}};
        sim::Simulator sim = make(j, d.file(""));
        std::istringstream in(
            "# a recorded session\n"
            "0.000 applier 5 0 4 -1 0 0 0 0 1 40 0 load:straight\n"
            "0.010 applier 4.5 0 4 -1 0 0 0 0 1 40 0\n"
            "hello world\n"
            "\n"
            "0.020 applier nan 0 4 -1 0 0 0 0 1 40 0\n"
            "0.030 applier 4 0 4 -1 0 0 -1 0 0 40 0\n"   // up parallel to axis
            "0.040 scalpel 4 0 4 -1 0 0 0 0 1 40 0\n"
            "0.005 applier 4 0 4 -1 0 0 0 0 1 40 0\n"    // time goes back
            "0.050 applier 4 0 4 -1 0 0 0 0 1 40 0 explode\n"
            "0.060 applier 4 0 4 -1 0 0 0 0 1 40 0\n");
        std::vector<std::string> msgs;
        sim::RunOptions opt;
        opt.deterministic = deterministic;
        opt.live = &in;
        opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
        const sim::Assessment a = sim::run_scene(sim, opt);
        EXPECT_EQ(a.skipped_inputs, 6);
        ASSERT_EQ(msgs.size(), 6u);
        EXPECT_NE(msgs[0].find("line 4 skipped"), std::string::npos) << msgs[0];
        EXPECT_NE(msgs[1].find("not finite"), std::string::npos) << msgs[1];
        EXPECT_NE(msgs[2].find("parallel"), std::string::npos) << msgs[2];
        EXPECT_NE(msgs[3].find("unknown instrument \"scalpel\""), std::string::npos) << msgs[3];
        EXPECT_NE(msgs[4].find("goes back"), std::string::npos) << msgs[4];
        EXPECT_NE(msgs[5].find("unknown action"), std::string::npos) << msgs[5];
        EXPECT_EQ(a.clips_used, 1);
        if (deterministic) {
            EXPECT_NEAR(a.total_time_s, 0.06, 1e-9);
        }
    }
}

namespace {

// One clip across the tube's side (as in two_clip_scene), its applier relaxed to 0° and then held there: with a
// spring the clip stops where the tissue's moment balances it.
json spring_scene(const std::string& bundle, double label_n, bool spring) {
    json keys = json::array();
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 0, 1};
    auto k = [&](double t, double x, double open) { return key(t, {x, 0, 4.0}, ax, up, open); };
    json k0 = k(0.00, 5.0, 40);
    k0["load"] = "straight";
    keys.push_back(k0);
    keys.push_back(k(0.05, 2.6, 40));
    keys.push_back(k(0.10, 2.6, 0));
    keys.push_back(k(0.40, 2.6, 0));
    json model = {{"jaw_length_mm", 4.0}, {"jaw_width_mm", 1.2}, {"jaw_thickness_mm", 0.5}, {"closed_gap_mm", 0.0}, {"max_opening_deg", 45}};
    if (spring) model["spring"] = {{"label_force_n", label_n}, {"open_force_n", 1.6 * label_n}, {"placeholder", true}};
    return json{{"bundle", bundle},
                {"clip_models", {{"straight", model}}},
                {"rates_hz", {{"haptic", 1000}, {"physics", 250}, {"log", 250}, {"series", 50}}},
                {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}, {"keyframes", keys}}})}};
}

}  // namespace

TEST(Simulator, ASpringClipStopsWhereTheTissueBalancesItsSpring) {
    test::TempDir d("spring");
    struct Out {
        double opening = 0, torque = 0, moment = 0, grip = 0;
    };
    auto run = [&](double label_n, bool spring, const std::string& name) {
        sim::Simulator s = make(spring_scene(tube_bundle(Precision::FLOAT64), label_n, spring), d.file(""), name);
        sim::run_scene(s, {});
        const sim::Clip& c = s.clips().at(0);
        EXPECT_EQ(c.state, sim::Clip::State::HELD);
        EXPECT_DOUBLE_EQ(c.forceps_deg, 0.0);
        if (spring) {
            // The force at the label point is the tissue's moment over its arm; held where the tissue balances the
            // spring, it is the spring's force there at that opening (what its label range is stated for).
            const sim::ClipModel& cm = s.scene().clip_models.at(c.model);
            EXPECT_NEAR(c.label_force_n, c.tissue_moment_nmm / cm.label_arm_mm(), 1e-12);
            if (c.opening_deg > 0) {
                EXPECT_NEAR(c.label_force_n, cm.spring->force_at(cm.label_arm_mm(), c.opening_deg * aneu::DEG), 0.01 * c.label_force_n);
            }
        }
        return Out{c.opening_deg, c.spring_torque_nmm, c.tissue_moment_nmm, c.grip_force_n};
    };
    const Out none = run(0, false, "none.json");
    const Out weak = run(0.3, true, "weak.json");
    const Out strong = run(1.0, true, "strong.json");
    // Without a spring the jaws follow the applier shut. A weak spring is held open by the tissue where its
    // moment about the hinge balances the spring's torque; a strong one closes the clip (the blades meet, its
    // torque still above the tissue's moment).
    EXPECT_DOUBLE_EQ(none.opening, 0.0);
    EXPECT_GT(weak.opening, 1.0);
    EXPECT_LT(weak.opening, 44.0);
    EXPECT_NEAR(weak.moment, weak.torque, 0.01 * weak.torque);
    EXPECT_DOUBLE_EQ(strong.opening, 0.0);
    EXPECT_GT(strong.torque, strong.moment);
    EXPECT_GT(strong.grip, weak.grip);
    std::printf("applier shut: no spring 0 deg (grip %.3f N); spring 0.3 N label: %.2f deg (grip %.3f N, torque %.4f, moment %.4f N mm); "
                "1 N: %.2f deg (grip %.3f N, torque %.4f > moment %.4f N mm)\n",
                none.grip, weak.opening, weak.grip, weak.torque, weak.moment, strong.opening, strong.grip, strong.torque, strong.moment);
}

TEST(ClipFiles, ShippedClipModelsReadWithTheirLabelForce) {
    // configs/clips: every file reads, its spring gives back its label force at the ISO 9713 point (1 mm opening,
    // a third of the blade from its tip), and its values are flagged as placeholders (configs/clips/README.md).
    int n = 0;
    for (const auto& e : std::filesystem::directory_iterator(std::string(ANEU_SOURCE_DIR) + "/configs/clips")) {
        if (e.path().extension() != ".json") continue;
        const sim::ClipModel c = sim::read_clip_file(e.path().string());
        ASSERT_TRUE(c.spring) << e.path();
        const double r = 2.0 * c.jaw_length_mm / 3.0;
        EXPECT_NEAR(c.spring->force_at(r, 2 * std::asin(0.5 / r)), c.label_force_n, 1e-9) << e.path();
        EXPECT_NEAR(c.spring->force_at(r, c.max_opening_deg * M_PI / 180), c.open_force_n, 1e-9) << e.path();
        EXPECT_TRUE(c.spring_placeholder) << e.path();
        EXPECT_EQ(c.name, e.path().stem().string());
        ++n;
    }
    EXPECT_GE(n, 5);
    // A scene's clip model may name a clip file and override its keys.
    test::TempDir d("clipfile");
    json j = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
    j["clip_models"]["straight"] = {{"file", std::string(ANEU_SOURCE_DIR) + "/configs/clips/straight_7mm.json"}, {"jaw_length_mm", 4.0}};
    put(d.file("s.json"), j.dump());
    const sim::Scene sc = sim::read_scene(d.file("s.json"));
    const sim::ClipModel& c = sc.clip_models.at("straight");
    EXPECT_DOUBLE_EQ(c.jaw_length_mm, 4.0);
    EXPECT_DOUBLE_EQ(c.label_force_n, 1.5);
    ASSERT_TRUE(c.spring);
}

namespace {
/// Scene j with its clip model "straight" replaced by `model` is refused with an input error that says `says`.
void expect_clip_model_refused(const json& j, const json& model, const std::string& says, const std::string& path) {
    json k = j;
    k["clip_models"]["straight"] = model;
    put(path, k.dump());
    try {
        sim::read_scene(path);
        ADD_FAILURE() << "accepted " << model.dump();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
}
}  // namespace

TEST(ClipFiles, AFulcrumBehindTheHeelMovesTheLabelPoint) {
    // A clip model whose blades turn about a fulcrum 20 mm behind their heel (ClipModel::fulcrum_mm): its jaws reach
    // 20 + 9 mm from the pose's position, and its spring gives its label force at the ISO 9713 point measured from the
    // fulcrum (1 mm opening at 20 + 6 mm), not at 6 mm; its blades' faces begin at the heel. Refused: a negative fulcrum, one with a mesh jaw, a reach
    // beyond 100 mm (each one line naming the key).
    test::TempDir d("fulcrum");
    json j = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
    j["clip_models"]["straight"] = {{"file", std::string(ANEU_SOURCE_DIR) + "/configs/clips/straight_9mm.json"}, {"fulcrum_mm", 20.0}};
    put(d.file("s.json"), j.dump());
    const sim::Scene sc = sim::read_scene(d.file("s.json"));
    const sim::ClipModel& c = sc.clip_models.at("straight");
    EXPECT_DOUBLE_EQ(c.fulcrum_mm, 20.0);
    EXPECT_DOUBLE_EQ(c.reach_mm(), 29.0);
    EXPECT_DOUBLE_EQ(c.turn_per_heel_turn(), 4.5 / 24.5);  // the blade's middle 24.5 mm from the fulcrum, 4.5 from the heel
    // Its faces begin at the heel (the arms and box before it do not clamp tissue); "arms_press" clamps with them too.
    EXPECT_FALSE(c.arms_press);
    EXPECT_DOUBLE_EQ(c.blades(sim::Pose{}).face_from_mm, 20.0);
    EXPECT_DOUBLE_EQ(c.blades(sim::Pose{}).length_mm, 29.0);
    {
        json k = j;
        k["clip_models"]["straight"]["arms_press"] = true;
        put(d.file("arms.json"), k.dump());
        const sim::Scene ka = sim::read_scene(d.file("arms.json"));
        EXPECT_TRUE(ka.clip_models.at("straight").arms_press);
        EXPECT_DOUBLE_EQ(ka.clip_models.at("straight").blades(sim::Pose{}).face_from_mm, 0.0);
    }
    ASSERT_TRUE(c.spring);
    const double r = 20.0 + 6.0;
    EXPECT_NEAR(c.spring->force_at(r, 2 * std::asin(0.5 / r)), 1.5, 1e-9);
    EXPECT_NEAR(c.spring->force_at(r, c.max_opening_deg * M_PI / 180), 2.5, 1e-9);
    // The same clip turning at its heel holds it 6 mm out: about the fulcrum it takes 26/6 the torque there.
    const sim::ClipModel heel = sim::read_clip_file(std::string(ANEU_SOURCE_DIR) + "/configs/clips/straight_9mm.json");
    EXPECT_EQ(heel.turn_per_heel_turn(), 1.0);  // without a fulcrum the caps are as they were, to the bit
    EXPECT_NEAR(c.spring->torque(2 * std::asin(0.5 / r)) / heel.spring->torque(2 * std::asin(0.5 / 6.0)), 26.0 / 6.0, 1e-9);
    auto refused = [&](const json& model, const std::string& says) { expect_clip_model_refused(j, model, says, d.file("bad.json")); };
    refused({{"jaw_length_mm", 9.0}, {"fulcrum_mm", -1.0}}, "fulcrum_mm");
    refused({{"jaw_length_mm", 9.0}, {"fulcrum_mm", 95.0}}, "expected at most 100 mm");
    const std::string stl = d.file("jaw.stl");
    put(stl, "solid j\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid j\n");
    refused({{"jaw_length_mm", 9.0}, {"fulcrum_mm", 5.0}, {"jaw_mesh", stl}}, "with a jaw_mesh");
}

TEST(ClipFiles, ACurvedClipsJawsBendFromTheHeelAndATooTightCurveIsRefused) {
    // A 9 mm clip with a fulcrum 5 mm behind its heel, its blades curved at 12 mm towards axis × up: the model keeps
    // the radius, its jaws (a box bent along the centre line) hold a point on the bent centre line 8 mm into the curve
    // and not the straight blade's place there, and the blades' frame (blades_of, the patch and the spring) bends
    // from the heel. Refused: a curve tighter than the blade allows, a curve with a jaw mesh.
    test::TempDir d("curved");
    json j = two_clip_scene(tube_bundle(Precision::FLOAT32), "exact");
    j["clip_models"]["straight"] = {{"file", std::string(ANEU_SOURCE_DIR) + "/configs/clips/straight_9mm.json"}, {"fulcrum_mm", 5.0},
                                    {"jaw_curve_radius_mm", 12.0}};
    put(d.file("s.json"), j.dump());
    const sim::Scene sc = sim::read_scene(d.file("s.json"));
    const sim::ClipModel& c = sc.clip_models.at("straight");
    EXPECT_DOUBLE_EQ(c.jaw_curve_radius_mm, 12.0);
    sim::Pose p;
    p.position = Eigen::Vector3d(1, 2, 3);
    p.axis = Eigen::Vector3d::UnitX();
    p.up = Eigen::Vector3d::UnitZ();  // axis × up = −y: the blades bend towards −y
    const auto jaws = sim::clip_jaws(c, p, 0.0);
    ASSERT_EQ(jaws[0].kind, sim::Shape::Kind::BOX);
    EXPECT_DOUBLE_EQ(jaws[0].bend_radius, 12.0);
    const double phi = 8.0 / 12.0;
    const Eigen::Vector3d on = p.position + Eigen::Vector3d(5.0 + 12.0 * std::sin(phi), -12.0 * (1 - std::cos(phi)), 0.25);  // 0.25 into jaw +1
    EXPECT_LT(jaws[0].sdf(on), -0.2);
    EXPECT_GT(jaws[0].sdf(Eigen::Vector3d(on.x(), p.position.y(), on.z())), 0.5);  // where a straight blade would be: outside
    EXPECT_LT(jaws[0].sdf(p.position + Eigen::Vector3d(3.0, 0.0, 0.25)), -0.2);  // the arms before the heel: straight
    // Inside the swept jaw exactly where the bent blade is (along its centre line within the reach, across it within
    // half the width, behind its face within its thickness), on a grid round it; opened 20°.
    {
        const auto open = sim::clip_jaws(c, p, 20.0);
        const fem::ClipBlades b = c.blades(p);
        Eigen::Vector3d t, n, w;
        b.frame(1, 20.0 * M_PI / 180, t, n, w);
        int wrong = 0, inside = 0;
        for (double x = -1; x <= 15; x += 0.37)
            for (double y = -6; y <= 2; y += 0.23)
                for (double z = -1; z <= 1.5; z += 0.17) {
                    const Eigen::Vector3d q = p.position + x * t + y * w + z * (-n);  // -n: into jaw +1 from its face
                    const fem::ClipBlades::FaceCoords fc = b.face_coords(x, y);
                    const bool in = x >= 0 && fc.s <= b.length_mm && std::abs(fc.a) <= 0.5 * b.width_mm && z >= 0 && z <= c.jaw_thickness_mm;
                    const double sd = open[0].sdf(q);
                    if (std::abs(sd) < 0.02) continue;  // on its surface (the mesh's chords)
                    inside += in;
                    if ((sd < 0) != in && ++wrong <= 5)
                        ADD_FAILURE() << "at (" << x << ", " << y << ", " << z << ") along, across, into the jaw: sdf " << sd << ", s " << fc.s << ", a " << fc.a;
                }
        EXPECT_GT(inside, 100);
        EXPECT_EQ(wrong, 0);
    }
    auto refused = [&](const json& model, const std::string& says) { expect_clip_model_refused(j, model, says, d.file("bad.json")); };
    refused({{"jaw_length_mm", 9.0}, {"jaw_curve_radius_mm", 5.0}}, "bends past 90 degrees");
    refused({{"jaw_length_mm", 9.0}, {"jaw_curve_radius_mm", -1.0}}, "jaw_curve_radius_mm");
    const std::string stl = d.file("jaw.stl");
    put(stl, "solid j\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid j\n");
    refused({{"jaw_length_mm", 9.0}, {"jaw_curve_radius_mm", 20.0}, {"jaw_mesh", stl}}, "with a jaw_mesh");
}

TEST(Simulator, AFastClosingJawKeepsTheWallBetweenTheJaws) {
    // A clip across the whole tube (hinge 6 mm off its axis, 8 mm jaws along −x, opening along y) snaps shut from
    // 60° in 3 physics frames: the jaws cross the tube's wall at up to 1.3 mm a frame, more than their 0.5 mm
    // thickness. The wall nodes that were between the jaws must stay on the jaws' inner side, not be carried out
    // through their backs (behind a jaw's inner face by more than its thickness).
    test::TempDir d("fastjaw");
    json keys = json::array();
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 1, 0};
    json k0 = key(0.0, {9.0, 0, 4.0}, ax, up, 60);
    k0["load"] = "straight";
    keys.push_back(k0);
    keys.push_back(key(0.05, {6.0, 0, 4.0}, ax, up, 60));
    keys.push_back(key(0.06, {6.0, 0, 4.0}, ax, up, 60));
    keys.push_back(key(0.072, {6.0, 0, 4.0}, ax, up, 0));
    keys.push_back(key(0.12, {6.0, 0, 4.0}, ax, up, 0));
    json j = {{"bundle", tube_bundle(Precision::FLOAT64)},
              {"clip_models", {{"straight", {{"jaw_length_mm", 8.0}, {"jaw_width_mm", 1.2}, {"jaw_thickness_mm", 0.5}, {"max_opening_deg", 60}}}}},
              {"rates_hz", {{"haptic", 1000}, {"physics", 250}, {"log", 250}, {"series", 50}}},
              {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}, {"keyframes", keys}}})}};
    sim::Simulator s = make(j, d.file(""));
    sim::run_scene(s, {});
    const Eigen::MatrixX3d x = s.deformed_surface();
    const Eigen::MatrixX3d& X = s.model().surface.X;
    fem::ClipBlades bl;
    bl.hinge = Eigen::Vector3d(6.0, 0, 4.0);
    bl.axis = -Eigen::Vector3d::UnitX();
    bl.up = Eigen::Vector3d::UnitY();
    bl.length_mm = 8.0;
    bl.width_mm = 1.2;
    int between = 0, through = 0;
    for (Eigen::Index v = 0; v < X.rows(); ++v) {
        const Eigen::Vector3d rel0 = X.row(v).transpose() - bl.hinge;
        if (std::abs(rel0.z()) > 0.4) continue;  // within the jaws' width, clear of their edges
        ++between;
        const Eigen::Vector3d rel = x.row(v).transpose() - bl.hinge;
        for (int sg : {1, -1}) {
            Eigen::Vector3d t, n, w;
            bl.frame(sg, 0.0, t, n, w);
            if (rel.dot(n) < -0.5) ++through;  // beyond the closed jaw's back face
        }
    }
    std::printf("%d wall nodes between the jaws, %d went through\n", between, through);
    EXPECT_GE(between, 40);
    EXPECT_EQ(through, 0) << through << " of " << between << " wall nodes went through a jaw";
}

namespace {

// A clip across the tube at z = 4: jaws along −x from a hinge at x = 8, squeezing along y, closed from 40° to
// θ_end, where its blades are 0.9 mm apart on the tube's axis (the two 0.4 mm walls touch inside).
constexpr double FLAT_HINGE_X = 8.0, FLAT_END_DEG = 5.014;
json flattening_scene(const std::string& bundle, const std::string& wall, bool release, double end_deg = FLAT_END_DEG) {
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 1, 0};
    auto k = [&](double t, double open) { return key(t, {FLAT_HINGE_X, 0, 4.0}, ax, up, open); };
    json keys = json::array();
    json k0 = k(0.0, 40);
    k0["load"] = "flat";
    keys.push_back(k0);
    keys.push_back(k(0.02, 40));
    keys.push_back(k(0.14, end_deg));
    keys.push_back(k(0.16, end_deg));
    if (release) {
        json r = k(0.17, end_deg);
        r["release"] = true;
        keys.push_back(r);
        keys.push_back(key(0.20, {FLAT_HINGE_X + 3, 0, 4.0}, ax, up, end_deg));
        keys.push_back(key(0.32, {FLAT_HINGE_X + 3, 0, 4.0}, ax, up, end_deg));
    }
    json clip = {{"jaw_length_mm", 10.5}, {"jaw_width_mm", 1.2}, {"jaw_thickness_mm", 0.5}, {"closed_gap_mm", 0.2}, {"max_opening_deg", 45}};
    if (release) clip["spring"] = {{"label_force_n", 0.3}, {"open_force_n", 0.5}, {"placeholder", true}, {"source", "test"}};
    return json{{"bundle", bundle},
                {"clip_models", {{"flat", clip}}},
                {"model", {{"wall", wall}, {"newton_per_frame", 40}}},
                {"rates_hz", {{"haptic", 1000}, {"physics", 100}, {"log", 100}, {"series", 50}}},
                {"outputs", {{"log", wall + "_log.csv"}}},
                {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}, {"keyframes", keys}}})}};
}

/// The flattening scene on the compliance frames relinearised every `refresh` frames (model.patch_solver compliance),
/// the clip held at the end opening until `held_until` (< 0: the scene's own keyframes only).
json compliance_flattening_scene(const std::string& bundle, int refresh, double held_until) {
    json j = flattening_scene(bundle, "patch", false);
    j["model"]["patch_solver"] = "compliance";
    j["model"]["refresh_frames"] = refresh;
    if (held_until >= 0) j["instruments"][0]["keyframes"].push_back(key(held_until, {FLAT_HINGE_X, 0, 4.0}, {-1, 0, 0}, {0, 1, 0}, FLAT_END_DEG));
    return j;
}

/// Run options counting the simulator's warnings that the compliance frames went beyond their linear range into `n`.
sim::RunOptions counting_range_warnings(int& n) {
    sim::RunOptions ro;
    ro.on_message = [&n](const std::string& m) { n += m.find("beyond the compliance frames' range") != std::string::npos; };
    return ro;
}

}  // namespace

namespace {

/// The flattening clip's blades at its end opening: how many surface vertices lie under them (within the blades'
/// width and length), and the deepest one's distance in front of a blade's inner face (negative: behind it).
std::pair<int, double> under_the_flat_blades(const Eigen::MatrixX3d& x, double z = 4.0, double half_width = 0.6) {
    fem::ClipBlades jb;
    jb.hinge = {FLAT_HINGE_X, 0, z};
    jb.axis = {-1, 0, 0};
    jb.up = {0, 1, 0};
    jb.closed_gap_mm = 0.2;
    double worst = 1e9;
    int under = 0;
    for (int sgn : {1, -1}) {
        Eigen::Vector3d t, n, w;
        jb.frame(sgn, FLAT_END_DEG * aneu::DEG, t, n, w);
        for (Eigen::Index v = 0; v < x.rows(); ++v) {
            const Eigen::Vector3d rel = x.row(v).transpose() - jb.hinge;
            const double r = rel.dot(t);
            if (std::abs(rel.dot(w)) > half_width || r < 0 || r > 10.5) continue;
            worst = std::min(worst, 0.5 * jb.closed_gap_mm + rel.dot(n));  // in front of the blade's inner face: > 0
            ++under;
        }
    }
    return {under, worst};
}


/// The reference for the flattening scene: the whole tube neo-Hookean, closed along the openings of the simulator's
/// frames (100 Hz, 40° at 0.02 s to end_deg at 0.14 s, held for two more frames) with the same blade friction (μ =
/// 0.3, the default), its grips renewed after each step as the simulator renews them each frame (friction is path
/// dependent: the same steps give the same path). The blades touch every outer node (10-node elements: mid-edge
/// nodes too), the walls touch on the inner surface's triangles (10-node elements: split at their mid-edge nodes,
/// fem::quadratic_surface_triangles), as in the patch. Returns the blades' loads and the walls' closest distance.
std::pair<fem::BladeLoads, double> flattening_reference(const std::string& bundle, double end_deg) {
    BundleParts parts;
    parts.image = parts.surfaces = parts.condensed_W = parts.flow = false;
    const Bundle b = read_bundle(bundle, parts);
    const VolumeData& vol = *b.volume;
    const fem::NeoHookeanSolid solid(vol.nodes, vol.tets, vol.tet_region, b.fem->materials);
    const Eigen::MatrixXi IF = fem::boundary_faces_in_set(vol.nodes, vol.tets, vol.node_sets.at("inner"));
    const Eigen::MatrixX3i inner =
        vol.tets.cols() == 10 ? fem::quadratic_surface_triangles(fem::MidEdgeNodes(vol.tets), IF.leftCols(3)) : Eigen::MatrixX3i(IF.leftCols(3));
    std::vector<int> outer(vol.node_sets.at("outer").data(), vol.node_sets.at("outer").data() + vol.node_sets.at("outer").size());
    fem::ClipBlades bl;
    bl.hinge = {FLAT_HINGE_X, 0, 4};
    bl.axis = {-1, 0, 0};
    bl.up = {0, 1, 0};
    bl.length_mm = 10.5;
    bl.width_mm = 1.2;
    bl.thickness_mm = 0.5;
    bl.closed_gap_mm = 0.2;
    Eigen::VectorXd v = Eigen::VectorXd::Zero(solid.dofs() + 1);
    v[solid.dofs()] = 40 * aneu::DEG;
    fem::BladeLoads ref;
    double ref_min = 0;
    std::vector<double> steps;
    for (int k = 1; k <= 12; ++k) steps.push_back(40 - k / 12.0 * (40 - end_deg));
    steps.push_back(end_deg);
    steps.push_back(end_deg);
    fem::ClipContactParams bp;
    bp.friction = 0.3;
    std::vector<fem::BladeGrip> grips;
    for (size_t k = 0; k < steps.size(); ++k) {
        fem::ContactParams cp;
        cp.search_mm = 0.2 + 2.0 * 3.0 * aneu::DEG * bl.length_mm;  // as far as the jaws close in a step
        const fem::ContactBody wall(solid, vol.nodes, inner, v.head(solid.dofs()), cp);
        const fem::ClipBody cb(wall, vol.nodes, outer, v, bl, fem::ClipSpring{1e-3, 0.0}, bp, k ? &grips : nullptr);
        v = fem::solve_neo_hookean(cb, b.fem->fixed_dofs, std::vector<std::pair<int, double>>{{static_cast<int>(cb.theta_dof()), steps[k] * aneu::DEG}}, v).u;
        grips = cb.grips(v);
        if (k + 1 == steps.size()) {
            ref = cb.loads(v);
            ref_min = wall.min_distance(v.head(solid.dofs()));
        }
    }
    return {ref, ref_min};
}
}  // namespace

TEST(SimulatorPatch, AClipFlatteningTheTubeMatchesTheNeoHookeanReferenceAndTheWallsDoNotCross) {
    // The nonlinear patch (model.wall = "patch") against the whole tube as a neo-Hookean solid with the same
    // blades (friction μ = 0.3, the default) and wall contact, solved offline to convergence along the same
    // openings: the patch's exterior is linear, so the two differ only by the exterior's nonlinearity (small
    // 1.5 mm away from the jaws).
    test::TempDir d("patchsim");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    sim::Simulator s = make(flattening_scene(bundle, "patch", false), d.file(""), "patch.json");
    std::vector<std::string> msgs;
    sim::RunOptions opt;
    opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
    const sim::Assessment a = sim::run_scene(s, opt);
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_EQ(p.builds, 1);
    EXPECT_GT(p.frames, 10);
    EXPECT_EQ(p.unconverged_frames, 0);
    // The inner walls are pressed together and do not pass through each other (acceptance: ≤ 0.02 mm).
    EXPECT_GT(p.wall_pairs_touching, 0);
    EXPECT_GT(p.min_wall_distance_mm, -0.02);
    EXPECT_LT(p.min_wall_distance_mm, 0.011);
    const sim::Clip& c = s.clips().at(0);
    EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
    // The surface the simulator shows is the patch's: no vertex under a blade lies behind its inner face (by more
    // than the contact's 0.02 mm).
    {
        const auto [under, worst] = under_the_flat_blades(s.deformed_surface());
        EXPECT_GT(under, 20);
        EXPECT_GT(worst, -0.02);
        std::printf("%d surface vertices under the blades, the deepest %.4f mm in front of a blade face\n", under, worst);
    }
    for (const auto& m : msgs) EXPECT_EQ(m.find("beyond the linear model's range"), std::string::npos) << m;

    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    EXPECT_GT(ref_min, -0.02);
    EXPECT_NEAR(c.grip_force_n, f_ref, 0.02 * f_ref);
    // The blades hold the tissue by friction (below μλ: the grips stick), both in the reference and in the patch.
    EXPECT_GT(ref.friction_n[0], 0.05 * ref.force_n[0]);
    EXPECT_LT(ref.friction_n[0], 0.3 * ref.force_n[0]);
    std::printf("clip flattening the tube to %.2f deg: patch %d nodes (%d interface), blade force %.4f N vs neo-Hookean %.4f N (%+.2f %%); "
                "inner walls %.4f mm apart at the closest (reference %.4f), %d pairs touching; %.1f Newton its, %.1f ms a frame\n",
                FLAT_END_DEG, p.nodes, p.interface_nodes, c.grip_force_n, f_ref, 100 * (c.grip_force_n / f_ref - 1), p.min_wall_distance_mm,
                ref_min, p.wall_pairs_touching, p.mean_iterations, p.mean_solve_ms);
}

namespace {
/// The tandem pair on the tube: scene `one`'s applier moved 1 mm down the tube (z = 3 mm) and a copy of it, "applier 2",
/// 1 mm up (z = 5 mm): mirror images about the tube's middle.
json tandem_pair(const json& one) {
    json two = one;
    json second = one["instruments"][0];
    second["name"] = "applier 2";
    for (json& k : two["instruments"][0]["keyframes"]) k["position"][2] = k["position"][2].get<double>() - 1.0;
    for (json& k : second["keyframes"]) k["position"][2] = k["position"][2].get<double>() + 1.0;
    two["instruments"].push_back(second);
    return two;
}
/// Run options counting the simulator's messages that a clip joined another's patch and that two patches share nodes
/// (the last of those in `said`).
struct PatchSays {
    int shared = 0, joined = 0;
    std::string said;
    sim::RunOptions options() {
        sim::RunOptions ro;
        ro.on_message = [this](const std::string& m) {
            joined += m.find("clip 1 joins clip 0's nonlinear patch") != std::string::npos;
            if (m.find("nonlinear patch shares") != std::string::npos) {
                ++shared;
                said = m;
            }
        };
        return ro;
    }
};
/// Both clips of the tandem pair at the applier's end opening, the first gripping, the second gripping as it does
/// within `share` of its grip.
void expect_tandem_held(const sim::Simulator& s, double share) {
    ASSERT_EQ(s.clips().size(), 2u);
    const sim::Clip& c0 = s.clips().at(0);
    const sim::Clip& c1 = s.clips().at(1);
    EXPECT_NEAR(c0.opening_deg, FLAT_END_DEG, 1e-9);
    EXPECT_NEAR(c1.opening_deg, FLAT_END_DEG, 1e-9);
    EXPECT_GT(c0.grip_force_n, 0.1);
    EXPECT_NEAR(c1.grip_force_n, c0.grip_force_n, share * c0.grip_force_n);
}
}  // namespace

TEST(SimulatorPatch, TandemClipsOnTheSameTissueShareOnePatchAndBothGripAsMirrorImages) {
    // Two appliers close the flattening clip model side by side on the compliance frames, at z = 3 and z = 5 (0.8 mm
    // between the 1.2 mm blades), mirror images of each other about the tube's middle (z = 4; the tube, its sac region
    // and its rings of nodes are symmetric about it). The second clip's patch would share tissue with the first's: it
    // joins it, the patch is remade over both clips' jaws, and each frame solves both clips' blades and the walls in one
    // problem (fem::CompliantClip). So: one patch, no warning that two patches share nodes, both clips at the applier's
    // opening, their grip forces equal within the mesh's asymmetry (its tetrahedra are not mirror images: one clip
    // alone at z = 3 and at z = 5 grips 1.1015 / 1.0980 N linearised once, 0.7967 / 0.8149 N relinearised every frame),
    // the walls not through each other (acceptance: 0.02 mm) and no surface vertex behind either clip's blades. And
    // coupled: each clip of the pair grips less than it does alone at its place, the tube between them flattened by
    // both (measured 0.9585 / 0.9797 N linearised once, 0.5619 / 0.5539 N relinearised every frame); two uncoupled
    // patches, as before this, each solved with its own clip's blades only, and both wrote the nodes they share.
    // Linearised once (refresh 0: the walls meet under the clips) and every frame (1: they come within 0.005 mm).
    test::TempDir d("patchtwo");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    for (const int refresh : {0, 1}) {
        SCOPED_TRACE("refresh_frames " + std::to_string(refresh));
        const json one = compliance_flattening_scene(bundle, refresh, -1);
        auto moved = [&](json inst, double dz) {
            for (json& k : inst["keyframes"]) k["position"][2] = k["position"][2].get<double>() + dz;
            return inst;
        };
        // One clip alone at each place.
        double alone[2] = {0, 0};
        for (int c = 0; c < 2; ++c) {
            json j = one;
            j["instruments"][0] = moved(one["instruments"][0], c == 0 ? -1.0 : 1.0);
            sim::Simulator s = make(j, d.file(""), "alone" + std::to_string(c) + ".json");
            sim::run_scene(s, sim::RunOptions{});
            alone[c] = s.clips().at(0).grip_force_n;
        }
        sim::Simulator s = make(tandem_pair(one), d.file(""), "two.json");
        PatchSays says;
        const sim::Assessment a = sim::run_scene(s, says.options());
        EXPECT_EQ(says.shared, 0) << says.said;
        EXPECT_EQ(says.joined, 1);
        ASSERT_EQ(a.patches.size(), 1u);
        const auto& p = a.patches[0];
        EXPECT_EQ(p.clip, 0);
        EXPECT_EQ(p.more_clips, std::vector<int>{1});
        EXPECT_EQ(p.unconverged_frames, 0);
        if (refresh == 0) {
            EXPECT_GT(p.wall_pairs_touching, 0);
        }
        EXPECT_GT(p.min_wall_distance_mm, -0.02);
        EXPECT_LT(p.min_wall_distance_mm, 0.01);
        expect_tandem_held(s, 0.05);
        const sim::Clip& c0 = s.clips().at(0);
        const sim::Clip& c1 = s.clips().at(1);
        EXPECT_LT(c0.grip_force_n, 0.95 * alone[0]);
        EXPECT_LT(c1.grip_force_n, 0.95 * alone[1]);
        // Neither clip's blades have surface vertices behind their inner faces (by more than the contact's 0.02 mm;
        // within 0.05 mm of the blades' edges, on their rounded sides, they may lie below the faces' planes).
        const Eigen::MatrixX3d x = s.deformed_surface();
        for (const double z : {3.0, 5.0}) {
            const auto [under, worst] = under_the_flat_blades(x, z, 0.55);
            EXPECT_GT(under, 20) << "the clip at z = " << z;
            EXPECT_GT(worst, -0.02) << "the clip at z = " << z;
        }
        std::printf("refresh %d: tandem clips at z = 3 and 5 mm: one patch of %d nodes; grip %.4f / %.4f N (alone %.4f / %.4f N); walls %.4f mm at the closest, %d pairs touching\n",
                    refresh, p.nodes, c0.grip_force_n, c1.grip_force_n, alone[0], alone[1], p.min_wall_distance_mm, p.wall_pairs_touching);
    }
}

TEST(SimulatorPatch, OnTheNewtonFramesTandemClipsGetAPatchEachAndAreWarnedUncoupled) {
    // The Newton frames take one clip (fem::ClipBody): the tandem pair of the test above with patch_solver "newton" gets
    // a patch per clip, and the simulator says, once, that they share tissue and are not coupled, naming both.
    test::TempDir d("patchtwonewton");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    json one = flattening_scene(bundle, "patch", false);
    one["duration_s"] = 0.09;  // (the patches are made as the jaws close on the tube, by t = 0.08 s)
    sim::Simulator s = make(tandem_pair(one), d.file(""), "two.json");
    PatchSays says;
    const sim::Assessment a = sim::run_scene(s, says.options());
    EXPECT_EQ(a.patches.size(), 2u);
    EXPECT_EQ(says.joined, 0);
    EXPECT_EQ(says.shared, 1) << says.said;
    EXPECT_NE(says.said.find("clip 1's nonlinear patch shares"), std::string::npos) << says.said;
    EXPECT_NE(says.said.find("with clip 0's"), std::string::npos) << says.said;
}

TEST(SimulatorPatch, ATandemClipThatLetsGoLeavesThePatchToTheOtherWhichGripsAsIfAlone) {
    // The tandem pair of the test above (linearised once: the frames are the linear problem about rest), then one
    // applier opens its clip to 40 deg (no spring: the clip opens with it) and releases it gripping nothing: it falls
    // away and leaves the patch; the other clip goes on in it, alone. Either way round: the further clip leaving, and
    // the first (the patch's θ and course handed to the other). On the linear frames what is left is the one clip's
    // problem: it grips as that clip alone at its place does, up to its friction's path (stick points made with the
    // other clip there).
    test::TempDir d("patchleave");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    const json one = compliance_flattening_scene(bundle, 0, -1);
    auto moved = [&](json inst, double dz, bool lets_go) {
        for (json& k : inst["keyframes"]) k["position"][2] = k["position"][2].get<double>() + dz;
        json last = inst["keyframes"].back();
        if (lets_go) {
            last["t"] = 0.20;
            last["opening_deg"] = 40;
            inst["keyframes"].push_back(last);
            last["t"] = 0.21;
            last["release"] = true;
            inst["keyframes"].push_back(last);
        }
        last.erase("release");
        last["t"] = 0.30;
        last["opening_deg"] = lets_go ? 40.0 : FLAT_END_DEG;
        inst["keyframes"].push_back(last);
        return inst;
    };
    for (const int leaving : {1, 0}) {
        SCOPED_TRACE("clip " + std::to_string(leaving) + " lets go");
        const int stays = 1 - leaving;
        const double dz_stays = stays == 0 ? -1.0 : 1.0;
        json alone = one;
        alone["instruments"][0] = moved(one["instruments"][0], dz_stays, false);
        sim::Simulator sa = make(alone, d.file(""), "alone.json");
        sim::run_scene(sa, sim::RunOptions{});
        const double grip_alone = sa.clips().at(0).grip_force_n;
        json two = one;
        two["instruments"][0] = moved(one["instruments"][0], -1.0, leaving == 0);
        json second = moved(one["instruments"][0], 1.0, leaving == 1);
        second["name"] = "applier 2";
        two["instruments"].push_back(second);
        sim::Simulator s = make(two, d.file(""), "leave" + std::to_string(leaving) + ".json");
        int fell = 0;
        sim::RunOptions ro;
        ro.on_message = [&](const std::string& m) {
            fell += m.find("clip " + std::to_string(leaving) + " released") != std::string::npos && m.find("falls away") != std::string::npos;
        };
        const sim::Assessment a = sim::run_scene(s, ro);
        EXPECT_EQ(fell, 1);
        ASSERT_EQ(a.patches.size(), 1u);
        const auto& p = a.patches[0];
        EXPECT_EQ(p.clip, 0);  // (the clip it was made for; the first clip falling hands the patch on)
        EXPECT_EQ(p.more_clips, std::vector<int>{1});
        EXPECT_EQ(p.unconverged_frames, 0);
        EXPECT_GT(p.frames, 25);  // the patch went on after the release (0.21 s) to the end (0.30 s)
        const sim::Clip& c = s.clips().at(static_cast<size_t>(stays));
        EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
        EXPECT_NEAR(c.grip_force_n, grip_alone, 0.05 * grip_alone);
        EXPECT_TRUE(s.clips().at(static_cast<size_t>(leaving)).model.empty());  // lost, not deposited
        EXPECT_GT(p.min_wall_distance_mm, -0.02);
        std::printf("clip %d lets go: clip %d grips %.4f N in the patch alone, %.4f N alone from the start\n", leaving, stays, c.grip_force_n, grip_alone);
    }
}

TEST(SimulatorPatch, TheComplianceSolverFlattensTheTubeAsTheNeoHookeanReferenceWhenRelinearisedEveryFrame) {
    // model.patch_solver = "compliance": each frame is the blades' and walls' hard contact on the patch's compliance
    // at a linearisation (fem::solve_compliant_clip_walls). Relinearised every frame (refresh_frames 1) the frames are
    // Newton steps with the contact, one per frame, and end where the neo-Hookean reference does (the same blades,
    // friction and walls, solved to convergence; its barrier keeps pressed nodes up to 0.01 mm off the blades). Never
    // relinearised (0) they are the linear model about rest: the same contact, held as well, at a larger force (the
    // study's linear-model error at this closure).
    test::TempDir d("patchcomp");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    double grip[2] = {0, 0};
    for (const int refresh : {1, 0}) {
        const json j = compliance_flattening_scene(bundle, refresh, 0.30);  // held 15 frames
        sim::Simulator s = make(j, d.file(""), "comp" + std::to_string(refresh) + ".json");
        int range_warnings = 0;
        const sim::RunOptions ro = counting_range_warnings(range_warnings);
        const sim::Assessment a = sim::run_scene(s, ro);
        ASSERT_EQ(a.patches.size(), 1u);
        const auto& p = a.patches[0];
        EXPECT_EQ(p.builds, 1);
        EXPECT_EQ(p.unconverged_frames, 0);
        // Relinearised after every frame that presses the tube (those closing through the air before it do not count).
        // How far the frames take the surface from their linearisation, over the wall's thickness (the linear model's
        // measure, trusted to 0.3): relinearised every frame, a frame that goes further (this scene's close the blades
        // ~1.5 deg each: up to 0.63 x before session 45) is solved again on a linearisation made where it got to, so
        // none ends beyond the range (measured 0.098 x, 3 frames solved again) and none is warned; held, it settles on
        // the last linearisation. Never relinearised, the whole flattening (3.7 x), where it ends too: warned once.
        // A refresh selects the candidates again for the jaws as they are (measured: 256 as the jaws first close on
        // the tube, 240 at the end); never relinearised, the first selection stays.
        if (refresh) {
            EXPECT_GT(p.linearisations, 10);
            EXPECT_GT(p.range_refreshes, 0);
            EXPECT_LT(p.linearisations - p.range_refreshes, p.frames);
            EXPECT_GT(p.first_candidates, 0);
            EXPECT_LT(p.last_candidates, p.first_candidates);
            EXPECT_GT(p.max_lag_to_thickness, 0.0);
            EXPECT_LE(p.max_lag_to_thickness, 0.3);
            EXPECT_LT(p.end_lag_to_thickness, 0.01);
            EXPECT_EQ(range_warnings, 0);
        } else {
            EXPECT_EQ(p.linearisations, 1);
            EXPECT_EQ(p.range_refreshes, 0);
            EXPECT_EQ(p.last_candidates, p.first_candidates);
            EXPECT_GT(p.max_lag_to_thickness, 3.0);
            EXPECT_GT(p.end_lag_to_thickness, 3.0);
            EXPECT_EQ(range_warnings, 1);
        }
        EXPECT_NEAR(p.max_lag_to_thickness, p.max_lag_mm / p.max_lag_thickness_mm, 1e-12);
        EXPECT_EQ(p.linearisations_failed, 0);
        // The walls brought together (as near as the reference's barrier leaves them), not through each other by more
        // than the acceptance's 0.02 mm; nothing behind a blade's face.
        EXPECT_GT(p.min_wall_distance_mm, -0.02);
        EXPECT_LT(p.min_wall_distance_mm, 0.011);
        const auto [under, worst] = under_the_flat_blades(s.deformed_surface());
        EXPECT_GT(under, 20);
        EXPECT_GT(worst, -0.02);
        // The lumen is not through itself by more than 0.02 mm, and the tissue does not overlap itself anywhere in
        // the patch (no node inside an element not its own deeper than 1 µm; linear about rest, four nodes lie
        // 1e-7 mm inside a neighbour).
        EXPECT_LE(a.lumen_crossing_mm, 0.02);
        EXPECT_EQ(a.patch_nodes_in_other_tissue, 0);
        EXPECT_LE(a.patch_tissue_overlap_mm, 1e-3);
        const sim::Clip& c = s.clips().at(0);
        EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
        grip[refresh] = c.grip_force_n;
        std::printf("compliance frames, relinearised every %d frame(s): %ld frames, %d linearisations (%.2f s), blade force %.4f N vs neo-Hookean %.4f N "
                    "(%+.2f %%), walls %.4f mm apart at the closest (reference %.4f), %d pairs touching, deepest %.4f mm in front of a blade, %.1f ms a frame; "
                    "reach from the linearisation %.4f mm on %.3f mm of wall (%.3g x, at the end %.3g x); lumen through itself %.4f mm, behind a face in no tissue "
                    "%.4f mm (%d vertices), patch nodes in other tissue %d (%.4f mm)\n",
                    refresh, p.frames, p.linearisations, p.linearise_s, c.grip_force_n, f_ref, 100 * (c.grip_force_n / f_ref - 1), p.min_wall_distance_mm,
                    ref_min, p.wall_pairs_touching, worst, p.mean_solve_ms, p.max_lag_mm, p.max_lag_thickness_mm, p.max_lag_to_thickness, p.end_lag_to_thickness, a.lumen_crossing_mm,
                    a.lumen_beside_tissue_mm, a.lumen_beside_tissue_vertices, a.patch_nodes_in_other_tissue, a.patch_tissue_overlap_mm);
    }
    // Measured: -1.39 % relinearised every frame (session 51; -1.46 % and -1.5 % in earlier sessions' notes); +74.9 %
    // linear about rest (the study's linear model: +75 % at full closure on the artery).
    EXPECT_NEAR(grip[1], f_ref, 0.05 * f_ref);
    EXPECT_GT(grip[0], 1.5 * f_ref);
}

/// The tube flattened by compliance frames never relinearised (compliance_flattening_scene, held to 0.30 s) with the
/// `model` keys given: its patch's end, the clip's opening and force, and how far the lumen goes through itself.
struct WallsLimitedRun {
    sim::Assessment::PatchEnd p;
    double opening_deg = 0, grip_n = 0, lumen_crossing_mm = 0;
};
WallsLimitedRun walls_limited_run(const std::string& bundle, const std::string& dir, const std::string& name, const json& model) {
    json j = compliance_flattening_scene(bundle, 0, 0.30);
    for (const auto& [k, v] : model.items()) j["model"][k] = v;
    sim::Simulator s = make(j, dir, name + ".json");
    const sim::Assessment a = sim::run_scene(s, {});
    WallsLimitedRun r;
    if (a.patches.size() != 1) {
        ADD_FAILURE() << name << ": " << a.patches.size() << " patches, expected 1";
        return r;
    }
    r.p = a.patches[0];
    r.opening_deg = s.clips().at(0).opening_deg;
    r.grip_n = s.clips().at(0).grip_force_n;
    r.lumen_crossing_mm = a.lumen_crossing_mm;
    return r;
}

TEST(SimulatorPatch, AComplianceFrameThatTakesTheWallsThroughEachOtherPastTheLimitIsNotTaken) {
    // The tube flattened by compliance frames never relinearised (the linear model about rest, as above): its walls
    // end 0.0012 mm through each other at the closest (measured). With model.walls_reject_mm at half that, a frame
    // that ends with the walls further through is not taken: it counts as not converged, the patch stays where the
    // frame started, and a second in a row goes back to the last converged state with a smaller step. So no frame
    // taken has the walls further through than the limit, and the clip stops short of the flattening the applier
    // asks for. With the rule off (0) every frame is taken and the walls go past it. (Measured: 13 of 28 frames not
    // taken, 6 restarts, the walls -0.0004 mm at the closest, the clip at 5.287 deg for 5.014 asked.)
    // (The rule's default, 0.1 mm, is for frames whose linearisation went wrong, as the sample's 2 mm jaws at
    // t = 1.252 s, session 63: 0.30 then 0.40 mm; no tube scene takes the walls that far.)
    test::TempDir d("wallsreject");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    constexpr double LIMIT_MM = 0.0006;
    for (const double limit : {0.0, LIMIT_MM}) {
        SCOPED_TRACE("walls_reject_mm " + std::to_string(limit));
        const WallsLimitedRun r = walls_limited_run(bundle, d.file(""), "wr" + std::to_string(limit > 0), {{"walls_reject_mm", limit}});
        const auto& p = r.p;
        if (limit == 0) {
            EXPECT_EQ(p.walls_absurd, 0);
            EXPECT_EQ(p.unconverged_frames, 0);
            EXPECT_LT(p.min_wall_distance_mm, -LIMIT_MM) << "the walls did not go past the limit: the rule was not exercised";
            EXPECT_NEAR(r.opening_deg, FLAT_END_DEG, 1e-9);
        } else {
            EXPECT_GT(p.walls_absurd, 0);
            EXPECT_GE(p.unconverged_frames, p.walls_absurd);
            EXPECT_GT(p.restarts, 0);
            EXPECT_GE(p.min_wall_distance_mm, -LIMIT_MM);
            EXPECT_GT(r.opening_deg, FLAT_END_DEG + 1e-3);
        }
        std::printf("walls_reject_mm %.4f: %ld frames, %d not taken for the walls, %ld unconverged, %ld restarts; walls %.4f mm apart at the closest; "
                    "clip at %.3f deg (asked %.3f), blade force %.4f N\n",
                    limit, p.frames, p.walls_absurd, p.unconverged_frames, p.restarts, p.min_wall_distance_mm, r.opening_deg, FLAT_END_DEG, r.grip_n);
    }
}

TEST(SimulatorPatch, AComplianceFrameThatTakesTheWallsThroughEachOtherPastTheLimitIsShortenedToWhereTheyAreWithinIt) {
    // The scene above with model.walls_shorten: a frame that ends with the walls past the limit is taken shortened,
    // the patch moved 1/2, 1/4, ... of its step, the longest whose walls are within the limit, its loads between the
    // last frame's and its end's. So no frame taken has the walls past the limit, as when such frames are not taken,
    // fewer frames fail, and the frames after go on from the shortened ones: the clip gets (nearly) where the
    // applier asks, with the blade force of the frames with no limit there. (Measured: 11 of 28 frames shortened, 6
    // not taken, 3 restarts, the walls -0.0006 mm, the clip at 5.019 deg for 5.014 asked, 0.8500 N against the
    // unlimited frames' 0.8505 N; not shortened: 13 not taken, 6 restarts, 5.287 deg.)
    test::TempDir d("wallsshorten");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    constexpr double LIMIT_MM = 0.0006;
    sim::Assessment::PatchEnd ends[3];
    double opening[3] = {0, 0, 0}, grip[3] = {0, 0, 0};
    for (const int run : {0, 1, 2}) {  // no limit; the limit, not shortened; the limit, shortened
        const int halvings = run == 2 ? 6 : 0;
        SCOPED_TRACE("run " + std::to_string(run));
        const WallsLimitedRun r =
            walls_limited_run(bundle, d.file(""), "ws" + std::to_string(run), {{"walls_reject_mm", run == 0 ? 0.0 : LIMIT_MM}, {"walls_shorten", halvings}});
        const auto& p = r.p;
        ends[run] = p;
        opening[run] = r.opening_deg;
        grip[run] = r.grip_n;
        if (run > 0) {
            EXPECT_GE(p.min_wall_distance_mm, -LIMIT_MM);
        }
        std::printf("walls_reject_mm %.4f, walls_shorten %d: %ld frames, %d shortened, %d not taken for the walls, %ld unconverged, %ld restarts; walls %.5f mm "
                    "apart at the closest; clip at %.3f deg (asked %.3f), blade force %.4f N\n",
                    run == 0 ? 0.0 : LIMIT_MM, halvings, p.frames, p.walls_shortened, p.walls_absurd, p.unconverged_frames, p.restarts, p.min_wall_distance_mm,
                    r.opening_deg, FLAT_END_DEG, r.grip_n);
    }
    EXPECT_EQ(ends[1].walls_shortened, 0);
    EXPECT_GT(ends[2].walls_shortened, 0);
    EXPECT_LT(ends[2].walls_absurd, ends[1].walls_absurd);
    EXPECT_LT(ends[2].unconverged_frames, ends[1].unconverged_frames);
    EXPECT_LT(opening[2] - FLAT_END_DEG, 0.1 * (opening[1] - FLAT_END_DEG));
    EXPECT_NEAR(opening[2], opening[0], 0.02);
    EXPECT_NEAR(grip[2], grip[0], 0.01 * grip[0]);
}

TEST(SimulatorPatch, AComplianceFrameThatTakesTheWallsThroughEachOtherPastTheLimitIsSolvedAsANewtonFrame) {
    // The scene above with model.walls_newton: a frame that ends with the walls past the limit is solved as a Newton
    // frame instead (the neo-Hookean patch with the blades' and walls' barriers, from where the frame started; its
    // steps bounded by collision detection), and the frames go on from its state, linearised there. So no frame
    // taken has the walls past the limit (the barrier's frames keep them apart), fewer frames fail than when such
    // frames are not taken, the clip gets where the applier asks, and its force is the nonlinear patch's, not the
    // linearisation's. (Measured: 17 of 28 frames solved as Newton frames, none failed, none not taken, no restart,
    // the walls 0.0094 mm apart (the barrier's d̂ = 0.01 mm), the clip at 5.014 deg as asked, 0.4570 N against the
    // neo-Hookean reference's 0.4862 N (-6.0 %); not solved so: 13 not taken, 6 restarts, 5.287 deg, 0.7965 N,
    // +63.8 %: the frames are linear about rest.)
    test::TempDir d("wallsnewton");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    constexpr double LIMIT_MM = 0.0006;
    sim::Assessment::PatchEnd ends[3];
    double opening[3] = {0, 0, 0}, grip[3] = {0, 0, 0};
    const int budget[3] = {0, 40, 30};
    for (const int run : {0, 1, 2}) {  // the limit, not solved as Newton frames; solved so; with 30 iterations
        SCOPED_TRACE("run " + std::to_string(run));
        const WallsLimitedRun r =
            walls_limited_run(bundle, d.file(""), "wn" + std::to_string(run), {{"walls_reject_mm", LIMIT_MM}, {"walls_newton", budget[run]}});
        const auto& p = r.p;
        ends[run] = p;
        opening[run] = r.opening_deg;
        grip[run] = r.grip_n;
        EXPECT_GE(p.min_wall_distance_mm, -LIMIT_MM);
        EXPECT_LE(r.lumen_crossing_mm, LIMIT_MM);
        std::printf("walls_reject_mm %.4f, walls_newton %d: %ld frames, %d solved as Newton frames (%d did not converge, %d taken where their iterations ran out), %d not taken for the walls, %ld unconverged, "
                    "%ld restarts, %d linearisations; walls %.5f mm apart at the closest, lumen through itself %.5f mm; clip at %.3f deg (asked %.3f), blade force %.4f N\n",
                    LIMIT_MM, budget[run], p.frames, p.walls_newton_frames, p.walls_newton_failed, p.newton_frames_loose, p.walls_absurd, p.unconverged_frames, p.restarts,
                    p.linearisations, p.min_wall_distance_mm, r.lumen_crossing_mm, r.opening_deg, FLAT_END_DEG, r.grip_n);
    }
    EXPECT_EQ(ends[0].walls_newton_frames, 0);
    EXPECT_GT(ends[1].walls_newton_frames, 0);
    EXPECT_EQ(ends[1].walls_newton_failed, 0);
    EXPECT_LT(ends[1].walls_absurd, ends[0].walls_absurd);
    EXPECT_LT(ends[1].unconverged_frames, ends[0].unconverged_frames);
    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    std::printf("neo-Hookean reference: blade force %.4f N; Newton frames %+.2f %%, frames linear about rest (walls limited) %+.2f %%\n", f_ref,
                100 * (grip[1] / f_ref - 1), 100 * (grip[0] / f_ref - 1));
    EXPECT_NEAR(grip[1], f_ref, 0.10 * f_ref);
    EXPECT_GT(grip[0], 1.3 * f_ref);
    EXPECT_LT(opening[1] - FLAT_END_DEG, 0.1 * (opening[0] - FLAT_END_DEG));
    // With 30 iterations the first Newton frame (37 with 40) runs out before the tolerance: taken where it stands when the opening
    // is reached and its residual is at most 1e-2 of the force (the next frame goes on from it), not where it is not.
    EXPECT_GT(ends[2].newton_frames_loose, 0);
    EXPECT_EQ(ends[1].newton_frames_loose, 0);
    EXPECT_LE(ends[2].newton_frames_loose, ends[2].walls_newton_frames);
    // ... and the frames after it finish the balance: the clip ends where the converged frames leave it. (Measured:
    // 1 frame taken so, the clip at 5.014 deg, 0.4602 N against 0.4570 N.)
    EXPECT_NEAR(opening[2], opening[1], 1e-6);
    EXPECT_NEAR(grip[2], grip[1], 0.02 * grip[1]);
}

TEST(SimulatorPatch, RefreshesThatBorrowTheLastCompliancesWFlattenTheTubeAsThoseThatMakeTheirOwn) {
    // The test above's scene relinearised every frame, with model.compliance_reuse 3: three refreshes in four (and
    // the frames' re-solves for the linear range) borrow the last W (the tangent factorised at the new state, W kept;
    // each frame's passes corrected on the new tangent). The frames solve the same problems as with W made each time:
    // the blades end at the same force, within the linear range, the walls apart.
    test::TempDir d("borrow");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    struct End {
        sim::Assessment::PatchEnd p;
        double grip = 0;
        int warnings = 0;
    };
    auto run = [&](int reuse) {
        json j = compliance_flattening_scene(bundle, 1, 0.30);
        if (reuse > 0) j["model"]["compliance_reuse"] = reuse;
        sim::Simulator s = make(j, d.file(""), "borrow" + std::to_string(reuse) + ".json");
        End e;
        const sim::RunOptions ro = counting_range_warnings(e.warnings);
        const sim::Assessment a = sim::run_scene(s, ro);
        EXPECT_EQ(a.patches.size(), 1u);
        if (a.patches.size() != 1) return e;
        e.p = a.patches[0];
        e.grip = s.clips().at(0).grip_force_n;
        EXPECT_EQ(e.p.unconverged_frames, 0);
        EXPECT_LE(e.p.max_lag_to_thickness, 0.3);
        EXPECT_EQ(e.warnings, 0);
        EXPECT_GT(e.p.min_wall_distance_mm, -0.02);
        EXPECT_LE(a.lumen_crossing_mm, 0.02);
        EXPECT_NEAR(s.clips().at(0).opening_deg, FLAT_END_DEG, 1e-9);
        return e;
    };
    const End own = run(0), lent = run(3);
    EXPECT_EQ(own.p.linearisations_borrowed, 0);
    EXPECT_EQ(own.p.borrow_fallbacks, 0);
    EXPECT_GT(lent.p.linearisations_borrowed, lent.p.linearisations / 2);
    EXPECT_LE(lent.p.linearisations_borrowed, 3 * lent.p.linearisations / 4 + 1);
    EXPECT_GT(lent.p.borrow_fallbacks, 0);  // the path exercised: frames whose passes ended beyond borrow_accept_mm on W (measured 6)
    EXPECT_LT(lent.p.borrow_fallbacks, lent.p.linearisations_borrowed / 2);
    EXPECT_NEAR(lent.grip, own.grip, 0.01 * own.grip);
    EXPECT_NEAR(lent.grip, f_ref, 0.05 * f_ref);
    std::printf("tube relinearised every frame: W made every time %.4f N (%d linearisations, %.2f s); %d of %d borrowing W %.4f N (%.2f s, %d frames "
                "solved again with their own W); neo-Hookean %.4f N; reach %.3f / %.3f x\n",
                own.grip, own.p.linearisations, own.p.linearise_s, lent.p.linearisations_borrowed, lent.p.linearisations, lent.grip, lent.p.linearise_s,
                lent.p.borrow_fallbacks, f_ref, own.p.max_lag_to_thickness, lent.p.max_lag_to_thickness);
}

TEST(SimulatorPatch, APatchGrowsWhereTheLumenMeetsItselfBesideIt) {
    // The compliance flattening with a patch of 0.1 mm round the jaws: the flattened lumen's walls come within 0.3 mm
    // of each other beside the blades too (to 0.8 mm from the clip's middle), beyond the patch (its lumen 0.4 mm to
    // either side), where the linear exterior has no wall contact. With model.patch_grow (the default) the patch is
    // remade once to cover them (PatchRun::grown; measured 480 -> 595 nodes, its lumen to 0.8 mm); without it the
    // patch stays as made.
    test::TempDir d("grow");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    struct End {
        sim::Assessment::PatchEnd p;
        int grown = 0;
        double crossing = 0, grip = 0;
    };
    auto run = [&](bool grow) {
        json j = compliance_flattening_scene(bundle, 1, 0.30);
        j["model"]["patch_radius_mm"] = 0.1;
        j["model"]["patch_grow"] = grow;
        sim::Simulator s = make(j, d.file(""), std::string("grow") + (grow ? "1" : "0") + ".json");
        End e;
        sim::RunOptions ro;
        ro.on_message = [&e](const std::string& m) { e.grown += m.find("grown where the lumen meets itself beside it") != std::string::npos; };
        const sim::Assessment a = sim::run_scene(s, ro);
        EXPECT_EQ(a.patches.size(), 1u);
        if (a.patches.size() != 1) return e;
        e.p = a.patches[0];
        e.crossing = a.lumen_crossing_mm;
        e.grip = s.clips().at(0).grip_force_n;
        EXPECT_NEAR(s.clips().at(0).opening_deg, FLAT_END_DEG, 1e-9);
        return e;
    };
    const End fixed = run(false), grown = run(true);
    EXPECT_EQ(fixed.grown, 0);
    EXPECT_EQ(fixed.p.builds, 1);
    EXPECT_GT(grown.grown, 0);
    EXPECT_EQ(grown.p.builds, 1 + grown.grown);
    EXPECT_GT(grown.p.nodes, fixed.p.nodes);
    EXPECT_LE(grown.crossing, 0.02);
    std::printf("patch 0.1 mm round the jaws: as made %d nodes, lumen through itself %.4f mm, grip %.4f N; grown %d times to %d nodes, %.4f mm, %.4f N\n",
                fixed.p.nodes, fixed.crossing, fixed.grip, grown.grown, grown.p.nodes, grown.crossing, grown.grip);
}

TEST(SimulatorPatch, InRealTimeTheComplianceFramesRefreshOnAnotherThreadAndConvergeOnTheNeoHookeanReference) {
    // The threaded (real-time) mode makes a compliance patch's refreshes on another thread, from the state of the frame
    // that asked for one, while the frames go on with the linearisation they have; a frame takes a refresh once it is
    // done (the deterministic mode makes them inline, as the test above). Held for 4 s of wall clock, the tube's
    // flattened walls are relinearised again and again and the grip converges on the neo-Hookean reference as it does
    // relinearised every frame (+74.5 % linear about rest, -1.5 % relinearised every frame). A refresh the frames have
    // left by more than the linear range by the time it is done is dropped, and a Newton step that would invert an
    // element is shortened (without either, the first refresh taken inverted an element and every one after it was
    // refused).
    test::TempDir d("patchcomprt");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    json j = compliance_flattening_scene(bundle, 1, 4.30);  // held 4 s
    j["outputs"] = {{"log", "rt_log.csv"}, {"report", "rt_report.json"}};
    sim::Simulator s = make(j, d.file(""), "comprt.json");
    sim::RunOptions opt;
    opt.deterministic = false;
    const sim::Assessment a = sim::run_scene(s, opt);
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_EQ(p.linearisations_failed, 0);
    EXPECT_GE(p.linearisations, 3);
    EXPECT_EQ(p.unconverged_frames, 0);
    EXPECT_GT(p.min_wall_distance_mm, -0.02);
    const sim::Clip& c = s.clips().at(0);
    EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
    // Measured -4.8 % after 8 linearisations (one dropped as stale while the jaws closed), each 0.4-0.5 s on its own
    // thread beside the frames; with the candidates selected again at each refresh (session 39) -7.5 % after 12-14,
    // settled on the last (-5.0 % with the first selection kept; why the threaded path ends lower is not found: the
    // inline one ends at -1.5 % either way). The test allows 10 % (a loaded machine makes fewer refreshes in the 4 s).
    EXPECT_NEAR(c.grip_force_n, f_ref, 0.10 * f_ref);
    EXPECT_LT(p.end_lag_to_thickness, 0.3);
    std::printf("real time, refreshed on another thread: %ld frames, %d linearisations (%.2f s), blade force %.4f N vs neo-Hookean %.4f N (%+.2f %%), "
                "walls %.4f mm apart at the closest, reach from the linearisation at the end %.3g x\n",
                p.frames, p.linearisations, p.linearise_s, c.grip_force_n, f_ref, 100 * (c.grip_force_n / f_ref - 1), p.min_wall_distance_mm,
                p.end_lag_to_thickness);
}

TEST(SimulatorPatch, InRealTimeTandemClipsShareThePatchAndItsRefreshesOnAnotherThread) {
    // The tandem pair (two appliers at z = 3 and 5 mm, test TandemClipsOnTheSameTissue...) in the threaded real-time mode,
    // held 4 s of wall clock: the second clip joins the first's patch while the frames run, the refreshes are made on the
    // other thread for both clips' jaws, and each clip's opening and loads are written back to it after a frame solved
    // without the lock. Both end at the applier's opening, gripping alike (their mirror images within the mesh's
    // asymmetry and what the refreshes taken in that time leave), the walls apart. (Held 2 s, both refreshes begun
    // while the jaws closed were dropped as stale, the surface 3.1 and 0.66 wall thicknesses on, and the frames ended on
    // the linearisation at rest: 0.97 / 0.98 N.)
    test::TempDir d("patchtworeal");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    json one = compliance_flattening_scene(bundle, 1, 4.30);
    one["outputs"] = {{"log", "rt2_log.csv"}, {"report", "rt2_report.json"}};
    sim::Simulator s = make(tandem_pair(one), d.file(""), "tworeal.json");
    sim::RunOptions opt;
    opt.deterministic = false;
    const sim::Assessment a = sim::run_scene(s, opt);
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_EQ(p.more_clips, std::vector<int>{1});
    EXPECT_EQ(p.linearisations_failed, 0);
    EXPECT_GE(p.linearisations, 2);
    EXPECT_EQ(p.unconverged_frames, 0);
    EXPECT_GT(p.min_wall_distance_mm, -0.02);
    // Measured 0.5073 / 0.5446 N after 5 linearisations (deterministic, relinearised every frame: 0.5619 / 0.5539 N);
    // in real time each clip's last frames lie on whatever refresh came last, so 15 % between them is allowed.
    expect_tandem_held(s, 0.15);
    const sim::Clip& c0 = s.clips().at(0);
    const sim::Clip& c1 = s.clips().at(1);
    std::printf("real time, tandem: %ld frames, %d linearisations; grip %.4f / %.4f N; walls %.4f mm apart at the closest\n", p.frames, p.linearisations,
                c0.grip_force_n, c1.grip_force_n, p.min_wall_distance_mm);
}

namespace {
/// The spring clip on the tube (flattening_scene with a 0.3 N spring, released) on the patch solver `solver`, run
/// twice: the applier can only hold it open, so the clip stops where the tissue's moment about the hinge equals the
/// spring's torque (the frames step the opening onto τ = M by secant steps on the solve's τ − M), and stays there
/// released, still gripping by friction; the two runs' logs are identical. Returns the opening [deg] and grip [N].
std::pair<double, double> spring_clip_balance(const std::string& solver) {
    test::TempDir d("patchspring_" + solver);
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    std::string logs[2];
    std::pair<double, double> out{0, 0};
    for (int run = 0; run < 2; ++run) {
        json j = flattening_scene(bundle, "patch", true);
        if (solver == "compliance") {
            j["model"]["patch_solver"] = "compliance";
            j["model"]["refresh_frames"] = 1;  // relinearised after every pressing frame: the neo-Hookean patch's balance
        }
        j["outputs"]["log"] = "log" + std::to_string(run) + ".csv";
        sim::Simulator s = make(j, d.file(""), "spring" + std::to_string(run) + ".json");
        const sim::Assessment a = sim::run_scene(s, {});
        EXPECT_EQ(a.patches.size(), 1u);
        if (a.patches.size() != 1) return out;
        EXPECT_EQ(a.patches[0].unconverged_frames, 0);
        const sim::Clip& c = s.clips().at(0);
        EXPECT_EQ(c.state, sim::Clip::State::DEPOSITED);
        EXPECT_GT(c.opening_deg, FLAT_END_DEG + 0.5);
        EXPECT_LT(c.opening_deg, 30.0);
        EXPECT_GT(a.patches[0].min_wall_distance_mm, -0.02);
        EXPECT_GT(c.spring_torque_nmm, 0);
        EXPECT_NEAR(c.tissue_moment_nmm, c.spring_torque_nmm, 1e-3 * c.spring_torque_nmm);
        // The clip's force at its label point is the spring's force there at the opening it stopped at (the moment
        // over the label point's arm), and the session's peak is at least that.
        const sim::ClipModel& cm = s.scene().clip_models.at(c.model);
        EXPECT_NEAR(c.label_force_n, cm.spring->force_at(cm.label_arm_mm(), c.opening_deg * aneu::DEG), 1e-3 * c.label_force_n);
        EXPECT_GE(a.peak_clip_label_force_n, c.label_force_n);
        EXPECT_DOUBLE_EQ(a.patches[0].peak_label_force_n, a.peak_clip_label_force_n);
        // Released, the blades still hold the tissue by friction (the compliance frames of a released clip had none
        // until session 34: the sample's neck then slid out from between the jaws as the spring took over).
        EXPECT_GT(c.friction_n, 0.01 * c.grip_force_n);
        if (run == 0) {
            std::printf("%s frames, released: open %.3f deg (held at %.3f), spring %.5f N mm, tissue %.5f N mm, grip %.4f N, friction %.4f N\n",
                        solver.c_str(), c.opening_deg, FLAT_END_DEG, c.spring_torque_nmm, c.tissue_moment_nmm, c.grip_force_n, c.friction_n);
            out = {c.opening_deg, c.grip_force_n};
        }
        logs[run] = slurp(d.file("log" + std::to_string(run) + ".csv"));
    }
    EXPECT_GT(logs[0].size(), 100u);
    EXPECT_EQ(logs[0], logs[1]);
    return out;
}
}  // namespace

TEST(SimulatorPatch, OnTheComplianceSolverASpringClipStopsWhereTheTissueBalancesItsSpringAndLogsRepeatBitForBit) {
    // Measured: 7.931 deg, 0.2706 N; the Newton frames (the test below): 7.938 deg, 0.2703 N.
    const auto [deg, grip] = spring_clip_balance("compliance");
    EXPECT_NEAR(deg, 7.938, 0.05);
    EXPECT_NEAR(grip, 0.2703, 0.01 * 0.2703);
}

TEST(SimulatorPatch, OnTenNodeElementsTheWallsTouchAlongTheQuadraticSurface) {
    // One layer of 10-node tetrahedra (as the pipeline's bundles), the outer surface's corners condensed: the patch's
    // blades press its corners and the mid-edge nodes between them, its walls touch on the lumen's triangles split at
    // their mid-edge nodes. Flattened until the blades stand 0.7 mm apart on the axis (the two 0.4 mm walls 12 %
    // compressed), the patch matches the whole tube solved with the same contact, and no node of the quadratic inner
    // surface lies behind the opposite wall. (With the walls' contact on the corner triangles only, the quadratic
    // surface passes through: WallContact.QuadraticPlatesTouchAlongTheirMidEdgeNodesOnlyWithTheSplitFaces.)
    test::TempDir d("patchsim10");
    const std::string bundle = d.file("tube10.h5");
    write_bundle(bundle, test::quadratic_tube_case(Precision::FLOAT64, 16, 12).bundle);
    const double end_deg = 2 * std::asin((0.7 - 0.2) / (2 * FLAT_HINGE_X)) / aneu::DEG;  // 3.58°
    json scene = flattening_scene(bundle, "patch", false, end_deg);
    scene["model"]["newton_per_frame"] = 80;  // the quadratic surface's contact takes more iterations near the end
    sim::Simulator s = make(scene, d.file(""), "patch10.json");
    const sim::Assessment a = sim::run_scene(s, sim::RunOptions{});
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_EQ(p.unconverged_frames, 0);
    EXPECT_GT(p.wall_pairs_touching, 0);
    EXPECT_GT(p.min_wall_distance_mm, -1e-3);  // on the split triangles: every node of the quadratic surface
    EXPECT_LT(p.min_wall_distance_mm, 0.011);
    const sim::Clip& c = s.clips().at(0);
    EXPECT_NEAR(c.opening_deg, end_deg, 1e-9);
    const auto [ref, ref_min] = flattening_reference(bundle, end_deg);
    const double f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    EXPECT_GT(ref_min, -1e-3);
    EXPECT_NEAR(c.grip_force_n, f_ref, 0.03 * f_ref);  // measured +0.8 %
    std::printf("10-node tube flattened to %.2f deg: patch %d nodes, blade force %.4f N vs neo-Hookean %.4f N (%+.2f %%), walls %.4f mm apart "
                "at the closest (reference %.4f), %d pairs touching\n",
                end_deg, p.nodes, c.grip_force_n, f_ref, 100 * (c.grip_force_n / f_ref - 1), p.min_wall_distance_mm, ref_min, p.wall_pairs_touching);
}

TEST(SimulatorPatch, APatchTakesOverTissueTheLinearModelPushedWithTheOpenJaws) {
    // The handover: the applier slides over the tube with its jaws only 22° open, so that the linear model pushes
    // the wall aside with them (the blades would cut 0.27 mm into the wall), and only then closes. The patch is made
    // at rest, where those wall nodes lie inside the blades; its blades start open enough to hold none and close to
    // the applier's opening from there. The end state is the one the clip reaches closing from clear air (the test
    // above): nothing behind a blade, walls apart, every frame converged, the same blade force (friction makes it
    // path dependent: within 5 %).
    test::TempDir d("handover");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    json j = flattening_scene(bundle, "patch", false);
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 1, 0};
    json keys = json::array();
    json k0 = key(0.0, {FLAT_HINGE_X + 12, 0, 4.0}, ax, up, 22);
    k0["load"] = "flat";
    keys.push_back(k0);
    keys.push_back(key(0.05, {FLAT_HINGE_X, 0, 4.0}, ax, up, 22));
    keys.push_back(key(0.06, {FLAT_HINGE_X, 0, 4.0}, ax, up, 22));
    keys.push_back(key(0.14, {FLAT_HINGE_X, 0, 4.0}, ax, up, FLAT_END_DEG));
    keys.push_back(key(0.16, {FLAT_HINGE_X, 0, 4.0}, ax, up, FLAT_END_DEG));
    j["instruments"][0]["keyframes"] = keys;
    sim::Simulator s = make(j, d.file(""), "handover.json");
    std::vector<std::string> msgs;
    sim::RunOptions opt;
    opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
    const sim::Assessment a = sim::run_scene(s, opt);
    int pushed = 0;
    double start_deg = 0;
    for (const auto& m : msgs) {
        const auto at = m.find("surface nodes the linear model had pushed lay inside the blades at");
        if (at == std::string::npos) continue;
        std::sscanf(m.c_str() + m.find(": ") + 2, "%d", &pushed);
        std::sscanf(m.c_str() + m.find("start at ") + 9, "%lf", &start_deg);
    }
    EXPECT_GT(pushed, 5) << "the linear model pushed no wall node into the blades' rest position: no handover tested";
    EXPECT_GT(start_deg, 26.0);  // the wall's outer radius (1.9 mm) touches the blades at 26° when they are centred on it
    EXPECT_LT(start_deg, 45.0);
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_EQ(p.unconverged_frames, 0);
    EXPECT_GT(p.wall_pairs_touching, 0);
    EXPECT_GT(p.min_wall_distance_mm, -0.02);
    const sim::Clip& c = s.clips().at(0);
    EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
    const double worst = under_the_flat_blades(s.deformed_surface()).second;
    EXPECT_GT(worst, -0.02);
    constexpr double FROM_CLEAR_AIR_N = 0.4886;  // the test above's blade force (closing from 40° in clear air)
    EXPECT_NEAR(c.grip_force_n, FROM_CLEAR_AIR_N, 0.05 * FROM_CLEAR_AIR_N);
    std::printf("handover: %d wall nodes inside the blades at rest, blades start at %.2f deg; end: blade force %.4f N (from clear air %.4f N), "
                "walls %.4f mm apart, deepest %.4f mm in front of a blade, %d frames (%d unconverged)\n",
                pushed, start_deg, c.grip_force_n, FROM_CLEAR_AIR_N, p.min_wall_distance_mm, worst, static_cast<int>(p.frames), static_cast<int>(p.unconverged_frames));
}

TEST(SimulatorPatch, FramesThatDoNotConvergeTwiceInARowRestartFromTheLastConvergedStateWithSmallerSteps) {
    // The flattening scene with only 8 Newton iterations a frame (the full frames take 9.3 on average): closing 2.9°
    // a frame onto the tube does not converge in 8 once the blades touch. A frame that does not converge is continued
    // by the next; a second in a row goes back to the last converged state and halves the opening's change a frame.
    // The clip still reaches the applier's opening (held longer), and the end state is the one closing in full
    // frames gives: walls apart, nothing behind a blade, the same blade force within 5 % (friction makes the path
    // matter). Measured: 58 frames, 33 not converged, 14 restarts, 0.4970 N. Then the same with the jaws sliding 2 mm
    // along the tube as they close, out of their first patch: the patch is remade and carries the last converged
    // state and the restart's bookkeeping over (measured: 2 builds, 14 restarts, 0.5105 N; the other path: 10 %).
    for (const bool slide : {false, true}) {
        test::TempDir d("patchrestart");
        const std::string bundle = tube_bundle(Precision::FLOAT64);
        json j = flattening_scene(bundle, "patch", false);
        j["model"]["newton_per_frame"] = 8;
        const std::array<double, 3> ax{-1, 0, 0}, up{0, 1, 0};
        if (slide) {
            j["instruments"][0]["keyframes"][0]["position"] = {FLAT_HINGE_X, 0, 2.0};
            j["instruments"][0]["keyframes"][1]["position"] = {FLAT_HINGE_X, 0, 2.0};
        }
        j["instruments"][0]["keyframes"].push_back(key(0.60, {FLAT_HINGE_X, 0, 4.0}, ax, up, FLAT_END_DEG));
        sim::Simulator s = make(j, d.file(""), "restart.json");
        const sim::Assessment a = sim::run_scene(s, sim::RunOptions{});
        ASSERT_EQ(a.patches.size(), 1u);
        const auto& p = a.patches[0];
        EXPECT_GT(p.unconverged_frames, 1);
        EXPECT_GT(p.restarts, 0) << "no two unconverged frames in a row: the restart was not exercised";
        EXPECT_LE(p.restarts, p.unconverged_frames / 2);
        if (slide) {
            EXPECT_GE(p.builds, 2) << "the sliding jaws did not leave their first patch";
        }
        const sim::Clip& c = s.clips().at(0);
        EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
        EXPECT_GT(p.wall_pairs_touching, 0);
        EXPECT_GT(p.min_wall_distance_mm, -0.02);
        const double worst = under_the_flat_blades(s.deformed_surface()).second;
        EXPECT_GT(worst, -0.02);
        constexpr double FROM_CLEAR_AIR_N = 0.4886;  // AClipFlatteningTheTube...'s blade force (40 iterations a frame)
        EXPECT_NEAR(c.grip_force_n, FROM_CLEAR_AIR_N, (slide ? 0.10 : 0.05) * FROM_CLEAR_AIR_N);
        std::printf("8 Newton iterations a frame%s: %d builds, %ld frames, %ld not converged, %ld restarts; end: %.3f deg, blade force %.4f N "
                    "(40 a frame: %.4f N), walls %.4f mm apart, deepest %.4f mm in front of a blade\n",
                    slide ? ", jaws sliding" : "", p.builds, p.frames, p.unconverged_frames, p.restarts, c.opening_deg, c.grip_force_n, FROM_CLEAR_AIR_N,
                    p.min_wall_distance_mm, worst);
    }
}

TEST(SimulatorPatch, ARemadeCompliancePatchsFirstFrameIsSolvedWithinTheLinearRange) {
    // The jaws slide 3 mm along the tube as they close (2.9 deg a frame), out of their patch: it is remade twice. A
    // remade patch takes nodes from the linear exterior where its linear map put them, off the neo-Hookean
    // equilibrium, and is linearised where its state was carried. Its first compliance frame starts where the patch
    // stands: measured at most one re-solve for the linear range in any frame (7 in the run), reach 0.217 x, blade
    // force 0.4342 N. (Until session 55 it started at the new linearisation's free state, the gripped tissue sprung
    // back through the blades, and went 2.3 wall thicknesses from its linearisation: re-solved 2.27 -> 2.33 -> 1.83
    // -> 0.36 -> 0.23 x, four re-solves, 10 in the run, reach 0.232 x, 0.4433 N; with three allowed, before session
    // 49, it ended at 0.36 x, warned. Before the re-solves kept the frame's start, every re-solve turned the gripped
    // tissue with the blades again, and this frame's attempts stayed at 0.6-0.8 x however many.)
    test::TempDir d("remade");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    json j = compliance_flattening_scene(bundle, 1, -1);
    const std::array<double, 3> ax{-1, 0, 0}, up{0, 1, 0};
    j["instruments"][0]["keyframes"][0]["position"] = {FLAT_HINGE_X, 0, 1.0};
    j["instruments"][0]["keyframes"][1]["position"] = {FLAT_HINGE_X, 0, 1.0};
    j["instruments"][0]["keyframes"].push_back(key(0.40, {FLAT_HINGE_X, 0, 4.0}, ax, up, FLAT_END_DEG));
    sim::Simulator s = make(j, d.file(""), "remade.json");
    int warnings = 0;
    const sim::RunOptions ro = counting_range_warnings(warnings);
    const sim::Assessment a = sim::run_scene(s, ro);
    ASSERT_EQ(a.patches.size(), 1u);
    const auto& p = a.patches[0];
    EXPECT_GE(p.builds, 3) << "the sliding jaws did not leave their patch twice";
    EXPECT_EQ(p.unconverged_frames, 0);
    EXPECT_EQ(p.linearisations_failed, 0);
    EXPECT_GT(p.range_refreshes, 0);
    EXPECT_LE(p.max_frame_resolves, 1);
    EXPECT_EQ(p.range_earlier_kept, 0);
    EXPECT_LE(p.max_lag_to_thickness, 0.3);
    EXPECT_EQ(warnings, 0);
    EXPECT_GT(p.min_wall_distance_mm, -0.02);
    const sim::Clip& c = s.clips().at(0);
    EXPECT_NEAR(c.opening_deg, FLAT_END_DEG, 1e-9);
    std::printf("remade patch: %d builds, %ld frames, %d linearisations, %d re-solves for the range (at most %d in a frame, %d kept an earlier "
                "attempt); reach %.3f x at t = %.3f s, %d warnings; blade force %.4f N, walls %.4f mm apart at the closest\n",
                p.builds, p.frames, p.linearisations, p.range_refreshes, p.max_frame_resolves, p.range_earlier_kept, p.max_lag_to_thickness, p.max_lag_t,
                warnings, c.grip_force_n, p.min_wall_distance_mm);
}

namespace {

/// The tube flattened by the compliance frames relinearised every frame (held to 0.30 s) with no re-solves for the
/// linear range (model.range_resolves 0) and the scene's `model` entries `extra` on top: the run's patch, its clip at
/// the end, the neo-Hookean reference's blade force there and the range warnings. Checked here, what every way of
/// solving a frame beyond the range again must give: every frame converged and within the range (or no linearisation's),
/// none warned, the walls apart, the blades where the reference holds them (within 5 %).
struct BeyondRange {
    sim::Assessment::PatchEnd p;
    sim::Clip c;
    double f_ref = 0;
    int warnings = 0;
};
BeyondRange flattened_beyond_the_range(const std::string& tag, const json& extra) {
    test::TempDir d(tag);
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    const auto [ref, ref_min] = flattening_reference(bundle, FLAT_END_DEG);
    BeyondRange r;
    r.f_ref = 0.5 * (ref.force_n[0] + ref.force_n[1]);
    json j = compliance_flattening_scene(bundle, 1, 0.30);
    j["model"]["range_resolves"] = 0;
    for (const auto& [k, v] : extra.items()) j["model"][k] = v;
    sim::Simulator s = make(j, d.file(""), tag + ".json");
    const sim::RunOptions ro = counting_range_warnings(r.warnings);
    const sim::Assessment a = sim::run_scene(s, ro);
    EXPECT_EQ(a.patches.size(), 1u);
    if (a.patches.size() != 1) return r;
    r.p = a.patches[0];
    r.c = s.clips().at(0);
    EXPECT_EQ(r.p.unconverged_frames, 0);
    EXPECT_EQ(r.p.range_refreshes, 0);
    EXPECT_LE(r.p.max_lag_to_thickness, 0.3);
    EXPECT_EQ(r.warnings, 0);
    EXPECT_GT(r.p.min_wall_distance_mm, -0.02);
    EXPECT_NEAR(r.c.opening_deg, FLAT_END_DEG, 1e-9);
    EXPECT_NEAR(r.c.grip_force_n, r.f_ref, 0.05 * r.f_ref);
    return r;
}

}  // namespace

TEST(SimulatorPatch, AComplianceFrameStillBeyondTheLinearRangeAfterItsReSolvesIsSolvedInHalvesOfItsStep) {
    // The tube flattened by the compliance frames relinearised every frame, as above (whose frames close the blades
    // ~1.5 deg each and go up to 0.63 wall thicknesses from their linearisation), but with no re-solves allowed
    // (model.range_resolves 0) and halvings (model.range_splits 2): a frame beyond the linear range is solved again in
    // two halves of its opening's change, each a frame of its own linearised where it starts, and a half still beyond
    // it in halves again (at most twice). Measured: 11 halvings, reach 0.294 x, blade force -1.33 %.
    // Every frame then ends within the range, none is warned, and the blades end where the neo-Hookean reference
    // holds them, as with the re-solves.
    const BeyondRange r = flattened_beyond_the_range("split", {{"range_splits", 2}});
    const auto& p = r.p;
    EXPECT_EQ(p.linearisations_failed, 0);
    EXPECT_EQ(p.max_frame_resolves, 0);
    EXPECT_GT(p.range_splits, 0) << "no frame went beyond the range: the halving was not exercised";
    EXPECT_GE(p.max_frame_splits, 1);
    EXPECT_LE(p.max_frame_splits, 2);
    EXPECT_GT(p.max_lag_to_thickness, 0.0);
    std::printf("no re-solves, frames halved: %ld frames, %d linearisations, %d halvings (at most %d in a frame); reach %.3f x at t = %.3f s, %d warnings; "
                "blade force %.4f N vs neo-Hookean %.4f N (%+.2f %%), walls %.4f mm apart at the closest\n",
                p.frames, p.linearisations, p.range_splits, p.max_frame_splits, p.max_lag_to_thickness, p.max_lag_t, r.warnings, r.c.grip_force_n, r.f_ref,
                100 * (r.c.grip_force_n / r.f_ref - 1), p.min_wall_distance_mm);
}

TEST(SimulatorPatch, AComplianceFrameStillBeyondTheLinearRangeAfterItsReSolvesIsSolvedAsANewtonFrame) {
    // The same with no halvings but model.range_newton 40: a frame beyond the linear range of its linearisation is
    // solved as a Newton frame (the neo-Hookean patch with the blades' and walls' barriers, from where the frame
    // started, its walls and pressed nodes first set 0.005 mm apart), and the frames go on from its state, linearised
    // there. Measured: 7 of 28 frames Newton's, none failed, reach 0.098 x, blade force -3.90 %.
    const BeyondRange r = flattened_beyond_the_range("rnewton", {{"range_newton", 40}});
    const auto& p = r.p;
    EXPECT_EQ(p.range_splits, 0);
    EXPECT_GT(p.range_newton_frames, 0) << "no frame went beyond the range: the Newton frames were not exercised";
    EXPECT_EQ(p.range_newton_failed, 0);
    std::printf("no re-solves, Newton frames: %ld frames, %d linearisations, %d Newton frames (%d not converged); reach %.3f x at t = %.3f s, %d warnings; "
                "blade force %.4f N vs neo-Hookean %.4f N (%+.2f %%), walls %.4f mm apart at the closest\n",
                p.frames, p.linearisations, p.range_newton_frames, p.range_newton_failed, p.max_lag_to_thickness, p.max_lag_t, r.warnings, r.c.grip_force_n,
                r.f_ref, 100 * (r.c.grip_force_n / r.f_ref - 1), p.min_wall_distance_mm);
}

TEST(SimulatorPatch, ASpringClipStopsWhereTheTissueBalancesItsSpringAndLogsRepeatBitForBit) {
    // A clip with a 0.3 N spring (at the label point) on the tube: the applier can only hold it open, so as the
    // applier closes, the clip stops where the tissue's moment about the hinge equals the spring's torque, short
    // of the flattening the applier asks for; released, it stays there. The patch's solve gives that balance
    // (its reaction on the opening is τ − M; the frames step the opening onto τ = M). The same scene run twice
    // gives the same log, byte for byte.
    spring_clip_balance("newton");
}

TEST(SimulatorPatch, InRealTimeAClipReleasedWhileItsPatchIsMadeOrSolvedEndsCleanly) {
    // The threaded real-time mode runs the scene on the wall clock: the patch's build and Newton frames take far
    // longer than the scene's 0.01 s frames, so the haptic thread releases the clip while the physics thread is
    // making its patch or solving it without the lock. Released early (the jaws still in the air or just
    // touching) the clip grips nothing and falls away; later it is deposited on what it grips. Either way the run
    // ends, the patch goes with a clip that fell away, and a kept patch belongs to a clip that is still there.
    // (Before: the build read the fallen clip's emptied model name, std::out_of_range, and the process ended in
    // std::terminate; a fall during a solve freed the patch model the solve was using.)
    test::TempDir d("patchrt");
    const std::string bundle = tube_bundle(Precision::FLOAT64);
    for (const double release_s : {0.03, 0.06, 0.1}) {
        SCOPED_TRACE("release at " + std::to_string(release_s) + " s");
        json j = flattening_scene(bundle, "patch", true);
        json& keys = j["instruments"][0]["keyframes"];
        // The release moved earlier: the keyframes after it shifted with it.
        json moved = json::array();
        const double shift = 0.17 - release_s;
        for (json k : keys) {
            const double t = k["t"].get<double>();
            if (t > 0.02 && t < 0.17 && t > release_s) continue;  // the closing keys after the release
            if (t >= 0.17) k["t"] = t - shift;
            moved.push_back(k);
        }
        keys = moved;
        j["outputs"] = {{"log", "rt_log.csv"}, {"report", "rt_report.json"}};
        sim::Simulator s = make(j, d.file(""), "rt.json");
        std::vector<std::string> msgs;
        sim::RunOptions opt;
        opt.deterministic = false;
        opt.on_message = [&](const std::string& m) { msgs.push_back(m); };
        const sim::Assessment a = sim::run_scene(s, opt);
        const sim::Clip& c = s.clips().at(0);
        EXPECT_EQ(c.state, sim::Clip::State::DEPOSITED);
        for (const auto& p : a.patches) EXPECT_EQ(p.clip, 0);
        const bool fell = c.model.empty();
        std::string said;
        for (const auto& m : msgs) said += m + "\n";
        if (fell) {
            EXPECT_NE(said.find("falls away"), std::string::npos) << said;
        } else {
            EXPECT_GT(c.grip_force_n, 0.0);  // deposited on tissue it grips
        }
        // A patch made for a clip released meanwhile is not used: it is not among the patches the run reports.
        if (said.find("the patch is not used") != std::string::npos) {
            EXPECT_TRUE(a.patches.empty()) << said;
        }
        // A patch the run kept that belonged to a clip that fell away was dropped with it: nothing of it stays on the
        // surface (the deformed surface is the linear model's, which a fallen clip no longer pushes: within the
        // linear solve's own displacement of the tube at rest, zero).
        if (fell) {
            EXPECT_LT((s.deformed_surface() - s.model().surface.X).cwiseAbs().maxCoeff(), 1e-9);
        }
        std::printf("released at %.2f s (wall clock): %s, %zu patch(es), opening %.2f deg\n%s", release_s, fell ? "fell away" : "deposited",
                    a.patches.size(), c.opening_deg, said.c_str());
        EXPECT_TRUE(std::filesystem::exists(d.file("rt_report.json")));
    }
}
