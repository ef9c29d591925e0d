// SPDX-License-Identifier: MIT
// The fold of a flattened tube: how wide a channel stays open at its two edges, against the mesh (issue #15: the
// sample's clipped neck keeps a 0.18 mm channel at its far fold; is that the wall or its discretisation?).
//
// A straight tube wall (structured mesh, `--layers` cells through the wall, `--around` round it, `--along` along
// it; 10-node tetrahedra, neo-Hookean, ends held) is flattened by the simulator's blades (fem::ClipBody: rigid,
// rounded edges, barrier contact, friction 0.3, grips renewed every step) crossing it at mid-length: `--jaw-mm`
// wide along the tube, hinged 100 mm to the side so that they stay parallel, closing along y. The inner walls
// touch through fem::ContactBody with the crossing check (fem::solve_without_crossings), as the simulator's
// patch does. The blades close in steps (0.1 mm of their gap, 0.05 mm once the walls are within 0.6 mm of
// touching) and at each gap of `--gaps` (multiples of twice the wall: 0.9 = the blades 0.9 × 2t apart) it prints
// one JSON line: the blades' force, the inner walls' closest distance, and the channel — the widest path of the
// deformed lumen from one side of the blades to the other (faces joined across edges, widest first, until a face
// more than 1.5 mm before the blades' mid-plane and one more than 1.5 mm beyond it connect), a face's width being
// the diameter of the largest ball inside the lumen touching it (sim::lumen_width, the simulator's neck channel
// measure). The lumen is the inner surface's 6-node faces split in four (the quadratic elements' mid-edge nodes
// shape the fold); the walls' contact acts on the corner triangles, as in the simulator, or with --p2-contact on
// the split faces (every node of the quadratic inner surface). Each line also gives how far the quadratic surface's
// walls pass through each other (its closest pair's signed distance), and the channel measured on the corner
// triangles alone (channel_corner_triangles_mm: the simulator's neck measures see the lumen's corner nodes).
// Usage: aneu_bench_fold [--layers 1] [--around 24] [--along 16] [--inner-radius-mm 1.5] [--wall-mm 0.28]
//                        [--length-mm 6] [--jaw-mm 1] [--E 1] [--nu 0.45] [--gaps 0.9,0.8,0.7,0.6] [--obj PREFIX]
// --obj PREFIX: the deformed lumen at each gap as PREFIX_<gap>.obj (with "# width f w" lines, as ANEU_LUMEN_OBJ).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/bundle.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/structured_mesh.hpp"
#include "aneu/sim/assessment.hpp"

using namespace aneu;

namespace {

std::vector<double> parse_list(const std::string& s) {
    std::vector<double> v;
    std::stringstream ss(s);
    for (std::string x; std::getline(ss, x, ',');) v.push_back(std::atof(x.c_str()));
    return v;
}

}  // namespace

