// SPDX-License-Identifier: MIT
// `aneuprep flow` (issue #17) against Hagen–Poiseuille in a straight tube, and its errors. Runs OpenFOAM
// (blockMesh, snappyHexMesh, simpleFoam) as child processes: scripts/install_deps.sh installs it.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <Eigen/Geometry>
#include <H5Cpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "aneu/pipeline/case_runner.hpp"
#include "aneu/pipeline/export.hpp"
#include "aneu/pipeline/flow.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/surface_checks.hpp"
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

/// Figures of a straight tube along x: the pressure gradient (slope of the wall's pressure along the middle half),
/// the area-weighted wall shear stress there, the flow and the radius from the inlet's area.
struct TubeFigures {
    double dpdx = 0, wss = 0, Q = 0, R = 0;
    int faces = 0;  ///< wall faces in the middle half
};
TubeFigures tube_figures(const Bundle& b) {
    const SurfaceData& s = b.surfaces.at("blood");
    TubeFigures t;
    t.R = std::sqrt(qa_of(b, "area_mm2_end_" + s.label_names[1].substr(4)) / PI) * 1e-3;
    t.Q = qa_of(b, "inflow_ml_s") * 1e-6;
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
    t.dpdx = std::abs((n * sxp - sx * sp) / (n * sxx - sx * sx));  // the inlet may be either end
    t.faces = static_cast<int>(n);
    t.wss = wsum / asum;
    return t;
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
    const TubeFigures tf = tube_figures(b);
    ASSERT_GT(tf.faces, 100);
    const double slope = tf.dpdx;
    const auto& wss = s.face_fields.at("wall_shear_stress_pa");
    const double mu = BLOOD_VISCOSITY_PA_S;
    const double dpdx = 8 * mu * Q / (PI * std::pow(Re, 4));
    const double tau = 4 * mu * Q / (PI * std::pow(Re, 3));
    std::printf("Poiseuille: dp/dx %.4f Pa/m (Hagen-Poiseuille %.4f, %+.2f %%), WSS %.5f Pa (%.5f, %+.2f %%), mass imbalance %.2e, %g cells\n", slope,
                dpdx, 100 * (slope / dpdx - 1), tf.wss, tau, 100 * (tf.wss / tau - 1), qa_of(b, "mass_imbalance"), qa_of(b, "cells"));
    EXPECT_NEAR(slope, dpdx, 0.02 * dpdx);
    EXPECT_NEAR(tf.wss, tau, 0.05 * tau);
    // The caps carry no wall shear stress; the vector field's magnitude is the scalar.
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (s.face_label[f] != 0) {
            EXPECT_EQ(wss(f, 0), 0.0);
        }
        EXPECT_NEAR(s.face_fields.at("wall_shear_stress_vector_pa").row(f).norm(), wss(f, 0), 1e-12);
    }
    // The cells' field: one entry per cell, the cells' volumes fill the tube, the flow through a cross-section
    // from the cells' velocities is the inflow; streamlines run straight down the tube, inlet to outlet.
    ASSERT_TRUE(b.flow.has_value());
    const FlowFieldData& fl = *b.flow;
    EXPECT_EQ(static_cast<double>(fl.centre.rows()), qa_of(b, "cells"));
    EXPECT_NEAR(fl.volume.sum(), PI * R * R * L, 0.02 * PI * R * R * L);
    double q_mid = 0;  // Σ u_x V / L over the middle half = the mean flow
    for (Eigen::Index c = 0; c < fl.centre.rows(); ++c)
        if (fl.centre(c, 0) > x0 + 0.25 * (x1 - x0) && fl.centre(c, 0) < x0 + 0.75 * (x1 - x0)) q_mid += std::abs(fl.velocity(c, 0)) * fl.volume[c];
    q_mid /= 0.5 * (x1 - x0);
    EXPECT_NEAR(q_mid * 1e-9, Q, 0.02 * Q) << "mm³/s from the cells against the inflow";
    const auto lines = trace_streamlines(fl, s, "end_" + std::to_string(static_cast<int>(qa_of(b, "inlet_end"))), 40);
    ASSERT_GE(lines.size(), 35u);
    double worst_drift = 0, shortest_run = 1e9;
    for (const auto& l : lines) {  // drift over the developed middle half (the plug inflow reshapes first)
        const Eigen::Vector3d a0 = l.points.front(), a1 = l.points.back();
        const Eigen::Vector3d* m0 = nullptr;
        for (const auto& x : l.points) {
            if (x.x() < x0 + 0.25 * (x1 - x0) || x.x() > x0 + 0.75 * (x1 - x0)) continue;
            if (m0 == nullptr) m0 = &x;
            worst_drift = std::max(worst_drift, std::hypot(x.y() - m0->y(), x.z() - m0->z()));
        }
        shortest_run = std::min(shortest_run, std::abs(a1.x() - a0.x()));
    }
    std::printf("Poiseuille: %zu streamlines, largest drift across the middle half %.3f mm (R %.1f), shortest run %.1f of %.1f mm\n", lines.size(),
                worst_drift, R, shortest_run, x1 - x0);
    EXPECT_LT(worst_drift, 0.05 * R);
    EXPECT_GT(shortest_run, 0.9 * (x1 - x0));
    // ParaView: the cells as points with velocity and pressure, read from the stage file in place.
    ExportParams ep;
    ep.format = ExportFormat::XDMF;
    export_file((d.p / "flow.h5").string(), (d.p / "cells.xdmf").string(), ep, null_reporter());
    std::stringstream xs;
    xs << std::ifstream(d.p / "cells.xdmf").rdbuf();
    EXPECT_NE(xs.str().find("TopologyType=\"Polyvertex\""), std::string::npos);
    EXPECT_NE(xs.str().find("flow.h5:/flow/velocity"), std::string::npos);
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
    CaseChain cp = c;
    EXPECT_EQ(plan_case(cp).back().inputs, std::vector<std::string>{(d.p / "b" / "surface.h5").string()}) << "the pre-clip flow's one input";
    ASSERT_EQ(c.options.at("flow").size(), 1u);
    EXPECT_EQ(c.options.at("flow")[0].first, "inflow-cm-s");
    // A session's flow ([flow] series): the case bundle is the input, the series a second input (a new session
    // reruns it); Makefile.cases depends on both.
    std::ofstream(d.p / "session.toml") << src << "[flow]\nseries = \"" << (d.p / "scene_series.h5").string() << "\"\n";
    CaseChain sc = make_case_chain((d.p / "session.toml").string(), (d.p / "s").string(), "", {});
    ASSERT_NE(sc.find("flow"), nullptr);
    EXPECT_EQ(sc.find("flow")->input, (d.p / "s" / "case.h5").string());
    const std::vector<StagePlan> plans = plan_case(sc);
    ASSERT_EQ(plans.back().inputs.size(), 2u);
    EXPECT_EQ(plans.back().inputs[1], (d.p / "scene_series.h5").string());
    std::ofstream(d.p / "empty_flow.toml") << src << "[flow]\n";
    EXPECT_NE(make_case_chain((d.p / "empty_flow.toml").string(), (d.p / "c").string(), "", {}).find("flow"), nullptr)
        << "an empty [flow] section asks for the stage with its defaults";
}

