// SPDX-License-Identifier: MIT
// CGAL side of the geometry stages: isotropic remeshing (with boundary loops kept as polylines),
// point-to-surface distance queries through an AABB tree, and the self-intersection check. One
// SurfaceData → Surface_mesh conversion serves all three.
#include <limits>

#include <CGAL/AABB_face_graph_triangle_primitive.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>

#include "cgal_types.hpp"

#include "aneu/core/error.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace aneu::pipeline {

namespace {
using namespace cgal;  // K, Point, Mesh, PMP (cgal_types.hpp)

Mesh to_cgal(const SurfaceData& s, const std::string& what) {
    Mesh m;
    std::vector<Mesh::Vertex_index> vi;
    vi.reserve(static_cast<size_t>(s.V.rows()));
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) vi.push_back(m.add_vertex(Point(s.V(i, 0), s.V(i, 1), s.V(i, 2))));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const auto fd = m.add_face(vi[static_cast<size_t>(s.F(f, 0))], vi[static_cast<size_t>(s.F(f, 1))], vi[static_cast<size_t>(s.F(f, 2))]);
        if (fd == Mesh::null_face()) throw InputError(what + ": face " + std::to_string(f) + " cannot be added (non-manifold)");
    }
    return m;
}

/// Output iterator that stops collecting after `max` pairs (CGAL keeps calling it; extra pairs are dropped).
struct PairCollector {
    std::vector<std::pair<int, int>>* out;
    std::size_t max;
    PairCollector& operator*() { return *this; }
    PairCollector& operator++() { return *this; }
    PairCollector operator++(int) { return *this; }
    PairCollector& operator=(const std::pair<Mesh::Face_index, Mesh::Face_index>& p) {
        if (out->size() < max) out->emplace_back(static_cast<int>(p.first.idx()), static_cast<int>(p.second.idx()));
        return *this;
    }
};

SurfaceData from_cgal(const Mesh& m) {
    SurfaceData s;
    s.V.resize(static_cast<Eigen::Index>(m.number_of_vertices()), 3);
    std::vector<int> map(m.num_vertices(), -1);
    int nv = 0;
    for (auto v : m.vertices()) {
        map[v.idx()] = nv;
        const Point& p = m.point(v);
        s.V.row(nv++) << p.x(), p.y(), p.z();
    }
    s.F.resize(static_cast<Eigen::Index>(m.number_of_faces()), 3);
    Eigen::Index f = 0;
    for (auto fd : m.faces()) {
        int k = 0;
        for (auto v : CGAL::vertices_around_face(m.halfedge(fd), m)) s.F(f, k++) = map[v.idx()];
        ++f;
    }
    s.face_label = Eigen::VectorXi::Zero(s.F.rows());
    s.label_names = {"surface"};
    return s;
}
}  // namespace

SurfaceData remesh_cgal(const SurfaceData& capped, double edge_mm, const std::vector<char>* fine, double fine_edge_mm) {
    Mesh m = to_cgal(capped, "remesh (CGAL)");
    // Patches: label 0 is the surface, labels >= 1 the caps; edges between patches are constrained so
    // each boundary polyline (in its plane) survives, resampled to the target length. A finer zone is a patch
    // of its own (patch id 2·label + 1), remeshed in a second pass at its own edge.
    auto patch = m.add_property_map<Mesh::Face_index, int>("f:patch", 0).first;
    for (auto fd : m.faces()) {
        const auto f = static_cast<Eigen::Index>(fd.idx());
        put(patch, fd, 2 * capped.face_label[f] + (fine != nullptr && (*fine)[static_cast<size_t>(f)] ? 1 : 0));
    }
    auto constrained = m.add_property_map<Mesh::Edge_index, bool>("e:constrained", false).first;
    for (auto e : m.edges()) {
        const auto h0 = m.halfedge(e), h1 = m.opposite(h0);
        if (m.is_border(h0) || m.is_border(h1)) {
            put(constrained, e, true);
            continue;
        }
        put(constrained, e, get(patch, m.face(h0)) != get(patch, m.face(h1)));
    }
    const auto pass = [&](bool zone, double edge) {
        std::vector<Mesh::Face_index> which;
        for (auto fd : m.faces())
            if (fine == nullptr || (get(patch, fd) % 2 == 1) == zone) which.push_back(fd);
        if (which.empty()) return;
        PMP::isotropic_remeshing(which, edge, m,
                                 CGAL::parameters::number_of_iterations(10)
                                     .edge_is_constrained_map(constrained)
                                     .protect_constraints(false)
                                     .face_patch_map(patch)
                                     .number_of_relaxation_steps(3));
    };
    pass(false, edge_mm);
    if (fine != nullptr) pass(true, fine_edge_mm);
    m.collect_garbage();
    SurfaceData out = from_cgal(m);
    Eigen::Index f = 0;
    for (auto fd : m.faces()) out.face_label[f++] = get(patch, fd) / 2;
    return out;
}

