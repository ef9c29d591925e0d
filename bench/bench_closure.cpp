// SPDX-License-Identifier: MIT
// Linear vs large deformation (issue #6, study part 2): a clip closing on the sac, from touching to full closure,
// solved with the linear model the simulator uses (K of /fem) and with the neo-Hookean reference (same mesh,
// elements, quadrature and materials; fem::solve_neo_hookean), and the linear model's error as a function of
// closure.
//
// The clip: two flat blades, `--blade-width-mm` wide (along x, away from the parent artery) and `--blade-length-mm`
// long (along z, the parent artery's axis), centred on `--centre` and closing symmetrically along y. Closure c runs
// from 0 (blades touch the sac: gap = the outer width of the model between the blades) to 1 (gap = `--full-gap-mm`,
// twice the sac wall: the lumen is closed). Contact is the simulator's: an outer node whose deformed position lies
// beyond a blade face within the blade's extent is prescribed onto the face and sticks there tangentially (its x,
// z where it entered); a node the blade pulls on (adhesive reaction) is released. Each model gets its own active
// set, found by iterating solve → detect → solve at every closure step.
//
// Errors, per closure: clip force (the y force one blade applies, mean of both) |F_lin − F_nl| / |F_nl|, and the
// clip-region displacement (outer nodes within `--region-mm` of the centre) ‖u_lin − u_nl‖ / ‖u_nl‖ (RMS over the
// nodes). Output: one JSON line per closure on stdout, a summary line last.
//
// With --patch-mm m > 0 a third model runs beside them (issue #15, item 2): the nonlinear patch (fem::PatchModel) —
// the tetrahedra whose centroid lies within m of the blades' footprint (|x − cx| ≤ width/2 + m, |z − cz| ≤
// length/2 + m, any y) are the neo-Hookean solid, the rest stays linear, condensed exactly onto the patch's
// interface — with its errors against the same reference.
// Usage: aneu_bench_closure FEM.h5 [--centre x,y,z] [--blade-width-mm 0.8] [--blade-length-mm 7] [--full-gap-mm 0.2]
//                           [--region-mm 3] [--closures 0.025,0.05,...] [--label sac] [--max-newton 100] [--max-seconds 900]
//                           [--patch-mm 0] [--no-reference] [--wall-contact] [--proximal] [--clip-body [--friction 0.3]]
// --wall-contact: the nonlinear models (reference and patch) also keep the lumen's opposite inner walls apart
// (fem::ContactBody on the corner nodes of the inner surface, gap 0.01 mm); the linear model cannot.
// --clip-body: the blades are the simulator's (fem::ClipBody, issue #15) for all three models instead of the
// prescribed, sticking contact above: rigid blades as a barrier with collision-bounded steps, Coulomb friction
// `--friction` (0.3, the simulator's default; grips renewed after each closure step, as the simulator renews them
// each frame, with sub-steps of at most 0.05 mm of the gap), the opening θ prescribed. To keep the blades parallel as above they hinge 100 mm behind the
// blades' proximal end (along −z; over the 7 mm the gap differs by 3.4 % of its excess over the full gap), and
// close to the full gap at θ = 0: full closure is the same parallel pair of faces. The candidates are the outer
// nodes over the blades' footprint (0.5 mm beside it and beyond the tip); the linear model is fem::LinearBody (K)
// in the same contact problem.
// --proximal: where a nonlinear model's Newton solve stops (a limit point: the sac buckles under the blades), proximal
// point iterations carry it to the equilibrium beyond (solve_through below); the steps taken are in the JSON lines.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/bundle_io.hpp"
#include "bench_util.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/patch.hpp"
#include "aneu/fem/static_solve.hpp"

using namespace aneu;

