// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Triangle-surface operations of the geometry stages: VTK (isosurface, clip, smoothing,
/// file readers, voxelisation; surface_ops_vtk.cpp), CGAL and Netgen (remeshing, distance queries;
/// remesh.cpp, surface_ops_cgal.cpp) and plain mesh topology (surface_topology.cpp). Standard/Eigen types only.
#include <array>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/image_grid.hpp"

namespace aneu::pipeline {

// ---------------------------------------------------------------- VTK
/// Isosurface of `field` at `level` (VTK flying edges, sub-voxel by linear interpolation), in the grid's
/// physical frame (VTK ignores the direction: the vertices are mapped through ImageGrid::point). Faces
/// are oriented with normals pointing out of the region where field > level (`above_is_inside`) or out
/// of the region where field < level. Only the largest connected piece is kept if `largest_only`.
SurfaceData isosurface(const Volume<float>& field, double level, bool above_is_inside, bool largest_only = true);

/// One block of a sparse (narrow-band) scalar field on a virtual grid: the samples with global indices
/// first[d] ... first[d] + size[d] − 1, x fastest. Adjacent blocks share their border samples.
struct FieldBlock {
    std::array<std::int64_t, 3> first{};
    std::array<std::int64_t, 3> size{};
    std::vector<float> values;
};
/// Isosurface of a field given only in blocks on the grid `g` (which is never allocated): flying edges per
/// block in the grid's global index space, merged where blocks meet (shared samples give the same vertex
/// exactly). The field must not cross `level` in a cell that no block holds. Orientation: normals point
/// out of the region where field < level, taken from the enclosed volume (the result must be closed);
/// the largest connected piece is kept. Memory follows the blocks, not the grid's box.
/// @throws MeshingError no surface at `level`
SurfaceData isosurface_blocks(const ImageGrid& g, const std::vector<FieldBlock>& blocks, double level);

/// Cuts the surface at end planes: for each plane, the pieces beyond it that cross it within `reach` ×
/// (radius + 1 mm) of its point are removed (another vessel passing beyond the plane elsewhere is kept); the
/// cut is exact (linear scalar = signed distance to the plane) and its vertices are snapped into the plane.
/// Of what remains, the largest connected piece is kept. Boundary loops lie in the planes.
/// With `margin_mm` ≥ 0 the disc's radius is 1.5 × radius + `margin_mm` instead (the wall's outer surface:
/// a wider disc would also cut the wall of a parent vessel that passes beyond a short branch's plane).
/// With `tips` (one point per plane) only one piece per plane is removed: the one nearest its tip (the end's own
/// stub, or a rounded end; the wall of a parent vessel that bulges beyond a short branch's plane within the disc
/// stays).
SurfaceData clip_at_planes(const SurfaceData& s, const std::vector<EndPlane>& planes, double reach = 3.0, double margin_mm = -1.0,
                           const std::vector<Eigen::Vector3d>& tips = {});

/// Cuts `s` at one plane, only where `region` (per vertex) is set: the region's part beyond the plane is removed
/// (exact cut, new loop snapped into the plane); the rest of the surface is untouched. The largest piece is kept.
SurfaceData clip_region_at_plane(const SurfaceData& s, const std::vector<char>& region, const EndPlane& plane);

/// Non-shrinking smoothing (VTK windowed sinc, Taubin); boundary vertices do not move.
void smooth_surface(SurfaceData& s, int iterations, double passband);

/// Reads a triangle surface from STL, VTP, VTK, OBJ or PLY (by extension); points closer than `weld` (in the
/// file's units; 0 = 1e-6 of the bounding-box diagonal) are merged, polygons triangulated.
/// @throws InputError unsupported extension, unreadable file, no triangles
SurfaceData read_mesh_file(const std::string& path, double weld = 0.0);

/// Writes a surface as VTP (face labels and regions as cell data) or STL, by extension.
void write_mesh_file(const std::string& path, const SurfaceData& s);

/// Voxelises a closed surface on an axis-aligned grid of the given spacing covering its bounding box plus
/// `margin` (VTK stencil): 1 inside, 0 outside.
Volume<std::uint8_t> voxelize(const SurfaceData& closed, double spacing, double margin);

// ---------------------------------------------------------------- topology and measures (plain)
/// Boundary loops (ordered vertex cycles) of an oriented triangle surface.
/// @throws InputError the surface is not an oriented 2-manifold (an edge in more than two faces, or two
///         faces using it in the same direction; the message names the vertices and the position)
std::vector<std::vector<int>> boundary_loops(const SurfaceData& s);

/// Keeps the faces with keep[f] != 0 and drops unused vertices (labels, regions follow; loops dropped).
SurfaceData sub_surface(const SurfaceData& s, const std::vector<char>& keep);

/// Adds a planar fan cap (a centre vertex and a triangle per loop edge) over every boundary loop, labelled
/// with the given label; returns the first cap face index.
Eigen::Index cap_loops(SurfaceData& s, const std::vector<std::vector<int>>& loops, const std::vector<int>& cap_labels);

/// Edge-length and angle figures of a triangle surface: triangles, vertices, edge mean/sd/min/max [mm],
/// min angle [deg], fraction of triangles with min angle below 25° and below 15°.
NamedValues triangle_quality(const SurfaceData& s);

/// Flips interior edges between nearly coplanar faces (dihedral below `max_dihedral_deg`) where that raises
/// the smaller of the two faces' minimum angles; boundary edges stay. Labels/regions of flipped faces are
/// those of the faces they replace. Returns the number of flips.
int improve_min_angle(SurfaceData& s, double max_dihedral_deg = 10.0, int passes = 5);

/// Collapses, to its midpoint, every boundary edge whose opposite angle is below `min_angle_deg` or that is shorter
/// than a quarter of the median edge (a short cut-end
/// segment a remesher left) where the link condition allows; a planar boundary loop stays in its plane.
/// Unused vertices are dropped. Returns the number of collapses.
int collapse_short_boundary_edges(SurfaceData& s, double min_angle_deg = 15.0);

/// Collapses every interior edge shorter than `fraction` × the median edge (a remesher's tiny triangle next to
/// a cut end: 0.03 mm among 0.4 mm edges on a real CTA, which TetGen must keep and turns into slivers): to its
/// midpoint, or onto its end on a boundary loop (loops keep their vertices' positions), where the link condition
/// holds and every face round it keeps its orientation and a 5° minimum angle. Returns the number of collapses.
int collapse_short_interior_edges(SurfaceData& s, double fraction = 0.25);

/// Signed volume enclosed by a closed surface (positive when outward-oriented).
double enclosed_volume(const SurfaceData& s);

// ---------------------------------------------------------------- CGAL / Netgen
/// Remeshes a surface to a target edge length, keeping its boundary loops in place (as polylines):
/// "netgen" (Netgen's STL surface mesher, in a child process with a timeout) or "cgal" (CGAL isotropic
/// remeshing). Open surfaces are capped before and uncapped after, so each boundary loop stays in its
/// plane. Labels/regions are not carried (the caller labels the result).
/// @throws MeshingError the mesher failed; InputError unknown method
SurfaceData remesh(const SurfaceData& s, double edge_mm, const std::string& method, double timeout_s = 300.0);

/// Part of a surface remeshed finer than the rest (CGAL only: the faces of `fine` at `fine_edge_mm`, the others at
/// the remesh's edge; the border between them is kept as a polyline, resampled, so the two parts stay conforming).
struct RemeshZone {
    std::vector<char> fine;     ///< per input face: 1 = in the fine zone
    double fine_edge_mm = 0.0;  ///< target edge in the zone [mm]
};
/// `remesh` with a finer zone (CGAL).
SurfaceData remesh(const SurfaceData& s, double edge_mm, const std::string& method, double timeout_s, const RemeshZone* zone);

/// What `remesh_checked` did: the remesher whose result was kept, and why the asked one was not.
struct RemeshOutcome {
    SurfaceData surface;
    std::string method;        ///< the remesher whose result is `surface`
    std::string fallback_why;  ///< empty when the asked remesher's result was kept
};
/// `remesh` with the asked method, then checks the result: an oriented 2-manifold with as many boundary
/// loops as the input and no self-intersection. If the mesher fails, times out or its result fails a check,
/// the other remesher runs (its result checked alike), and the outcome says so.
/// @throws MeshingError naming the check and the place when both remeshers fail
/// With a `zone`, only CGAL runs (Netgen has no zones here).
RemeshOutcome remesh_checked(const SurfaceData& s, double edge_mm, const std::string& method, double timeout_s, const RemeshZone* zone = nullptr);

/// Largest triangle count a remesh may be asked for (an equilateral mesh of the whole surface): beyond it the
/// surface, the wall and the tetrahedra would not fit in this tool's memory budget.
constexpr double MAX_REMESH_TRIANGLES = 4e6;
/// Refuses, before any work, a target edge that would give more than MAX_REMESH_TRIANGLES on `area_mm2`.
/// @throws InputError naming `what` (the option), the estimate and the smallest edge allowed
void refuse_triangle_count(const std::string& what, double edge_mm, double area_mm2);

/// Distances from points to a triangle surface (CGAL AABB tree): distance, nearest face, nearest point.
struct NearestOnSurface {
    Eigen::VectorXd distance;
    Eigen::VectorXi face;
    Eigen::MatrixX3d point;
};
NearestOnSurface nearest_on_surface(const SurfaceData& s, const Eigen::MatrixX3d& points);

/// Distance from each point to the nearest of the triangles F (any subset of a surface's faces; +∞ when F is
/// empty). CGAL AABB tree over the triangle soup, OpenMP over the points.
/// With `nearest_face`, also the row of F nearest to each point (−1 when F is empty).
Eigen::VectorXd distance_to_faces(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& points, Eigen::VectorXi* nearest_face = nullptr);

/// What reachable_distance found.
struct ReachableStats {
    std::size_t voxels = 0;          ///< grid size
    std::size_t reachable = 0;       ///< voxels reached from the seed
    std::size_t segment_tests = 0;   ///< neighbour links near the surface tested against it
    std::size_t blocked = 0;         ///< of them, crossing the surface
};

/// The part of a closed, possibly self-intersecting surface's inside that blood reaches from `seed` without
/// crossing the surface (a lumen pinched by a clip: walls that pass through each other or touch close off what
/// lies beyond), as a signed distance on an axis-aligned grid of spacing `spacing` covering the surface's box
/// plus two spacings: +d on reached voxels, −d elsewhere, d the exact distance to the surface (CGAL AABB tree),
/// clamped at 2 spacings. Reachability: a flood fill over the 6-neighbour links; a link with an end nearer the
/// surface than one spacing is followed only when the segment between the two centres does not meet a face.
/// The isosurface at 0 is the reachable region's boundary, free of self-intersections, on the surface to
/// within the linear interpolation of an exact distance.
/// @throws InputError the grid would exceed `max_voxels`, or the seed lies on the surface
Volume<float> reachable_distance(const SurfaceData& closed, const Eigen::Vector3d& seed, double spacing, std::size_t max_voxels,
                                 ReachableStats* stats = nullptr);

}  // namespace aneu::pipeline
