// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The simulator's view of a case bundle: mesh nodes and the columns of W its working region needs.
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "aneu/core/bundle.hpp"

namespace aneu::sim {

/// A spherical working region [mm]: only DOFs of nodes inside it can receive contact loads.
struct RegionSphere {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    double radius_mm = 0.0;
};

/// What the simulator keeps in memory from a bundle.
struct SimModel {
    Eigen::MatrixX3d nodes;        ///< #N×3 mesh nodes [mm]
    Eigen::VectorXi dof_node;      ///< #M: node of each row of W (the bundle's full DOF map)
    Eigen::VectorXi dof_axis;      ///< #M: axis of each row
    std::vector<int> active;       ///< the loaded columns, as rows of the DOF map (sorted)
    Precision precision = Precision::FLOAT32;  ///< of W in the file; Wf or Wd is filled accordingly
    Eigen::MatrixXf Wf;            ///< #M×#active, W(:, active) when stored float32 [mm/N]
    Eigen::MatrixXd Wd;            ///< #M×#active, W(:, active) when stored float64 [mm/N]
    double load_seconds = 0.0;
};

/// Loads a case bundle for simulation, reading only the columns of W whose node lies in `region`
/// (all columns when no region is given) by HDF5 hyperslabs.
/// @throws InputError the file is not a condensed case bundle, or the region holds no simulated node
SimModel load_model(const std::string& bundle_path, const std::optional<RegionSphere>& region = std::nullopt);

}  // namespace aneu::sim
