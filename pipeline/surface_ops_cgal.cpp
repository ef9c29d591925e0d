// SPDX-License-Identifier: MIT
// CGAL side of the geometry stages: isotropic remeshing (with boundary loops kept as polylines),
// point-to-surface distance queries through an AABB tree, and the self-intersection check. One
// SurfaceData → Surface_mesh conversion serves all three.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
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

Volume<float> reachable_distance(const SurfaceData& closed, const Eigen::Vector3d& seed, double g, std::size_t max_voxels, ReachableStats* stats) {
    if (!(g > 0) || closed.F.rows() == 0) throw InputError("reachable_distance: a positive spacing and a non-empty surface are needed");
    Eigen::Vector3d lo = closed.V.colwise().minCoeff().transpose(), hi = closed.V.colwise().maxCoeff().transpose();
    lo.array() -= 2 * g;
    hi.array() += 2 * g;
    Volume<float> out;
    ImageGrid& grid = out.grid;
    for (int k = 0; k < 3; ++k) {
        grid.size[static_cast<size_t>(k)] = static_cast<std::int64_t>(std::ceil((hi[k] - lo[k]) / g)) + 1;
        grid.origin[static_cast<size_t>(k)] = lo[k];
        grid.spacing[static_cast<size_t>(k)] = g;
    }
    const std::size_t n = grid.voxel_count();
    if (n > max_voxels)
        throw InputError("reachable_distance: a grid of " + std::to_string(grid.size[0]) + "x" + std::to_string(grid.size[1]) + "x" +
                         std::to_string(grid.size[2]) + " voxels of " + std::to_string(g) + " mm exceeds " + std::to_string(max_voxels) +
                         ": give a larger cell size");
    std::vector<K::Triangle_3> tris;
    tris.reserve(static_cast<size_t>(closed.F.rows()));
    auto pt = [&](int v) { return Point(closed.V(v, 0), closed.V(v, 1), closed.V(v, 2)); };
    for (Eigen::Index f = 0; f < closed.F.rows(); ++f) tris.emplace_back(pt(closed.F(f, 0)), pt(closed.F(f, 1)), pt(closed.F(f, 2)));
    using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<K::Triangle_3>::const_iterator>;
    using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
    Tree tree(tris.cbegin(), tris.cend());
    tree.accelerate_distance_queries();
    const auto nx = grid.size[0], ny = grid.size[1], nz = grid.size[2];
    auto centre = [&](std::int64_t i, std::int64_t j, std::int64_t k) { return Point(lo.x() + g * i, lo.y() + g * j, lo.z() + g * k); };
    // The band: voxels within one spacing of a face lie in that face's box grown by a spacing.
    const float FAR = static_cast<float>(2 * g);
    std::vector<float> dist(n, FAR);
    std::vector<std::size_t> band;
    {
        std::vector<std::uint8_t> mark(n, 0);
        for (const auto& t : tris) {
            const auto bb = t.bbox();
            const std::int64_t i0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((bb.xmin() - g - lo.x()) / g)));
            const std::int64_t j0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((bb.ymin() - g - lo.y()) / g)));
            const std::int64_t k0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((bb.zmin() - g - lo.z()) / g)));
            const std::int64_t i1 = std::min<std::int64_t>(nx - 1, static_cast<std::int64_t>(std::ceil((bb.xmax() + g - lo.x()) / g)));
            const std::int64_t j1 = std::min<std::int64_t>(ny - 1, static_cast<std::int64_t>(std::ceil((bb.ymax() + g - lo.y()) / g)));
            const std::int64_t k1 = std::min<std::int64_t>(nz - 1, static_cast<std::int64_t>(std::ceil((bb.zmax() + g - lo.z()) / g)));
            for (std::int64_t k = k0; k <= k1; ++k)
                for (std::int64_t j = j0; j <= j1; ++j)
                    for (std::int64_t i = i0; i <= i1; ++i) {
                        const std::size_t v = grid.linear(i, j, k);
                        if (!mark[v]) {
                            mark[v] = 1;
                            band.push_back(v);
                        }
                    }
        }
    }
#pragma omp parallel for schedule(dynamic, 4096)
    for (std::size_t b = 0; b < band.size(); ++b) {
        const std::size_t v = band[b];
        const auto i = static_cast<std::int64_t>(v % static_cast<std::size_t>(nx)), j = static_cast<std::int64_t>((v / static_cast<std::size_t>(nx)) % static_cast<std::size_t>(ny)),
                   k = static_cast<std::int64_t>(v / static_cast<std::size_t>(nx * ny));
        dist[v] = std::min(FAR, static_cast<float>(std::sqrt(tree.squared_distance(centre(i, j, k)))));
    }
    // Flood fill from the voxel nearest the seed.
    ReachableStats st;
    st.voxels = n;
    std::vector<std::uint8_t> reached(n, 0);
    const auto clampi = [](double x, std::int64_t m) { return std::clamp<std::int64_t>(static_cast<std::int64_t>(std::llround(x)), 0, m - 1); };
    const std::int64_t si = clampi((seed.x() - lo.x()) / g, nx), sj = clampi((seed.y() - lo.y()) / g, ny), sk = clampi((seed.z() - lo.z()) / g, nz);
    const Point sp(seed.x(), seed.y(), seed.z());
    if (tree.squared_distance(sp) < 1e-12 || tree.do_intersect(K::Segment_3(sp, centre(si, sj, sk))))
        throw InputError("reachable_distance: the seed point lies on the surface or cannot reach its nearest grid point");
    std::deque<std::size_t> queue{grid.linear(si, sj, sk)};
    reached[queue.front()] = 1;
    const double near = g;  // a link can meet a face only if one of its ends is within its length of it
    while (!queue.empty()) {
        const std::size_t v = queue.front();
        queue.pop_front();
        ++st.reachable;
        const auto i = static_cast<std::int64_t>(v % static_cast<std::size_t>(nx)), j = static_cast<std::int64_t>((v / static_cast<std::size_t>(nx)) % static_cast<std::size_t>(ny)),
                   k = static_cast<std::int64_t>(v / static_cast<std::size_t>(nx * ny));
        static constexpr int step[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
        for (const auto& s : step) {
            const std::int64_t a = i + s[0], b = j + s[1], c = k + s[2];
            if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
            const std::size_t w = grid.linear(a, b, c);
            if (reached[w]) continue;
            if (dist[v] < near || dist[w] < near) {
                ++st.segment_tests;
                if (tree.do_intersect(K::Segment_3(centre(i, j, k), centre(a, b, c)))) {
                    ++st.blocked;
                    continue;
                }
            }
            reached[w] = 1;
            queue.push_back(w);
        }
    }
    out.data.resize(n);
    // Never exactly 0 at a sample: the isosurface would get vertices of zero-area triangles there.
    const float tiny = static_cast<float>(1e-4 * g);
    for (std::size_t v = 0; v < n; ++v) out.data[v] = reached[v] ? std::max(dist[v], tiny) : -std::max(dist[v], tiny);
    if (stats != nullptr) *stats = st;
    return out;
}

std::vector<std::pair<int, int>> self_intersections(const SurfaceData& s, std::size_t max_pairs) {
    const Mesh m = to_cgal(s, "surface");
    std::vector<std::pair<int, int>> pairs;
    PMP::self_intersections(m, PairCollector{&pairs, max_pairs});
    return pairs;
}

}  // namespace aneu::pipeline
