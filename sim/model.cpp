// SPDX-License-Identifier: MIT
#include "aneu/sim/model.hpp"

#include <chrono>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"

namespace aneu::sim {

SimModel load_model(const std::string& bundle_path, const std::optional<RegionSphere>& region) {
    const auto t0 = std::chrono::steady_clock::now();
    BundleParts parts;
    parts.image = parts.surfaces = parts.fem = parts.condensed_W = false;
    Bundle b = read_bundle(bundle_path, parts);
    if (!b.condensed) {
        throw InputError(bundle_path + ": no /condensed group; run `aneuprep condense` to make a case bundle");
    }
    if (!b.volume) throw InputError(bundle_path + ": no /volume group; a case bundle needs the mesh nodes");
    SimModel m;
    m.nodes = std::move(b.volume->nodes);
    m.dof_node = std::move(b.condensed->dof_node);
    m.dof_axis = std::move(b.condensed->dof_axis);
    m.precision = b.condensed->precision;
    for (Eigen::Index r = 0; r < m.dof_node.size(); ++r) {
        const int node = m.dof_node[r];
        if (node >= m.nodes.rows()) {
            throw InputError(bundle_path + ": /condensed/dof_node[" + std::to_string(r) + "] = " + std::to_string(node) +
                             " but /volume has " + std::to_string(m.nodes.rows()) + " nodes");
        }
        if (!region || (m.nodes.row(node).transpose() - region->centre).norm() <= region->radius_mm) {
            m.active.push_back(static_cast<int>(r));
        }
    }
    if (m.active.empty()) {
        throw InputError(bundle_path + ": the working region (centre " + std::to_string(region->centre.x()) + "," +
                         std::to_string(region->centre.y()) + "," + std::to_string(region->centre.z()) + ", radius " +
                         std::to_string(region->radius_mm) + " mm) contains no simulated node");
    }
    if (m.precision == Precision::FLOAT32) {
        m.Wf = read_condensed_columns_f(bundle_path, m.active);
    } else {
        m.Wd = read_condensed_columns(bundle_path, m.active);
    }
    m.load_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return m;
}

}  // namespace aneu::sim
