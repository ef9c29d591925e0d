// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Geometry stages: `segment` (CT volume → lumen mask, centerline, end planes), `surface` (→ labelled lumen
/// surface) and `wall` (→ closed, labelled wall surface). Every automatic decision (threshold, seed, end
/// planes, aneurysm label) can be overridden by a parameter. Lengths in mm, intensities in HU.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

// ---------------------------------------------------------------- segment
/// Parameters of `aneuprep segment`.
struct SegmentParams {
    std::optional<std::array<double, 6>> roi_mm;  ///< xmin,ymin,zmin,xmax,ymax,zmax (physical); none = whole image
    int smoothing_iterations = 5;                 ///< gradient anisotropic diffusion steps (0 = off)
    double conductance_hu_per_mm = 100.0;         ///< gradients well above this are kept as edges
    std::optional<double> threshold_hu;           ///< lower lumen threshold; none = automatic (half maximum)
    std::optional<double> upper_hu;               ///< upper lumen threshold; none = no upper bound
    std::vector<std::array<double, 3>> seeds_mm;  ///< region-growing seeds; none = automatic (brightest vessel tree)
    std::string select = "seed";                  ///< "seed": seed-connected lumen; "largest": largest component
    bool fill_holes = true;
    double min_end_area_mm2 = 0.5;                ///< smaller crossings of the ROI border are not vessel ends
    double end_inset_mm = 0.0;                    ///< end plane distance inside the border; 0 = automatic
    std::vector<EndPlane> planes;                 ///< given end planes (replace the detected ones)
};
/// @throws InputError naming the first invalid field
void validate(const SegmentParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const SegmentParams& p);

/// Result of a segmentation: /image content and QA figures.
struct Segmentation {
    ImageData image;  ///< ROI grid, mask (1 = lumen), smoothed intensity, threshold, centerline, planes
    NamedValues qa;
};

/// Segments the lumen of a CT volume (DICOM directory, NIfTI, NRRD, MHA).
/// @throws InputError unreadable image, ROI outside the image, seed outside the ROI or the lumen,
///         threshold that selects nothing, a lumen that does not leave the ROI at two ends
Segmentation segment(const std::string& image_path, const SegmentParams& p, Reporter& rep = null_reporter());

/// The same on a volume already in memory (tests).
Segmentation segment_volume(const Volume<float>& ct, const SegmentParams& p, Reporter& rep = null_reporter());

/// Centerline of a binary lumen mask by minimal paths through its distance map, from the largest end to
/// every other; ends are the given voxel sets (one per end). Radius per point from the distance map.
/// Returns the centerline and one plane per end (`inset_mm` inside along the centerline; 0 = automatic:
/// the first point whose cross-section disc lies wholly inside the ROI, plus two voxels).
struct CenterlineResult {
    Centerline centerline;
    std::vector<EndPlane> planes;
};
CenterlineResult centerline_from_ends(const Volume<std::uint8_t>& mask, const Volume<float>& inside_distance,
                                      const std::vector<std::uint8_t>& roi, const std::vector<std::vector<std::size_t>>& ends,
                                      double inset_mm);

/// Voxel sets where a mask touches the border of its ROI (or grid), at least `min_area_mm2` each, largest first.
std::vector<std::vector<std::size_t>> border_crossings(const Volume<std::uint8_t>& mask, const std::vector<std::uint8_t>& roi,
                                                       double min_area_mm2);

void segment_file(const std::string& image_path, const std::string& out, const SegmentParams& p, StageRecord stage,
                  const std::string& snapshot_png = "", Reporter& rep = null_reporter());

// ---------------------------------------------------------------- surface
/// Parameters of `aneuprep surface`.
struct SurfaceParams {
    double edge_mm = 0.4;                 ///< target edge length of the remeshed surface
    std::string remesher = "netgen";      ///< netgen (the published method) or cgal
    int smoothing_iterations = 20;        ///< windowed-sinc iterations (0 = off)
    double smoothing_passband = 0.1;
    double iso_hu = 0.0;                  ///< isosurface level on the smoothed CT; 0 = the segmentation's threshold
    double aneurysm_ratio_high = 1.6;     ///< a face is surely sac when its centerline distance > this × local radius
    double aneurysm_ratio_low = 1.4;      ///< ... and the sac grows over connected faces above this
    std::optional<std::array<double, 4>> aneurysm_sphere;  ///< override: faces whose centroid is inside are the sac
    std::string aneurysm_labelmap;        ///< override: image whose non-zero voxels are the sac
    double timeout_s = 30.0;              ///< Netgen runs in a child process, killed after this; then CGAL runs
    double cap_tolerance_deg = 5.0;       ///< surface input: a cap's faces turn at most this from its plane
    double cap_tolerance_mm = 0.1;        ///< surface input: a cap's vertices lie at most this from its plane
    double input_scale = 1.0;             ///< surface input: coordinates are multiplied by this (1000 for a file in metres)
    double end_clearance_mm = 1.0;        ///< end planes move inward until other vessels are this far from the cut (≥ 2 × the wall)
};
void validate(const SurfaceParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const SurfaceParams& p);

