// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// In-memory form of a case bundle (schema v1, docs/hdf5_layout.md). Every stage file is a Bundle with
/// the groups that exist so far; the last stage's file is the case bundle the simulator loads.
/// Units: mm, N, MPa (= N/mm²), s. Indices are 0-based.
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/image_grid.hpp"
#include "aneu/core/tiled_symmetric.hpp"

namespace aneu {

/// (name, value) figures: QA numbers, quality statistics, diagnostics.
using NamedValues = std::vector<std::pair<std::string, double>>;

/// Schema version written by this build and the only one it reads.
inline constexpr int BUNDLE_SCHEMA_VERSION = 1;
/// Value of the /meta attribute `format`, to tell our files from other HDF5 files.
inline constexpr const char* BUNDLE_FORMAT = "aneuclip-bundle";

/// One input file of a stage and the SHA-256 of its content (hex; a directory hashes its sorted files).
struct InputFile {
    std::string path;
    std::string sha256;
};

/// Provenance of one stage run: who wrote the file, how, from what.
struct StageRecord {
    std::string stage;         ///< "phantom", "segment", ...
    std::string tool_version;  ///< aneu::tool_version() of the writer
    std::string git_revision;  ///< aneu::git_revision() of the writer
    std::string created_utc;   ///< ISO 8601, e.g. "2026-11-21T11:44:47Z"
    std::string command_line;  ///< the full command line, shell-quoted
    std::vector<std::pair<std::string, std::string>> parameters;  ///< every parameter, defaults included
    std::vector<InputFile> inputs;
    double wall_time_s = 0.0;
    std::vector<std::pair<std::string, double>> qa;  ///< the stage's QA figures (voxel counts, edge stats, ...)
};

/// /meta: identity of the case and the provenance of every stage that contributed to the file.
struct Meta {
    int schema_version = BUNDLE_SCHEMA_VERSION;
    std::string case_id;
    std::string units = "mm, N, MPa, s";
    std::vector<StageRecord> stages;  ///< in the order they ran
};

/// Centerline polylines with a radius per point.
struct Centerline {
    Eigen::MatrixX3d points;   ///< #P×3 [mm], physical frame
    Eigen::VectorXd radius;    ///< #P [mm]
    Eigen::VectorXi offsets;   ///< #L+1: polyline l is points[offsets[l] .. offsets[l+1])
};

/// A plane where a vessel leaves the region of interest.
struct EndPlane {
    int id = 0;                 ///< end id, referenced by boundary loops and caps
    Eigen::Vector3d point;      ///< on the centerline [mm]
    Eigen::Vector3d normal;     ///< unit, pointing out of the region
    double radius_mm = 0.0;     ///< lumen radius there
};

/// /image: segmentation (or ground-truth) mask with full geometry, centerline and end planes.
struct ImageData {
    ImageGrid grid;
    std::vector<std::uint8_t> mask;              ///< grid.voxel_count() labels, i fastest
    std::vector<std::string> mask_label_names;   ///< name of label value v at [v]; [0] = "background"
    std::vector<float> intensity;                ///< empty, or grid.voxel_count() smoothed CT values [HU]
    double threshold_hu = 0.0;                   ///< lumen threshold on `intensity` (when it is set)
    Centerline centerline;
    std::vector<EndPlane> planes;
};

/// A labelled triangle surface (/surface/<name>, e.g. "lumen", "wall").
struct SurfaceData {
    Eigen::MatrixX3d V;                    ///< #V×3 [mm]
    Eigen::MatrixX3i F;                    ///< #F×3 vertex indices, counter-clockwise seen from outside
    Eigen::VectorXi face_label;            ///< #F, index into label_names
    std::vector<std::string> label_names;  ///< e.g. {"artery","aneurysm"} or {"inner","outer","cap:0"}
    Eigen::VectorXi loop_offsets;          ///< #loops+1 (empty if none): loop l = loop_vertices[o[l]..o[l+1])
    Eigen::VectorXi loop_vertices;         ///< boundary loop vertex indices, in order
    Eigen::VectorXi loop_end_id;           ///< #loops: EndPlane::id of each loop
    Eigen::VectorXi face_region;           ///< #F or empty: index into region_names (artery/aneurysm)
    std::vector<std::string> region_names; ///< e.g. {"artery","aneurysm"}; empty if face_region is
    Eigen::VectorXd vertex_thickness;      ///< #V or empty: wall thickness at the vertex [mm] (wall stage)
    /// Per-face data, name -> #F×k, the unit at the end of the name (e.g. wall_shear_stress_pa; flow stage).
    std::map<std::string, Eigen::MatrixXd> face_fields;
};

/// /volume: the tetrahedral mesh of the wall.
struct VolumeData {
    Eigen::MatrixX3d nodes;                             ///< #N×3 [mm]
    Eigen::MatrixXi tets;                               ///< #T×4 (linear) or #T×10 (quadratic)
    Eigen::VectorXi tet_region;                         ///< #T, index into region_names
    std::vector<std::string> region_names;              ///< e.g. {"artery","aneurysm"}
    std::map<std::string, Eigen::VectorXi> node_sets;   ///< "outer", "inner", "fixed" -> node indices
    std::vector<std::pair<std::string, double>> quality;  ///< e.g. ("min_dihedral_deg", 12.3)
};

/// Isotropic linear-elastic material of one region.
struct Material {
    std::string region;
    double E_mpa = 1.0;
    double nu = 0.45;
};

/// /fem: the assembled stiffness matrix.
struct FemData {
    int element_order = 1;                              ///< 1 = 4-node, 2 = 10-node tetrahedra
    Eigen::SparseMatrix<double, Eigen::RowMajor> K;     ///< 3#N×3#N [N/mm], DOF 3*node+axis
    bool K_upper_only = true;                           ///< only the upper triangle is stored
    std::vector<Material> materials;
    Eigen::VectorXi fixed_dofs;                         ///< sorted DOF indices with u = 0
};

/// Storage precision of W in the file. W is always computed in double.
enum class Precision { FLOAT32, FLOAT64 };

/// /condensed: W = (K⁻¹)_MM on the kept DOF set M, the compliance seen from the simulated surface.
struct CondensedData {
    Eigen::VectorXi dof_node;    ///< #M: node of row r
    Eigen::VectorXi dof_axis;    ///< #M: axis (0,1,2) of row r
    Precision precision = Precision::FLOAT64;  ///< storage precision; also says which of W64/W32 is set
    TiledSymmetric<double> W64;  ///< #M×#M [mm/N] when precision = FLOAT64
    TiledSymmetric<float> W32;   ///< #M×#M [mm/N] when precision = FLOAT32
    std::string method;          ///< e.g. "sparse-cholmod-syrk"
    std::vector<std::pair<std::string, double>> diagnostics;  ///< time_s, peak_memory_bytes, residual, ...

    Eigen::Index size() const { return dof_node.size(); }
};

/// /flow: the blood's velocity and pressure at the fluid mesh's cell centres (the flow stage: OpenFOAM's finite
/// volumes), for streamlines and ParaView (`aneuprep export FLOW.h5 --format xdmf`: the cells as points).
struct FlowFieldData {
    Eigen::MatrixX3d centre;    ///< #C×3 [mm]
    Eigen::MatrixX3d velocity;  ///< #C×3 [mm/s]
    Eigen::VectorXd pressure;   ///< #C gauge pressure [Pa] (outlets at 0)
    Eigen::VectorXd volume;     ///< #C cell volume [mm³]
};

/// A whole stage file. Absent groups are not written.
struct Bundle {
    Meta meta;
    std::optional<ImageData> image;
    std::map<std::string, SurfaceData> surfaces;
    std::optional<VolumeData> volume;
    std::optional<FemData> fem;
    std::optional<CondensedData> condensed;
    std::optional<FlowFieldData> flow;
};

}  // namespace aneu