int main(int argc, char** argv) {
    aneu::reexec_with_blas_kernels(argv);  // OpenBLAS's kernels for this CPU (aneu/core/dependency_info.hpp)
    int layers = 1, around = 24, along = 16;
    double r_in = 1.5, wall = 0.28, length = 6.0, jaw = 1.0, E = 1.0, nu = 0.45;
    std::vector<double> gaps = {0.9, 0.8, 0.7, 0.6};
    std::string obj;
    bool p2_contact = false;
    for (int a = 1; a < argc; a += 2) {
        if (a + 1 >= argc && std::string(argv[a]) != "--p2-contact") {
            std::fprintf(stderr, "usage: %s [--p2-contact] [--layers N] [--around N] [--along N] [--inner-radius-mm R] [--wall-mm T] [--length-mm L] "
                                 "[--jaw-mm W] [--E MPa] [--nu NU] [--gaps g1,g2,...] [--obj PREFIX]\n", argv[0]);
            return 2;
        }
        const std::string k = argv[a];
        if (k == "--p2-contact") {
            p2_contact = true;
            --a;
            continue;
        }
        const std::string v = argv[a + 1];
        if (k == "--layers") layers = std::atoi(v.c_str());
        else if (k == "--around") around = std::atoi(v.c_str());
        else if (k == "--along") along = std::atoi(v.c_str());
        else if (k == "--inner-radius-mm") r_in = std::atof(v.c_str());
        else if (k == "--wall-mm") wall = std::atof(v.c_str());
        else if (k == "--length-mm") length = std::atof(v.c_str());
        else if (k == "--jaw-mm") jaw = std::atof(v.c_str());
        else if (k == "--E") E = std::atof(v.c_str());
        else if (k == "--nu") nu = std::atof(v.c_str());
        else if (k == "--gaps") gaps = parse_list(v);
        else if (k == "--obj") obj = v;
        else {
            std::fprintf(stderr, "unknown option %s\n", k.c_str());
            return 2;
        }
    }
    if (layers < 1 || around < 8 || along < 2 || !(wall > 0) || !(r_in > 0) || !(length > 2 * jaw) || gaps.empty()) {
        std::fprintf(stderr, "bad options\n");
        return 2;
    }
    std::sort(gaps.begin(), gaps.end(), std::greater<>());
    try {
        const Stopwatch total;
        const fem::StructuredMesh m = fem::tube_mesh(r_in, r_in + wall, length, layers, around, along);
        const fem::QuadraticMesh q = fem::quadratic_mesh(m.V, m.T);
        const int n_lin = static_cast<int>(m.V.rows());
        const Eigen::VectorXi region = Eigen::VectorXi::Zero(q.T.rows());
        const fem::NeoHookeanSolid solid(q.V, q.T, region, {Material{"artery", E, nu}});
        const Eigen::MatrixX3d& X = q.V;
        const double zc = 0.5 * length;
        // Held: every node at an end.
        std::vector<int> fixed;
        for (Eigen::Index n = 0; n < X.rows(); ++n)
            if (X(n, 2) < 1e-9 || X(n, 2) > length - 1e-9)
                for (int d = 0; d < 3; ++d) fixed.push_back(static_cast<int>(3 * n + d));
        const Eigen::VectorXi fixed_dofs = Eigen::Map<Eigen::VectorXi>(fixed.data(), static_cast<Eigen::Index>(fixed.size()));
        // The blades' candidates: outer nodes (corners and mid-edges) within 1.5 mm of the blades' mid-plane.
        const Eigen::VectorXi outer = fem::quadratic_node_set(q, m.T, n_lin, m.outer);
        std::vector<int> cand;
        for (Eigen::Index k = 0; k < outer.size(); ++k)
            if (std::abs(X(outer[k], 2) - zc) <= 0.5 * jaw + 1.0) cand.push_back(outer[k]);
        // The inner walls: corner triangles (contact), 6-node faces split in four (the measured lumen).
        const Eigen::MatrixXi inner3 = fem::boundary_faces_in_set(m.V, m.T, m.inner);
        const Eigen::MatrixX3i corner_faces = inner3.leftCols(3);
        // The quadratic surface's triangles (normals into the lumen, as the corners').
        const Eigen::MatrixX3i split_faces = fem::quadratic_surface_triangles(fem::MidEdgeNodes(q.T), corner_faces);
        const Eigen::MatrixX3i& contact_faces = p2_contact ? split_faces : corner_faces;
        // The measured lumen: the same triangles over the inner surface's nodes only, reversed (a lumen's faces
        // point into the wall).
        struct Lumen {
            sim::SimLumen L;
            std::vector<int> node;  // the tube's node of each lumen vertex
        };
        auto lumen_of = [&](const Eigen::MatrixX3i& faces) {
            Lumen out;
            std::vector<int> of(static_cast<size_t>(X.rows()), -1);
            auto lum = [&](int n) {
                if (of[static_cast<size_t>(n)] < 0) {
                    of[static_cast<size_t>(n)] = static_cast<int>(out.node.size());
                    out.node.push_back(n);
                }
                return of[static_cast<size_t>(n)];
            };
            out.L.F.resize(faces.rows(), 3);
            for (Eigen::Index f = 0; f < faces.rows(); ++f) out.L.F.row(f) << lum(faces(f, 0)), lum(faces(f, 2)), lum(faces(f, 1));
            out.L.X.resize(static_cast<Eigen::Index>(out.node.size()), 3);
            for (size_t k = 0; k < out.node.size(); ++k) out.L.X.row(static_cast<Eigen::Index>(k)) = X.row(out.node[k]);
            out.L.wall_mm = Eigen::VectorXd::Constant(out.L.X.rows(), wall);
            return out;
        };
        // The quadratic surface (what the walls' contact acts on with --p2-contact) and its corner triangles (what
        // the simulator's neck measures see: the lumen's corner nodes).
        const Lumen quad = lumen_of(split_faces), corner = lumen_of(corner_faces);
        const sim::SimLumen& L = quad.L;
        std::fprintf(stderr, "tube: %d layers, %d around, %d along: %lld nodes (%lld DOFs), %lld tetrahedra; %zu blade candidates, %lld wall faces\n",
                     layers, around, along, static_cast<long long>(X.rows()), static_cast<long long>(solid.dofs()), static_cast<long long>(q.T.rows()),
                     cand.size(), static_cast<long long>(contact_faces.rows()));

        // Parallel blades: hinged H to the side (along −x), crossing the tube along x, jaw wide along z, closing along y.
        constexpr double H = 100.0;
        fem::ClipBlades blades;
        blades.hinge = Eigen::Vector3d(-H, 0, zc);
        blades.axis = Eigen::Vector3d::UnitX();
        blades.up = Eigen::Vector3d::UnitY();
        blades.length_mm = H + r_in + wall + 0.5 * M_PI * (r_in + wall) + 0.5;  // past the flattened tube's far fold
        blades.width_mm = jaw;
        blades.thickness_mm = 0.5;
        blades.closed_gap_mm = 0;
        const fem::ClipSpring spring{1e-3, 0.0};  // θ is prescribed: the spring does not matter
        auto theta_of = [&](double gap) { return 2 * std::asin(gap / (2 * H)); };
        const double gap0 = 2 * (r_in + wall) + 0.02;
        fem::ClipContactParams bp;
        bp.friction = 0.3;
        fem::NewtonOptions o;
        o.tolerance = 1e-8;
        o.max_iterations = 60;
        o.max_halvings = 6;
        o.keep_going = true;
        o.force_scale = 1e-3;
        Eigen::VectorXd v = Eigen::VectorXd::Zero(solid.dofs() + 1);
        v[solid.dofs()] = theta_of(gap0);
        std::vector<fem::BladeGrip> grips;
        bool gripped = false;
        double kappa_wall = 0, kappa_blade = 0;
        std::vector<int> close;
        double gap = gap0;
        const double two_t = 2 * wall;
        int steps = 0, unconverged = 0, its = 0;
        for (double target_rel : gaps) {
            const double target = target_rel * two_t;
            while (gap > target + 1e-12) {
                const double step = gap > two_t + 0.6 ? 0.1 : 0.05;
                gap = std::max(target, gap - step);
                const Eigen::VectorXd v0 = v;
                fem::ContactParams cp;
                cp.stiffness = kappa_wall;
                cp.search_mm = std::max(cp.search_mm, 0.2 + 2.0 * step);
                cp.close_vertices = close;
                fem::BladeLoads loads;
                const fem::CrossingFreeSolve cs = fem::solve_without_crossings(solid, X, contact_faces, v0.head(solid.dofs()), cp, [&](const fem::ContactBody& wb) {
                    kappa_wall = wb.stiffness();
                    bp.stiffness = kappa_blade;
                    const fem::ClipBody cb(wb, X, cand, v0, blades, spring, bp, gripped ? &grips : nullptr);
                    kappa_blade = cb.stiffness();
                    fem::NewtonResult r = fem::solve_neo_hookean(cb, fixed_dofs, {{static_cast<int>(cb.theta_dof()), theta_of(gap)}}, v0, o);
                    grips = cb.grips(r.u);
                    return r;
                });
                close = cs.close_vertices;
                gripped = true;
                v = cs.result.u;
                ++steps;
                its += cs.result.iterations;
                if (!cs.result.converged) ++unconverged;
                std::fprintf(stderr, "gap %.3f mm (%.2f x 2t): %d iterations%s, %d repeats, %.1f s\n", gap, gap / two_t, cs.result.iterations,
                             cs.result.converged ? "" : " (not converged)", cs.rounds, total.seconds());
            }
            // Measure.
            const Eigen::VectorXd u = v.head(solid.dofs());
            const fem::ClipBody cb(solid, X, cand, v, blades, spring, bp, &grips);
            const fem::BladeLoads loads = cb.loads(v);
            fem::ContactParams cp;
            const fem::ContactBody wb(solid, X, contact_faces, u, cp);
            // The quadratic surface itself (mid-edge nodes included): how far its walls pass through each other
            // where the contact acts on the corner triangles only.
            const fem::ContactBody wb2(solid, X, split_faces, u, cp);
            struct Channel {
                double width = 0, fold_max = 0;
                int measured = 0;
                Eigen::Vector3d where = Eigen::Vector3d::Zero();
                Eigen::MatrixX3d y;
                std::vector<double> face_width;
            };
            auto channel_of = [&](const Lumen& lu) {
                Channel c;
                const sim::SimLumen& M = lu.L;
                c.y = M.X;
                for (size_t k = 0; k < lu.node.size(); ++k) c.y.row(static_cast<Eigen::Index>(k)) += u.segment<3>(3 * lu.node[k]).transpose();
                c.face_width.assign(static_cast<size_t>(M.F.rows()), 2.0);
                std::vector<char> before(static_cast<size_t>(M.F.rows())), beyond(static_cast<size_t>(M.F.rows()));
                for (Eigen::Index f = 0; f < M.F.rows(); ++f) {
                    const double z = (M.X(M.F(f, 0), 2) + M.X(M.F(f, 1), 2) + M.X(M.F(f, 2), 2)) / 3.0;
                    // The channel from before the blades to beyond them: faces more than 1.5 mm from their mid-plane at rest.
                    before[static_cast<size_t>(f)] = z < zc - 1.5;
                    beyond[static_cast<size_t>(f)] = z > zc + 1.5;
                    if (std::abs(z - zc) > 0.5 * jaw + 1.5) continue;
                    c.face_width[static_cast<size_t>(f)] = sim::lumen_width(M, c.y, static_cast<int>(f), Eigen::Vector3d::Constant(1.0 / 3.0), 2.0);
                    ++c.measured;
                    if (std::abs(z - zc) <= 0.5 * jaw) c.fold_max = std::max(c.fold_max, c.face_width[static_cast<size_t>(f)]);
                }
                const auto [w, at] = sim::widest_channel(M.F, c.face_width, before, beyond);
                c.width = w;
                if (at >= 0)
                    for (int k = 0; k < 3; ++k) c.where += c.y.row(M.F(at, k)).transpose() / 3.0;
                return c;
            };
            const Channel cq = channel_of(quad), cc = channel_of(corner);
            const Eigen::MatrixX3d& y = cq.y;
            const std::vector<double>& width = cq.face_width;
            const double ch = cq.width;
            const Eigen::Vector3d& where = cq.where;
            if (!obj.empty()) {
                char name[64];
                std::snprintf(name, sizeof name, "_%.2f.obj", target_rel);
                std::FILE* fo = std::fopen((obj + name).c_str(), "w");
                if (fo) {
                    for (Eigen::Index k = 0; k < y.rows(); ++k) std::fprintf(fo, "v %.6f %.6f %.6f\n", y(k, 0), y(k, 1), y(k, 2));
                    for (Eigen::Index f = 0; f < L.F.rows(); ++f) std::fprintf(fo, "f %d %d %d\n", L.F(f, 0) + 1, L.F(f, 1) + 1, L.F(f, 2) + 1);
                    for (Eigen::Index f = 0; f < L.F.rows(); ++f) std::fprintf(fo, "# width %lld %.6f\n", static_cast<long long>(f), width[static_cast<size_t>(f)]);
                    std::fprintf(fo, "# channel %.6f %.6f %.6f %.6f\n", ch, where.x(), where.y(), where.z());
                    std::fclose(fo);
                }
            }
            nlohmann::json j;
            j["layers"] = layers;
            j["around"] = around;
            j["along"] = along;
            j["dofs"] = solid.dofs();
            j["wall_mm"] = wall;
            j["gap_over_2t"] = target_rel;
            j["gap_mm"] = gap;
            j["blade_force_n"] = {loads.force_n[0], loads.force_n[1]};
            j["walls_closest_mm"] = wb.min_distance(u);
            j["walls_closest_quadratic_surface_mm"] = wb2.min_distance(u);
            j["contact_on"] = p2_contact ? "quadratic surface (6-node faces split in four)" : "corner triangles";
            j["channel_mm"] = ch;
            j["channel_at"] = {where.x(), where.y(), where.z()};
            j["channel_corner_triangles_mm"] = cc.width;  // the same measure on the corner triangles (the simulator's lumen)
            j["widest_face_under_jaws_mm"] = cq.fold_max;
            j["faces_measured"] = cq.measured;
            j["steps"] = steps;
            j["unconverged_steps"] = unconverged;
            j["newton_iterations"] = its;
            j["seconds"] = total.seconds();
            std::printf("%s\n", j.dump().c_str());
            std::fflush(stdout);
        }
    } catch (const Error& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
    return 0;
}
