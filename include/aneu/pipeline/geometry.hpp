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
#include "aneu/core/options.hpp"
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
    double bone_clearance_mm = 2.0;               ///< with automatic bone detection: no lumen within this of bone
    double air_clearance_mm = 1.5;                ///< likewise, no lumen within this of air (< −300 HU: sinus walls blur into contrast)
    std::vector<EndPlane> planes;                 ///< given end planes (replace the detected ones)
};
/// The options of `aneuprep segment`, declared once (command line, case config, --set, validation,
/// provenance, --help: aneu/core/options.hpp).
inline const opt::Spec<SegmentParams>& segment_spec() {
    using namespace opt;
    using P = SegmentParams;
    static const Spec<P> spec = [] {
        Spec<P> s("segment");
        s.optional_numbers<6>("roi-mm", &P::roi_mm, "mm", "whole image", "region of interest xmin,ymin,zmin,xmax,ymax,zmax (default: whole image)")
            .integer("smoothing-iterations", &P::smoothing_iterations, closed(0, 100), "anisotropic diffusion steps (0 = off)")
            .real("conductance-hu-per-mm", &P::conductance_hu_per_mm, "HU/mm", gt(0), "diffusion keeps gradients well above this as edges")
            .optional_real("threshold-hu", &P::threshold_hu, "HU", "auto", "lumen threshold or 'auto' (half maximum between tissue and lumen)")
            .optional_real("upper-hu", &P::upper_hu, "HU", "none", "upper lumen threshold or 'none'")
            .tuples<3>("seed", &P::seeds_mm, "mm", "auto", "seed point x,y,z in the lumen (repeatable; default: automatic)")
            .named("seeds_mm")
            .text("select", &P::select, {"seed", "largest"}, "seed: the seed-connected lumen; largest: the largest component")
            .flag("fill-holes", &P::fill_holes, "fill cavities of the mask")
            .real("min-end-area-mm2", &P::min_end_area_mm2, "mm²", gt(0), "smaller crossings of the ROI border are not vessel ends")
            .real("end-inset-mm", &P::end_inset_mm, "mm", ge(0), "end plane distance inside the ROI border along the centerline (0 = automatic)", "auto")
            .real("bone-clearance-mm", &P::bone_clearance_mm, "mm", closed(0, 10),
                  "with the automatic threshold, when bone brighter than the vessels is found: no lumen within this of it (its blurred rim)")
            .real("air-clearance-mm", &P::air_clearance_mm, "mm", closed(0, 10), "with the automatic threshold, when bone is found: no lumen within this of air (< -300 HU: thin bone round the sinuses)");
        Option planes;
        planes.key = "plane";
        planes.name = "planes";
        planes.unit = "mm";
        planes.form = Form::REPEATED;
        planes.count = 7;
        planes.help = "end plane x,y,z,nx,ny,nz,radius (repeatable; replaces the detected planes)";
        s.custom(
            planes,
            [](P& p, const std::vector<std::string>& v) {
                p.planes.clear();
                for (const auto& text : v) {
                    const auto x = parse_numbers({text}, 7, "--plane '" + text + "'");
                    EndPlane e;
                    e.id = static_cast<int>(p.planes.size());
                    e.point = Eigen::Vector3d(x[0], x[1], x[2]);
                    e.normal = Eigen::Vector3d(x[3], x[4], x[5]);
                    if (e.normal.norm() > 0) e.normal.normalize();
                    e.radius_mm = x[6];
                    p.planes.push_back(e);
                }
            },
            [](const P& p) {
                std::string t;
                for (const auto& e : p.planes) {
                    t += (t.empty() ? "" : ";") + join_numbers(std::array<double, 7>{e.point.x(), e.point.y(), e.point.z(), e.normal.x(),
                                                                                      e.normal.y(), e.normal.z(), e.radius_mm});
                }
                return t.empty() ? std::string("auto") : t;
            },
            [](const P& p) {
                for (const auto& e : p.planes) {
                    if (!(e.radius_mm > 0) || !(std::abs(e.normal.norm() - 1.0) < 1e-6)) {
                        throw InputError("segment: --plane " + std::to_string(e.id) + ": needs a unit normal and a radius > 0");
                    }
                }
            });
        s.rule([](const P& p) {
             if (p.roi_mm) {
                 const auto& b = *p.roi_mm;
                 if (!(b[0] < b[3] && b[1] < b[4] && b[2] < b[5])) throw InputError("segment: --roi-mm needs xmin < xmax, ymin < ymax, zmin < zmax");
             }
         }).rule([](const P& p) {
            if (p.threshold_hu && p.upper_hu && !(*p.upper_hu > *p.threshold_hu)) throw InputError("segment: --upper-hu must be above --threshold-hu");
        });
        return s;
    }();
    return spec;
}
/// @throws InputError naming the first invalid field
inline void validate(const SegmentParams& p) { segment_spec().validate(p); }

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
    int ends_moved_to_tubular = 0;  ///< automatic planes moved inwards past a sheet- or lump-like cross-section
    int ends_not_tubular = 0;       ///< automatic planes with no tubular cross-section within reach (kept)
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
    double weld_mm = 0.0;                 ///< surface input: vertices closer than this are one; 0 = 1e-6 of the bounding-box diagonal
};
/// The options of `aneuprep surface`, declared once.
inline const opt::Spec<SurfaceParams>& surface_spec() {
    using namespace opt;
    using P = SurfaceParams;
    static const Spec<P> spec = [] {
        Spec<P> s("surface");
        s.real("edge-mm", &P::edge_mm, "mm", gt(0), "target edge length")
            .text("remesher", &P::remesher, {"netgen", "cgal"}, "netgen (the published method) or cgal (isotropic remeshing)")
            .integer("smoothing-iterations", &P::smoothing_iterations, ge(0), "windowed-sinc smoothing iterations (0 = off)")
            .real("smoothing-passband", &P::smoothing_passband, "", open(0, 2), "windowed-sinc pass band (smaller = smoother)")
            .real("iso-hu", &P::iso_hu, "HU", any(), "isosurface level (0 = the segmentation's threshold)", "segmentation threshold")
            .real("aneurysm-ratio-high", &P::aneurysm_ratio_high, "", gt(1), "sac seed: centerline distance > this x local radius")
            .real("aneurysm-ratio-low", &P::aneurysm_ratio_low, "", gt(1), "sac growth: connected faces above this x local radius")
            .optional_numbers<4>("aneurysm-sphere", &P::aneurysm_sphere, "mm", "none", "override: faces inside x,y,z,r are the sac")
            .text("aneurysm-labelmap", &P::aneurysm_labelmap, {}, "override: image whose non-zero voxels are the sac (e.g. painted in 3D Slicer)", "none")
            .real("timeout-s", &P::timeout_s, "s", gt(0), "kill Netgen after this many seconds, then remesh with CGAL")
            .real("cap-tolerance-deg", &P::cap_tolerance_deg, "deg", open(0, 45), "surface input: a flat end cap's faces turn at most this from its fitted plane")
            .real("cap-tolerance-mm", &P::cap_tolerance_mm, "mm", open(0, 10), "surface input: a flat end cap's vertices lie at most this from its fitted plane")
            .real("input-scale", &P::input_scale, "", open(0, 1e7), "surface input: multiply coordinates by this (1000 for a file in metres)")
            .real("end-clearance-mm", &P::end_clearance_mm, "mm", closed_open(0, 100), "move end planes inward until other vessels are this far from the cut")
            .real("weld-mm", &P::weld_mm, "mm", closed(0, 0.1), "surface input: merge vertices closer than this (0 = 1e-6 of the bounding-box diagonal)",
                  "1e-6 of the diagonal")
            .rule([](const P& p) {
                if (!(p.aneurysm_ratio_high >= p.aneurysm_ratio_low)) throw InputError("surface: need --aneurysm-ratio-high >= --aneurysm-ratio-low > 1");
            })
            .rule([](const P& p) {
                if (p.aneurysm_sphere && !((*p.aneurysm_sphere)[3] > 0)) throw InputError("surface: --aneurysm-sphere radius must be > 0");
                if (p.aneurysm_sphere && !p.aneurysm_labelmap.empty()) throw InputError("surface: give --aneurysm-sphere or --aneurysm-labelmap, not both");
            });
        return s;
    }();
    return spec;
}
inline void validate(const SurfaceParams& p) { surface_spec().validate(p); }

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