namespace {


struct Contact {
    int side = 1;        ///< +1: the blade at y = +gap/2, −1: at −gap/2
    double x = 0, z = 0; ///< where it sticks
};

struct Clip {
    Eigen::Vector3d centre;
    double width = 0.8, length = 7, gap = 0;
    bool within(const Eigen::Vector3d& p) const {
        return std::abs(p.x() - centre.x()) <= 0.5 * width && std::abs(p.z() - centre.z()) <= 0.5 * length;
    }
};

/// One model's state along the closure path.
struct Track {
    std::map<int, Contact> active;  // node -> contact
    Eigen::VectorXd u;
    double force = 0;               // mean y force of the two blades on the wall [N], > 0 squeezing
    int rounds = 0, iterations = 0, substeps = 0, shifted = 0, prox_steps = 0;
    double min_J = 1, seconds = 0;
    double wall_gap = std::numeric_limits<double>::infinity();  // smallest inner-wall distance among pairs in contact
    std::size_t wall_pairs = 0;
    double theta = -1;                    // --clip-body: the blades' opening [rad] (< 0: not yet placed)
    std::vector<fem::BladeGrip> grips;    // --clip-body: the grips of the last step (the track's own numbering)
    int blade_contacts = 0;
    double kappa_wall = 0, kappa_blade = 0;  // --clip-body: 0 until the first step computes them
};

std::vector<std::pair<int, double>> prescribed_of(const Track& t, const Eigen::MatrixX3d& X, const Clip& clip) {
    std::vector<std::pair<int, double>> p;
    p.reserve(3 * t.active.size());
    for (const auto& [v, c] : t.active) {
        p.emplace_back(3 * v, c.x - X(v, 0));
        p.emplace_back(3 * v + 1, c.side * 0.5 * clip.gap - X(v, 1));
        p.emplace_back(3 * v + 2, c.z - X(v, 2));
    }
    return p;
}

/// E(u) + β/2 |u − a|²: one step of the proximal point method. Where the static path turns (the sac buckles under
/// the blades and a displacement-controlled Newton solve finds no neighbouring equilibrium), the sequence of
/// proximal solves, each anchored at the last, walks down the energy to the equilibrium beyond; its fixed point is
/// an equilibrium of E itself (β (u − a) → 0).
class ProximalBody final : public fem::ElasticBody {
public:
    ProximalBody(const fem::ElasticBody& body, const Eigen::VectorXd& anchor, double beta) : m_body(body), m_a(anchor), m_beta(beta) {}
    Eigen::Index dofs() const override { return m_body.dofs(); }
    double energy(const Eigen::VectorXd& u) const override { return m_body.energy(u) + 0.5 * m_beta * (u - m_a).squaredNorm(); }
    Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const override { return m_body.internal_force(u) + m_beta * (u - m_a); }
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& u, bool project = false) const override {
        Eigen::SparseMatrix<double, Eigen::RowMajor> K = m_body.tangent(u, project);
        for (Eigen::Index r = 0; r < K.rows(); ++r) K.coeffRef(r, r) += m_beta;  // the diagonal is in every body's pattern
        return K;
    }
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override { return m_body.pattern(); }
    double min_jacobian(const Eigen::VectorXd& u) const override { return m_body.min_jacobian(u); }
    double max_step(const Eigen::VectorXd& u, const Eigen::VectorXd& du) const override { return m_body.max_step(u, du); }

private:
    const fem::ElasticBody& m_body;
    Eigen::VectorXd m_a;
    double m_beta;
};

