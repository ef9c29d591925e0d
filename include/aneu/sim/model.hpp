// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The simulator's view of a case bundle: the simulated surface (boundary faces of the tetrahedral mesh
/// whose nodes all carry condensed DOFs) and the columns of W its working region needs.
#include <functional>
#include <memory>
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

/// A point of the neck line on the lumen: a face and barycentric weights of its corners (it moves with them).
struct NeckPointOnLumen {
    int face = -1;
    Eigen::Vector3d weights = Eigen::Vector3d::Zero();
};

/// Binomial (¼ ½ ¼) smoothing passes along a neck loop (smoothed_neck_line).
inline constexpr int NECK_SMOOTHING_PASSES = 10;

/// The lumen (the wall's inner surface) under the working region, for the assessment: the real-time model
/// computes the outer surface only, and each lumen vertex moves with the nearest simulated vertex (a thin wall:
/// its compression under a clip is small beside the displacements that close a neck).
struct SimLumen {
    Eigen::MatrixX3d X;                ///< #L×3 rest positions [mm]
    Eigen::MatrixX3i F;                ///< #F×3 triangles, normals out of the lumen (into the wall)
    Eigen::VectorXi face_region;       ///< #F: index into SimSurface::region_names
    Eigen::VectorXi node;              ///< #L: volume node of each vertex
    Eigen::VectorXi bind;              ///< #L: simulated-surface vertex whose displacement the vertex takes
    Eigen::VectorXd wall_mm;           ///< #L: distance to that vertex at rest (the local wall thickness)
    std::vector<std::vector<int>> neck_loops;  ///< closed vertex loops between "aneurysm" faces and others: the neck line
    /// Per neck loop, the neck line smoothed onto the lumen (smoothed_neck_line): what the occlusion is measured on.
    std::vector<std::vector<NeckPointOnLumen>> neck_line;
    /// Deformed positions, given the simulated surface's deformed positions `x` (#S×3) and rest positions `X`.
    Eigen::MatrixX3d deformed(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& X_sim) const;
};

/// The simulated (outer) surface, indexed by its own vertices s = 0..#S-1.
struct SimSurface {
    Eigen::MatrixX3d X;                ///< #S×3 rest positions [mm]
    Eigen::MatrixX3i F;                ///< #F×3 triangles (local vertex ids), counter-clockwise from outside
    Eigen::MatrixX3d N;                ///< #S×3 unit outward vertex normals at rest (area-weighted)
    Eigen::VectorXi node;              ///< #S: volume node of each vertex
    Eigen::MatrixX3i row;              ///< #S×3: row of W (in SimModel's permuted order) of each DOF
    Eigen::VectorXi face_region;       ///< #F: index into region_names
    std::vector<std::string> region_names;
    std::vector<int> adj_offsets;      ///< #S+1: neighbours of s are adj[adj_offsets[s] .. adj_offsets[s+1])
    std::vector<int> adj;
    std::vector<std::vector<int>> neck_loops;  ///< closed vertex loops between an "aneurysm" and another region
    /// #S local wall thickness [mm]: distance to the inner wall surface (faces of node set "inner"); NaN where
    /// the bundle has no inner node set or no inner face lies within 8 mm. Set by load_model.
    Eigen::VectorXd thickness;
    /// The lumen under the simulated surface (empty when the bundle has no "inner" node set). Set by load_model.
    SimLumen lumen;
    Eigen::Index size() const { return X.rows(); }
};

/// Local wall thickness at every vertex of `s`: the distance to the nearest boundary face of `tets` whose
/// corners are all in `inner` (NaN when there is none within 8 mm, or `inner` is empty).
Eigen::VectorXd wall_thickness(const SimSurface& s, const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets,
                               const Eigen::VectorXi& inner);

/// The lumen under a simulated surface: boundary faces of `tets` whose corners are all in `inner` (corner
/// faces of 10-node elements), regions from their tetrahedra, each vertex bound to the nearest simulated
/// vertex within 1.5 mm; faces with a vertex left unbound (outside the working region) are dropped.
SimLumen extract_lumen(const SimSurface& s, const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets, const Eigen::VectorXi& tet_region,
                       const Eigen::VectorXi& inner);

/// The lumen on the quadratic surface of 10-node elements, for measuring it (the neck's occlusion and channel):
/// every face of `lumen` split in four at its edges' mid-edge nodes (`mid(a, b)`: the volume node between volume
/// nodes a and b, −1 if none), children 4f … 4f + 3 of face f as fem::quadratic_surface_triangles orders them; the
/// lumen's vertices first, then one per edge (`between`: its two lumen vertices), at the mid-edge node's rest
/// position, its wall the mean of theirs, bound to the first. The neck loops pass through the mid-edge vertices
/// of their edges and the smoothed neck line keeps its points, on the children. On the corner triangles alone a
/// flattened fold's channel reads about twice what the quadratic surface leaves (bench/bench_fold.cpp).
/// @throws InputError an edge of the lumen has no mid-edge node
struct SplitLumen {
    SimLumen lumen;
    Eigen::MatrixX2i between;  ///< per vertex after the original ones: the two lumen vertices it lies between
};
SplitLumen split_lumen(const SimLumen& lumen, const std::function<int(int, int)>& mid, const Eigen::MatrixX3d& nodes);

