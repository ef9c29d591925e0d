// SPDX-License-Identifier: MIT
// `aneuprep flow` (issue #17) against Hagen–Poiseuille in a straight tube, and its errors. Runs OpenFOAM
// (blockMesh, snappyHexMesh, simpleFoam) as child processes: scripts/install_deps.sh installs it.
#include <cmath>
#include <filesystem>
#include <fstream>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <unistd.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/pipeline/case_runner.hpp"
#include "aneu/pipeline/flow.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace fs = std::filesystem;
using namespace aneu;
using namespace aneu::pipeline;

namespace {

constexpr double PI = 3.14159265358979323846;

/// An open tube along x (no end caps), radius R, length L, as an ASCII STL.
void write_tube_stl(const fs::path& p, double R, double L, int n = 96, int m = 160) {
    std::ofstream out(p);
    out.precision(10);
    auto ring = [&](double x, int k) { return Eigen::Vector3d(x, R * std::cos(2 * PI * k / n), R * std::sin(2 * PI * k / n)); };
    auto tri = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
        const Eigen::Vector3d nn = (b - a).cross(c - a).normalized();
        out << "facet normal " << nn.x() << " " << nn.y() << " " << nn.z() << "\n outer loop\n";
        for (const auto* v : {&a, &b, &c}) out << "  vertex " << v->x() << " " << v->y() << " " << v->z() << "\n";
        out << " endloop\nendfacet\n";
    };
    out << "solid tube\n";
    for (int j = 0; j < m; ++j)
        for (int k = 0; k < n; ++k) {
            const double x0 = L * j / m, x1 = L * (j + 1) / m;
            tri(ring(x0, k), ring(x1, k + 1), ring(x1, k));
            tri(ring(x0, k), ring(x0, k + 1), ring(x1, k + 1));
        }
    out << "endsolid tube\n";
}

double qa_of(const Bundle& b, const std::string& k) {
    for (const auto& [n, v] : b.meta.stages.back().qa)
        if (n == k) return v;
    ADD_FAILURE() << "no QA figure " << k;
    return NAN;
}

struct TempDir {
    fs::path p = fs::temp_directory_path() / ("aneu_flow_test_" + std::to_string(::getpid()));
    TempDir() { fs::create_directories(p); }
    ~TempDir() { fs::remove_all(p); }
};

/// The tube's lumen as `aneuprep surface` writes it (two open ends with end planes).
fs::path tube_lumen(const TempDir& d, double R, double L) {
    write_tube_stl(d.p / "tube.stl", R, L);
    const LumenResult r = lumen_from_mesh((d.p / "tube.stl").string(), SurfaceParams{});
    Bundle b;
    b.meta.case_id = "tube";
    b.image = r.image;
    b.surfaces["lumen"] = r.lumen;
    const fs::path s = d.p / "surface.h5";
    write_bundle(s.string(), b);
    return s;
}

StageRecord record() {
    StageRecord r;
    r.stage = "flow";
    return r;
}

}  // namespace