/// What the automatic label found: every connected candidate piece, and the one kept.
struct SacCandidates {
    struct Piece {
        double area_mm2 = 0, max_ratio = 0;
        Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
        double d90_mm = 0;    ///< 90th percentile of its faces' distance to the nearest centerline segment
        double along_mm = 0;  ///< length of centerline its faces project to (0.25 mm bins, per branch)
        bool tube = false;    ///< along_mm > TUBE_ALONG_PER_DISTANCE × d90_mm: a stretch of vessel, never the sac
    };
    std::vector<Piece> pieces;  ///< in face order of their first face
    int kept = -1;              ///< index into pieces; -1 when there is none
};
/// A candidate whose faces stay within d90 of the centerline along more than this many times d90 of it is a
/// stretch of vessel (real sacs: 0.5–2.2; a thin vessel against another in a real CTA: 17).
inline constexpr double TUBE_ALONG_PER_DISTANCE = 4.0;
/// Labels every face artery (0) or aneurysm (1): hysteresis on (distance to the centerline) / (local radius),
/// then one sac: of the connected candidate pieces that are not tubes (above), the most prominent (area ×
/// (largest ratio − 1)) is kept. The others are bulges the ratio also sees — a junction's, a flattened vessel's
/// sides, a faded branch's blind tip (measured: up to 11 pieces of 1.6–24 mm² on a real Circle of Willis, 3 beside
/// a real sac) — and become artery. When every candidate is a tube, no face is aneurysm.
Eigen::VectorXi label_aneurysm(const SurfaceData& s, const Centerline& c, double ratio_high, double ratio_low, SacCandidates* found = nullptr);

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
    double blend_mm = 1.0;               ///< width of the thickness change across the neck: ±blend/2 about the label border, at most 1.5·Δt/blend per mm
    double grid_spacing_mm = 0.0;        ///< narrow-band distance-field grid; 0 = min(thinnest wall, outer edge / 2)
    double edge_mm = 0.0;                ///< target edge of the outer surface; 0 = the lumen's mean edge
    std::string remesher = "cgal";       ///< cgal or netgen, for the outer surface
    double timeout_s = 30.0;             ///< a Netgen remesh is killed after this; then CGAL runs
};
/// The options of `aneuprep wall`, declared once.
inline const opt::Spec<WallParams>& wall_spec() {
    using namespace opt;
    using P = WallParams;
    static const Spec<P> spec = [] {
        Spec<P> s("wall");
        s.real("artery-thickness-mm", &P::artery_thickness_mm, "mm", gt(0), "wall thickness of the artery")
            .real("aneurysm-thickness-mm", &P::aneurysm_thickness_mm, "mm", ge(0), "wall thickness of the sac (0 = one third of the artery's)", "artery / 3")
            .real("blend-mm", &P::blend_mm, "mm", gt(0), "width of the thickness transition across the neck")
            .real("grid-spacing-mm", &P::grid_spacing_mm, "mm", ge(0), "distance-field grid spacing (0 = the thinner of the thinnest wall and half the outer edge)",
                  "min(thinnest wall, outer edge / 2)")
            .real("edge-mm", &P::edge_mm, "mm", ge(0), "target edge of the outer surface (0 = the lumen's mean edge)", "lumen mean edge")
            .text("remesher", &P::remesher, {"cgal", "netgen"}, "remesher of the outer surface")
            .real("timeout-s", &P::timeout_s, "s", gt(0), "kill Netgen after this many seconds, then remesh with CGAL");
        return s;
    }();
    return spec;
}
inline void validate(const WallParams& p) { wall_spec().validate(p); }

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
