// SPDX-License-Identifier: MIT
// Surface remeshing to a target edge length: Netgen's STL surface mesher (the published method) or CGAL
// isotropic remeshing. Open surfaces are capped with planar fans first, so that every boundary loop is a
// crease of a closed surface that both meshers keep; the caps are removed after.
#include <cmath>

#include <Eigen/Dense>

#ifdef ANEU_WITH_NETGEN
namespace nglib {
#include <nglib.h>
}
#endif

#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "child_process.hpp"

namespace aneu::pipeline {

SurfaceData remesh_cgal(const SurfaceData& capped, double edge_mm, const std::vector<char>* fine, double fine_edge_mm);  // surface_ops_cgal.cpp

namespace {

struct LoopPlane {
    Eigen::Vector3d c, n;
    double radius;
};

/// Least-squares plane of a loop (PCA), normal along the loop's winding.
LoopPlane plane_of(const SurfaceData& s, const std::vector<int>& loop) {
    LoopPlane p;
    p.c.setZero();
    for (int v : loop) p.c += s.V.row(v).transpose();
    p.c /= static_cast<double>(loop.size());
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    p.radius = 0;
    for (int v : loop) {
        const Eigen::Vector3d d = s.V.row(v).transpose() - p.c;
        C += d * d.transpose();
        p.radius = std::max(p.radius, d.norm());
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
    p.n = es.eigenvectors().col(0);
    Eigen::Vector3d w = Eigen::Vector3d::Zero();  // vector area of the loop
    for (size_t i = 0; i < loop.size(); ++i)
        w += (s.V.row(loop[i]).transpose() - p.c).cross(s.V.row(loop[(i + 1) % loop.size()]).transpose() - p.c);
    if (p.n.dot(w) < 0) p.n = -p.n;
    return p;
}

#ifdef ANEU_WITH_NETGEN
SurfaceData remesh_netgen(const SurfaceData& capped, double edge_mm, double timeout_s) {
    RawMesh raw = run_isolated(
        [&](RawMesh& out, std::string& msg) {
            nglib::Ng_Init();
            nglib::Ng_STL_Geometry* geom = nglib::Ng_STL_NewGeometry();
            for (Eigen::Index f = 0; f < capped.F.rows(); ++f) {
                double p[3][3];
                for (int k = 0; k < 3; ++k)
                    for (int d = 0; d < 3; ++d) p[k][d] = capped.V(capped.F(f, k), d);
                const Eigen::Vector3d a = capped.V.row(capped.F(f, 0)), b = capped.V.row(capped.F(f, 1)), c = capped.V.row(capped.F(f, 2));
                Eigen::Vector3d n = (b - a).cross(c - a).normalized();
                nglib::Ng_STL_AddTriangle(geom, p[0], p[1], p[2], n.data());
            }
            if (nglib::Ng_STL_InitSTLGeometry(geom) != nglib::NG_OK) {
                msg = "Netgen could not build an STL geometry from the surface";
                return 1;
            }
            nglib::Ng_Mesh* m = nglib::Ng_NewMesh();
            nglib::Ng_Meshing_Parameters mp;
            mp.maxh = edge_mm;
            mp.minh = 0.2 * edge_mm;
            mp.grading = 0.2;
            mp.optsteps_2d = 10;
            if (nglib::Ng_STL_MakeEdges(geom, m, &mp) != nglib::NG_OK) {
                msg = "Netgen could not find the surface's edges";
                return 1;
            }
            if (nglib::Ng_STL_GenerateSurfaceMesh(geom, m, &mp) != nglib::NG_OK) {
                msg = "Netgen surface meshing failed";
                return 1;
            }
            const int np = nglib::Ng_GetNP(m), nse = nglib::Ng_GetNSE(m);
            out.points.resize(static_cast<size_t>(3 * np));
            for (int i = 0; i < np; ++i) nglib::Ng_GetPoint(m, i + 1, out.points.data() + 3 * i);
            out.cells.resize(static_cast<size_t>(3 * nse));
            for (int e = 0; e < nse; ++e) {
                int t[8];
                if (nglib::Ng_GetSurfaceElement(m, e + 1, t) != nglib::NG_TRIG) {
                    msg = "Netgen produced a non-triangular surface element";
                    return 1;
                }
                for (int a = 0; a < 3; ++a) out.cells[static_cast<size_t>(3 * e + a)] = t[a] - 1;
            }
            nglib::Ng_DeleteMesh(m);
            nglib::Ng_Exit();
            return 0;
        },
        timeout_s, "surface remesh (Netgen)");
    SurfaceData s;
    const auto np = static_cast<Eigen::Index>(raw.points.size() / 3), nt = static_cast<Eigen::Index>(raw.cells.size() / 3);
    s.V = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(raw.points.data(), np, 3);
    s.F = Eigen::Map<Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>>(raw.cells.data(), nt, 3);
    // Netgen may keep unused STL points: compact.
    std::vector<char> all(static_cast<size_t>(nt), 1);
    s.face_label = Eigen::VectorXi::Zero(nt);
    s = sub_surface(s, all);
    if (enclosed_volume(s) < 0) s.F.col(1).swap(s.F.col(2));
    return s;
}
#endif

/// Moves every interior vertex towards the centroid of its neighbours within its tangent plane, then onto
/// the reference surface (its nearest point); boundary vertices stay.
void relax_tangentially(SurfaceData& s, const SurfaceData& reference, int iterations) {
    const Eigen::Index nv = s.V.rows();
    std::vector<char> boundary(static_cast<size_t>(nv), 0);
    for (const auto& l : boundary_loops(s))
        for (int v : l) boundary[static_cast<size_t>(v)] = 1;
    std::vector<std::vector<int>> nb(static_cast<size_t>(nv));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) nb[static_cast<size_t>(s.F(f, k))].push_back(s.F(f, (k + 1) % 3));
    for (int it = 0; it < iterations; ++it) {
        Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(nv, 3);
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
            const Eigen::RowVector3d n = (b - a).cross(c - a).transpose();
            for (int k = 0; k < 3; ++k) N.row(s.F(f, k)) += n;
        }
        Eigen::MatrixX3d X = s.V;
        for (Eigen::Index v = 0; v < nv; ++v) {
            if (boundary[static_cast<size_t>(v)] || nb[static_cast<size_t>(v)].empty()) continue;
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int w : nb[static_cast<size_t>(v)]) c += s.V.row(w).transpose();
            c /= static_cast<double>(nb[static_cast<size_t>(v)].size());
            const Eigen::Vector3d n = N.row(v).transpose().normalized();
            const Eigen::Vector3d d = c - s.V.row(v).transpose();
            X.row(v) += (d - n.dot(d) * n).transpose();
        }
        const NearestOnSurface p = nearest_on_surface(reference, X);
        for (Eigen::Index v = 0; v < nv; ++v)
            if (!boundary[static_cast<size_t>(v)]) s.V.row(v) = p.point.row(v);
    }
}

}  // namespace

