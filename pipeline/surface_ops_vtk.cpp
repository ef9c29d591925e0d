// SPDX-License-Identifier: MIT
// VTK side of the geometry stages: isosurface, clipping at end planes, smoothing, mesh file
// readers/writers and voxelisation. VTK lives in this translation unit (and snapshot_vtk.cpp) only.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>

#include <vtkAppendPolyData.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkCleanPolyData.h>
#include <vtkClipPolyData.h>
#include <vtkDoubleArray.h>
#include <vtkFloatArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkImageStencil.h>
#include <vtkIntArray.h>
#include <vtkNew.h>
#include <vtkOBJReader.h>
#include <vtkPLYReader.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataConnectivityFilter.h>
#include <vtkPolyDataReader.h>
#include <vtkPolyDataToImageStencil.h>
#include <vtkSTLReader.h>
#include <vtkSTLWriter.h>
#include <vtkTriangleFilter.h>
#include <vtkWindowedSincPolyDataFilter.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLPolyDataWriter.h>

#include <Eigen/Geometry>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "vtk_convert.hpp"

namespace aneu::pipeline {

namespace {

/// Triangles of a vtkPolyData (other cells ignored), points compacted to those used.
SurfaceData from_vtk(vtkPolyData* poly) {
    SurfaceData s;
    vtkCellArray* polys = poly->GetPolys();
    std::vector<std::array<vtkIdType, 3>> tris;
    vtkNew<vtkIdList> ids;
    for (polys->InitTraversal(); polys->GetNextCell(ids);) {
        if (ids->GetNumberOfIds() != 3) continue;
        tris.push_back({ids->GetId(0), ids->GetId(1), ids->GetId(2)});
    }
    std::vector<int> map(static_cast<size_t>(poly->GetNumberOfPoints()), -1);
    int nv = 0;
    for (const auto& t : tris)
        for (auto v : t)
            if (map[static_cast<size_t>(v)] < 0) map[static_cast<size_t>(v)] = nv++;
    s.V.resize(nv, 3);
    for (size_t i = 0; i < map.size(); ++i) {
        if (map[i] < 0) continue;
        double x[3];
        poly->GetPoint(static_cast<vtkIdType>(i), x);
        s.V.row(map[i]) << x[0], x[1], x[2];
    }
    s.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
    for (size_t f = 0; f < tris.size(); ++f)
        for (int k = 0; k < 3; ++k) s.F(static_cast<Eigen::Index>(f), k) = map[static_cast<size_t>(tris[f][static_cast<size_t>(k)])];
    s.face_label = Eigen::VectorXi::Zero(s.F.rows());
    s.label_names = {"surface"};
    return s;
}

vtkSmartPointer<vtkPolyData> largest_piece(vtkPolyData* in) {
    vtkNew<vtkPolyDataConnectivityFilter> conn;
    conn->SetInputData(in);
    conn->SetExtractionModeToLargestRegion();
    conn->Update();
    vtkNew<vtkCleanPolyData> clean;  // drop the points of the other pieces
    clean->SetInputConnection(conn->GetOutputPort());
    clean->PointMergingOff();
    clean->Update();
    auto out = vtkSmartPointer<vtkPolyData>::New();
    out->DeepCopy(clean->GetOutput());
    return out;
}

/// Trilinear sample of a volume at a continuous index (clamped).
double sample(const Volume<float>& v, double i, double j, double k) {
    const auto& n = v.grid.size;
    i = std::clamp(i, 0.0, static_cast<double>(n[0] - 1));
    j = std::clamp(j, 0.0, static_cast<double>(n[1] - 1));
    k = std::clamp(k, 0.0, static_cast<double>(n[2] - 1));
    const auto i0 = std::min<std::int64_t>(static_cast<std::int64_t>(i), n[0] - 2 < 0 ? 0 : n[0] - 2);
    const auto j0 = std::min<std::int64_t>(static_cast<std::int64_t>(j), n[1] - 2 < 0 ? 0 : n[1] - 2);
    const auto k0 = std::min<std::int64_t>(static_cast<std::int64_t>(k), n[2] - 2 < 0 ? 0 : n[2] - 2);
    const double a = i - static_cast<double>(i0), b = j - static_cast<double>(j0), c = k - static_cast<double>(k0);
    double r = 0;
    for (int q = 0; q < 8; ++q) {
        const std::int64_t ii = std::min(i0 + (q & 1), n[0] - 1), jj = std::min(j0 + ((q >> 1) & 1), n[1] - 1),
                           kk = std::min(k0 + ((q >> 2) & 1), n[2] - 1);
        const double w = ((q & 1) ? a : 1 - a) * (((q >> 1) & 1) ? b : 1 - b) * (((q >> 2) & 1) ? c : 1 - c);
        r += w * v.data[v.grid.linear(ii, jj, kk)];
    }
    return r;
}

/// Flying edges of `values` (borrowed, x fastest) on `img`'s extent at `level`, without normals, gradients or scalars.
vtkSmartPointer<vtkPolyData> flying_edges(vtkImageData* img, const std::vector<float>& values, double level) {
    vtkNew<vtkFloatArray> sc;
    sc->SetNumberOfComponents(1);
    sc->SetArray(const_cast<float*>(values.data()), static_cast<vtkIdType>(values.size()), 1);  // borrowed, not freed
    img->GetPointData()->SetScalars(sc);
    vtkNew<vtkFlyingEdges3D> fe;
    fe->SetInputData(img);
    fe->SetValue(0, level);
    fe->ComputeNormalsOff();
    fe->ComputeGradientsOff();
    fe->ComputeScalarsOff();
    fe->Update();
    vtkSmartPointer<vtkPolyData> out = vtkSmartPointer<vtkPolyData>::New();
    out->ShallowCopy(fe->GetOutput());
    return out;
}

bool ends_with(const std::string& s, const std::string& suffix) {
    if (s.size() < suffix.size()) return false;
    return std::equal(suffix.rbegin(), suffix.rend(), s.rbegin(),
                      [](char a, char b) { return std::tolower(static_cast<unsigned char>(a)) == b; });
}

}  // namespace

SurfaceData isosurface(const Volume<float>& field, double level, bool above_is_inside, bool largest_only) {
    const ImageGrid& g = field.grid;
    if (field.data.size() != g.voxel_count() || g.size[0] < 2 || g.size[1] < 2 || g.size[2] < 2) {
        throw InputError("isosurface: the volume needs at least 2 voxels along each axis");
    }
    // VTK works in index space (origin 0, spacing 1); the vertices are mapped to the physical frame after.
    vtkNew<vtkImageData> img;
    img->SetDimensions(static_cast<int>(g.size[0]), static_cast<int>(g.size[1]), static_cast<int>(g.size[2]));
    img->SetOrigin(0, 0, 0);
    img->SetSpacing(1, 1, 1);
    vtkSmartPointer<vtkPolyData> poly = flying_edges(img, field.data, level);
    if (poly->GetNumberOfPolys() == 0) throw InputError("isosurface: no surface at level " + shortest(level));
    if (largest_only) poly = largest_piece(poly);
    SurfaceData s = from_vtk(poly);
    // Orientation: compare each face normal (index space) with the field's gradient; flip all faces if the
    // majority points the wrong way (flying edges orients consistently; which way depends on the data).
    double vote = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
        const Eigen::Vector3d n = (b - a).cross(c - a), x = (a + b + c) / 3.0;
        const double h = 0.5;
        const Eigen::Vector3d grad((sample(field, x.x() + h, x.y(), x.z()) - sample(field, x.x() - h, x.y(), x.z())),
                                   (sample(field, x.x(), x.y() + h, x.z()) - sample(field, x.x(), x.y() - h, x.z())),
                                   (sample(field, x.x(), x.y(), x.z() + h) - sample(field, x.x(), x.y(), x.z() - h)));
        vote += n.dot(grad) > 0 ? 1 : -1;
    }
    // Outward = towards decreasing field when above is inside.
    const bool flip_index_space = above_is_inside ? vote > 0 : vote < 0;
    // The map to physical coordinates flips orientation when the direction matrix is a reflection.
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> D(g.direction.data());
    const bool flip = flip_index_space != (D.determinant() < 0);
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
        const auto p = g.point(s.V(i, 0), s.V(i, 1), s.V(i, 2));
        s.V.row(i) << p[0], p[1], p[2];
    }
    if (flip) s.F.col(1).swap(s.F.col(2));
    return s;
}

