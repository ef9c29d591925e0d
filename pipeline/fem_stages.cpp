// SPDX-License-Identifier: MIT
#include "aneu/core/common.hpp"
#include "aneu/pipeline/stages.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <set>

#include <Eigen/Geometry>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/fem/assembly.hpp"
#include "stage_util.hpp"

namespace aneu::pipeline {





std::string resolved_region_label(const VolumeData& v, const CondenseStageParams& p) {
    if (p.region_label == "all") return "";
    if (p.region_label != "auto") return p.region_label;
    if (p.region_sphere || p.region_box) return "";
    const auto it = std::find(v.region_names.begin(), v.region_names.end(), "aneurysm");
    if (it == v.region_names.end()) return "";
    const int r = static_cast<int>(it - v.region_names.begin());
    for (Eigen::Index t = 0; t < v.tet_region.size(); ++t)
        if (v.tet_region[t] == r) return "aneurysm";
    return "";
}

std::vector<int> kept_nodes(const VolumeData& v, const CondenseStageParams& p) {
    for (const char* s : {"outer", "fixed"})
        if (!v.node_sets.count(s)) throw InputError(std::string("condense: /volume has no node set '") + s + "'");
    std::set<int> fixed(v.node_sets.at("fixed").data(), v.node_sets.at("fixed").data() + v.node_sets.at("fixed").size());
    const std::string label = resolved_region_label(v, p);
    std::vector<char> in_label(static_cast<size_t>(v.nodes.rows()), label.empty());
    if (!label.empty()) {
        const auto it = std::find(v.region_names.begin(), v.region_names.end(), label);
        if (it == v.region_names.end()) throw InputError("condense: region label '" + label + "' is not a region of the mesh");
        const int r = static_cast<int>(it - v.region_names.begin());
        for (Eigen::Index t = 0; t < v.tets.rows(); ++t)
            if (v.tet_region[t] == r)
                for (Eigen::Index a = 0; a < v.tets.cols(); ++a) in_label[static_cast<size_t>(v.tets(t, a))] = 1;
        if (p.region_margin_mm > 0) {  // grow by the margin (straight-line distance to the region's nodes)
            // The region's nodes in cells of the margin's size: a node within the margin of one lies in one of the
            // 27 cells around its own.
            const double m = p.region_margin_mm, m2 = m * m;
            const auto cell = [&](const Eigen::Vector3d& x) {
                return std::array<long, 3>{static_cast<long>(std::floor(x.x() / m)), static_cast<long>(std::floor(x.y() / m)),
                                           static_cast<long>(std::floor(x.z() / m))};
            };
            std::map<std::array<long, 3>, std::vector<Eigen::Vector3d>> core;
            for (Eigen::Index n = 0; n < v.nodes.rows(); ++n)
                if (in_label[static_cast<size_t>(n)]) core[cell(v.nodes.row(n).transpose())].push_back(v.nodes.row(n).transpose());
            const Eigen::VectorXi& outer = v.node_sets.at("outer");
            for (Eigen::Index k = 0; k < outer.size(); ++k) {
                const Eigen::Vector3d x = v.nodes.row(outer[k]).transpose();
                const auto c = cell(x);
                bool near = false;
                for (long i = -1; i <= 1 && !near; ++i)
                    for (long j = -1; j <= 1 && !near; ++j)
                        for (long l = -1; l <= 1 && !near; ++l) {
                            const auto it = core.find({c[0] + i, c[1] + j, c[2] + l});
                            if (it == core.end()) continue;
                            for (const auto& y : it->second)
                                if ((x - y).squaredNorm() <= m2) {
                                    near = true;
                                    break;
                                }
                        }
                if (near) in_label[static_cast<size_t>(outer[k])] = 1;
            }
        }
    }
    std::vector<char> corner(static_cast<size_t>(v.nodes.rows()), v.tets.cols() == 4 || p.nodes == "all");
    for (Eigen::Index t = 0; t < v.tets.rows(); ++t)
        for (int a = 0; a < 4; ++a) corner[static_cast<size_t>(v.tets(t, a))] = 1;
    std::vector<int> kept;
    const Eigen::VectorXi& outer = v.node_sets.at("outer");
    for (Eigen::Index k = 0; k < outer.size(); ++k) {
        const int n = outer[k];
        if (fixed.count(n) || !in_label[static_cast<size_t>(n)] || !corner[static_cast<size_t>(n)]) continue;
        const Eigen::Vector3d x = v.nodes.row(n).transpose();
        if (p.region_sphere) {
            const auto& s = *p.region_sphere;
            if ((x - Eigen::Vector3d(s[0], s[1], s[2])).norm() > s[3]) continue;
        }
        if (p.region_box) {
            const auto& b = *p.region_box;
            if (x.x() < b[0] || x.y() < b[1] || x.z() < b[2] || x.x() > b[3] || x.y() > b[4] || x.z() > b[5]) continue;
        }
        kept.push_back(n);
    }
    if (kept.empty()) throw InputError("condense: the working region contains no simulated node (outer, not fixed)");
    return kept;
}

void tubewall_file(const TubeWallParams& p, const std::string& out, StageRecord stage, Reporter& rep) {
    validate(p);
    const Stopwatch t0;
    Bundle b;
    b.meta.case_id = case_id_of(out);
    if (p.sac_radius_mm > 0) {
        b.surfaces["wall"] = tube_sac_wall_surface({p.inner_radius_mm, p.thickness_mm, p.length_mm, p.sac_radius_mm,
                                                    p.sac_thickness_mm, p.neck_radius_mm, p.edge_mm});
    } else {
        b.surfaces["wall"] = tube_wall_surface(p.inner_radius_mm, p.thickness_mm, p.length_mm, p.n_theta, p.n_z, p.bend_radius_mm);
    }
    finish(b, stage, t0, out, rep);
}

void tetmesh_file(const std::string& in, const std::string& out, const TetMeshParams& p, StageRecord stage, Reporter& rep) {
    validate(p);
    const Stopwatch t0;
    Bundle b = read_bundle(in);
    const auto it = b.surfaces.find("wall");
    if (it == b.surfaces.end()) throw InputError(in + ": no /surface/wall (run `aneuprep wall` or `aneuprep tubewall` first)");
    b.volume = tetmesh(it->second, p, rep);
    b.fem.reset();
    b.condensed.reset();
    finish(b, stage, t0, out, rep);
}

void assemble_file(const std::string& in, const std::string& out, const AssembleParams& p, StageRecord stage, Reporter& rep) {
    validate(p);
    const Stopwatch t0;
    Bundle b = read_bundle(in);
    if (!b.volume) throw InputError(in + ": no /volume (run `aneuprep tetmesh` first)");
    VolumeData& v = *b.volume;
    if (v.tets.cols() != 4) throw InputError(in + ": /volume is already quadratic; assemble a file from `tetmesh`");
    if (!v.node_sets.count("fixed")) throw InputError(in + ": /volume has no node set 'fixed'");
    fem::check_constrained(v.nodes, v.tets, v.node_sets.at("fixed"));
    if (p.element_order == 2) {
        const int n_lin = static_cast<int>(v.nodes.rows());
        const fem::QuadraticMesh q = fem::quadratic_mesh(v.nodes, v.tets);
        for (auto& [name, set] : v.node_sets) set = fem::quadratic_node_set(q, v.tets, n_lin, set);
        v.nodes = q.V;
        v.tets = q.T;
    }
    std::vector<Material> mats;
    for (const auto& r : v.region_names) {
        if (r == "artery") {
            mats.push_back({r, p.E_artery_mpa, p.nu_artery});
        } else if (r == "aneurysm") {
            mats.push_back({r, p.E_aneurysm_mpa, p.nu_aneurysm});
        } else {
            throw InputError(in + ": region '" + r + "' has no material (expected artery or aneurysm)");
        }
    }
    // Slivers: quality η = 6√2·V / l_rms³ (1 for a regular tetrahedron, → 0 when flat). Their stiffness grows as
    // 1/η and spoils K's conditioning; say where they are (TetGen's bounds normally keep η well above 0.01).
    {
        double worst = 1e300;
        Eigen::Index worst_t = -1, n_bad = 0;
        for (Eigen::Index t = 0; t < v.tets.rows(); ++t) {
            const Eigen::Vector3d a = v.nodes.row(v.tets(t, 0)), b = v.nodes.row(v.tets(t, 1)), c = v.nodes.row(v.tets(t, 2)),
                                  d = v.nodes.row(v.tets(t, 3));
            const double vol = std::abs((b - a).cross(c - a).dot(d - a)) / 6.0;
            const double l2 = ((b - a).squaredNorm() + (c - a).squaredNorm() + (d - a).squaredNorm() + (c - b).squaredNorm() +
                               (d - b).squaredNorm() + (d - c).squaredNorm()) / 6.0;
            const double eta = 6.0 * std::sqrt(2.0) * vol / std::pow(l2, 1.5);
            if (eta < worst) {
                worst = eta;
                worst_t = t;
            }
            n_bad += eta < 1e-3;
        }
        stage.qa.emplace_back("min_tet_quality", worst);
        stage.qa.emplace_back("tets_quality_below_1e-3", static_cast<double>(n_bad));
        if (n_bad > 0) {
            const Eigen::Vector3d g = (v.nodes.row(v.tets(worst_t, 0)) + v.nodes.row(v.tets(worst_t, 1)) + v.nodes.row(v.tets(worst_t, 2)) +
                                       v.nodes.row(v.tets(worst_t, 3))).transpose() / 4.0;
            rep.warn("assemble: " + std::to_string(n_bad) + " sliver tetrahedra (quality < 1e-3; the worst " + shortest(worst) + ", tet " +
                     std::to_string(worst_t) + " near " + shortest(g.x()) + ", " + shortest(g.y()) + ", " + shortest(g.z()) +
                     " mm): K is ill-conditioned there; remesh (tetmesh --min-dihedral-deg, --max-volume-mm3)");
        }
    }
    // Near incompressibility, 4-node tetrahedra lock: measured on the Lamé tube at h = 0.2 mm (test
    // NearIncompressibleLinearTetsLockQuadraticTetsDoNot) the wall is 3 % too stiff at ν = 0.45, 9 % at 0.49,
    // 18 % at 0.499 and 21 % at 0.4999; 10-node tetrahedra stay within 0.5 %.
    for (const auto& m : mats) {
        if (p.element_order == 1 && m.nu >= 0.49) {
            rep.warn("assemble: region '" + m.region + "': nu = " + shortest(m.nu) + " with 4-node tetrahedra: volumetric locking "
                     "makes the wall stiffer than it is (about " + (m.nu >= 0.499 ? std::string("20") : std::string("10")) +
                     " % on a tube at 0.2 mm elements); use --element-order 2");
        }
    }
    FemData fe;
    fe.element_order = p.element_order;
    const auto K = fem::assemble_stiffness(v.nodes, v.tets, v.tet_region, mats, rep);
    fe.K = K.triangularView<Eigen::Upper>();
    fe.K.makeCompressed();
    fe.K_upper_only = true;
    fe.materials = mats;
    const Eigen::VectorXi& fixed = v.node_sets.at("fixed");
    fe.fixed_dofs.resize(3 * fixed.size());
    for (Eigen::Index k = 0; k < fixed.size(); ++k)
        for (int a = 0; a < 3; ++a) fe.fixed_dofs[3 * k + a] = 3 * fixed[k] + a;
    std::sort(fe.fixed_dofs.data(), fe.fixed_dofs.data() + fe.fixed_dofs.size());
    rep.info("assemble: " + std::to_string(K.rows()) + " DOFs, " + std::to_string(K.nonZeros()) + " nonzeros, order " +
             std::to_string(p.element_order));
    b.fem = std::move(fe);
    b.condensed.reset();
    finish(b, stage, t0, out, rep);
}

void condense_file(const std::string& in, const std::string& out, const CondenseStageParams& p, StageRecord stage, Reporter& rep) {
    validate(p);
    const Stopwatch t0;
    Bundle b = read_bundle(in);
    if (!b.volume || !b.fem) throw InputError(in + ": needs /volume and /fem (run `aneuprep assemble` first)");
    const std::vector<int> nodes = kept_nodes(*b.volume, p);
    {
        const std::string label = resolved_region_label(*b.volume, p);
        rep.info(label.empty() ? std::string("condense: working region: every outer node") + (p.region_label == "auto" && !p.region_sphere && !p.region_box ? " (no aneurysm region in the mesh)" : "") +
                                     (p.region_sphere || p.region_box ? " inside the given sphere/box" : "")
                               : "condense: working region: region '" + label + "' and " + shortest(p.region_margin_mm) + " mm around it (" +
                                     std::to_string(nodes.size()) + " of " + std::to_string(b.volume->node_sets.at("outer").size()) + " outer nodes)");
    }
    Eigen::VectorXi kept(3 * static_cast<Eigen::Index>(nodes.size()));
    for (size_t k = 0; k < nodes.size(); ++k)
        for (int a = 0; a < 3; ++a) kept[3 * static_cast<Eigen::Index>(k) + a] = 3 * nodes[k] + a;
    // K is stored as its upper triangle: the sparse method reads only that; the dense one needs both.
    const bool symmetrise = b.fem->K_upper_only && p.numeric.method == fem::CondenseMethod::DENSE;
    Eigen::SparseMatrix<double, Eigen::RowMajor> full;
    if (symmetrise) full = b.fem->K.selfadjointView<Eigen::Upper>();
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& K = symmetrise ? full : b.fem->K;
    b.condensed = fem::condense(K, b.fem->fixed_dofs, kept, p.numeric, rep);
    finish(b, stage, t0, out, rep);
}

}  // namespace aneu::pipeline