namespace {

/// A lumen along x pinched at x = xc across y, as a clip's jaws press it (the simulator lets walls pass through
/// each other): y' = y − δ·exp(−((x − xc)/w)²)·tanh(y/ε)·c(z), c(z) = 1 / (1 + exp((z − z_edge)/0.05)), so the jaws
/// cover z < z_edge (the whole width for z_edge = +∞). With δ > R the top wall ends up below the bottom one.
struct Pinch {
    double xc = 6, w = 0.8, delta = 1.4, eps = 0.15, z_edge = 1e9;
    double c(double z) const { return z_edge > 1e8 ? 1.0 : 1.0 / (1.0 + std::exp((z - z_edge) / 0.05)); }
    Eigen::Vector3d operator()(const Eigen::Vector3d& x) const {
        Eigen::Vector3d y = x;
        y.y() -= delta * std::exp(-std::pow((x.x() - xc) / w, 2)) * std::tanh(x.y() / eps) * c(x.z());
        return y;
    }
    /// The pinched cross-section at x = xc, from the tube's circle of radius R (n points).
    std::vector<Eigen::Vector2d> section(double R, int n = 2000) const {
        std::vector<Eigen::Vector2d> s;
        for (int i = 0; i < n; ++i) {
            const double t = 2 * PI * i / n;
            const Eigen::Vector3d p = (*this)(Eigen::Vector3d(xc, R * std::cos(t), R * std::sin(t)));
            s.emplace_back(p.y(), p.z());
        }
        return s;
    }
};

/// Winding number of the closed polygon `c` around q.
int winding(const std::vector<Eigen::Vector2d>& c, const Eigen::Vector2d& q) {
    int w = 0;
    for (size_t i = 0; i < c.size(); ++i) {
        const Eigen::Vector2d& a = c[i];
        const Eigen::Vector2d& b = c[(i + 1) % c.size()];
        const double side = (b.x() - a.x()) * (q.y() - a.y()) - (q.x() - a.x()) * (b.y() - a.y());
        if (a.y() <= q.y()) {
            if (b.y() > q.y() && side > 0) ++w;
        } else if (b.y() <= q.y() && side < 0) {
            --w;
        }
    }
    return w;
}

double distance_to_polygon(const std::vector<Eigen::Vector2d>& c, const Eigen::Vector2d& q) {
    double d = 1e300;
    for (size_t i = 0; i < c.size(); ++i) {
        const Eigen::Vector2d a = c[i], b = c[(i + 1) % c.size()];
        const double t = std::clamp((q - a).dot(b - a) / std::max((b - a).squaredNorm(), 1e-300), 0.0, 1.0);
        d = std::min(d, (a + t * (b - a) - q).norm());
    }
    return d;
}

double field_at(const Volume<float>& f, const Eigen::Vector3d& x) {
    const auto ci = f.grid.continuous_index({x.x(), x.y(), x.z()});
    std::array<std::int64_t, 3> i{};
    for (size_t k = 0; k < 3; ++k) {
        i[k] = std::llround(ci[k]);
        if (i[k] < 0 || i[k] >= f.grid.size[k]) return -1.0;  // outside the grid: outside the surface
    }
    return f.data[f.grid.linear(i[0], i[1], i[2])];
}

/// The tube's lumen (radius 1 mm, 12 mm along x) with the pinch applied to its vertices.
SurfaceData pinched_lumen(const TempDir& d, const Pinch& pinch) {
    SurfaceData s = read_bundle(tube_lumen(d, 1.0, 12.0).string()).surfaces.at("lumen");
    for (Eigen::Index v = 0; v < s.V.rows(); ++v) s.V.row(v) = pinch(s.V.row(v).transpose()).transpose();
    return s;
}

}  // namespace