/// The neck line of one loop, smoothed. A loop of label-border vertices is a staircase of mesh edges: on a
/// mesh of edge h it zig-zags by about h on either side of the sac's border (the sample's: 21.5 mm long where
/// the border it follows is 14 mm, its corners up to 0.25 mm further from the border's mean plane). A clip
/// blade's 1 mm face pinches the border, not the staircase's outer corners, so the occlusion is measured on the
/// border: the loop's rest positions after NECK_SMOOTHING_PASSES binomial passes (a zig-zag of period 2–4 vertices
/// falls to ≤ 0.1 %, of period 6 to 6 %; a loop of 60 vertices shrinks by 2.7 % towards its centre, about 0.07 mm
/// on the sample), each put back on the closest point of the lumen.
std::vector<NeckPointOnLumen> smoothed_neck_line(const SimLumen& lumen, const std::vector<int>& loop);

/// What the simulator keeps in memory from a bundle.
///
/// Rows of W are permuted so that the working region's rows come first: W's loaded columns are the
/// region's DOFs, and column j of Wf/Wd holds W(:, j) in the permuted row order. The top #active×#active
/// block is therefore the region's own (symmetric) block, contiguous in every column.
struct SimModel {
    Eigen::MatrixX3d nodes;        ///< #N×3 mesh nodes [mm]
    Eigen::VectorXi dof_node;      ///< #M: node of each row of W, in the permuted order
    Eigen::VectorXi dof_axis;      ///< #M: axis of each row
    Eigen::VectorXi file_row;      ///< #M: row of the bundle's DOF map each permuted row came from
    Eigen::Index n_active = 0;     ///< rows/columns 0..n_active-1 are the working region
    std::vector<int> active;       ///< the loaded columns, as rows of the bundle's DOF map, in spatial (Morton) order
    Precision precision = Precision::FLOAT32;  ///< of W in the file; Wf or Wd is filled accordingly
    Eigen::MatrixXf Wf;            ///< #M×#active when stored float32 [mm/N]
    Eigen::MatrixXd Wd;            ///< #M×#active when stored float64 [mm/N]
    SimSurface surface;
    /// The mesh and K (Scene::wall_model = PATCH: the nonlinear patch needs them; the Simulator reads them from
    /// the bundle when its scene asks for the patch and they are not here).
    std::shared_ptr<const VolumeData> volume;
    std::shared_ptr<const FemData> fem;
    /// The mesh nodes held at zero displacement (the bundle's "fixed" node set: the domain's cut ends, clamped);
    /// empty when the bundle has none. The planner keeps the jaws off them (plan.hpp).
    Eigen::VectorXi fixed_nodes;
    std::string case_id;
    double load_seconds = 0.0;
    bool is_float() const { return precision == Precision::FLOAT32; }
};

/// Options of load_model.
struct LoadOptions {
    std::optional<RegionSphere> region;        ///< none: the whole simulated surface
    std::optional<Precision> working_precision;  ///< convert W after reading (none: keep the file's)
    bool geometry_only = false;                  ///< the mesh, surface and lumen without W (planning, inspection)
};

/// Loads a case bundle for simulation, reading only the columns of W whose node lies in the region
/// (all columns when none is given) by HDF5 hyperslabs, and extracts the simulated surface.
/// @throws InputError the file is not a condensed case bundle of this schema, the DOF map does not fit the
///         mesh, or the region holds no simulated node
SimModel load_model(const std::string& bundle_path, const LoadOptions& opt = {});

/// Overload kept for the command line: region only.
inline SimModel load_model(const std::string& bundle_path, const std::optional<RegionSphere>& region) {
    LoadOptions o;
    o.region = region;
    return load_model(bundle_path, o);
}

/// The simulated surface of a mesh: boundary faces whose nodes all have their three DOFs in `row_of_dof`
/// (−1 = not condensed), oriented outward. 10-node elements: a face whose mid-edge nodes are condensed too is
/// split in four; one whose corners only are condensed (`condense --nodes corners`) is the corner triangle.
/// @param[in] row_of_dof  3#N: row of each DOF (3·node + axis), −1 if absent
SimSurface extract_surface(const Eigen::MatrixX3d& nodes, const Eigen::MatrixXi& tets, const Eigen::VectorXi& tet_region,
                           const std::vector<std::string>& region_names, const std::vector<int>& row_of_dof);

}  // namespace aneu::sim