/// Result of `surface`: the lumen surface (labels artery/aneurysm, loops with end ids), the /image it was
/// made from (for a mesh input: the voxelised surface with its centerline and planes) and QA figures.
struct LumenResult {
    SurfaceData lumen;
    ImageData image;
    NamedValues qa;
};
/// From a segmentation (/image with intensity, threshold, planes, centerline).
LumenResult lumen_from_segmentation(const ImageData& seg, const SurfaceParams& p, Reporter& rep = null_reporter());
/// From a lumen surface made by another tool (STL/VTP/OBJ/PLY): open ends, or flat caps that are removed.
/// @throws InputError non-manifold surface, no open end and no detectable cap
LumenResult lumen_from_mesh(const std::string& path, const SurfaceParams& p, Reporter& rep = null_reporter());

/// Labels every face artery (0) or aneurysm (1): hysteresis on (distance to the centerline) / (local radius).
Eigen::VectorXi label_aneurysm(const SurfaceData& s, const Centerline& c, double ratio_high, double ratio_low);

/// Flat caps of a closed surface (the inlet/outlet caps of a CFD lumen mesh): connected sets of faces whose
/// normals lie within `tol_deg` of their area-weighted mean and whose vertices lie within `tol_mm` of the
/// plane fitted to them, bounded by a crease against the wall (at least 90 % of the border edges turn by
/// more than 30°).
std::vector<std::vector<int>> detect_flat_caps(const SurfaceData& s, double tol_deg = 5.0, double tol_mm = 0.1);

/// Rounded ends of a closed surface (a segmentation's blind vessel ends): one end plane per skeleton tip whose
/// vessel becomes tubular within a few radii of the tip (radius within ±15 % of its median over 3 radii),
/// half a radius inside that point, perpendicular to the medial path, normal towards the tip. Tips that never
/// become tubular (a sac, a bleb, a bump at a junction) are kept whole and listed. Voxels of `spacing_mm`.
/// pipeline/rounded_ends.cpp (TEASAR-style tips on the voxelised surface).
struct RoundedEnds {
    std::vector<EndPlane> planes;
    std::vector<Eigen::Vector3d> tips;  ///< per plane: the tip it cuts off
    std::vector<Eigen::Vector3d> kept_tips;
};
RoundedEnds find_rounded_ends(const SurfaceData& closed, double spacing_mm);

void surface_file(const std::string& in, const std::string& out, const SurfaceParams& p, StageRecord stage,
                  const std::string& snapshot_png = "", Reporter& rep = null_reporter());

// ---------------------------------------------------------------- wall
/// Parameters of `aneuprep wall`.
struct WallParams {
    double artery_thickness_mm = 0.4;
    double aneurysm_thickness_mm = 0.0;  ///< 0 = one third of the artery's (as published)
    double blend_mm = 1.0;               ///< the thickness changes across the neck at most 1.5·Δt/blend per mm (over ±blend about the label border)
    double grid_spacing_mm = 0.0;        ///< narrow-band distance-field grid; 0 = min(thinnest wall, outer edge / 2)
    double edge_mm = 0.0;                ///< target edge of the outer surface; 0 = the lumen's mean edge
    std::string remesher = "cgal";       ///< cgal or netgen, for the outer surface
    double timeout_s = 30.0;             ///< a Netgen remesh is killed after this; then CGAL runs
};
void validate(const WallParams& p);
std::vector<std::pair<std::string, std::string>> parameter_list(const WallParams& p);

/// Result of `wall`: the closed wall surface (labels inner, outer, cap:<end>; regions artery/aneurysm;
/// thickness per outer vertex) and QA figures (thickness statistics per region, checks, triangle quality).
struct WallResult {
    SurfaceData wall;
    NamedValues qa;
};
/// @throws MeshingError naming the failed check (closed, manifold, oriented, self-intersection) and where
WallResult make_wall(const SurfaceData& lumen, const std::vector<EndPlane>& planes, const WallParams& p, Reporter& rep = null_reporter());

void wall_file(const std::string& in, const std::string& out, const WallParams& p, StageRecord stage,
               const std::string& snapshot_png = "", Reporter& rep = null_reporter());

}  // namespace aneu::pipeline