SurfaceData isosurface_blocks(const ImageGrid& g, const std::vector<FieldBlock>& blocks, double level) {
    vtkNew<vtkAppendPolyData> all;
    std::vector<vtkSmartPointer<vtkPolyData>> pieces;
    for (const FieldBlock& b : blocks) {
        if (b.size[0] < 2 || b.size[1] < 2 || b.size[2] < 2) continue;
        float lo = b.values.front(), hi = lo;
        for (float v : b.values) {
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        if (!(lo < level && hi > level) && lo != level && hi != level) continue;  // no crossing in this block
        // Global index space (origin 0, spacing 1, the block's extent): a vertex on a shared edge is computed
        // from the same two samples at the same integer coordinates in both blocks, so it comes out identical.
        vtkNew<vtkImageData> img;
        img->SetExtent(static_cast<int>(b.first[0]), static_cast<int>(b.first[0] + b.size[0] - 1), static_cast<int>(b.first[1]),
                       static_cast<int>(b.first[1] + b.size[1] - 1), static_cast<int>(b.first[2]), static_cast<int>(b.first[2] + b.size[2] - 1));
        img->SetOrigin(0, 0, 0);
        img->SetSpacing(1, 1, 1);
        vtkSmartPointer<vtkPolyData> piece = flying_edges(img, b.values, level);
        if (piece->GetNumberOfPolys() == 0) continue;
        pieces.push_back(piece);
        all->AddInputData(piece);
    }
    if (pieces.empty()) throw MeshingError("isosurface: no surface at level " + shortest(level) + " in " + std::to_string(blocks.size()) + " blocks");
    vtkNew<vtkCleanPolyData> merge;  // exact merge (tolerance 0) of the vertices blocks share
    merge->SetInputConnection(all->GetOutputPort());
    merge->SetTolerance(0.0);
    merge->Update();
    vtkSmartPointer<vtkPolyData> poly = merge->GetOutput();
    poly = largest_piece(poly);
    SurfaceData s = from_vtk(poly);
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
        const auto p = g.point(s.V(i, 0), s.V(i, 1), s.V(i, 2));
        s.V.row(i) << p[0], p[1], p[2];
    }
    // Flying edges orients consistently; outward (towards field > level) is a positive enclosed volume.
    if (enclosed_volume(s) < 0) s.F.col(1).swap(s.F.col(2));
    return s;
}