// Hagen–Poiseuille, the acceptance at the default mesh: a tube of radius 2 mm and length 40 mm, blood at a
// mean 1 cm/s (Re 12, so the flow is developed within 3 mm of the plug inlet). In the middle half, away from the
// ends: the wall pressure's gradient within 2 % of 8μQ/(πR⁴), the wall shear stress within 5 % of 4μQ/(πR³)
// (R from the end caps' area: the remeshed lumen's own cross-section); inflow − outflow within 0.5 % of inflow.
TEST(Flow, PoiseuilleInAStraightTube) {
    const TempDir d;
    const double R = 2.0, L = 40.0;
    const fs::path in = tube_lumen(d, R, L);
    FlowParams p;
    p.inflow_cm_s = 1.0;
    flow_file(in.string(), (d.p / "flow.h5").string(), p, record(), null_reporter());
    const Bundle b = read_bundle((d.p / "flow.h5").string());
    ASSERT_TRUE(b.surfaces.count("blood"));
    const SurfaceData& s = b.surfaces.at("blood");
    ASSERT_EQ(s.label_names.size(), 3u);
    EXPECT_EQ(qa_of(b, "converged"), 1.0);
    const double area = qa_of(b, "area_mm2_end_" + s.label_names[1].substr(4));
    const double Re = std::sqrt(area / PI) * 1e-3;  // m
    const double Q = qa_of(b, "inflow_ml_s") * 1e-6;  // m³/s
    EXPECT_NEAR(Q, 0.01 * area * 1e-6, 0.01 * Q) << "the plug inflow (over the fluid mesh's inlet patch, snapped to the cap)";
    EXPECT_LE(qa_of(b, "mass_imbalance"), 0.005);
    // The axis: the tube runs along x; the middle half of its length.
    const double x0 = s.V.col(0).minCoeff(), x1 = s.V.col(0).maxCoeff();
    const auto& pr = s.face_fields.at("pressure_pa");
    const auto& wss = s.face_fields.at("wall_shear_stress_pa");
    double sx = 0, sp = 0, sxx = 0, sxp = 0, n = 0, wsum = 0, asum = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (s.face_label[f] != 0) continue;
        const Eigen::Vector3d a = s.V.row(s.F(f, 0)), bb = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
        const double x = (a.x() + bb.x() + c.x()) / 3;
        if (x < x0 + 0.25 * (x1 - x0) || x > x0 + 0.75 * (x1 - x0)) continue;
        const double xm = x * 1e-3;
        sx += xm;
        sp += pr(f, 0);
        sxx += xm * xm;
        sxp += xm * pr(f, 0);
        n += 1;
        const double ar = 0.5 * (bb - a).cross(c - a).norm();
        wsum += ar * wss(f, 0);
        asum += ar;
    }
    ASSERT_GT(n, 100);
    const double slope = std::abs((n * sxp - sx * sp) / (n * sxx - sx * sx));  // the inlet may be either end
    const double mu = BLOOD_VISCOSITY_PA_S;
    const double dpdx = 8 * mu * Q / (PI * std::pow(Re, 4));
    const double tau = 4 * mu * Q / (PI * std::pow(Re, 3));
    std::printf("Poiseuille: dp/dx %.4f Pa/m (Hagen-Poiseuille %.4f, %+.2f %%), WSS %.5f Pa (%.5f, %+.2f %%), mass imbalance %.2e, %g cells\n", slope,
                dpdx, 100 * (slope / dpdx - 1), wsum / asum, tau, 100 * (wsum / asum / tau - 1), qa_of(b, "mass_imbalance"), qa_of(b, "cells"));
    EXPECT_NEAR(slope, dpdx, 0.02 * dpdx);
    EXPECT_NEAR(wsum / asum, tau, 0.05 * tau);
    // The caps carry no wall shear stress; the vector field's magnitude is the scalar.
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (s.face_label[f] != 0) {
            EXPECT_EQ(wss(f, 0), 0.0);
        }
        EXPECT_NEAR(s.face_fields.at("wall_shear_stress_vector_pa").row(f).norm(), wss(f, 0), 1e-12);
    }
}

// The flow into a sidewall sac through its neck: a tube of radius 1.5 mm along z with a sphere of radius 2.5 mm on
// its side (the sac labelled by the surface stage), blood at 10 cm/s. The sac has no outlet, so what enters
// through the neck leaves through it again: inflow and outflow sampled on the neck agree within 10 %, the inflow is
// a real part of the parent's flow (between 0.1 % and 50 %), and the net flux through the neck is small.
TEST(Flow, SacInflowThroughTheNeckOfASidewallSac) {
    const TempDir d;
    const double R = 1.5, Rs = 2.5;
    const Eigen::Vector3d sac(0, 3.4, 1.0);
    Volume<float> v;
    v.grid.size = {50, 60, 140};
    v.grid.spacing = {0.2, 0.2, 0.2};
    v.grid.origin = {-4.9, -4.9, -13.9};
    v.data.resize(v.grid.voxel_count());
    for (std::int64_t k = 0; k < v.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < v.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < v.grid.size[0]; ++i) {
                const Eigen::Vector3d x(-4.9 + 0.2 * i, -4.9 + 0.2 * j, -13.9 + 0.2 * k);
                v.data[v.grid.linear(i, j, k)] = static_cast<float>(std::max(R - std::hypot(x.x(), x.y()), Rs - (x - sac).norm()));
            }
    write_mesh_file((d.p / "sac.stl").string(), isosurface(v, 0.0, true));
    const LumenResult r = lumen_from_mesh((d.p / "sac.stl").string(), SurfaceParams{});
    Bundle in;
    in.meta.case_id = "sac";
    in.image = r.image;
    in.surfaces["lumen"] = r.lumen;
    write_bundle((d.p / "surface.h5").string(), in);
    FlowParams p;
    p.inflow_cm_s = 10.0;
    flow_file((d.p / "surface.h5").string(), (d.p / "flow.h5").string(), p, record(), null_reporter());
    const Bundle b = read_bundle((d.p / "flow.h5").string());
    const double q_in = qa_of(b, "sac_inflow_ml_s"), q_out = qa_of(b, "sac_outflow_ml_s"), frac = qa_of(b, "sac_inflow_fraction");
    std::printf("sidewall sac: neck %.2f mm², sac inflow %.4f mL/s, outflow %.4f mL/s (%.1f %% of the inflow %.3f mL/s)\n", qa_of(b, "neck_area_mm2"), q_in,
                q_out, 100 * frac, qa_of(b, "inflow_ml_s"));
    EXPECT_GT(qa_of(b, "neck_area_mm2"), 3.0) << "the neck spans the sac's opening";
    EXPECT_GT(frac, 0.001);
    EXPECT_LT(frac, 0.5);
    EXPECT_NEAR(q_in, q_out, 0.1 * q_in) << "what enters a closed sac leaves it";
    // The sac's volume seen by the fluid mesh: between half and all of the sphere (its part inside the parent and
    // below the neck's plane is not sac); the flow in it is slower than the parent's mean.
    const double sphere = 4.0 / 3.0 * PI * Rs * Rs * Rs;
    std::printf("sidewall sac: volume %.1f mm³ (sphere %.1f), mean speed %.2f cm/s (parent mean 10)\n", qa_of(b, "sac_volume_mm3"), sphere,
                qa_of(b, "sac_mean_speed_cm_s"));
    EXPECT_GT(qa_of(b, "sac_volume_mm3"), 0.5 * sphere);
    EXPECT_LT(qa_of(b, "sac_volume_mm3"), 1.0 * sphere);
    EXPECT_GT(qa_of(b, "sac_mean_speed_cm_s"), 0.0);
    EXPECT_LT(qa_of(b, "sac_mean_speed_cm_s"), 10.0);
}