// A tube pinched flat across its whole width: the walls pass through each other (the capped surface
// self-intersects); what blood reaches from the inlet stops at the pinch: the clean surface is closed,
// manifold and free of self-intersections, its volume the tube's up to the pinch, the far end not reached; the
// flow stage refuses to solve a vessel with no outlet left (a stage failure, exit 1).
TEST(Flow, APinchedTubeKeepsOnlyWhatBloodReaches) {
    const TempDir d;
    const Pinch pinch;
    const SurfaceData lumen = pinched_lumen(d, pinch);
    const SurfaceData capped = blood_domain(lumen);
    EXPECT_FALSE(self_intersections(capped, 4).empty()) << "the pinch makes the walls cross";
    // The inlet: the end at x = 0.
    const double g = 0.0625;
    const Volume<float> f = reachable_distance(capped, Eigen::Vector3d(0.5, 0.013, 0.021), g, 100'000'000);
    EXPECT_GT(field_at(f, Eigen::Vector3d(3, 0, 0)), 0) << "before the pinch";
    EXPECT_LT(field_at(f, Eigen::Vector3d(9, 0, 0)), 0) << "beyond the pinch: not reached";
    EXPECT_LT(field_at(f, Eigen::Vector3d(6, 0, 0.99)), 0) << "the lateral corner of the pinch: closed at this resolution";
    const SurfaceData clean = isosurface(f, 0.0, true, true);
    EXPECT_NO_THROW(boundary_loops(clean));
    EXPECT_TRUE(boundary_loops(clean).empty()) << "closed";
    EXPECT_TRUE(self_intersections(clean, 4).empty());
    const double vol = enclosed_volume(clean), tube = PI * 12.0;
    std::printf("pinched tube: reachable %.2f mm³ of the tube's %.2f (up to x = %.2f)\n", vol, tube, vol / PI);
    EXPECT_GT(vol / PI, 4.5) << "the tube up to the pinch (x = 6 less the jaws' half width)";
    EXPECT_LT(vol / PI, 6.0);
    // The stage: no outlet reachable.
    Bundle in;
    in.meta.case_id = "pinched";
    in.surfaces["lumen"] = lumen;
    write_bundle((d.p / "pinched.h5").string(), in);
    FlowParams p;
    p.domain = "voxel";
    p.inlet_end = lumen.loop_end_id[0];
    try {
        flow_file((d.p / "pinched.h5").string(), (d.p / "flow.h5").string(), p, record(), null_reporter());
        ADD_FAILURE() << "a vessel pinched shut was solved";
    } catch (const InputError& e) {
        ADD_FAILURE() << "not the input's fault: " << e.what();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("no outlet is reachable"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(d.p / "flow.h5"));
}

// The same tube pinched across half its width (jaws over z < 0): blood passes, only where the lumen stays open.
// Checked against the geometry, the analytic cross-section at the pinch (winding number of the pinched circle):
// beyond a grid spacing from the walls the reachable field is positive exactly where the section is open (< 3 %
// of the open area missed, none where the walls crossed); no fluid cell centre where the walls crossed (beyond
// half a cell of a wall); the flow passes with ≤ 0.5 % mass imbalance.
TEST(Flow, BloodPassesAHalfPinchedTubeOnlyWhereItStaysOpen) {
    const TempDir d;
    Pinch pinch;
    pinch.z_edge = 0.0;
    const SurfaceData lumen = pinched_lumen(d, pinch);
    const double R = 1.0;
    const std::vector<Eigen::Vector2d> sec = pinch.section(R);
    // The reachable field against the analytic section.
    const double g = 0.0625;
    const Volume<float> f = reachable_distance(blood_domain(lumen), Eigen::Vector3d(0.5, 0.013, 0.021), g, 100'000'000);
    // Away from the walls (beyond one grid spacing), reached must mean open.
    double open_area = 0, found_area = 0, wrong_area = 0, open_far = 0, missed_far = 0;
    const double s = 0.01;
    for (double y = -1.5; y <= 1.5; y += s)
        for (double z = -1.5; z <= 1.5; z += s) {
            const Eigen::Vector2d q(y, z);
            const bool open = winding(sec, q) == 1;
            const double fv = field_at(f, Eigen::Vector3d(pinch.xc, y, z));
            const bool found = fv > 0;
            // Far from the walls in 3-D (the field's magnitude is the distance to the surface; the walls slant
            // across the section, so the in-section distance alone overstates it) and in the section.
            const bool far = std::abs(fv) >= g && distance_to_polygon(sec, q) > g;
            open_area += open ? s * s : 0;
            found_area += found ? s * s : 0;
            if (far && found && !open) wrong_area += s * s;
            if (far && open) open_far += s * s;
            if (far && open && !found) missed_far += s * s;
        }
    std::printf("half-pinched tube: open section %.3f mm² (circle %.3f), reached %.3f mm²; beyond a grid spacing from the walls: open %.3f mm², of it "
                "not reached %.4f, reached where closed %.4f\n",
                open_area, PI, found_area, open_far, missed_far, wrong_area);
    if (std::getenv("ANEU_DEBUG_PINCH"))  // the section as characters: # reached and open, - crossed, o open not reached
        for (double z = 1.5; z >= -1.5; z -= 0.1) {
            for (double y = -1.5; y <= 1.5; y += 0.05) {
                const int w = winding(sec, Eigen::Vector2d(y, z));
                const bool found = field_at(f, Eigen::Vector3d(pinch.xc, y, z)) > 0;
                std::putchar(found ? (w == 1 ? '#' : (w == 0 ? 'O' : 'X')) : (w == 1 ? 'o' : (w == 0 ? '.' : '-')));
            }
            std::putchar('\n');
        }
    EXPECT_GT(open_area, 0.3 * PI) << "the half beside the jaws stays open";
    EXPECT_LT(open_area, 0.8 * PI) << "the half under the jaws is closed";
    EXPECT_LT(missed_far, 0.03 * open_far) << "the open part is reached";
    EXPECT_EQ(wrong_area, 0.0) << "no blood where the walls crossed";
    EXPECT_NEAR(found_area, open_area, 0.15 * open_area) << "the wedges narrower than a grid spacing where the walls converge are closed";
    // The flow.
    Bundle in;
    in.meta.case_id = "half_pinched";
    in.surfaces["lumen"] = lumen;
    write_bundle((d.p / "half.h5").string(), in);
    FlowParams p;
    p.domain = "voxel";
    p.inflow_cm_s = 5.0;
    p.case_dir = (d.p / "case").string();
    flow_file((d.p / "half.h5").string(), (d.p / "flow.h5").string(), p, record(), null_reporter());
    const Bundle b = read_bundle((d.p / "flow.h5").string());
    EXPECT_EQ(qa_of(b, "ends_closed_off"), 0.0);
    EXPECT_EQ(qa_of(b, "converged"), 1.0);
    EXPECT_LE(qa_of(b, "mass_imbalance"), 0.005);
    // The reachable volume: less than the unpinched tube's (the capped surface's signed volume counts the crossed
    // part negative, so it is no bound).
    EXPECT_LT(qa_of(b, "domain_volume_mm3"), 0.97 * PI * R * R * 12.0);
    // Cell centres at the pinch, from the case's last time folder.
    std::string last;
    double lt = -1;
    for (const auto& e : fs::directory_iterator(d.p / "case")) {
        char* end = nullptr;
        const std::string name = e.path().filename().string();
        const double t = std::strtod(name.c_str(), &end);
        if (e.is_directory() && end != name.c_str() && *end == '\0' && t > lt) {
            lt = t;
            last = name;
        }
    }
    std::ifstream cf(d.p / "case" / last / "C");
    ASSERT_TRUE(cf.good());
    std::stringstream ss;
    ss << cf.rdbuf();
    const std::string t = ss.str();
    size_t q = t.find('(', t.find("List<vector>"));
    const double h = qa_of(b, "cell_mm");
    int at_pinch = 0, in_closed = 0;
    const char* c = t.c_str() + q + 1;
    for (long i = 0, n = std::strtol(t.c_str() + t.find("List<vector>") + 12, nullptr, 10); i < n; ++i) {
        double x[3];
        for (double& xi : x) {
            while (*c == '(' || *c == ')' || std::isspace(static_cast<unsigned char>(*c))) ++c;
            char* e = nullptr;
            xi = std::strtod(c, &e) * 1e3;
            c = e;
        }
        if (std::abs(x[0] - pinch.xc) > 0.5 * h) continue;
        ++at_pinch;
        const Eigen::Vector2d p2(x[1], x[2]);
        if (winding(sec, p2) != 1 && distance_to_polygon(sec, p2) > 0.5 * h) ++in_closed;
    }
    std::printf("half-pinched tube: %d cell centres at the pinch, %d where the walls crossed; %g cells\n", at_pinch, in_closed, qa_of(b, "cells"));
    EXPECT_GT(at_pinch, 20);
    EXPECT_EQ(in_closed, 0);
}

// The lumen follows the wall of a simulator frame. A tube wall (10-node tets, no end held) whose outer surface's
// corner nodes (as the simulator's surface) are given a rigid motion u = A x + b (A skew: no strain, so no stress
// and free surfaces stay free) in a series file: the whole wall moves with them, so every lumen vertex (an inner
// node) must move by A x + b; a wrong node map or a missed frame shows. A series without node ids, a frame
// beyond its last and a surface file in place of the case bundle are the input's fault.
TEST(Flow, TheLumenFollowsTheWallOfASeriesFrame) {
    const TempDir d;
    const fem::StructuredMesh m = fem::tube_mesh(1.0, 1.3, 6.0, 2, 24, 10);
    const fem::QuadraticMesh q = fem::quadratic_mesh(m.V, m.T);
    Bundle b;
    b.meta.case_id = "tube";
    VolumeData vol;
    vol.nodes = q.V;
    vol.tets = q.T;
    vol.tet_region = Eigen::VectorXi::Zero(q.T.rows());
    vol.region_names = {"artery"};
    b.volume = vol;
    FemData fem;
    fem.element_order = 2;
    fem.materials = {{"artery", 1.0, 0.45}};
    fem.K = fem::assemble_stiffness(q.V, q.T, vol.tet_region, fem.materials);
    fem.K_upper_only = false;
    b.fem = fem;
    // The lumen: the inner boundary faces' corners (the corner nodes keep their numbers in the quadratic mesh).
    const Eigen::MatrixXi faces = fem::boundary_faces_in_set(m.V, m.T, m.inner);
    SurfaceData lumen;
    std::map<int, int> local;
    std::vector<int> nodes;
    lumen.F.resize(faces.rows(), 3);
    for (Eigen::Index f = 0; f < faces.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            const auto [it, fresh] = local.emplace(faces(f, k), static_cast<int>(nodes.size()));
            if (fresh) nodes.push_back(faces(f, k));
            lumen.F(f, k) = it->second;
        }
    lumen.V.resize(static_cast<Eigen::Index>(nodes.size()), 3);
    for (size_t i = 0; i < nodes.size(); ++i) lumen.V.row(static_cast<Eigen::Index>(i)) = m.V.row(nodes[i]);
    lumen.face_label = Eigen::VectorXi::Zero(lumen.F.rows());
    lumen.label_names = {"artery"};
    b.surfaces["lumen"] = lumen;
    Eigen::Matrix3d A;  // skew: an infinitesimal rotation, no strain
    A << 0.0, -0.02, 0.01, 0.02, 0.0, -0.03, -0.01, 0.03, 0.0;
    const Eigen::Vector3d t(0.1, -0.05, 0.2);
    auto write_series = [&](const fs::path& path, bool with_nodes) {
        H5::H5File h(path.string(), H5F_ACC_TRUNC);
        std::vector<int> nn(m.outer.data(), m.outer.data() + m.outer.size());
        const hsize_t n1[1] = {nn.size()};
        if (with_nodes) h.createDataSet("node", H5::PredType::NATIVE_INT, H5::DataSpace(1, n1)).write(nn.data(), H5::PredType::NATIVE_INT);
        h.createGroup("steps");
        for (int k = 0; k < 2; ++k) {
            H5::Group g = h.createGroup("steps/" + std::to_string(k));
            std::vector<float> u;
            for (int v : nn) {
                const Eigen::Vector3d uv = k * (A * m.V.row(v).transpose() + t);
                for (int a = 0; a < 3; ++a) u.push_back(static_cast<float>(uv[a]));
            }
            const hsize_t n2[2] = {nn.size(), 3};
            g.createDataSet("displacement", H5::PredType::NATIVE_FLOAT, H5::DataSpace(2, n2)).write(u.data(), H5::PredType::NATIVE_FLOAT);
        }
    };
    write_series(d.p / "series.h5", true);
    int used = -2;
    const SurfaceData moved = deformed_lumen(b, lumen, (d.p / "series.h5").string(), -1, null_reporter(), &used);
    EXPECT_EQ(used, 1) << "-1 is the last frame";
    double worst = 0;
    for (Eigen::Index v = 0; v < lumen.V.rows(); ++v) {
        const Eigen::Vector3d x = lumen.V.row(v).transpose();
        worst = std::max(worst, (moved.V.row(v).transpose() - (x + A * x + t)).norm());
    }
    std::printf("series frame: largest error of the lumen's displacement %.2e mm (displacements ~0.2 mm)\n", worst);
    EXPECT_LT(worst, 1e-5);
    const SurfaceData still = deformed_lumen(b, lumen, (d.p / "series.h5").string(), 0, null_reporter());
    EXPECT_LT((still.V - lumen.V).cwiseAbs().maxCoeff(), 1e-9) << "frame 0 is at rest";
    EXPECT_THROW(deformed_lumen(b, lumen, (d.p / "series.h5").string(), 2, null_reporter()), InputError);
    write_series(d.p / "old.h5", false);
    EXPECT_THROW(deformed_lumen(b, lumen, (d.p / "old.h5").string(), -1, null_reporter()), InputError);
    Bundle surface_only;
    surface_only.surfaces["lumen"] = lumen;
    EXPECT_THROW(deformed_lumen(surface_only, lumen, (d.p / "series.h5").string(), -1, null_reporter()), InputError);
}

namespace {

/// Fully developed Carreau–Yasuda flow in a tube of radius R [m] under a pressure gradient G [Pa/m]:
/// the shear stress G r / 2 = μ(γ̇) γ̇ gives γ̇(r) (monotone: bisection), Q = π ∫ γ̇ r² dr.
double carreau_yasuda_tube_flow(double G, double R) {
    const int n = 2000;
    double Q = 0;
    for (int i = 0; i < n; ++i) {
        const double r = (i + 0.5) * R / n, tau = G * r / 2;
        double lo = 0, hi = tau / CY_MUINF_PA_S;
        for (int k = 0; k < 100; ++k) {
            const double mid = 0.5 * (lo + hi);
            (carreau_yasuda_pa_s(mid) * mid < tau ? lo : hi) = mid;
        }
        Q += PI * 0.5 * (lo + hi) * r * r * (R / n);
    }
    return Q;
}

}  // namespace

// Carreau–Yasuda blood in a straight tube at a low flow (wall shear rate about 20/s, where blood's viscosity is
// twice its high-shear value and 45× at the axis): the pressure gradient within 3 % of the fully developed
// non-Newtonian solution for the same flow, the wall shear stress within 5 % of G R / 2 (force balance), and both
// clearly apart from the Newtonian values (so the model is really in use).
TEST(Flow, CarreauYasudaBloodInAStraightTube) {
    const TempDir d;
    const fs::path in = tube_lumen(d, 2.0, 40.0);
    FlowParams p;
    p.inflow_cm_s = 1.0;
    p.viscosity = "carreau-yasuda";
    flow_file(in.string(), (d.p / "flow.h5").string(), p, record(), null_reporter());
    const Bundle b = read_bundle((d.p / "flow.h5").string());
    EXPECT_EQ(qa_of(b, "converged"), 1.0);
    EXPECT_LE(qa_of(b, "mass_imbalance"), 0.005);
    const TubeFigures t = tube_figures(b);
    double lo = 0, hi = 1e5;  // the analytic G for the measured Q
    for (int k = 0; k < 100; ++k) {
        const double mid = 0.5 * (lo + hi);
        (carreau_yasuda_tube_flow(mid, t.R) < t.Q ? lo : hi) = mid;
    }
    const double G = 0.5 * (lo + hi), newtonian = 8 * BLOOD_VISCOSITY_PA_S * t.Q / (PI * std::pow(t.R, 4));
    std::printf("Carreau-Yasuda tube: dp/dx %.4f Pa/m (1-D solution %.4f, %+.2f %%; Newtonian %.4f), WSS %.5f Pa (G R/2 %.5f, %+.2f %%)\n", t.dpdx, G,
                100 * (t.dpdx / G - 1), newtonian, t.wss, G * t.R / 2, 100 * (t.wss / (G * t.R / 2) - 1));
    EXPECT_NEAR(t.dpdx, G, 0.03 * G);
    EXPECT_NEAR(t.wss, G * t.R / 2, 0.05 * G * t.R / 2);
    EXPECT_GT(G, 1.5 * newtonian) << "shear-thinning blood at low shear is more viscous than the Newtonian 3.5 mPa·s";
}

// Murray's law at a T-junction: a parent (radius 1.5 mm, along z) branching into two daughters along ±x (radii 1.25
// and 0.95 mm). With --outlets murray the daughters' flows are in the ratio of their radii cubed (r from each
// outlet's area) within 2 %, their sum the inflow; with every outlet at p = 0 the split follows the branches'
// resistances instead (a different ratio), so the test fails if the condition is not applied.
TEST(Flow, MurraysLawSplitsTheFlowAtAJunction) {
    const TempDir d;
    const double R0 = 1.5, R1 = 1.25, R2 = 0.95, hs = 0.1;
    Volume<float> v;
    v.grid.size = {161, 41, 101};
    v.grid.spacing = {hs, hs, hs};
    v.grid.origin = {-8.0, -2.0, -8.0};
    v.data.resize(v.grid.voxel_count());
    for (std::int64_t k = 0; k < v.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < v.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < v.grid.size[0]; ++i) {
                const Eigen::Vector3d x(-8.0 + hs * i, -2.0 + hs * j, -8.0 + hs * k);
                const double parent = R0 - (x.z() <= 0 ? std::hypot(x.x(), x.y()) : x.norm());
                const double daughter = (x.x() > 0 ? R1 : R2) - std::hypot(x.y(), x.z());
                v.data[v.grid.linear(i, j, k)] = static_cast<float>(std::max(parent, daughter));
            }
    write_mesh_file((d.p / "t.stl").string(), isosurface(v, 0.0, true, true));
    const LumenResult r = lumen_from_mesh((d.p / "t.stl").string(), SurfaceParams{});
    ASSERT_EQ(r.lumen.loop_end_id.size(), 3);
    Bundle in;
    in.meta.case_id = "junction";
    in.image = r.image;
    in.surfaces["lumen"] = r.lumen;
    write_bundle((d.p / "surface.h5").string(), in);
    auto split = [&](const std::string& outlets, double* ratio_murray) {
        FlowParams p;
        p.inflow_cm_s = 10.0;
        p.outlets = outlets;
        flow_file((d.p / "surface.h5").string(), (d.p / ("flow_" + outlets + ".h5")).string(), p, record(), null_reporter());
        const Bundle b = read_bundle((d.p / ("flow_" + outlets + ".h5")).string());
        EXPECT_LE(qa_of(b, "mass_imbalance"), 0.005);
        const int inlet = static_cast<int>(qa_of(b, "inlet_end"));
        std::vector<std::pair<double, double>> out;  // (area, flow) of the outlets
        for (int id : {0, 1, 2}) {
            if (id == inlet) continue;
            out.emplace_back(qa_of(b, "area_mm2_end_" + std::to_string(id)), qa_of(b, "flow_ml_s_end_" + std::to_string(id)));
        }
        std::sort(out.begin(), out.end());
        *ratio_murray = std::pow(out[1].first / out[0].first, 1.5);
        std::printf("junction, outlets %s: flows %.4f and %.4f mL/s (ratio %.3f; Murray %.3f), inflow %.4f\n", outlets.c_str(), out[1].second,
                    out[0].second, out[1].second / out[0].second, *ratio_murray, qa_of(b, "inflow_ml_s"));
        return out[1].second / out[0].second;
    };
    double murray = 0;
    const double with_murray = split("murray", &murray);
    EXPECT_NEAR(with_murray, murray, 0.02 * murray);
    const double with_zero = split("zero-pressure", &murray);
    EXPECT_GT(std::abs(with_zero / murray - 1), 0.04) << "zero pressure at both outlets splits by resistance, not by Murray (measured 5.6 % apart)";
    // Cells of 0.7 mm: the 0.95 mm daughter is narrower than three cells across, so it is closed as wall (with a
    // warning) and all the blood leaves through the other.
    FlowParams coarse;
    coarse.inflow_cm_s = 10.0;
    coarse.cell_mm = 0.7;
    flow_file((d.p / "surface.h5").string(), (d.p / "flow_coarse.h5").string(), coarse, record(), null_reporter());
    const Bundle c = read_bundle((d.p / "flow_coarse.h5").string());
    EXPECT_EQ(qa_of(c, "ends_closed_as_wall"), 1.0);
    ASSERT_EQ(c.surfaces.at("blood").label_names.size(), 3u) << "wall, the inlet and one outlet";
    double out = 0;
    for (const auto& [k, v] : c.meta.stages.back().qa)
        if (k.rfind("flow_ml_s_end_", 0) == 0 && v > 0) out += v;
    EXPECT_NEAR(out, qa_of(c, "inflow_ml_s"), 0.005 * out) << "everything leaves through the wide daughter";
}