namespace {
/// The part of `s` where the per-vertex `scalar` is <= 0, cut exactly where it crosses 0 (VTK clip, the cut's
/// duplicated points merged); the largest connected piece.
SurfaceData clip_nonpositive(const SurfaceData& s, const std::vector<double>& scalar) {
    auto poly = to_vtk(s);
    vtkNew<vtkDoubleArray> sc;
    sc->SetNumberOfValues(s.V.rows());
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) sc->SetValue(i, scalar[static_cast<size_t>(i)]);
    poly->GetPointData()->SetScalars(sc);
    vtkNew<vtkClipPolyData> clip;
    clip->SetInputData(poly);
    clip->SetValue(0.0);
    clip->InsideOutOn();  // keep scalar <= 0
    vtkNew<vtkTriangleFilter> tri;
    tri->SetInputConnection(clip->GetOutputPort());
    vtkNew<vtkCleanPolyData> clean;  // merge the points the clip duplicated at the cut
    clean->SetInputConnection(tri->GetOutputPort());
    clean->SetTolerance(0.0);
    clean->Update();
    return from_vtk(largest_piece(clean->GetOutput()));
}
}  // namespace

SurfaceData clip_region_at_plane(const SurfaceData& s, const std::vector<char>& region, const EndPlane& plane) {
    std::vector<double> scalar(static_cast<size_t>(s.V.rows()));
    for (Eigen::Index i = 0; i < s.V.rows(); ++i)
        scalar[static_cast<size_t>(i)] = region[static_cast<size_t>(i)] ? plane.normal.dot(s.V.row(i).transpose() - plane.point) : -1.0;
    SurfaceData out = clip_nonpositive(s, scalar);
    for (Eigen::Index i = 0; i < out.V.rows(); ++i) {
        const Eigen::Vector3d x = out.V.row(i).transpose();
        const double d = plane.normal.dot(x - plane.point);
        if (std::abs(d) < 1e-6) out.V.row(i) = (x - d * plane.normal).transpose();
    }
    return out;
}

