// SPDX-License-Identifier: MIT
// A clip that closes by its spring (issue #15, items 2–4): a hinged straight clip (fem::ClipBody) is held open
// across the vessel, then released; its blades close until the tissue's moment balances the spring's torque.
// The equilibrium is solved with the neo-Hookean reference (the whole model), the nonlinear patch on the exact
// linear exterior (fem::PatchModel) and the linear model (fem::LinearBody on K), each in the same contact problem
// (blades, and with --wall-contact the lumen's opposite inner walls). Figures: where each model's clip stops
// (opening), the blade force, the clip-region displacement against the reference, and the inner walls' gap.
//
// Presets for the study's tube with a sidewall sac (bench/run_study.sh; tube along z, sac on +x):
//   --case artery: the clip across the parent artery at z = 2 mm, hinge `--hinge-back-mm` (0.5) outside the wall
//                  at −x, blades along +x, opening along y;
//   --case sac:    the clip across the sac's neck, blades along +z just outside the parent's wall (x = outer radius
//                  + 0.6 mm), hinge `--hinge-back-mm` before the sac, opening along y.
// Usage: aneu_bench_clip_spring FEM.h5 --case artery|sac [--length-mm 7] [--width-mm 1] [--label-force-n 1.5]
//        [--open-force-n 2.5] [--max-opening-deg 40] [--patch-mm 0] [--wall-contact] [--no-reference] [--no-linear]
//        [--region-mm 3] [--hinge-back-mm 0.5] [--max-newton 400 per step] [--step-deg 1] [--trace]
// Spring: label force (ISO 9713: at 1 mm opening, a third of the blade from its tip) and the force at the same
// point at the maximum opening; placeholders until a clip's published figures are available (configs/clips).
// Output: one JSON line per model, then a summary line.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/patch.hpp"
#include "aneu/fem/static_solve.hpp"
#include "bench_util.hpp"

using namespace aneu;

