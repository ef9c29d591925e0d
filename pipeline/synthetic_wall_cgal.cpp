// SPDX-License-Identifier: MIT
// A closed wall surface of a tube with a spherical sac, by CGAL corefinement: (outer tube ∪ outer sphere)
// minus (inner tube ∪ inner sphere), then isotropic remeshing with the cap borders protected, then labels
// from the analytic geometry. CGAL lives in this translation unit only.
#include <CGAL/Polygon_mesh_processing/corefinement.h>

#include "cgal_types.hpp"

#include <cmath>

#include <Eigen/Geometry>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/pipeline/tetmesh.hpp"

namespace aneu::pipeline {

namespace {

using namespace cgal;  // K, Point, Mesh, PMP (cgal_types.hpp)

/// Closed cylinder around z of radius r over [z0, z1], outward faces, ~h edges. With `overhang`, it reaches
/// half a ring spacing beyond both ends, so that no ring of it lies in the end planes of a cylinder made
/// over the same [z0, z1] (coplanar rings make the corefinement produce coincident vertices).
Mesh cylinder(double r, double z0, double z1, double h, bool overhang = false) {
    Mesh m;
    const int n = std::max(12, static_cast<int>(std::ceil(2 * PI * r / h)));
    int nz = std::max(1, static_cast<int>(std::ceil((z1 - z0) / h)));
    const double dz = (z1 - z0) / nz;
    if (overhang) {
        z0 -= 0.5 * dz;
        ++nz;
    }
    std::vector<std::vector<Mesh::Vertex_index>> ring(static_cast<size_t>(nz + 1));
    for (int k = 0; k <= nz; ++k)
        for (int j = 0; j < n; ++j) {
            // Rings rotated by half a step on odd levels give better triangles.
            const double th = 2 * PI * (j + 0.5 * (k % 2)) / n;
            ring[static_cast<size_t>(k)].push_back(m.add_vertex(Point(r * std::cos(th), r * std::sin(th), z0 + dz * k)));
        }
    for (int k = 0; k < nz; ++k)
        for (int j = 0; j < n; ++j) {
            const auto a = ring[static_cast<size_t>(k)][static_cast<size_t>(j)], b = ring[static_cast<size_t>(k)][static_cast<size_t>((j + 1) % n)];
            const auto c = ring[static_cast<size_t>(k + 1)][static_cast<size_t>(j)], d = ring[static_cast<size_t>(k + 1)][static_cast<size_t>((j + 1) % n)];
            m.add_face(a, b, d);
            m.add_face(a, d, c);
        }
    const auto c0 = m.add_vertex(Point(0, 0, z0)), c1 = m.add_vertex(Point(0, 0, z1));
    for (int j = 0; j < n; ++j) {
        m.add_face(c0, ring[0][static_cast<size_t>((j + 1) % n)], ring[0][static_cast<size_t>(j)]);
        m.add_face(c1, ring[static_cast<size_t>(nz)][static_cast<size_t>(j)], ring[static_cast<size_t>(nz)][static_cast<size_t>((j + 1) % n)]);
    }
    return m;
}

/// UV sphere of radius R at c, outward faces, ~h edges.
Mesh sphere(const Point& c, double R, double h) {
    Mesh m;
    const int nl = std::max(8, static_cast<int>(std::ceil(PI * R / h)));
    const int n = std::max(12, static_cast<int>(std::ceil(2 * PI * R / h)));
    const auto top = m.add_vertex(Point(c.x(), c.y(), c.z() + R)), bottom = m.add_vertex(Point(c.x(), c.y(), c.z() - R));
    std::vector<std::vector<Mesh::Vertex_index>> ring(static_cast<size_t>(nl - 1));
    for (int i = 1; i < nl; ++i) {
        const double ph = PI * i / nl;
        for (int j = 0; j < n; ++j) {
            const double th = 2 * PI * (j + 0.5 * (i % 2)) / n;
            ring[static_cast<size_t>(i - 1)].push_back(
                m.add_vertex(Point(c.x() + R * std::sin(ph) * std::cos(th), c.y() + R * std::sin(ph) * std::sin(th), c.z() + R * std::cos(ph))));
        }
    }
    for (int j = 0; j < n; ++j) {
        m.add_face(top, ring[0][static_cast<size_t>(j)], ring[0][static_cast<size_t>((j + 1) % n)]);
        m.add_face(bottom, ring.back()[static_cast<size_t>((j + 1) % n)], ring.back()[static_cast<size_t>(j)]);
    }
    for (size_t i = 0; i + 1 < ring.size(); ++i)
        for (int j = 0; j < n; ++j) {
            const auto a = ring[i][static_cast<size_t>(j)], b = ring[i][static_cast<size_t>((j + 1) % n)];
            const auto c2 = ring[i + 1][static_cast<size_t>(j)], d = ring[i + 1][static_cast<size_t>((j + 1) % n)];
            m.add_face(a, c2, d);
            m.add_face(a, d, b);
        }
    return m;
}

void boolean(Mesh& a, Mesh& b, Mesh& out, bool unite, const char* what) {
    const bool ok = unite ? PMP::corefine_and_compute_union(a, b, out) : PMP::corefine_and_compute_difference(a, b, out);
    if (!ok) throw MeshingError(std::string("tube_sac_wall_surface: CGAL corefinement failed for the ") + what);
}

}  // namespace

SurfaceData tube_sac_wall_surface(const TubeSacParams& p) {
    const double r = p.inner_radius_mm, t = p.thickness_mm, L = p.length_mm, R = p.sac_radius_mm, ts = p.sac_thickness_mm;
    if (!(r > 0 && t > 0 && L > 4 * (r + t) && R > 0 && ts > 0 && p.neck_radius_mm > 0 && p.neck_radius_mm < R && p.edge_mm > 0)) {
        throw InputError("tube_sac_wall_surface: need positive sizes, length > 4 outer radii, neck radius < sac radius");
    }
    const double h = p.edge_mm;
    // Sac centre on +x at mid-length, placed so the inner sphere meets the inner cylinder in a neck of the given radius.
    const Point C(r + std::sqrt(R * R - p.neck_radius_mm * p.neck_radius_mm), 0, 0.5 * L);
    Mesh to = cylinder(r + t, 0, L, h), so = sphere(C, R + ts, h), ti = cylinder(r, 0, L, h, true), si = sphere(C, R, h);
    Mesh outer, inner, wall;
    boolean(to, so, outer, true, "outer union");
    boolean(ti, si, inner, true, "inner union");
    boolean(outer, inner, wall, false, "wall difference");
    // Remesh to the target edge, keeping the cap borders as feature polylines (split and collapsed, but kept) (edges between a face in an end plane and one
    // that is not). The neck creases are left free: protecting them keeps the corefinement's tiny edges
    // along the intersection curves, which fold into self-intersections when the rest is remeshed.
    auto constrained = wall.add_property_map<Mesh::Edge_index, bool>("e:constrained", false).first;
    auto in_cap = [&](Mesh::Face_index fd) {
        double zmin = 1e300, zmax = -1e300;
        for (auto v : CGAL::vertices_around_face(wall.halfedge(fd), wall)) {
            zmin = std::min(zmin, wall.point(v).z());
            zmax = std::max(zmax, wall.point(v).z());
        }
        return zmax - zmin < 1e-9 * L && (std::abs(zmin) < 1e-9 * L || std::abs(zmin - L) < 1e-9 * L);
    };
    for (auto e : wall.edges()) {
        const auto h0 = wall.halfedge(e), h1 = wall.opposite(h0);
        if (wall.is_border(h0) || wall.is_border(h1)) continue;
        put(constrained, e, in_cap(wall.face(h0)) != in_cap(wall.face(h1)));
    }
    PMP::isotropic_remeshing(faces(wall), h, wall,
                             CGAL::parameters::number_of_iterations(5).edge_is_constrained_map(constrained).protect_constraints(false));
    wall.collect_garbage();

    SurfaceData s;
    s.V.resize(static_cast<Eigen::Index>(wall.number_of_vertices()), 3);
    for (auto v : wall.vertices()) {
        const Point& q = wall.point(v);
        s.V.row(static_cast<Eigen::Index>(v.idx())) << q.x(), q.y(), q.z();
    }
    s.F.resize(static_cast<Eigen::Index>(wall.number_of_faces()), 3);
    s.face_label.resize(s.F.rows());
    s.face_region.resize(s.F.rows());
    const Eigen::Vector3d c(C.x(), C.y(), C.z());
    Eigen::Index f = 0;
    for (auto fd : wall.faces()) {
        int k = 0;
        Eigen::Vector3d x[3];
        for (auto v : CGAL::vertices_around_face(wall.halfedge(fd), wall)) {
            s.F(f, k) = static_cast<int>(v.idx());
            x[k++] = s.V.row(static_cast<Eigen::Index>(v.idx())).transpose();
        }
        const Eigen::Vector3d centroid = (x[0] + x[1] + x[2]) / 3.0, n = (x[1] - x[0]).cross(x[2] - x[0]);
        const double rho = centroid.head<2>().norm(), dc = (centroid - c).norm();
        // Which primitive the face belongs to: the tube or the sphere whose mid-wall surface is nearer.
        const bool on_sphere = std::abs(dc - (R + 0.5 * ts)) < std::abs(rho - (r + 0.5 * t));
        const Eigen::Vector3d radial = on_sphere ? Eigen::Vector3d(centroid - c)
                                                 : Eigen::Vector3d(centroid.x(), centroid.y(), 0.0);
        const double tol = 1e-6 * L;
        int label;
        if (std::abs(centroid.z()) < tol && std::abs(n.normalized().z()) > 0.99) {
            label = 2;
        } else if (std::abs(centroid.z() - L) < tol && std::abs(n.normalized().z()) > 0.99) {
            label = 3;
        } else {
            label = n.dot(radial) < 0 ? 0 : 1;  // the wall's outward normal points into the lumen on the inner surface
        }
        s.face_label[f] = label;
        s.face_region[f] = label < 2 && on_sphere ? 1 : 0;
        ++f;
    }
    s.label_names = {"inner", "outer", "cap:0", "cap:1"};
    s.region_names = {"artery", "aneurysm"};
    return s;
}

}  // namespace aneu::pipeline
