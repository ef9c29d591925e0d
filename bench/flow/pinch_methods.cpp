// SPDX-License-Identifier: MIT
// The CGAL alternatives for a pinched lumen (issue #17), on the tube pinched shut and pinched across half its
// width that the flow tests use: alpha wrapping (CGAL 5.5 alpha_wrap_3) at a cell and at a quarter millimetre, and
// PMP::experimental::remove_self_intersections. Is the pinch (6,0,0) and what lies beyond it (9,0,0) blood? Built
// and run by bench/flow/pinch_methods.sh.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/alpha_wrap_3.h>
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polygon_mesh_processing/repair_self_intersections.h>
#include <CGAL/Polygon_mesh_processing/IO/polygon_mesh_io.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <iostream>
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Mesh = CGAL::Surface_mesh<K::Point_3>;
namespace PMP = CGAL::Polygon_mesh_processing;
int main(int argc, char** argv) {
  Mesh m; PMP::IO::read_polygon_mesh(argv[1], m);
  std::cout << argv[1] << ": " << num_faces(m) << " faces, self-intersecting " << PMP::does_self_intersect(m) << ", signed volume " << PMP::volume(m) << "\n";
  for (double alpha : {0.0625, 0.25}) {
    Mesh wrap; CGAL::alpha_wrap_3(m, alpha, alpha / 10, wrap);
    CGAL::Side_of_triangle_mesh<Mesh, K> inside(wrap);
    std::cout << "  alpha wrap alpha " << alpha << ": " << num_faces(wrap) << " faces, volume " << PMP::volume(wrap) << " (tube 37.70)"
              << ", point (9,0,0) beyond the pinch " << (inside(K::Point_3(9,0,0)) == CGAL::ON_BOUNDED_SIDE ? "inside" : "outside")
              << ", point (6,0,0) in the pinch " << (inside(K::Point_3(6,0,0)) == CGAL::ON_BOUNDED_SIDE ? "inside" : "outside") << "\n";
  }
  Mesh r = m;
  const bool ok = PMP::experimental::remove_self_intersections(r);
  std::cout << "  remove_self_intersections: " << (ok ? "succeeded" : "failed") << ", still self-intersecting " << PMP::does_self_intersect(r) << ", faces " << num_faces(r) << ", closed " << CGAL::is_closed(r) << "\n";
}