NearestOnSurface nearest_on_surface(const SurfaceData& s, const Eigen::MatrixX3d& points) {
    Mesh m = to_cgal(s, "distance query");
    using Primitive = CGAL::AABB_face_graph_triangle_primitive<Mesh>;
    using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
    Tree tree(faces(m).first, faces(m).second, m);
    tree.accelerate_distance_queries();
    NearestOnSurface r;
    const Eigen::Index n = points.rows();
    r.distance.resize(n);
    r.face.resize(n);
    r.point.resize(n, 3);
#pragma omp parallel for schedule(dynamic, 1024)
    for (Eigen::Index i = 0; i < n; ++i) {
        const Point q(points(i, 0), points(i, 1), points(i, 2));
        const auto [p, fd] = tree.closest_point_and_primitive(q);
        r.distance[i] = std::sqrt(CGAL::squared_distance(p, q));
        r.face[i] = static_cast<int>(fd.idx());
        r.point.row(i) << p.x(), p.y(), p.z();
    }
    return r;
}

Eigen::VectorXd distance_to_faces(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& points, Eigen::VectorXi* nearest_face) {
    // A triangle soup: any subset of a surface's faces (it need not be a manifold mesh).
    std::vector<K::Triangle_3> tris;
    tris.reserve(static_cast<size_t>(F.rows()));
    auto pt = [&](int v) { return Point(V(v, 0), V(v, 1), V(v, 2)); };
    for (Eigen::Index f = 0; f < F.rows(); ++f) tris.emplace_back(pt(F(f, 0)), pt(F(f, 1)), pt(F(f, 2)));
    Eigen::VectorXd d = Eigen::VectorXd::Constant(points.rows(), std::numeric_limits<double>::infinity());
    if (nearest_face != nullptr) *nearest_face = Eigen::VectorXi::Constant(points.rows(), -1);
    if (tris.empty()) return d;
    using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<K::Triangle_3>::const_iterator>;
    using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
    Tree tree(tris.cbegin(), tris.cend());
    tree.accelerate_distance_queries();
    if (nearest_face == nullptr) {
#pragma omp parallel for schedule(dynamic, 1024)
        for (Eigen::Index i = 0; i < points.rows(); ++i) d[i] = std::sqrt(tree.squared_distance(Point(points(i, 0), points(i, 1), points(i, 2))));
        return d;
    }
#pragma omp parallel for schedule(dynamic, 1024)
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
        const Point q(points(i, 0), points(i, 1), points(i, 2));
        const auto [p, it] = tree.closest_point_and_primitive(q);
        d[i] = std::sqrt(CGAL::squared_distance(p, q));
        (*nearest_face)[i] = static_cast<int>(it - tris.cbegin());
    }
    return d;
}

std::vector<std::pair<int, int>> self_intersections(const SurfaceData& s, std::size_t max_pairs) {
    const Mesh m = to_cgal(s, "surface");
    std::vector<std::pair<int, int>> pairs;
    PMP::self_intersections(m, PairCollector{&pairs, max_pairs});
    return pairs;
}

}  // namespace aneu::pipeline
