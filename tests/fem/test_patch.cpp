// SPDX-License-Identifier: MIT
// The nonlinear patch inside the linear model (fem::PatchModel, issue #15 item 2): its exterior condensation
// is exact, and with the push inside the patch it gives the full neo-Hookean answer, not the linear one.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/patch.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/fem/structured_mesh.hpp"

using namespace aneu;

namespace {

/// A 10-node tube wall (r 1.5–1.9 mm, 6 mm long) held at both ends, and a patch of outer nodes to push.
struct Tube {
    VolumeData vol;
    FemData fem;
    std::vector<int> pushed;
    Tube() {
        const fem::StructuredMesh t = fem::tube_mesh(1.5, 1.9, 6.0, 2, 20, 10);
        const fem::QuadraticMesh q = fem::quadratic_mesh(t.V, t.T);
        vol.nodes = q.V;
        vol.tets = q.T;
        vol.tet_region = Eigen::VectorXi::Zero(q.T.rows());
        vol.region_names = {"wall"};
        fem.materials = {{"wall", 1.0, 0.45}};
        fem.element_order = 2;
        fem.K = fem::assemble_stiffness(q.V, q.T, vol.tet_region, fem.materials);
        fem.K_upper_only = false;
        std::vector<int> fd;
        for (Eigen::Index i = 0; i < q.V.rows(); ++i)
            if (q.V(i, 2) < 1e-9 || q.V(i, 2) > 6 - 1e-9)
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
        fem.fixed_dofs = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
        for (Eigen::Index i = 0; i < q.V.rows(); ++i) {
            const Eigen::Vector3d X = q.V.row(i);
            if (std::hypot(X.x(), X.y()) > 1.9 - 1e-6 && X.x() > 1.6 && std::abs(X.z() - 3) < 1.0) pushed.push_back(static_cast<int>(i));
        }
    }
    /// Tetrahedra whose centroid lies within `radius` of the pushed patch's centre (1.9, 0, 3).
    std::vector<int> tets_near(double radius) const {
        std::vector<int> out;
        for (Eigen::Index t = 0; t < vol.tets.rows(); ++t) {
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int k = 0; k < 4; ++k) c += vol.nodes.row(vol.tets(t, k)).transpose() / 4.0;
            if ((c - Eigen::Vector3d(1.9, 0, 3)).norm() <= radius) out.push_back(static_cast<int>(t));
        }
        return out;
    }
    std::vector<std::pair<int, double>> push(double depth) const {
        std::vector<std::pair<int, double>> p;
        for (int v : pushed)
            for (int k = 0; k < 3; ++k) p.emplace_back(3 * v + k, k == 0 ? -depth : 0.0);
        return p;
    }
};

}  // namespace

TEST(Patch, ExteriorCondensationIsExact) {
    // The patch's tangent at rest (its own K plus the condensed exterior S) solves the linear problem on the
    // patch exactly, and the recovered exterior is the linear model's: the condensation adds no error.
    const Tube tube;
    // Every third node of the mesh is a map node (inside the patch, outside it, and fixed ones).
    std::vector<int> map_nodes;
    for (Eigen::Index v = 0; v < tube.vol.nodes.rows(); v += 3) map_nodes.push_back(static_cast<int>(v));
    const fem::PatchModel patch(tube.vol, tube.fem, tube.tets_near(1.6), map_nodes);
    ASSERT_GT(patch.interface_nodes(), 10);
    ASSERT_LT(static_cast<Eigen::Index>(patch.nodes().size()), tube.vol.nodes.rows() / 2);
    const auto pres = tube.push(0.05);
    const Eigen::VectorXd u_full = fem::solve_dirichlet(tube.fem, pres).u;
    FemData local;
    local.K = patch.tangent(Eigen::VectorXd::Zero(patch.dofs()));
    local.K_upper_only = false;
    local.fixed_dofs = patch.fixed_dofs();
    std::vector<std::pair<int, double>> lp;
    for (const auto& [d, v] : pres) {
        const int a = patch.local(d / 3);
        ASSERT_GE(a, 0) << "pushed node outside the patch";
        ASSERT_FALSE(patch.on_interface(a));
        lp.emplace_back(3 * a + d % 3, v);
    }
    const fem::DirichletResult r = fem::solve_dirichlet(local, lp);
    const Eigen::VectorXd u = patch.full_displacement(r.u);
    EXPECT_LT((u - u_full).norm(), 1e-9 * u_full.norm());
    // The map nodes' displacement without a solve (the kept rows of K_EE⁻¹ K_EI) is the same.
    const Eigen::VectorXd um = patch.mapped_displacement(r.u);
    ASSERT_EQ(um.size(), 3 * static_cast<Eigen::Index>(map_nodes.size()));
    double worst = 0;
    for (size_t k = 0; k < map_nodes.size(); ++k)
        worst = std::max(worst, (um.segment<3>(3 * static_cast<Eigen::Index>(k)) - u.segment<3>(3 * map_nodes[k])).norm());
    EXPECT_LT(worst, 1e-9 * u_full.norm());
    EXPECT_THROW(fem::PatchModel(tube.vol, tube.fem, tube.tets_near(1.6), {static_cast<int>(tube.vol.nodes.rows())}), InputError);
    // A setup asked to stop (a real-time run ending) stops before its interface solves.
    const std::atomic<bool> stop{true};
    EXPECT_THROW(fem::PatchModel(tube.vol, tube.fem, tube.tets_near(1.6), map_nodes, &stop), Cancelled);
    // The reactions (the force to push) too.
    EXPECT_NEAR(r.reaction.sum(), fem::solve_dirichlet(tube.fem, pres).reaction.sum(), 1e-9 * r.reaction.cwiseAbs().sum());
}

