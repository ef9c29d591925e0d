// SPDX-License-Identifier: MIT
#pragma once
// The CGAL kernel and surface mesh type of the pipeline's CGAL translation units (surface_ops_cgal.cpp,
// synthetic_wall_cgal.cpp). Include only from those: CGAL headers are heavy.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Surface_mesh.h>

namespace aneu::pipeline::cgal {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
namespace PMP = CGAL::Polygon_mesh_processing;
}  // namespace aneu::pipeline::cgal