// Errors: an end that does not exist and a lumen without open ends are the input's fault; a time budget too short
// for the mesh is the stage's failure. Nothing is left under the output's name.
TEST(Flow, BadInputsAndABudgetTooShort) {
    const TempDir d;
    const fs::path in = tube_lumen(d, 1.0, 8.0);
    const fs::path out = d.p / "flow.h5";
    FlowParams p;
    p.inlet_end = 9;
    try {
        flow_file(in.string(), out.string(), p, record(), null_reporter());
        ADD_FAILURE() << "no error for --inlet-end 9";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("--inlet-end 9: the lumen has no such end"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(out));
    SurfaceData closed = read_bundle(in.string()).surfaces.at("lumen");
    closed.loop_offsets.resize(0);
    closed.loop_vertices.resize(0);
    closed.loop_end_id.resize(0);
    EXPECT_THROW(blood_domain(closed), InputError);
    p = FlowParams{};
    p.time_budget_s = 0.5;
    try {
        flow_file(in.string(), out.string(), p, record(), null_reporter());
        ADD_FAILURE() << "no error for a 0.5 s budget";
    } catch (const InputError& e) {
        ADD_FAILURE() << "a budget too short is not the input's fault: " << e.what();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("time budget"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(out));
}

// A case config with a [flow] section gets a flow stage after the case bundle, fed by the lumen (surface.h5), so a
// changed wall or condensation does not rerun it; without the section there is none, and --set cannot add one.
TEST(Flow, ACaseConfigWithAFlowSectionHasAFlowStage) {
    const TempDir d;
    write_tube_stl(d.p / "tube.stl", 2.0, 10.0, 24, 20);
    const std::string src = "[run]\nsource = \"" + (d.p / "tube.stl").string() + "\"\n";
    {
        std::ofstream(d.p / "plain.toml") << src;
        std::ofstream(d.p / "with_flow.toml") << src << "[flow]\ninflow-cm-s = 5\n";
    }
    const CaseChain plain = make_case_chain((d.p / "plain.toml").string(), (d.p / "a").string(), "", {});
    EXPECT_EQ(plain.find("flow"), nullptr);
    EXPECT_EQ(plain.bundle(), (d.p / "a" / "case.h5").string());
    EXPECT_THROW(make_case_chain((d.p / "plain.toml").string(), (d.p / "a").string(), "", {"flow.inflow-cm-s=5"}), InputError);
    const CaseChain c = make_case_chain((d.p / "with_flow.toml").string(), (d.p / "b").string(), "", {});
    ASSERT_NE(c.find("flow"), nullptr);
    EXPECT_EQ(c.steps.back().stage, "flow");
    EXPECT_EQ(c.find("flow")->input, (d.p / "b" / "surface.h5").string());
    EXPECT_EQ(c.find("flow")->output, (d.p / "b" / "flow.h5").string());
    EXPECT_EQ(c.bundle(), (d.p / "b" / "case.h5").string()) << "the case bundle is still condense's output";
    ASSERT_EQ(c.options.at("flow").size(), 1u);
    EXPECT_EQ(c.options.at("flow")[0].first, "inflow-cm-s");
    std::ofstream(d.p / "empty_flow.toml") << src << "[flow]\n";
    EXPECT_NE(make_case_chain((d.p / "empty_flow.toml").string(), (d.p / "c").string(), "", {}).find("flow"), nullptr)
        << "an empty [flow] section asks for the stage with its defaults";
}