namespace {
double disc_radius(const EndPlane& p, double reach, double margin_mm) { return margin_mm >= 0 ? 1.5 * p.radius_mm + margin_mm : reach * (p.radius_mm + 1.0); }
}  // namespace

SurfaceData clip_at_planes(const SurfaceData& s, const std::vector<EndPlane>& planes, double reach, double margin_mm,
                           const std::vector<Eigen::Vector3d>& tips) {
    // Per plane, only the piece beyond it that its disc cuts off is removed: the connected components of
    // the vertices beyond the plane that reach it through an edge crossing the plane within `reach` ×
    // (radius + 1 mm) of its point. Another vessel passing beyond the plane elsewhere is kept.
    const Eigen::Index nv = s.V.rows();
    std::vector<std::vector<int>> adj(static_cast<size_t>(nv));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            adj[static_cast<size_t>(s.F(f, k))].push_back(s.F(f, (k + 1) % 3));
            adj[static_cast<size_t>(s.F(f, (k + 1) % 3))].push_back(s.F(f, k));
        }
    std::vector<double> scalar(static_cast<size_t>(nv), -1.0);
    for (size_t q = 0; q < planes.size(); ++q) {
        const EndPlane& p = planes[q];
        const double R = disc_radius(p, reach, margin_mm);
        std::vector<double> d(static_cast<size_t>(nv));
        for (Eigen::Index i = 0; i < nv; ++i) d[static_cast<size_t>(i)] = p.normal.dot(s.V.row(i).transpose() - p.point);
        std::vector<int> comp(static_cast<size_t>(nv), -1);
        std::vector<char> cut_here;  // per component: crosses the plane within the disc
        for (Eigen::Index v0 = 0; v0 < nv; ++v0) {
            if (d[static_cast<size_t>(v0)] <= 0 || comp[static_cast<size_t>(v0)] >= 0) continue;
            const int id = static_cast<int>(cut_here.size());
            cut_here.push_back(0);
            std::vector<int> stack{static_cast<int>(v0)};
            comp[static_cast<size_t>(v0)] = id;
            while (!stack.empty()) {
                const int u = stack.back();
                stack.pop_back();
                for (int w : adj[static_cast<size_t>(u)]) {
                    if (d[static_cast<size_t>(w)] > 0) {
                        if (comp[static_cast<size_t>(w)] < 0) {
                            comp[static_cast<size_t>(w)] = id;
                            stack.push_back(w);
                        }
                        continue;
                    }
                    const double t = d[static_cast<size_t>(u)] / (d[static_cast<size_t>(u)] - d[static_cast<size_t>(w)]);
                    const Eigen::Vector3d x = (1 - t) * s.V.row(u).transpose() + t * s.V.row(w).transpose();
                    if ((x - p.point).norm() < R) cut_here[static_cast<size_t>(id)] = 1;
                }
            }
        }
        if (q < tips.size()) {  // only the piece nearest the plane's tip
            const Eigen::Vector3d& far = tips[q];
            int tip = -1;
            double best = 1e300;
            for (Eigen::Index v = 0; v < nv; ++v) {
                if (comp[static_cast<size_t>(v)] < 0) continue;
                const double dd = (s.V.row(v).transpose() - far).squaredNorm();
                if (dd < best) {
                    best = dd;
                    tip = comp[static_cast<size_t>(v)];
                }
            }
            for (int c = 0; c < static_cast<int>(cut_here.size()); ++c) cut_here[static_cast<size_t>(c)] = cut_here[static_cast<size_t>(c)] && c == tip;
        }
        for (Eigen::Index v = 0; v < nv; ++v) {
            const int c = comp[static_cast<size_t>(v)];
            bool near_cut = c >= 0 && cut_here[static_cast<size_t>(c)];
            if (!near_cut && c < 0)  // a vertex before the plane next to a removed piece keeps its exact distance
                for (int w : adj[static_cast<size_t>(v)]) {
                    const int cw = comp[static_cast<size_t>(w)];
                    near_cut = near_cut || (cw >= 0 && cut_here[static_cast<size_t>(cw)]);
                }
            if (near_cut) scalar[static_cast<size_t>(v)] = std::max(scalar[static_cast<size_t>(v)], d[static_cast<size_t>(v)]);
        }
    }
    SurfaceData out = clip_nonpositive(s, scalar);
    // Snap the cut's vertices exactly into their planes.
    for (Eigen::Index i = 0; i < out.V.rows(); ++i) {
        Eigen::Vector3d x = out.V.row(i).transpose();
        for (const auto& p : planes) {
            const double d = p.normal.dot(x - p.point);
            if (std::abs(d) < 1e-6 && (x - p.point).norm() < disc_radius(p, reach, margin_mm)) x -= d * p.normal;
        }
        out.V.row(i) = x.transpose();
    }
    return out;
}