SurfaceData remesh(const SurfaceData& in, double edge_mm, const std::string& method, double timeout_s) { return remesh(in, edge_mm, method, timeout_s, nullptr); }

SurfaceData remesh(const SurfaceData& in, double edge_mm, const std::string& method, double timeout_s, const RemeshZone* zone) {
    if (!(edge_mm > 0)) throw InputError("remesh: target edge must be > 0 mm");
    if (method != "netgen" && method != "cgal") throw InputError("remesh: method = '" + method + "': expected netgen or cgal");
    const auto loops = boundary_loops(in);
    std::vector<LoopPlane> planes;
    for (const auto& l : loops) planes.push_back(plane_of(in, l));
    SurfaceData capped = in;
    capped.face_label = Eigen::VectorXi::Zero(in.F.rows());
    capped.label_names = {"surface"};
    capped.face_region.resize(0);
    std::vector<int> cap_label;
    for (size_t q = 0; q < loops.size(); ++q) cap_label.push_back(static_cast<int>(q + 1));
    cap_loops(capped, loops, cap_label);
    const bool outward = enclosed_volume(capped) > 0;

    SurfaceData out;
    if (zone != nullptr && method != "cgal") throw InputError("remesh: a finer zone needs the cgal remesher");
    if (method == "cgal") {
        std::vector<char> fine;
        if (zone != nullptr) {
            if (zone->fine.size() != static_cast<size_t>(in.F.rows()) || !(zone->fine_edge_mm > 0)) throw InputError("remesh: the finer zone must give one flag per face and an edge > 0");
            fine = zone->fine;
            fine.resize(static_cast<size_t>(capped.F.rows()), 0);  // the caps are not in the zone
        }
        out = remesh_cgal(capped, edge_mm, zone != nullptr ? &fine : nullptr, zone != nullptr ? zone->fine_edge_mm : 0.0);
    } else {
#ifdef ANEU_WITH_NETGEN
        out = remesh_netgen(capped, edge_mm, timeout_s);
        if (!outward) out.F.col(1).swap(out.F.col(2));
        // Cap faces: all three vertices in a loop's plane, within its radius, normal along the plane's.
        for (Eigen::Index f = 0; f < out.F.rows(); ++f) {
            const Eigen::Vector3d a = out.V.row(out.F(f, 0)), b = out.V.row(out.F(f, 1)), c = out.V.row(out.F(f, 2));
            const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
            for (size_t q = 0; q < planes.size(); ++q) {
                const auto& p = planes[q];
                const double tol = 1e-6 * (1.0 + p.radius);
                bool on = std::abs(n.dot(p.n)) > 0.999;
                for (const Eigen::Vector3d* x : {&a, &b, &c}) on = on && std::abs(p.n.dot(*x - p.c)) < tol && (*x - p.c).norm() < 1.5 * p.radius;
                if (on) {
                    out.face_label[f] = static_cast<int>(q + 1);
                    break;
                }
            }
        }
#else
        (void)timeout_s;
        throw InputError("remesh: method = netgen, but this build has no Netgen (ANEU_WITH_NETGEN=OFF)");
#endif
    }
    std::vector<char> keep(static_cast<size_t>(out.F.rows()));
    for (Eigen::Index f = 0; f < out.F.rows(); ++f) keep[static_cast<size_t>(f)] = out.face_label[f] == 0;
    SurfaceData open = sub_surface(out, keep);
    const auto new_loops = boundary_loops(open);
    if (new_loops.size() != loops.size()) {
        throw MeshingError("remesh (" + method + "): the result has " + std::to_string(new_loops.size()) + " boundary loop(s), the input " +
                           std::to_string(loops.size()) + " (a cap was not kept as a separate face)");
    }
    open.label_names = {"surface"};
    // Both meshers leave a few thin triangles, mostly along the boundary loops (measured: 11.7° Netgen,
    // 14.6° CGAL; 1.3° Netgen on an oblique cut end): short boundary segments collapsed, tangential
    // relaxation of the interior vertices, projected back onto the surface, then edge flips between nearly
    // flat neighbours.
    collapse_short_boundary_edges(open);
    collapse_short_interior_edges(open);
    relax_tangentially(open, in, 3);
    collapse_short_interior_edges(open);  // relaxing can pull an interior vertex close to a loop's
    improve_min_angle(open);
    return open;
}

