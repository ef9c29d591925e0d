// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Rigid shapes of instruments, clip jaws and obstacles, and a uniform grid to find surface nodes near them.
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace aneu::fem {
struct ClipBlades;
}

namespace aneu::sim {

/// Axis-aligned bounding box.
struct Aabb {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = Eigen::Vector3d::Constant(-1e300);
    void extend(const Eigen::Vector3d& p) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    Aabb grown(double m) const { return {lo.array() - m, hi.array() + m}; }
};

/// Triangle mesh (rigid), with what signed-distance queries need.
struct TriMesh {
    Eigen::MatrixX3d V;
    Eigen::MatrixX3i F;
    Eigen::MatrixX3d face_normal;  ///< unit
    Eigen::MatrixX3d vertex_normal;  ///< angle weighted, unit
    std::unordered_map<long long, Eigen::Vector3d> edge_normal;  ///< key min*#V+max → sum of the two face normals
    void finish();                 ///< computes the normals; throws InputError for an empty mesh
    Aabb bounds() const;
};

/// Reads a triangle mesh: STL (ASCII or binary) or OBJ. @throws InputError naming the file and the defect
TriMesh read_trimesh(const std::string& path);

/// A rigid convex or mesh shape placed in the world: a box, a capsule, or a (closed) triangle mesh.
struct Shape {
    enum class Kind { BOX, CAPSULE, MESH } kind = Kind::BOX;
    // BOX: centre, axes (columns, orthonormal), half extents.
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
    Eigen::Vector3d half = Eigen::Vector3d::Zero();
    /// A BOX bent in the plane of its first two axes (a curved clip's jaw, fem::ClipBlades::curve_radius_mm): from
    /// `bend_from` along its first axis (from its −x end) its centre line bends on a circle of radius |bend_radius|
    /// towards +axes.col(1) (positive) or −axes.col(1); its length is along that line, its width across it. 0: straight.
    double bend_radius = 0.0, bend_from = 0.0;
    // CAPSULE: segment a–b, radius.
    Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();
    double radius = 0.0;
    // MESH: world-space copy of the mesh (placed).
    TriMesh mesh;

    /// Signed distance [mm], negative inside (exact for BOX and CAPSULE; for MESH by the nearest triangle
    /// and its angle-weighted pseudo-normal).
    double sdf(const Eigen::Vector3d& p) const;
    /// The point of the shape that lies deepest along −n (minimises n·x): what touches a plane of normal n.
    Eigen::Vector3d support(const Eigen::Vector3d& n) const;
    Aabb bounds() const;
    /// Distance t ≥ 0 along direction `dir` from p (inside) to the shape's boundary; bisection on sdf.
    double exit_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& dir) const;
    /// A bent BOX's centre line (fem::ClipBlades in its frame) and its cross-section's corners along it.
    fem::ClipBlades bent() const;
    std::vector<Eigen::Vector3d> bent_corners() const;
};

/// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5).
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c);

/// Uniform hash grid over points (the deformed surface nodes), rebuilt each collision frame.
class PointGrid {
public:
    /// @param[in] cell  cell size [mm] (about the mean edge length)
    void build(const Eigen::MatrixX3d& X, double cell, const std::vector<char>* include = nullptr);
    /// Indices of points inside the box, in increasing order (`sorted`; else in the grid's order, each at least once).
    void query(const Aabb& box, std::vector<int>& out, bool sorted = true) const;

private:
    double m_cell = 1.0;
    std::unordered_map<long long, std::vector<int>> m_cells;
    std::vector<int> m_points;  ///< the points kept, in increasing order
    const Eigen::MatrixX3d* m_X = nullptr;
    long long key(long long i, long long j, long long k) const { return (i * 73856093LL) ^ (j * 19349663LL) ^ (k * 83492791LL); }
};

}  // namespace aneu::sim
