// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// `aneuprep tetmesh`: quality tetrahedral mesh of a closed, labelled wall surface.
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

/// Parameters of `aneuprep tetmesh`.
struct TetMeshParams {
    std::string mesher = "tetgen";     ///< tetgen (boundary preserved) or netgen
    double max_volume_mm3 = 0.0;       ///< upper bound on tet volume; 0 = that of a regular tet with the surface's mean edge
    double radius_edge_max = 1.5;      ///< TetGen quality bound: circumradius / shortest edge
    double min_dihedral_deg = 10.0;    ///< TetGen quality bound on dihedral angles
    double opt_max_dihedral_deg = 140.0;  ///< TetGen's optimiser (level 9, flips + smoothing + insertion) works on tetrahedra whose largest dihedral angle exceeds this
    double timeout_s = 300.0;          ///< the mesher runs in a child process, killed after this
};
/// The options of `aneuprep tetmesh`, declared once.
inline const opt::Spec<TetMeshParams>& tetmesh_spec() {
    using namespace opt;
    using P = TetMeshParams;
    static const Spec<P> spec = [] {
        Spec<P> s("tetmesh");
        s.text("mesher", &P::mesher, {"tetgen", "netgen"}, "tetgen (boundary preserved) or netgen")
            .real("max-volume-mm3", &P::max_volume_mm3, "mm³", ge(0), "max tet volume (0 = from the surface's edge length)")
            .real("radius-edge-max", &P::radius_edge_max, "", ge(1), "TetGen radius-edge bound (> 1 to terminate reliably)")
            .real("min-dihedral-deg", &P::min_dihedral_deg, "deg", closed_open(0, 30), "TetGen dihedral bound")
            .real("opt-max-dihedral-deg", &P::opt_max_dihedral_deg, "deg", closed(90, 179),
                  "TetGen's optimiser flips and smooths tetrahedra with a larger dihedral angle")
            .real("timeout-s", &P::timeout_s, "s", gt(0), "kill the mesher after this");
        return s;
    }();
    return spec;
}
/// The spec's rules, and Netgen present in this build when asked for. @throws InputError naming the field
void validate(const TetMeshParams& p);

/// Checks that a surface is closed, 2-manifold and consistently oriented (every edge in exactly two
/// faces, once in each direction) and outward (positive enclosed volume).
/// @throws InputError saying what is wrong and where (an edge's vertices and position)
void check_closed_surface(const SurfaceData& s, const std::string& what);

/// Tetrahedralises the closed wall surface. Surface vertices are kept as the first nodes (TetGen: no
/// Steiner points on the boundary). Node sets: "outer", "inner" (vertices of faces labelled so) and
/// "fixed" (vertices of faces labelled cap:*). Tet regions from the nearest surface vertex's region.
/// Quality figures in VolumeData::quality.
/// @throws InputError the surface is not closed/manifold/labelled; MeshingError the mesher failed or timed out
VolumeData tetmesh(const SurfaceData& wall, const TetMeshParams& p, Reporter& rep = null_reporter());

/// Removes flat boundary slivers: tetrahedra with a dihedral angle below min_deg that have exactly two faces on
/// the boundary (`faces`, node indices, with `labels`), of one label, nearly coplanar (≥ 150° between them inside
/// the tetrahedron). Each removal flips the boundary's edge between those faces; it is skipped where the opposite
/// edge is already a boundary edge (non-manifold) or a node would be left without a tetrahedron. Up to 4 passes.
/// @return how many tetrahedra were removed (the rest keep their order)
int remove_boundary_slivers(VolumeData& v, const Eigen::MatrixX3i& faces, const Eigen::VectorXi& labels, double min_deg);

/// Quality figures of a tetrahedral mesh: counts, min/max dihedral angle, max radius-edge ratio, slivers
/// (min dihedral < 5°), layers of elements through the wall (graph distance inner → outer nodes).
std::vector<std::pair<std::string, double>> mesh_quality(const VolumeData& v);

/// A closed wall surface of a tube for tests and examples: inner radius r_in, wall thickness t, length L
/// along a circular arc of bend radius R (0 = straight), n_theta × n_z quads per cylinder, annular caps;
/// labels inner, outer, cap:0, cap:1; one region "artery".
SurfaceData tube_wall_surface(double r_in, double thickness, double length, int n_theta, int n_z,
                              double bend_radius = 0.0);

/// A tube with a spherical sac on its side, for tests and examples (CGAL corefinement + remeshing).
struct TubeSacParams {
    double inner_radius_mm = 1.7;
    double thickness_mm = 0.3;       ///< artery wall
    double length_mm = 12.0;
    double sac_radius_mm = 2.5;      ///< inner (lumen) radius of the sac
    double sac_thickness_mm = 0.1;   ///< sac wall (one third of the artery's, as published)
    double neck_radius_mm = 1.5;     ///< where the sac's lumen meets the tube's
    double edge_mm = 0.2;            ///< target edge length of the remeshed surface
};
/// Closed wall surface: labels inner, outer, cap:0, cap:1 and regions artery/aneurysm from the geometry.
/// @throws InputError bad sizes; MeshingError a CGAL boolean failed
SurfaceData tube_sac_wall_surface(const TubeSacParams& p);

}  // namespace aneu::pipeline