namespace {

struct Outcome {
    std::string model;
    bool ok = false;
    std::string failure;
    Eigen::VectorXd u;  // whole model, 3#N
    double theta = 0, force = 0, torque = 0, moment = 0, min_J = 1, seconds = 0, setup_s = 0, wall_gap = -1;
    int contacts = 0, iterations = 0, wall_pairs = 0, dofs = 0, steps = 0;
};

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s FEM.h5 --case artery|sac [options]\n", argv[0]);
        return 2;
    }
    std::string which;
    double length = 7, width = 1, label_n = 1.5, open_n = 2.5, max_open_deg = 40, patch_mm = 0, region = 3, back = 0.5;
    int max_newton = 400;
    double step_deg = 1.0;
    bool trace = false;
    bool reference = true, linear = true, wall_contact = false;
    for (int a = 2; a < argc; ++a) {
        const std::string k = argv[a];
        if (k == "--wall-contact") { wall_contact = true; continue; }
        if (k == "--no-reference") { reference = false; continue; }
        if (k == "--no-linear") { linear = false; continue; }
        if (k == "--trace") { trace = true; continue; }
        if (a + 1 >= argc) {
            std::fprintf(stderr, "option %s needs a value\n", k.c_str());
            return 2;
        }
        const char* v = argv[++a];
        if (k == "--case") which = v;
        else if (k == "--length-mm") length = std::atof(v);
        else if (k == "--width-mm") width = std::atof(v);
        else if (k == "--label-force-n") label_n = std::atof(v);
        else if (k == "--open-force-n") open_n = std::atof(v);
        else if (k == "--max-opening-deg") max_open_deg = std::atof(v);
        else if (k == "--patch-mm") patch_mm = std::atof(v);
        else if (k == "--region-mm") region = std::atof(v);
        else if (k == "--hinge-back-mm") back = std::atof(v);
        else if (k == "--max-newton") max_newton = std::atoi(v);
        else if (k == "--step-deg") step_deg = std::atof(v);
        else {
            std::fprintf(stderr, "unknown option %s\n", k.c_str());
            return 2;
        }
    }
    if (which != "artery" && which != "sac") {
        std::fprintf(stderr, "--case must be artery or sac\n");
        return 2;
    }
    const Bundle b = bench::read_model(argv[1]);
    const VolumeData& vol = *b.volume;
    const FemData& fem = *b.fem;
    const Eigen::MatrixX3d& X = vol.nodes;
    const Eigen::VectorXi& outer = vol.node_sets.at("outer");

    // The tube's outer radius (near its ends) and extent.
    const double rout = bench::tube_extent(X, outer).outer_radius;
    fem::ClipBlades blades;
    blades.length_mm = length;
    blades.width_mm = width;
    Eigen::Vector3d centre;  // the clip region's centre (displacement errors are taken around it)
    if (which == "artery") {
        blades.axis = Eigen::Vector3d::UnitX();
        blades.up = Eigen::Vector3d::UnitY();
        blades.hinge = Eigen::Vector3d(-rout - back, 0, 2.0);
        centre = Eigen::Vector3d(0, 0, 2.0);
    } else {
        // Where the sac leaves the parent: its extent along z at x just outside the parent's outer wall.
        const double xc = rout + 0.6;
        double s0 = 1e300, s1 = -1e300;
        for (Eigen::Index k = 0; k < outer.size(); ++k) {
            const Eigen::Vector3d p = X.row(outer[k]);
            if (std::abs(p.x() - xc) < 0.5 * width) {
                s0 = std::min(s0, p.z());
                s1 = std::max(s1, p.z());
            }
        }
        if (!(s1 > s0)) {
            std::fprintf(stderr, "%s: no sac wall at x = %.2f mm\n", argv[1], xc);
            return 2;
        }
        blades.axis = Eigen::Vector3d::UnitZ();
        blades.up = Eigen::Vector3d::UnitY();
        blades.hinge = Eigen::Vector3d(xc, 0, s0 - back);
        centre = Eigen::Vector3d(xc, 0, 0.5 * (s0 + s1));
        if (s1 - s0 + 1.0 > length) std::fprintf(stderr, "warning: the sac spans %.2f mm, the blades %.2f mm\n", s1 - s0, length);
    }
    const Eigen::Vector3d wdir = blades.axis.cross(blades.up);
    // Nodes that can touch the blades: the outer surface within the blades' sweep (and 0.5 mm around it).
    std::vector<int> swept;
    double phi_open = 0;  // the half-opening at which every swept node is between the blades
    for (Eigen::Index k = 0; k < outer.size(); ++k) {
        const Eigen::Vector3d rel = X.row(outer[k]).transpose() - blades.hinge;
        const double r = rel.dot(blades.axis), y = rel.dot(blades.up), w = rel.dot(wdir);
        if (r < -0.5 || r > length + 0.5 || std::abs(w) > 0.5 * width + 0.5) continue;
        swept.push_back(static_cast<int>(outer[k]));
        if (r > 0.5 && r <= length && std::abs(w) <= 0.5 * width) phi_open = std::max(phi_open, std::atan2(std::abs(y) + 0.05, r));
    }
    const double theta_open = 2 * phi_open;
    if (theta_open / DEG > max_open_deg) std::fprintf(stderr, "warning: the clip needs %.1f deg to pass the vessel, more than its %.0f\n", theta_open / DEG, max_open_deg);
    const double r_label = 2.0 * length / 3.0;
    const fem::ClipSpring spring = fem::ClipSpring::from_forces(r_label, fem::opening_angle(r_label, 1.0, 0.0), label_n, max_open_deg * DEG, open_n);
    std::fprintf(stderr, "clip: %g mm blades, hinge (%.2f, %.2f, %.2f), open %.1f deg, spring k %.3f N mm/rad, preload %.3f rad; %zu swept nodes\n",
                 length, blades.hinge.x(), blades.hinge.y(), blades.hinge.z(), theta_open / DEG, spring.k_nmm_per_rad, spring.preload_rad, swept.size());

    std::vector<int> probe;
    for (Eigen::Index k = 0; k < outer.size(); ++k)
        if ((X.row(outer[k]).transpose() - centre).norm() <= region) probe.push_back(outer[k]);
    // The inner wall's faces near the clip (within 1.5 mm of the blades' sweep), for wall-on-wall contact.
    Eigen::MatrixX3i inner_faces;
    {
        const Eigen::MatrixX3i all = fem::boundary_faces_in_set(X, vol.tets, vol.node_sets.at("inner")).leftCols(3);
        std::vector<Eigen::Index> keep;
        for (Eigen::Index f = 0; f < all.rows(); ++f) {
            const Eigen::Vector3d rel = (X.row(all(f, 0)) + X.row(all(f, 1)) + X.row(all(f, 2))).transpose() / 3.0 - blades.hinge;
            const double r = rel.dot(blades.axis), w = rel.dot(wdir);
            if (r >= -1.5 && r <= length + 1.5 && std::abs(w) <= 0.5 * width + 1.5) keep.push_back(f);
        }
        inner_faces.resize(static_cast<Eigen::Index>(keep.size()), 3);
        for (size_t k = 0; k < keep.size(); ++k) inner_faces.row(static_cast<Eigen::Index>(k)) = all.row(keep[k]);
        if (wall_contact) std::fprintf(stderr, "wall contact: %lld inner faces near the clip\n", static_cast<long long>(inner_faces.rows()));
    }
    fem::ContactParams wc;
    wc.search_mm = 1.0;
    fem::NewtonOptions no;
    no.max_total_iterations = max_newton;  // per step
    // Penalty contact's active set flickers at the gap: 1e-7 of the internal force (far below the figures' 1 %)
    // instead of the smooth problems' 1e-9.
    no.tolerance = 1e-7;


    // One model: the body, its nodes' reference positions, the candidates and inner faces in its numbering.
    auto run = [&](const std::string& name, const fem::ElasticBody& body, const Eigen::MatrixX3d& Xb, const std::vector<int>& cand,
                   const Eigen::MatrixX3i& faces, const Eigen::VectorXi& fixed, const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& full) {
        Outcome o;
        o.model = name;
        o.dofs = static_cast<int>(body.dofs());
        const Stopwatch sw;
        try {
            // The forceps closes the clip in steps of `step_deg` (θ prescribed: the solve's reaction on θ is the torque
            // the forceps holds, τ(θ) − the tissue's moment), each a Newton solve from the last with the contact pairs
            // found again from its start. Once the tissue's moment exceeds the spring's, the equilibrium is within
            // the last step: the clip is released there (θ free) and closes or opens to it. If the spring still wins
            // at θ = 0 the blades meet (the closed stop).
            Eigen::VectorXd v = Eigen::VectorXd::Zero(body.dofs() + 1);
            const auto th = body.dofs();
            v[th] = theta_open;
            fem::NewtonResult r;
            fem::BladeLoads L;
            auto solve_at = [&](const std::optional<double>& theta) {
                std::unique_ptr<fem::ContactBody> walls;
                if (wall_contact && faces.rows() > 0) walls = std::make_unique<fem::ContactBody>(body, Xb, faces, v.head(th), wc);
                const fem::ElasticBody& inner = walls ? static_cast<const fem::ElasticBody&>(*walls) : body;
                const fem::ClipBody clip(inner, Xb, cand, v, blades, spring);
                std::vector<std::pair<int, double>> pres;
                if (theta) pres.emplace_back(static_cast<int>(th), *theta);
                r = fem::solve_neo_hookean(clip, fixed, pres, v, no);
                v = r.u;
                o.iterations += r.iterations;
                L = clip.loads(v);
                if (walls) {
                    o.wall_pairs = static_cast<int>(walls->active(v.head(th)));
                    const double g = walls->min_distance(v.head(th));
                    o.wall_gap = std::isfinite(g) ? g : -1.0;
                }
                return theta ? r.reaction[0] : 0.0;
            };
            int steps = 0;
            for (double theta = theta_open;;) {
                const double next = std::max(0.0, theta - step_deg * DEG);
                const double held = solve_at(next);
                ++steps;
                if (trace)
                    std::fprintf(stderr, "%s: %.2f deg: forceps holds %.4f N mm, blade force %.4f N, wall pairs %d (gap %.4f mm), %d it, %.1f s\n", name.c_str(),
                                 next / DEG, held, 0.5 * (L.force_n[0] + L.force_n[1]), o.wall_pairs, o.wall_gap, r.iterations, sw.seconds());
                if (held <= 0 || next == 0) break;  // the tissue holds the clip open, or the blades meet
                theta = next;
            }
            solve_at(std::nullopt);  // released
            o.steps = steps;
            if (trace)
                std::fprintf(stderr, "%s: released: %.3f deg, blade force %.4f N, %d it, %.1f s\n", name.c_str(), v[th] / DEG,
                             0.5 * (L.force_n[0] + L.force_n[1]), r.iterations, sw.seconds());
            o.theta = v[body.dofs()];
            o.force = 0.5 * (L.force_n[0] + L.force_n[1]);
            o.moment = 0.5 * (L.moment_nmm[0] + L.moment_nmm[1]);
            o.torque = L.spring_torque_nmm;
            o.contacts = L.contacts[0] + L.contacts[1];
            o.min_J = r.min_J;
            o.u = full(v.head(body.dofs()));
            o.ok = true;
        } catch (const Error& e) {
            o.failure = e.what();
        }
        o.seconds = sw.seconds();
        return o;
    };
    auto identity = [](const Eigen::VectorXd& u) { return u; };
    std::vector<Outcome> out;
    const Stopwatch ts;
    const fem::NeoHookeanSolid solid(vol.nodes, vol.tets, vol.tet_region, fem.materials);
    const double solid_s = ts.seconds();
    if (reference) {
        out.push_back(run("neo-Hookean", solid, X, swept, inner_faces, fem.fixed_dofs, identity));
        out.back().setup_s = solid_s;
    }
    if (patch_mm > 0) {
        std::vector<int> tets;
        for (Eigen::Index t = 0; t < vol.tets.rows(); ++t) {
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int k = 0; k < 4; ++k) c += X.row(vol.tets(t, k)).transpose() / 4.0;
            const Eigen::Vector3d rel = c - blades.hinge;
            const double r = rel.dot(blades.axis), w = rel.dot(wdir);
            if (r >= -patch_mm && r <= length + patch_mm && std::abs(w) <= 0.5 * width + patch_mm) tets.push_back(static_cast<int>(t));
        }
        const fem::PatchModel patch(vol, fem, tets);
        Eigen::MatrixX3d PX(static_cast<Eigen::Index>(patch.nodes().size()), 3);
        for (size_t a = 0; a < patch.nodes().size(); ++a) PX.row(static_cast<Eigen::Index>(a)) = X.row(patch.nodes()[a]);
        std::vector<int> pc;
        int outside = 0;
        for (int v : swept) {
            const int a = patch.local(v);
            if (a >= 0) pc.push_back(a);
            else ++outside;
        }
        std::vector<Eigen::Vector3i> pf;
        for (Eigen::Index f = 0; f < inner_faces.rows(); ++f) {
            const Eigen::Vector3i l(patch.local(inner_faces(f, 0)), patch.local(inner_faces(f, 1)), patch.local(inner_faces(f, 2)));
            if (l.minCoeff() >= 0) pf.push_back(l);
        }
        Eigen::MatrixX3i PF(static_cast<Eigen::Index>(pf.size()), 3);
        for (size_t f = 0; f < pf.size(); ++f) PF.row(static_cast<Eigen::Index>(f)) = pf[f].transpose();
        std::fprintf(stderr, "patch %.1f mm: %zu tetrahedra, %zu nodes, %lld on the interface, %d swept nodes outside it, made in %.2f s\n", patch_mm,
                     tets.size(), patch.nodes().size(), static_cast<long long>(patch.interface_nodes()), outside, patch.setup_seconds());
        out.push_back(run("patch", patch, PX, pc, PF, patch.fixed_dofs(), [&](const Eigen::VectorXd& u) { return patch.full_displacement(u); }));
        out.back().setup_s = patch.setup_seconds();
    }
    if (linear) {
        const fem::LinearBody lin(fem.K, fem.K_upper_only);
        out.push_back(run("linear", lin, X, swept, Eigen::MatrixX3i(0, 3), fem.fixed_dofs, identity));  // no wall contact: the linear model's own
    }
    const Outcome* ref = nullptr;
    for (const auto& o : out)
        if (o.model == "neo-Hookean" && o.ok) ref = &o;
    nlohmann::json summary = {{"summary", true}, {"case", which}, {"model", argv[1]}, {"nodes", X.rows()}, {"element_order", fem.element_order},
                              {"blade_length_mm", length}, {"blade_width_mm", width}, {"open_deg", theta_open / DEG},
                              {"label_force_n", label_n}, {"open_force_n", open_n}, {"max_opening_deg", max_open_deg},
                              {"spring_k_nmm_per_rad", spring.k_nmm_per_rad}, {"spring_preload_rad", spring.preload_rad},
                              {"wall_contact", wall_contact}, {"step_deg", step_deg}, {"patch_mm", patch_mm}, {"probe_nodes", probe.size()}};
    for (const auto& o : out) {
        nlohmann::json j = {{"model", o.model}, {"ok", o.ok}, {"dofs", o.dofs}, {"seconds", o.seconds}, {"setup_s", o.setup_s}};
        if (!o.ok) {
            j["failure"] = o.failure;
        } else {
            j["opening_deg"] = o.theta / DEG;
            j["blade_force_n"] = o.force;
            j["spring_torque_nmm"] = o.torque;
            j["blade_moment_nmm"] = o.moment;
            j["label_point_force_n"] = o.torque / r_label;
            j["contacts"] = o.contacts;
            j["newton_iterations"] = o.iterations;
            j["closing_steps"] = o.steps;
            j["min_J"] = o.min_J;
            if (wall_contact && o.model != "linear") {
                j["wall_pairs"] = o.wall_pairs;
                j["wall_gap_mm"] = o.wall_gap;
            }
            double umax = 0;
            for (int v : probe) umax = std::max(umax, o.u.segment<3>(3 * v).norm());
            j["u_max_mm"] = umax;
            if (ref && &o != ref) {
                double num = 0, den = 0;
                for (int v : probe) {
                    num += (o.u.segment<3>(3 * v) - ref->u.segment<3>(3 * v)).squaredNorm();
                    den += ref->u.segment<3>(3 * v).squaredNorm();
                }
                j["force_error"] = std::abs(o.force - ref->force) / std::abs(ref->force);
                j["u_error"] = std::sqrt(num / den);
                j["opening_error_deg"] = (o.theta - ref->theta) / DEG;
            }
        }
        std::printf("%s\n", j.dump().c_str());
        std::fflush(stdout);
    }
    std::printf("%s\n", summary.dump().c_str());
    return 0;
}