/// Newton's static solve; where it stops (a limit point of the path), proximal point iterations from the last
/// state to the equilibrium beyond it, every fourth followed by a brief plain Newton attempt (15 iterations). β starts
/// at 1 % of the tangent's mean diagonal entry, grows ×10 when a proximal solve fails and shrinks ÷3 when one converges
/// quickly.
fem::NewtonResult solve_through(const fem::ElasticBody& body, const Eigen::VectorXi& fixed, const std::vector<std::pair<int, double>>& pres,
                                const Eigen::VectorXd& start, const fem::NewtonOptions& no, bool proximal, int& prox_steps) {
    try {
        return fem::solve_neo_hookean(body, fixed, pres, start, no);
    } catch (const NumericalError& e) {
        if (!proximal) throw;
        std::fprintf(stderr, "  Newton stopped (%s); proximal point iterations\n", e.what());
    }
    const Eigen::SparseMatrix<double, Eigen::RowMajor> K0 = body.tangent(start);
    double dmax = 0, dsum = 0;
    for (Eigen::Index r = 0; r < K0.rows(); ++r) {
        dmax = std::max(dmax, K0.coeff(r, r));
        dsum += K0.coeff(r, r);
    }
    double beta = 1e-2 * dsum / static_cast<double>(std::max<Eigen::Index>(1, K0.rows()));  // of the mean diagonal entry
    fem::NewtonOptions po = no;
    po.max_total_iterations = 40;
    Eigen::VectorXd a = start;
    bool any_step = false;
    int total = 0;
    for (int k = 0; k < 400; ++k) {
        fem::NewtonResult r;
        try {
            r = fem::solve_neo_hookean(ProximalBody(body, a, beta), fixed, pres, a, po);
        } catch (const NumericalError&) {
            beta *= 10;
            if (beta > 1e3 * dmax) break;
            continue;
        }
        total += r.iterations;
        ++prox_steps;
        const double move = (r.u - a).cwiseAbs().maxCoeff();
        a = r.u;
        any_step = true;
        if (r.iterations <= 5) beta /= 3;
        std::fprintf(stderr, "  proximal step %d: β %.3g N/mm, %d Newton iterations, largest move %.3g mm\n", k + 1, beta, r.iterations, move);
        if (k % 4 == 3 || move < 1e-4) {
            try {
                // Plain Newton from here, briefly: near the equilibrium beyond the limit point it converges fast.
                fem::NewtonOptions quick = no;
                quick.max_total_iterations = 15;
                fem::NewtonResult f = fem::solve_neo_hookean(body, fixed, pres, a, quick);
                std::fprintf(stderr, "  equilibrium after %d proximal steps (%d Newton iterations, last β %.3g N/mm)\n", k + 1, total, beta);
                f.iterations += total;
                return f;
            } catch (const NumericalError&) {
            }
        }
    }
    throw NumericalError(std::string("proximal point iterations did not reach an equilibrium") + (any_step ? "" : " (no proximal step converged)"));
}

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s FEM.h5 [--centre x,y,z] [--blade-width-mm 0.8] [--blade-length-mm 7] [--full-gap-mm 0.2] "
                             "[--region-mm 3] [--closures c1,c2,...]\n", argv[0]);
        return 2;
    }
    Clip clip;
    bool have_centre = false;
    double full_gap = 0.2, region = 3.0;
    int max_newton = 100;        // per contact round (a settled round takes ~10): past it the reference stops
    double max_seconds = 900;    // for the neo-Hookean solves in all: past it the reference stops at that closure
    std::vector<double> closures = {0.005, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0};
    std::string label = "sac";
    double patch_mm = 0;
    bool reference = true, wall_contact = false, proximal = false, clip_body = false;
    double friction = 0.3;
    for (int a = 2; a < argc; a += 2) {
        const std::string k = argv[a];
        if (k == "--clip-body") {
            clip_body = true;
            --a;
            continue;
        }
        if (k == "--no-reference" || k == "--wall-contact") {
            (k == "--no-reference" ? reference : wall_contact) = k == "--wall-contact";
            --a;
            continue;
        }
        if (k == "--proximal") {
            proximal = true;
            --a;
            continue;
        }
        if (a + 1 >= argc) {
            std::fprintf(stderr, "option %s needs a value\n", k.c_str());
            return 2;
        }
        const char* v = argv[a + 1];
        if (k == "--patch-mm") {
            patch_mm = std::atof(v);
        } else if (k == "--centre") {
            have_centre = std::sscanf(v, "%lf,%lf,%lf", &clip.centre.x(), &clip.centre.y(), &clip.centre.z()) == 3;
        } else if (k == "--blade-width-mm") {
            clip.width = std::atof(v);
        } else if (k == "--blade-length-mm") {
            clip.length = std::atof(v);
        } else if (k == "--full-gap-mm") {
            full_gap = std::atof(v);
        } else if (k == "--region-mm") {
            region = std::atof(v);
        } else if (k == "--max-seconds") {
            max_seconds = std::atof(v);
        } else if (k == "--friction") {
            friction = std::atof(v);
        } else if (k == "--max-newton") {
            max_newton = std::atoi(v);
        } else if (k == "--label") {
            label = v;
        } else if (k == "--closures") {
            closures.clear();
            std::stringstream ss(v);
            for (std::string s; std::getline(ss, s, ',');) closures.push_back(std::atof(s.c_str()));
        } else {
            std::fprintf(stderr, "unknown option %s\n", k.c_str());
            return 2;
        }
    }
    const Bundle b = bench::read_model(argv[1]);
    const VolumeData& vol = *b.volume;
    const FemData& fem = *b.fem;
    const Eigen::MatrixX3d& X = vol.nodes;
    const Eigen::VectorXi& outer = vol.node_sets.at("outer");
    if (!have_centre) {
        // Default: the tube-with-sac of bench/run_study.sh (tube along z, sac on +x): across the neck, 0.6 mm
        // outside the parent's outer wall, at the sac's mid-length.
        const bench::TubeExtent te = bench::tube_extent(X, outer);
        clip.centre = Eigen::Vector3d(te.outer_radius + 0.6, 0, 0.5 * (te.zmin + te.zmax));
    }
    // Outer width between the blades: the gap at closure 0.
    double half = 0;
    for (Eigen::Index k = 0; k < outer.size(); ++k) {
        const Eigen::Vector3d p = X.row(outer[k]);
        if (clip.within(p)) half = std::max(half, std::abs(p.y() - clip.centre.y()));
    }
    if (half <= 0) {
        std::fprintf(stderr, "%s: no outer node within the blades' extent\n", argv[1]);
        return 2;
    }
    // The clip closes about y = centre.y; shift coordinates so the blade faces are at ±gap/2.
    Eigen::MatrixX3d Xc = X;
    Xc.col(1).array() -= clip.centre.y();
    const double gap0 = 2 * half;

    Stopwatch t0;
    const fem::NeoHookeanSolid solid(vol.nodes, vol.tets, vol.tet_region, fem.materials);
    const double setup_s = t0.seconds();
    // The linear model's matrix is the neo-Hookean tangent at rest (same elements, quadrature, materials).
    double k_diff = 0, k_max = 0;
    {
        const auto K0 = solid.tangent(Eigen::VectorXd::Zero(solid.dofs()));
        for (Eigen::Index r = 0; r < fem.K.outerSize(); ++r)
            for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(fem.K, r); it; ++it) {
                k_diff = std::max(k_diff, std::abs(it.value() - K0.coeff(r, it.col())));
                k_max = std::max(k_max, std::abs(it.value()));
            }
    }
    std::vector<char> is_outer(static_cast<size_t>(X.rows()), 0);
    for (Eigen::Index k = 0; k < outer.size(); ++k) is_outer[static_cast<size_t>(outer[k])] = 1;
    std::vector<int> probe;  // the clip region
    for (Eigen::Index k = 0; k < outer.size(); ++k)
        if ((X.row(outer[k]).transpose() - clip.centre).norm() <= region) probe.push_back(outer[k]);

    std::unique_ptr<fem::PatchModel> patch;
    if (patch_mm > 0) {
        std::vector<int> tets;
        for (Eigen::Index t = 0; t < vol.tets.rows(); ++t) {
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int k = 0; k < 4; ++k) c += X.row(vol.tets(t, k)).transpose() / 4.0;
            if (std::abs(c.x() - clip.centre.x()) <= 0.5 * clip.width + patch_mm && std::abs(c.z() - clip.centre.z()) <= 0.5 * clip.length + patch_mm)
                tets.push_back(static_cast<int>(t));
        }
        patch = std::make_unique<fem::PatchModel>(vol, fem, tets);
        std::fprintf(stderr, "patch: %zu of %lld tetrahedra, %zu nodes, %lld on the interface, made in %.2f s\n", tets.size(),
                     static_cast<long long>(vol.tets.rows()), patch->nodes().size(), static_cast<long long>(patch->interface_nodes()),
                     patch->setup_seconds());
    }
    // The inner surface's triangles (corner nodes), for wall-on-wall contact: whole model and patch numbering.
    Eigen::MatrixX3i inner_faces, patch_faces;
    Eigen::MatrixX3d patch_X;
    if (wall_contact) {
        inner_faces = fem::boundary_faces_in_set(X, vol.tets, vol.node_sets.at("inner")).leftCols(3);
        if (patch) {
            std::vector<Eigen::Vector3i> pf;
            for (Eigen::Index f = 0; f < inner_faces.rows(); ++f) {
                const Eigen::Vector3i l(patch->local(inner_faces(f, 0)), patch->local(inner_faces(f, 1)), patch->local(inner_faces(f, 2)));
                if (l.minCoeff() >= 0) pf.push_back(l);
            }
            patch_faces.resize(static_cast<Eigen::Index>(pf.size()), 3);
            for (size_t f = 0; f < pf.size(); ++f) patch_faces.row(static_cast<Eigen::Index>(f)) = pf[f].transpose();
            patch_X.resize(static_cast<Eigen::Index>(patch->nodes().size()), 3);
            for (size_t a = 0; a < patch->nodes().size(); ++a) patch_X.row(static_cast<Eigen::Index>(a)) = X.row(patch->nodes()[a]);
        }
        std::fprintf(stderr, "wall contact: %lld inner faces (%lld in the patch)\n", static_cast<long long>(inner_faces.rows()),
                     static_cast<long long>(patch_faces.rows()));
    }
    fem::ContactParams contact;
    contact.search_mm = 1.0;  // walls approach by up to ~0.5 mm per closure step
    enum class Model { LINEAR, NONLINEAR, PATCH };
    // Solve one model at the current gap, iterating the contact set; returns false if it cannot be solved.
    auto solve = [&](Track& t, Model model) {
        const bool nonlinear = model != Model::LINEAR;
        const Stopwatch ts;
        for (int round = 0; round < 30; ++round) {
            const auto pres = prescribed_of(t, Xc, clip);
            Eigen::VectorXd reaction;
            if (model == Model::PATCH) {
                std::vector<std::pair<int, double>> lp;
                lp.reserve(pres.size());
                for (const auto& [d, v] : pres) {
                    const int a = patch->local(d / 3);
                    if (a < 0 || patch->on_interface(a)) throw NumericalError("a blade contact (node " + std::to_string(d / 3) + ") outside the patch's interior: widen --patch-mm");
                    lp.emplace_back(3 * a + d % 3, v);
                }
                fem::NewtonOptions no;
                no.max_total_iterations = max_newton;
                const Eigen::VectorXd start = patch->restrict_to_patch(t.u);
                fem::NewtonResult r;
                if (wall_contact) {
                    const fem::ContactBody body(*patch, patch_X, patch_faces, start, contact);
                    r = solve_through(body, patch->fixed_dofs(), lp, start, no, proximal, t.prox_steps);
                    t.wall_gap = body.min_distance(r.u);
                    t.wall_pairs = body.active(r.u);
                } else {
                    r = solve_through(*patch, patch->fixed_dofs(), lp, start, no, proximal, t.prox_steps);
                }
                t.u = patch->full_displacement(r.u);
                reaction = r.reaction;
                t.iterations += r.iterations;
                t.substeps += r.substeps;
                t.shifted += r.shifted;
                t.min_J = r.min_J;
            } else if (nonlinear) {
                fem::NewtonOptions no;
                no.max_total_iterations = max_newton;
                fem::NewtonResult r;
                if (wall_contact) {
                    const fem::ContactBody body(solid, X, inner_faces, t.u, contact);
                    r = solve_through(body, fem.fixed_dofs, pres, t.u, no, proximal, t.prox_steps);
                    t.wall_gap = body.min_distance(r.u);
                    t.wall_pairs = body.active(r.u);
                } else {
                    r = solve_through(solid, fem.fixed_dofs, pres, t.u, no, proximal, t.prox_steps);
                }
                t.u = r.u;
                reaction = r.reaction;
                t.iterations += r.iterations;
                t.substeps += r.substeps;
                t.shifted += r.shifted;
                t.min_J = r.min_J;
            } else {
                const fem::DirichletResult r = fem::solve_dirichlet(fem, pres);
                t.u = r.u;
                reaction = r.reaction;
            }
            ++t.rounds;
            if (nonlinear && t.seconds + ts.seconds() > max_seconds)
                throw NumericalError("time budget of " + std::to_string(static_cast<int>(max_seconds)) + " s for the neo-Hookean solves spent");
            // Release nodes the blade pulls on, then add the nodes that went through a blade.
            bool changed = false;
            std::vector<int> release;
            size_t k = 0;
            double f_top = 0, f_bottom = 0;
            for (const auto& [v, c] : t.active) {
                const double ry = reaction[static_cast<Eigen::Index>(3 * k + 1)];  // force the blade applies, along y
                if (c.side * ry > 1e-9) release.push_back(v);
                (c.side > 0 ? f_top : f_bottom) += -c.side * ry;
                ++k;
            }
            t.force = 0.5 * (f_top + f_bottom);
            for (int v : release) t.active.erase(v);
            changed = !release.empty();
            for (Eigen::Index v = 0; v < X.rows(); ++v) {
                if (!is_outer[static_cast<size_t>(v)] || t.active.count(static_cast<int>(v))) continue;
                const Eigen::Vector3d p = Xc.row(v).transpose() + t.u.segment<3>(3 * v);
                if (!clip.within(p + Eigen::Vector3d(0, clip.centre.y(), 0))) continue;
                if (std::abs(p.y()) > 0.5 * clip.gap) {
                    t.active[static_cast<int>(v)] = Contact{p.y() > 0 ? 1 : -1, p.x() + X(v, 0) - Xc(v, 0), p.z()};
                    changed = true;
                }
            }
            if (!changed) {
                t.seconds += ts.seconds();
                return;
            }
        }
        t.seconds += ts.seconds();
        std::fprintf(stderr, "contact set did not settle in 30 rounds\n");
    };

    // --clip-body: the simulator's blades (above). Coordinates Xc (the blades close about y = 0).
    constexpr double HINGE_BACK_MM = 100.0;
    fem::ClipBlades blades;
    blades.hinge = Eigen::Vector3d(clip.centre.x(), 0, clip.centre.z() - 0.5 * clip.length - HINGE_BACK_MM);
    blades.axis = Eigen::Vector3d::UnitZ();
    blades.up = Eigen::Vector3d::UnitY();
    blades.length_mm = HINGE_BACK_MM + clip.length;
    blades.width_mm = clip.width;
    blades.thickness_mm = 0.5;
    blades.closed_gap_mm = full_gap;
    const double r_centre = HINGE_BACK_MM + 0.5 * clip.length;
    std::vector<int> cand_all;  // outer nodes over the footprint
    for (Eigen::Index k = 0; k < outer.size(); ++k) {
        const Eigen::Vector3d p = X.row(outer[k]);
        const double dz = p.z() - clip.centre.z();
        if (std::abs(p.x() - clip.centre.x()) <= 0.5 * clip.width + 0.5 && dz >= -0.5 * clip.length && dz <= 0.5 * clip.length + 0.5)
            cand_all.push_back(outer[k]);
    }
    const fem::LinearBody linear_body(fem.K, fem.K_upper_only);
    // The patch's own numbering of the node positions and the candidates (once, not per step).
    Eigen::MatrixX3d patch_Xc;
    std::vector<int> cand_patch;
    if (clip_body && patch) {
        patch_Xc.resize(static_cast<Eigen::Index>(patch->nodes().size()), 3);
        for (size_t a = 0; a < patch->nodes().size(); ++a) patch_Xc.row(static_cast<Eigen::Index>(a)) = Xc.row(patch->nodes()[a]);
        for (int c : cand_all) {
            const int a = patch->local(c);
            if (a < 0 || patch->on_interface(a)) {
                std::fprintf(stderr, "a blade candidate (node %d) lies outside the patch's interior: widen --patch-mm\n", c);
                return 2;
            }
            cand_patch.push_back(a);
        }
    }
    // One step of the blades to the opening theta (a sub-step of a closure step: solve_clip below).
    auto clip_step = [&](Track& t, Model model, double theta) {
        fem::NewtonOptions no;
        no.max_total_iterations = max_newton;
        fem::NewtonResult r;
        // The body under the blades, its node positions, candidates and start in its own numbering.
        const fem::ElasticBody* base = &solid;
        const Eigen::MatrixX3d* XB = &Xc;
        std::vector<int> cand = cand_all;
        Eigen::VectorXd start = t.u;
        Eigen::VectorXi fixed = fem.fixed_dofs;
        const Eigen::MatrixX3i* faces = &inner_faces;
        if (model == Model::LINEAR) {
            base = &linear_body;
        } else if (model == Model::PATCH) {
            base = patch.get();
            XB = &patch_Xc;
            cand = cand_patch;
            start = patch->restrict_to_patch(t.u);
            fixed = patch->fixed_dofs();
            faces = &patch_faces;
        }
        std::unique_ptr<fem::ContactBody> wall;
        // κ of the walls and the blades: the body's largest diagonal entry at rest, computed once per model.
        if (wall_contact && model != Model::LINEAR) {
            fem::ContactParams cp = contact;
            cp.stiffness = t.kappa_wall;
            wall = std::make_unique<fem::ContactBody>(*base, *XB, *faces, start, cp);
            t.kappa_wall = wall->stiffness();
        }
        const fem::ElasticBody& body = wall ? static_cast<const fem::ElasticBody&>(*wall) : *base;
        Eigen::VectorXd v0(start.size() + 1);
        v0 << start, t.theta;
        fem::ClipContactParams bp;
        bp.friction = friction;
        bp.stiffness = t.kappa_blade;
        const fem::ClipBody cb(body, *XB, cand, v0, blades, fem::ClipSpring{1e-3, 0.0}, bp, t.grips.empty() ? nullptr : &t.grips);
        t.kappa_blade = cb.stiffness();
        r = solve_through(cb, fixed, {{static_cast<int>(cb.theta_dof()), theta}}, v0, no, proximal, t.prox_steps);
        const fem::BladeLoads L = cb.loads(r.u);
        t.force = 0.5 * (L.force_n[0] + L.force_n[1]);
        t.blade_contacts = L.contacts[0] + L.contacts[1];
        t.grips = cb.grips(r.u);
        t.theta = r.u[cb.theta_dof()];
        if (wall) {
            t.wall_gap = wall->min_distance(r.u.head(start.size()));
            t.wall_pairs = wall->active(r.u.head(start.size()));
        }
        t.u = model == Model::PATCH ? patch->full_displacement(r.u.head(start.size())) : Eigen::VectorXd(r.u.head(start.size()));
        t.iterations += r.iterations;
        t.substeps += r.substeps;
        t.shifted += r.shifted;
        t.min_J = r.min_J;
        ++t.rounds;
    };
    // A closure step in sub-steps of at most 0.05 mm of the gap, the grips renewed after each: the blades' friction
    // holds only where a node pressed at the start of a solve (lagged, as in the simulator's frames), and a thin sac
    // squeezed by a whole closure step with no grip yet slides sideways out of frictionless blades.
    auto solve_clip = [&](Track& t, Model model) {
        const Stopwatch ts;
        if (t.theta < 0) t.theta = 2 * std::asin((gap0 + 0.2 - full_gap) / (2 * r_centre));  // clear of the outer wall
        const double gap_from = full_gap + 2 * r_centre * std::sin(0.5 * t.theta), gap_to = std::max(clip.gap, full_gap);
        const int n = std::max(1, static_cast<int>(std::ceil(std::abs(gap_from - gap_to) / 0.05 - 1e-9)));
        for (int k = 1; k <= n; ++k) {
            const double g = gap_from + (gap_to - gap_from) * k / n;
            clip_step(t, model, 2 * std::asin((g - full_gap) / (2 * r_centre)));
            if (model != Model::LINEAR && t.seconds + ts.seconds() > max_seconds)
                throw NumericalError("time budget of " + std::to_string(static_cast<int>(max_seconds)) + " s for the neo-Hookean solves spent");
        }
        t.seconds += ts.seconds();
    };
    auto solve_any = [&](Track& t, Model m) {
        if (clip_body)
            solve_clip(t, m);
        else
            solve(t, m);
    };
    if (clip_body) std::fprintf(stderr, "clip body: %zu candidate nodes, hinge %.0f mm behind the blades, friction %.2f\n", cand_all.size(), HINGE_BACK_MM, friction);

    Track lin, nl, pt;
    lin.u = nl.u = pt.u = Eigen::VectorXd::Zero(solid.dofs());
    bool patch_alive = patch != nullptr, linear_alive = true;
    std::string reference_failed;
    nlohmann::json summary;
    double cross_force = -1, cross_disp = -1;
    double prev_c = 0, prev_ef = 0, prev_eu = 0;
    for (double c : closures) {
        clip.gap = gap0 - c * (gap0 - full_gap);
        // The linear model in the blades' contact problem can fail too (--clip-body): its figures then stop, the
        // others go on.
        std::string linear_failed;
        if (linear_alive) {
            try {
                solve_any(lin, Model::LINEAR);
            } catch (const Error& e) {
                linear_failed = e.what();
                linear_alive = false;
            }
        }
        std::string patch_failed;
        if (patch_alive) {
            try {
                solve_any(pt, Model::PATCH);
            } catch (const Error& e) {
                patch_failed = e.what();
                patch_alive = false;
            }
        }
        // A closure without the reference (it stopped here or earlier): linear and patch only; false: stop.
        auto without_reference = [&](const std::string& why) {
            nlohmann::json j = {{"closure", c}, {"gap_mm", clip.gap}, {"failed", why}, {"force_linear_N", lin.force}};
            if (patch_alive) j["force_patch_N"] = pt.force;
            if (!patch_failed.empty()) j["patch_failed"] = patch_failed;
            std::printf("%s\n", j.dump().c_str());
            std::fflush(stdout);
            return patch_alive;
        };
        if (reference && !reference_failed.empty()) {
            if (!without_reference("the reference stopped at an earlier closure")) break;
            continue;
        }
        if (reference) {
            try {
                solve_any(nl, Model::NONLINEAR);
            } catch (const Error& e) {
                reference_failed = e.what();
                if (!without_reference(e.what())) break;
                continue;
            }
        } else {
            nl = pt;  // no reference: errors are against the patch model
        }
        double num = 0, den = 0, umax = 0;
        for (int v : probe) {
            num += (lin.u.segment<3>(3 * v) - nl.u.segment<3>(3 * v)).squaredNorm();
            den += nl.u.segment<3>(3 * v).squaredNorm();
            umax = std::max(umax, nl.u.segment<3>(3 * v).norm());
        }
        const double ef = std::abs(lin.force - nl.force) / std::abs(nl.force);
        const double eu = std::sqrt(num / den);
        double num_p = 0;
        for (int v : probe) num_p += (pt.u.segment<3>(3 * v) - nl.u.segment<3>(3 * v)).squaredNorm();
        if (linear_alive && cross_force < 0 && ef > 0.1) cross_force = prev_c + (c - prev_c) * (0.1 - prev_ef) / (ef - prev_ef);
        if (linear_alive && cross_disp < 0 && eu > 0.1) cross_disp = prev_c + (c - prev_c) * (0.1 - prev_eu) / (eu - prev_eu);
        prev_c = c;
        prev_ef = ef;
        prev_eu = eu;
        nlohmann::json j = {{"closure", c},
                            {"gap_mm", clip.gap},
                            {"force_linear_N", lin.force},
                            {"force_nonlinear_N", nl.force},
                            {"force_error", ef},
                            {"u_error", eu},
                            {"u_max_mm", umax},
                            {"contacts_linear", clip_body ? static_cast<size_t>(lin.blade_contacts) : lin.active.size()},
                            {"contacts_nonlinear", clip_body ? static_cast<size_t>(nl.blade_contacts) : nl.active.size()},
                            {"min_J", nl.min_J},
                            {"newton_iterations", nl.iterations},
                            {"substeps", nl.substeps},
                            {"shifted", nl.shifted},
                            {"rounds_linear", lin.rounds},
                            {"rounds_nonlinear", nl.rounds},
                            {"seconds_linear", lin.seconds},
                            {"seconds_nonlinear", nl.seconds},
                            {"proximal_steps", nl.prox_steps}};
        if (!linear_alive) {
            j["linear_failed"] = linear_failed.empty() ? "at an earlier closure" : linear_failed;
            j.erase("force_linear_N");
            j.erase("force_error");
            j.erase("u_error");
        }
        if (wall_contact && reference) {
            j["wall_pairs"] = nl.wall_pairs;
            j["wall_gap_mm"] = std::isfinite(nl.wall_gap) ? nl.wall_gap : -1.0;
        }
        if (patch) {
            j["reference"] = reference;
            if (patch_failed.empty() && (patch_alive || reference)) {
                j["force_patch_N"] = pt.force;
                j["force_error_patch"] = std::abs(pt.force - nl.force) / std::abs(nl.force);
                j["u_error_patch"] = std::sqrt(num_p / den);
                j["contacts_patch"] = clip_body ? static_cast<size_t>(pt.blade_contacts) : pt.active.size();
                j["newton_iterations_patch"] = pt.iterations;
                j["seconds_patch"] = pt.seconds;
                j["proximal_steps_patch"] = pt.prox_steps;
                j["min_J_patch"] = pt.min_J;
                if (wall_contact) {
                    j["wall_pairs_patch"] = pt.wall_pairs;
                    j["wall_gap_patch_mm"] = std::isfinite(pt.wall_gap) ? pt.wall_gap : -1.0;
                }
            } else {
                j["patch_failed"] = patch_failed;
            }
        }
        // A cross-section through the clip (nodes within 0.15 mm of the plane z = centre.z): reference and both
        // deformed positions, for the report's picture.
        if (std::abs(c - 0.2) < 1e-9 || std::abs(c - 0.5) < 1e-9 || std::abs(c - 0.9) < 1e-9 || std::abs(c - 1.0) < 1e-9) {
            nlohmann::json sec = nlohmann::json::array();
            for (Eigen::Index v = 0; v < X.rows(); ++v) {
                if (std::abs(X(v, 2) - clip.centre.z()) > 0.15) continue;
                const Eigen::Vector3d xl = X.row(v).transpose() + lin.u.segment<3>(3 * v);
                const Eigen::Vector3d xn = X.row(v).transpose() + nl.u.segment<3>(3 * v);
                sec.push_back({X(v, 0), X(v, 1), xl.x(), xl.y(), xn.x(), xn.y()});
            }
            j["section"] = sec;
        }
        std::printf("%s\n", j.dump().c_str());
        std::fflush(stdout);
    }
    summary = {{"summary", true},
               {"label", label},
               {"model", argv[1]},
               {"nodes", X.rows()},
               {"tets", vol.tets.rows()},
               {"element_order", fem.element_order},
               {"dofs", solid.dofs()},
               {"materials", nlohmann::json::array()},
               {"clip_centre", {clip.centre.x(), clip.centre.y(), clip.centre.z()}},
               {"blade_width_mm", clip.width},
               {"blade_length_mm", clip.length},
               {"gap0_mm", gap0},
               {"full_gap_mm", full_gap},
               {"region_mm", region},
               {"probe_nodes", probe.size()},
               {"tangent_at_rest_vs_K", k_diff / k_max},
               {"setup_s", setup_s},
               {"closure_force_error_10pct", cross_force},
               {"closure_u_error_10pct", cross_disp},
               {"seconds_linear", lin.seconds},
               {"seconds_nonlinear", nl.seconds}};
    summary["wall_contact"] = wall_contact;
    summary["clip_body"] = clip_body;
    if (clip_body) summary["friction"] = friction;
    if (patch) {
        summary["patch_mm"] = patch_mm;
        summary["patch_nodes"] = patch->nodes().size();
        summary["patch_interface_nodes"] = patch->interface_nodes();
        summary["patch_setup_s"] = patch->setup_seconds();
        summary["seconds_patch"] = pt.seconds;
    }
    for (const auto& m : fem.materials) summary["materials"].push_back({{"region", m.region}, {"E_mpa", m.E_mpa}, {"nu", m.nu}});
    std::printf("%s\n", summary.dump().c_str());
    return 0;
}