void smooth_surface(SurfaceData& s, int iterations, double passband) {
    if (iterations <= 0) return;
    auto poly = to_vtk(s);
    vtkNew<vtkWindowedSincPolyDataFilter> f;
    f->SetInputData(poly);
    f->SetNumberOfIterations(iterations);
    f->SetPassBand(passband);
    f->BoundarySmoothingOff();
    f->FeatureEdgeSmoothingOff();
    f->NonManifoldSmoothingOn();
    f->NormalizeCoordinatesOn();
    f->Update();
    // The filter's "no boundary smoothing" still lets boundary vertices drift (measured ~0.02 mm off their
    // cut plane): put them back.
    std::vector<char> fixed(static_cast<size_t>(s.V.rows()), 0);
    for (const auto& l : boundary_loops(s))
        for (int v : l) fixed[static_cast<size_t>(v)] = 1;
    vtkPoints* p = f->GetOutput()->GetPoints();
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
        if (fixed[static_cast<size_t>(i)]) continue;
        double x[3];
        p->GetPoint(i, x);
        s.V.row(i) << x[0], x[1], x[2];
    }
}

SurfaceData read_mesh_file(const std::string& path, double weld) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) throw InputError(path + ": no such file (expected a surface mesh: .stl, .vtp, .vtk, .obj, .ply)");
    vtkSmartPointer<vtkPolyData> poly;
    auto run = [&](auto reader) {
        reader->SetFileName(path.c_str());
        reader->Update();
        poly = reader->GetOutput();
    };
    if (ends_with(path, ".stl")) {
        run(vtkSmartPointer<vtkSTLReader>::New());
    } else if (ends_with(path, ".vtp")) {
        run(vtkSmartPointer<vtkXMLPolyDataReader>::New());
    } else if (ends_with(path, ".obj")) {
        run(vtkSmartPointer<vtkOBJReader>::New());
    } else if (ends_with(path, ".ply")) {
        run(vtkSmartPointer<vtkPLYReader>::New());
    } else if (ends_with(path, ".vtk")) {  // legacy VTK polydata (VMTK, AneuriskWeb)
        auto reader = vtkSmartPointer<vtkPolyDataReader>::New();
        reader->SetFileName(path.c_str());
        if (!reader->IsFilePolyData()) throw InputError(path + ": not a legacy VTK POLYDATA file (expected a surface mesh)");
        reader->Update();
        poly = reader->GetOutput();
    } else {
        throw InputError(path + ": unsupported surface format (expected .stl, .vtp, .vtk, .obj or .ply)");
    }
    if (!poly || poly->GetNumberOfCells() == 0) throw InputError(path + ": cannot read a surface from the file (no cells)");
    vtkNew<vtkTriangleFilter> tri;
    tri->SetInputData(poly);
    tri->PassVertsOff();
    tri->PassLinesOff();
    // STL stores every triangle's corners separately, and other tools write the copies of one vertex with
    // rounding differences: weld vertices within 1e-6 of the bounding-box diagonal (0.05 µm on a 50 mm
    // vessel, far below any edge), or within the given distance (a coarse exporter: --weld-mm).
    vtkNew<vtkCleanPolyData> clean;
    clean->SetInputConnection(tri->GetOutputPort());
    if (weld > 0) {
        clean->ToleranceIsAbsoluteOn();
        clean->SetAbsoluteTolerance(weld);
    } else {
        clean->SetTolerance(1e-6);
    }
    clean->Update();
    SurfaceData s = from_vtk(clean->GetOutput());
    if (s.F.rows() == 0) throw InputError(path + ": the file holds no triangles");
    // Drop degenerate triangles (a vertex used twice) that merging can create.
    std::vector<char> keep(static_cast<size_t>(s.F.rows()), 1);
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        keep[static_cast<size_t>(f)] = s.F(f, 0) != s.F(f, 1) && s.F(f, 1) != s.F(f, 2) && s.F(f, 0) != s.F(f, 2);
    return sub_surface(s, keep);
}