TEST(Patch, PushInsideThePatchGivesTheNonlinearAnswer) {
    // Pushed in by 0.4 mm (a fifth of the radius), the linear model is off by several per cent. A neo-Hookean
    // patch reaching 1.2 mm beyond the push, on the exact linear exterior, recovers the full neo-Hookean
    // solution: displacement and force within a small fraction of the linear model's error.
    const Tube tube;
    const auto pres = tube.push(0.4);
    const fem::NeoHookeanSolid solid(tube.vol.nodes, tube.vol.tets, tube.vol.tet_region, tube.fem.materials);
    const fem::NewtonResult full = fem::solve_neo_hookean(solid, tube.fem.fixed_dofs, pres, Eigen::VectorXd::Zero(solid.dofs()));
    const fem::DirichletResult lin = fem::solve_dirichlet(tube.fem, pres);
    const fem::PatchModel patch(tube.vol, tube.fem, tube.tets_near(2.2));
    std::vector<std::pair<int, double>> lp;
    for (const auto& [d, v] : pres) lp.emplace_back(3 * patch.local(d / 3) + d % 3, v);
    const fem::NewtonResult pr = fem::solve_neo_hookean(patch, patch.fixed_dofs(), lp, Eigen::VectorXd::Zero(patch.dofs()));
    EXPECT_LT(pr.residual, 1e-9);
    const Eigen::VectorXd u_patch = patch.full_displacement(pr.u);
    // Displacement over the patch's nodes, and the pushing force (x).
    double e_lin = 0, e_patch = 0, ref = 0;
    for (int g : patch.nodes()) {
        ref += full.u.segment<3>(3 * g).squaredNorm();
        e_lin += (lin.u - full.u).segment<3>(3 * g).squaredNorm();
        e_patch += (u_patch - full.u).segment<3>(3 * g).squaredNorm();
    }
    const double du_lin = std::sqrt(e_lin / ref), du_patch = std::sqrt(e_patch / ref);
    auto force_x = [&](const Eigen::VectorXd& reaction) {
        double f = 0;
        for (size_t k = 0; k < pres.size(); k += 3) f += reaction[static_cast<Eigen::Index>(k)];
        return f;
    };
    const double f_full = force_x(full.reaction), f_lin = force_x(lin.reaction), f_patch = force_x(pr.reaction);
    const double ef_lin = std::abs(f_lin - f_full) / std::abs(f_full), ef_patch = std::abs(f_patch - f_full) / std::abs(f_full);
    std::printf("push 0.4 mm: force full %.5f N, linear %.5f (%.2f %%), patch %.5f (%.2f %%); displacement error linear %.2f %%, patch %.2f %%; "
                "patch %zu of %lld nodes, %lld on the interface, made in %.3f s\n",
                f_full, f_lin, 100 * ef_lin, f_patch, 100 * ef_patch, 100 * du_lin, 100 * du_patch, patch.nodes().size(),
                static_cast<long long>(tube.vol.nodes.rows()), static_cast<long long>(patch.interface_nodes()), patch.setup_seconds());
    EXPECT_GT(du_lin, 0.02);
    EXPECT_LT(du_patch, 0.25 * du_lin);
    EXPECT_LT(ef_patch, 0.25 * ef_lin);
}

TEST(Patch, RefusesAnEmptyOrWholePatch) {
    const Tube tube;
    EXPECT_THROW(fem::PatchModel(tube.vol, tube.fem, {}), InputError);
    std::vector<int> all(static_cast<size_t>(tube.vol.tets.rows()));
    for (size_t t = 0; t < all.size(); ++t) all[t] = static_cast<int>(t);
    EXPECT_THROW(fem::PatchModel(tube.vol, tube.fem, all), InputError);
    EXPECT_THROW(fem::PatchModel(tube.vol, tube.fem, {static_cast<int>(tube.vol.tets.rows())}), InputError);
}
