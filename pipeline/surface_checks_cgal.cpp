// SPDX-License-Identifier: MIT
// CGAL lives in this translation unit only (compile time).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <iterator>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/surface_checks.hpp"

namespace aneu::pipeline {

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Mesh = CGAL::Surface_mesh<K::Point_3>;
using face_descriptor = boost::graph_traits<Mesh>::face_descriptor;

/// Output iterator that stops collecting after `max` pairs (CGAL keeps calling it; extra pairs are dropped).
struct Collector {
    std::vector<std::pair<int, int>>* out;
    std::size_t max;
    Collector& operator*() { return *this; }
    Collector& operator++() { return *this; }
    Collector operator++(int) { return *this; }
    Collector& operator=(const std::pair<face_descriptor, face_descriptor>& p) {
        if (out->size() < max) out->emplace_back(static_cast<int>(p.first.idx()), static_cast<int>(p.second.idx()));
        return *this;
    }
};
}  // namespace

std::vector<std::pair<int, int>> self_intersections(const SurfaceData& s, std::size_t max_pairs) {
    Mesh m;
    std::vector<Mesh::Vertex_index> vi;
    vi.reserve(static_cast<size_t>(s.V.rows()));
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) vi.push_back(m.add_vertex(K::Point_3(s.V(i, 0), s.V(i, 1), s.V(i, 2))));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const auto fd = m.add_face(vi[static_cast<size_t>(s.F(f, 0))], vi[static_cast<size_t>(s.F(f, 1))], vi[static_cast<size_t>(s.F(f, 2))]);
        if (fd == Mesh::null_face()) throw InputError("surface: face " + std::to_string(f) + " cannot be added (non-manifold)");
    }
    std::vector<std::pair<int, int>> pairs;
    CGAL::Polygon_mesh_processing::self_intersections(m, Collector{&pairs, max_pairs});
    return pairs;
}

}  // namespace aneu::pipeline