void write_mesh_file(const std::string& path, const SurfaceData& s) {
    auto poly = to_vtk(s);
    const bool stl = ends_with(path, ".stl");
    if (!stl && !ends_with(path, ".vtp")) throw InputError(path + ": unsupported surface format for writing (expected .vtp or .stl)");
    AtomicPath out(path);
    if (stl) {
        vtkNew<vtkSTLWriter> w;
        w->SetFileName(out.tmp().c_str());
        w->SetInputData(poly);
        w->SetFileTypeToBinary();
        if (!w->Write()) throw IoError(path + ": cannot write STL");
        out.commit();
        return;
    }
    vtkNew<vtkIntArray> lab;
    lab->SetName("label");
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) lab->InsertNextValue(s.face_label.size() ? s.face_label[f] : 0);
    poly->GetCellData()->AddArray(lab);
    if (s.face_region.size() == s.F.rows()) {
        vtkNew<vtkIntArray> reg;
        reg->SetName("region");
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) reg->InsertNextValue(s.face_region[f]);
        poly->GetCellData()->AddArray(reg);
    }
    vtkNew<vtkXMLPolyDataWriter> w;
    w->SetFileName(out.tmp().c_str());
    w->SetInputData(poly);
    if (!w->Write()) throw IoError(path + ": cannot write VTP");
    out.commit();
}

Volume<std::uint8_t> voxelize(const SurfaceData& closed, double spacing, double margin) {
    const Eigen::Vector3d lo = closed.V.colwise().minCoeff().transpose().array() - margin;
    const Eigen::Vector3d hi = closed.V.colwise().maxCoeff().transpose().array() + margin;
    Volume<std::uint8_t> v;
    for (int d = 0; d < 3; ++d) {
        v.grid.size[static_cast<size_t>(d)] = static_cast<std::int64_t>(std::ceil((hi[d] - lo[d]) / spacing)) + 1;
        v.grid.origin[static_cast<size_t>(d)] = lo[d];
        v.grid.spacing[static_cast<size_t>(d)] = spacing;
    }
    vtkNew<vtkImageData> img;
    img->SetDimensions(static_cast<int>(v.grid.size[0]), static_cast<int>(v.grid.size[1]), static_cast<int>(v.grid.size[2]));
    img->SetOrigin(lo.x(), lo.y(), lo.z());
    img->SetSpacing(spacing, spacing, spacing);
    img->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
    auto* p = static_cast<unsigned char*>(img->GetScalarPointer());
    std::fill(p, p + v.grid.voxel_count(), 1);
    vtkNew<vtkPolyDataToImageStencil> st;
    st->SetInputData(to_vtk(closed));
    st->SetOutputOrigin(lo.x(), lo.y(), lo.z());
    st->SetOutputSpacing(spacing, spacing, spacing);
    st->SetOutputWholeExtent(img->GetExtent());
    vtkNew<vtkImageStencil> cut;
    cut->SetInputData(img);
    cut->SetStencilConnection(st->GetOutputPort());
    cut->ReverseStencilOff();
    cut->SetBackgroundValue(0);
    cut->Update();
    const auto* q = static_cast<const unsigned char*>(cut->GetOutput()->GetScalarPointer());
    v.data.assign(q, q + v.grid.voxel_count());
    return v;
}

}  // namespace aneu::pipeline
