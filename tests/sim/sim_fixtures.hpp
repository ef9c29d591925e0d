// SPDX-License-Identifier: MIT
#pragma once
// Small analytic case bundles for the simulator tests: a tube wall (radius 1.5–1.9 mm, 8 mm long, ends
// fixed, outer surface condensed), with a patch of elements labelled "aneurysm" for the neck measures.
#include <cmath>
#include <string>
#include <vector>

#include "aneu/core/bundle_io.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/condense.hpp"
#include "aneu/fem/structured_mesh.hpp"

namespace aneu::test {

struct TubeCase {
    Bundle bundle;                                       // volume + fem + condensed
    Eigen::SparseMatrix<double, Eigen::RowMajor> K;      // both triangles
    fem::StructuredMesh mesh;
};

/// A case bundle (volume, fem, condensed) of a mesh: K condensed onto `kept` with `fixed` held.
inline Bundle case_bundle(Precision precision, const std::string& id, const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets,
                          const Eigen::VectorXi& region, const std::vector<std::string>& region_names, const Eigen::VectorXi& outer,
                          const Eigen::VectorXi& inner, const std::vector<Material>& mats, const Eigen::SparseMatrix<double, Eigen::RowMajor>& K,
                          const Eigen::VectorXi& fixed, const Eigen::VectorXi& kept) {
    fem::CondenseParams cp;
    cp.precision = precision;
    cp.tile_size = 64;
    cp.residual_columns = 0;
    Bundle b;
    b.meta.case_id = id;
    VolumeData v;
    v.nodes = nodes;
    v.tets = tets;
    v.tet_region = region;
    v.region_names = region_names;
    v.node_sets["outer"] = outer;
    v.node_sets["inner"] = inner;
    b.volume = v;
    FemData f;
    f.element_order = tets.cols() == 10 ? 2 : 1;
    f.K = K;
    f.K_upper_only = false;
    f.materials = mats;
    f.fixed_dofs = fixed;
    b.fem = f;
    b.condensed = fem::condense(K, fixed, kept, cp);
    return b;
}

/// Tube r 1.5..1.9 mm, length 8 mm along z; elements whose centroid has z in [sac_z0, sac_z1] (3, 5) and angle
/// within ±sac_deg (40°) of +x are "aneurysm" (E_sac), the rest "artery" (E_art).
inline TubeCase tube_case(Precision precision, int n_theta = 24, int n_z = 16, double E_art = 1.0, double E_sac = 1.0,
                          double nu = 0.45, double sac_z0 = 3.0, double sac_z1 = 5.0, double sac_deg = 40.0) {
    TubeCase c;
    c.mesh = fem::tube_mesh(1.5, 1.9, 8.0, 2, n_theta, n_z);
    const auto& m = c.mesh;
    Eigen::VectorXi region(m.T.rows());
    for (Eigen::Index e = 0; e < m.T.rows(); ++e) {
        Eigen::RowVector3d g = Eigen::RowVector3d::Zero();
        for (int k = 0; k < 4; ++k) g += m.V.row(m.T(e, k)) / 4.0;
        const double ang = std::atan2(g.y(), g.x());
        region[e] = (g.z() > sac_z0 && g.z() < sac_z1 && std::abs(ang) < sac_deg * M_PI / 180.0) ? 1 : 0;
    }
    std::vector<Material> mats{{"artery", E_art, nu}, {"aneurysm", E_sac, nu}};
    c.K = fem::assemble_stiffness(m.V, m.T, region, mats);
    const fem::WallDofSets sets = fem::wall_dof_sets(m);
    c.bundle = case_bundle(precision, "tube-test", m.V, m.T, region, {"artery", "aneurysm"}, m.outer, m.inner, mats, c.K, sets.fixed, sets.kept);
    return c;
}


/// The tube r 1.5..1.9 mm, 8 mm long, one layer of 10-node tetrahedra through its wall ("artery" throughout), ends
/// fixed, the outer surface's corner nodes condensed (as the pipeline's bundles: the simulated surface is the
/// corners', the elements quadratic).
inline TubeCase quadratic_tube_case(Precision precision, int n_theta = 24, int n_z = 16, double E = 1.0, double nu = 0.45) {
    TubeCase c;
    c.mesh = fem::tube_mesh(1.5, 1.9, 8.0, 1, n_theta, n_z);
    const auto& m = c.mesh;
    const fem::QuadraticMesh q = fem::quadratic_mesh(m.V, m.T);
    const int n_lin = static_cast<int>(m.V.rows());
    const Eigen::VectorXi region = Eigen::VectorXi::Zero(q.T.rows());
    std::vector<Material> mats{{"artery", E, nu}};
    c.K = fem::assemble_stiffness(q.V, q.T, region, mats);
    std::vector<int> fixed, kept;
    std::vector<char> outer(static_cast<size_t>(n_lin), 0);
    for (Eigen::Index k = 0; k < m.outer.size(); ++k) outer[static_cast<size_t>(m.outer[k])] = 1;
    for (Eigen::Index n = 0; n < q.V.rows(); ++n) {
        const bool end = q.V(n, 2) < 1e-9 || q.V(n, 2) > 8.0 - 1e-9;
        for (int a = 0; a < 3; ++a) {
            if (end) fixed.push_back(static_cast<int>(3 * n + a));
            else if (n < n_lin && outer[static_cast<size_t>(n)]) kept.push_back(static_cast<int>(3 * n + a));
        }
    }
    c.bundle = case_bundle(precision, "quadratic-tube-test", q.V, q.T, region, {"artery"}, fem::quadratic_node_set(q, m.T, n_lin, m.outer),
                           fem::quadratic_node_set(q, m.T, n_lin, m.inner), mats, c.K,
                           Eigen::Map<Eigen::VectorXi>(fixed.data(), static_cast<Eigen::Index>(fixed.size())),
                           Eigen::Map<Eigen::VectorXi>(kept.data(), static_cast<Eigen::Index>(kept.size())));
    return c;
}

}  // namespace aneu::test
