// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Pictures of stage results (VTK, rendered off screen to PNG).
#include <string>
#include <vector>

#include "aneu/core/bundle.hpp"

namespace aneu::pipeline {

/// What colours the faces of a surface snapshot.
enum class ColorBy { LABEL, REGION, THICKNESS, FIELD };

/// One surface of a snapshot.
struct SnapshotLayer {
    SurfaceData surface;
    ColorBy by = ColorBy::LABEL;  ///< THICKNESS uses SurfaceData::vertex_thickness (colour bar in mm)
    double opacity = 1.0;
    bool edges = true;
    /// FIELD: the face field (SurfaceData::face_fields; its magnitude when it has 3 columns), coloured blue (low)
    /// to red (high) up to its 98th percentile, so that one extreme (a plug inlet's rim) does not wash out the rest.
    std::string field;
};
/// A picture: surfaces, optionally a centerline (tubes) and end planes (discs with their normals), a title.
struct SnapshotScene {
    std::vector<SnapshotLayer> layers;
    Centerline centerline;
    std::vector<EndPlane> planes;
    std::string title;
    /// Polylines (streamlines) coloured by a value per point, blue (low) to red (its 98th percentile), with a
    /// colour bar titled `line_title`.
    std::vector<std::vector<Eigen::Vector3d>> lines;
    std::vector<std::vector<double>> line_values;
    std::string line_title;
};
/// Renders a scene to PNG off screen. The camera looks along the direction in which the geometry is
/// thinnest (its smallest principal axis), slightly from above, so the whole vessel tree is in view.
/// @throws InputError no X display (DISPLAY unset; run under `xvfb-run -a`); IoError the PNG cannot be written
void snapshot_scene(const SnapshotScene& scene, const std::string& png, int width = 1200, int height = 900);

/// The pictures of the geometry stages, as `--snapshot` renders them and the case report shows them:
/// the lumen mask (voxel surface, translucent) with the centerline and end planes;
SnapshotScene segment_scene(const ImageData& image, const std::string& title);
/// the lumen surface by label (artery/aneurysm) with the end planes;
SnapshotScene surface_scene(const SurfaceData& lumen, const std::vector<EndPlane>& planes, const std::string& title);
/// the outer wall and caps (every face not labelled inner) coloured by thickness.
SnapshotScene wall_thickness_scene(const SurfaceData& wall, const std::string& title);

/// @throws InputError when no X display is available for rendering (DISPLAY unset), with the remedy.
void require_snapshot_display();

/// Renders a surface to a PNG, faces coloured by label or region, from a camera looking at the surface's
/// centre along −y with +z up, one view. Debian's VTK renders through X11 only: needs a display
/// (run under `xvfb-run -a`).
/// @throws InputError no X display (DISPLAY unset); IoError the PNG cannot be written
void snapshot_surface(const SurfaceData& s, ColorBy by, const std::string& png, int width = 1000, int height = 800, const std::string& field = "");

}  // namespace aneu::pipeline