namespace {

/// Empty when `s` is an oriented 2-manifold with `n_loops` boundary loops and no self-intersection;
/// otherwise the failed check and where.
std::string remesh_defect(const SurfaceData& s, size_t n_loops) {
    try {
        const auto loops = boundary_loops(s);
        if (loops.size() != n_loops) return std::to_string(loops.size()) + " boundary loops, the input " + std::to_string(n_loops);
    } catch (const InputError& e) {
        return e.what();
    }
    const auto inter = self_intersections(s, 1);
    if (!inter.empty()) {
        const int f = inter.front().first;
        const Eigen::Vector3d c = (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
        return "self-intersection near (" + shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) + ") mm";
    }
    return {};
}

}  // namespace

RemeshOutcome remesh_checked(const SurfaceData& s, double edge_mm, const std::string& method, double timeout_s, const RemeshZone* zone) {
    const size_t n_loops = boundary_loops(s).size();
    std::vector<std::string> order{zone != nullptr ? std::string("cgal") : method};
#ifdef ANEU_WITH_NETGEN
    if (zone == nullptr) order.push_back(method == "netgen" ? "cgal" : "netgen");
#endif
    std::string why;
    for (const auto& m : order) {
        std::string defect;
        try {
            SurfaceData out = remesh(s, edge_mm, m, timeout_s, zone);
            defect = remesh_defect(out, n_loops);
            if (defect.empty()) return {std::move(out), m, why};
        } catch (const Error& e) {  // the mesher failed, timed out or left a surface the clean-up cannot walk
            defect = e.what();
        }
        why += (why.empty() ? "" : "; ") + m + ": " + defect;
    }
    throw MeshingError("remesh: check failed with every remesher: " + why);
}

}  // namespace aneu::pipeline
