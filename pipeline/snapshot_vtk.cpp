// SPDX-License-Identifier: MIT
// VTK lives in this translation unit only.
#include <cstdlib>

#include <vtkActor.h>
#include <algorithm>

#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDiskSource.h>
#include <vtkDoubleArray.h>
#include <vtkIntArray.h>
#include <vtkLookupTable.h>
#include <vtkNew.h>
#include <vtkPNGWriter.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkTransform.h>
#include <vtkTransformPolyDataFilter.h>
#include <vtkTubeFilter.h>
#include <vtkWindowToImageFilter.h>

#include <Eigen/Dense>

#include "aneu/core/common.hpp"
#include "aneu/core/atomic_file.hpp"
#include "aneu/core/error.hpp"
#include "aneu/pipeline/snapshot.hpp"
#include "vtk_convert.hpp"

namespace aneu::pipeline {

namespace {

/// A lookup table's range [lo, hi] on a mapper.
void colour_scale(vtkLookupTable* lut, vtkPolyDataMapper* mapper, double lo, double hi) {
    lut->SetTableRange(lo, hi);
    lut->Build();
    mapper->SetLookupTable(lut);
    mapper->SetScalarRange(lo, hi);
}

/// A colour bar at the right edge: `x` its left edge, `width` its width (fractions of the window).
vtkSmartPointer<vtkScalarBarActor> scalar_bar(vtkLookupTable* lut, const std::string& title, double x, double width) {
    auto bar = vtkSmartPointer<vtkScalarBarActor>::New();
    bar->SetLookupTable(lut);
    bar->SetTitle(title.c_str());
    bar->SetNumberOfLabels(5);
    bar->GetTitleTextProperty()->SetColor(0.1, 0.1, 0.1);
    bar->GetLabelTextProperty()->SetColor(0.1, 0.1, 0.1);
    bar->SetPosition(x, 0.1);
    bar->SetWidth(width);
    bar->SetHeight(0.8);
    return bar;
}

const double PALETTE[8][3] = {{0.85, 0.33, 0.27}, {0.95, 0.80, 0.35}, {0.30, 0.55, 0.85}, {0.40, 0.75, 0.45},
                              {0.70, 0.50, 0.80}, {0.95, 0.55, 0.20}, {0.45, 0.80, 0.85}, {0.60, 0.60, 0.60}};

}  // namespace

void require_snapshot_display() {
    const char* display = std::getenv("DISPLAY");
    if (!display || !*display) {
        throw InputError("snapshot: no X display (DISPLAY is unset); Debian's VTK renders through X11 only: run the "
                         "command under `xvfb-run -a`");
    }
}

void snapshot_scene(const SnapshotScene& scene, const std::string& png, int width, int height) {
    require_snapshot_display();
    vtkNew<vtkRenderer> ren;
    ren->SetBackground(1, 1, 1);
    std::vector<Eigen::Vector3d> all;
    int legend_line = 0;
    auto legend = [&](const std::string& text, const double* rgb) {
        vtkNew<vtkTextActor> t;
        t->SetInput(text.c_str());
        t->GetTextProperty()->SetFontSize(18);
        t->GetTextProperty()->SetColor(rgb[0] * 0.8, rgb[1] * 0.8, rgb[2] * 0.8);
        t->GetTextProperty()->BoldOn();
        t->SetDisplayPosition(12, height - 60 - 24 * legend_line++);
        ren->AddActor2D(t);
    };
    for (const auto& layer : scene.layers) {
        const SurfaceData& s = layer.surface;
        for (Eigen::Index i = 0; i < s.V.rows(); ++i) all.push_back(s.V.row(i).transpose());
        auto poly = to_vtk(s);
        vtkNew<vtkPolyDataMapper> mapper;
        mapper->SetInputData(poly);
        vtkNew<vtkLookupTable> lut;
        if (layer.by == ColorBy::THICKNESS && s.vertex_thickness.size() == s.V.rows()) {
            vtkNew<vtkDoubleArray> t;
            t->SetName("thickness [mm]");
            for (Eigen::Index i = 0; i < s.V.rows(); ++i) t->InsertNextValue(s.vertex_thickness[i]);
            poly->GetPointData()->SetScalars(t);
            const double lo = s.vertex_thickness.minCoeff(), hi = std::max(lo + 1e-6, s.vertex_thickness.maxCoeff());
            lut->SetHueRange(0.0, 0.66);  // thin = red, thick = blue
            colour_scale(lut, mapper, lo, hi);
            mapper->SetScalarModeToUsePointData();
            ren->AddActor2D(scalar_bar(lut, "thickness [mm]", 0.88, 0.1));
        } else if (layer.by == ColorBy::FIELD) {
            const auto f = s.face_fields.find(layer.field);
            if (f == s.face_fields.end() || f->second.rows() != s.F.rows()) throw InputError("snapshot: the surface has no face field '" + layer.field + "'");
            vtkNew<vtkDoubleArray> t;
            t->SetName(layer.field.c_str());
            std::vector<double> v;
            for (Eigen::Index i = 0; i < s.F.rows(); ++i) v.push_back(f->second.cols() == 1 ? f->second(i, 0) : f->second.row(i).norm());
            for (double x : v) t->InsertNextValue(x);
            poly->GetCellData()->SetScalars(t);
            std::vector<double> sorted = v;
            std::sort(sorted.begin(), sorted.end());
            const double lo = sorted.front(), hi = std::max(lo + 1e-12, sorted[static_cast<size_t>(0.98 * static_cast<double>(sorted.size() - 1))]);
            lut->SetHueRange(0.66, 0.0);  // low = blue, high = red
            colour_scale(lut, mapper, lo, hi);
            mapper->SetScalarModeToUseCellData();
            ren->AddActor2D(scalar_bar(lut, layer.field, 0.85, 0.12));
        } else {
            const bool region = layer.by == ColorBy::REGION && s.face_region.size() == s.F.rows();
            const Eigen::VectorXi& c = region ? s.face_region : s.face_label;
            const auto& names = region ? s.region_names : s.label_names;
            const int ncolors = std::max<int>(1, static_cast<int>(names.size()));
            vtkNew<vtkIntArray> color;
            for (Eigen::Index f = 0; f < s.F.rows(); ++f) color->InsertNextValue(c.size() ? c[f] : 0);
            poly->GetCellData()->SetScalars(color);
            lut->SetNumberOfTableValues(ncolors);
            for (int k = 0; k < ncolors; ++k) lut->SetTableValue(k, PALETTE[k % 8][0], PALETTE[k % 8][1], PALETTE[k % 8][2], 1.0);
            lut->SetTableRange(0, ncolors - 1);
            lut->Build();
            mapper->SetLookupTable(lut);
            mapper->SetScalarRange(0, ncolors - 1);
            mapper->SetScalarModeToUseCellData();
            if (layer.opacity >= 0.99)
                for (int k = 0; k < ncolors; ++k) legend(names.empty() ? "surface" : names[static_cast<size_t>(k)], PALETTE[k % 8]);
        }
        vtkNew<vtkActor> actor;
        actor->SetMapper(mapper);
        actor->GetProperty()->SetOpacity(layer.opacity);
        if (layer.edges) {
            actor->GetProperty()->EdgeVisibilityOn();
            actor->GetProperty()->SetEdgeColor(0.15, 0.15, 0.15);
            actor->GetProperty()->SetLineWidth(0.5);
        }
        ren->AddActor(actor);
    }
    if (!scene.lines.empty()) {
        vtkNew<vtkPolyData> poly;
        vtkNew<vtkPoints> pts;
        vtkNew<vtkCellArray> cells;
        vtkNew<vtkDoubleArray> val;
        val->SetName(scene.line_title.c_str());
        std::vector<double> all_v;
        for (size_t l = 0; l < scene.lines.size(); ++l) {
            const auto& line = scene.lines[l];
            cells->InsertNextCell(static_cast<vtkIdType>(line.size()));
            for (size_t i = 0; i < line.size(); ++i) {
                cells->InsertCellPoint(pts->InsertNextPoint(line[i].x(), line[i].y(), line[i].z()));
                const double v = l < scene.line_values.size() && i < scene.line_values[l].size() ? scene.line_values[l][i] : 0.0;
                val->InsertNextValue(v);
                all_v.push_back(v);
                all.push_back(line[i]);
            }
        }
        poly->SetPoints(pts);
        poly->SetLines(cells);
        poly->GetPointData()->SetScalars(val);
        std::sort(all_v.begin(), all_v.end());
        const double lo = all_v.front(), hi = std::max(lo + 1e-12, all_v[static_cast<size_t>(0.98 * static_cast<double>(all_v.size() - 1))]);
        vtkNew<vtkPolyDataMapper> m;
        m->SetInputData(poly);
        vtkNew<vtkLookupTable> lut;
        lut->SetHueRange(0.66, 0.0);
        colour_scale(lut, m, lo, hi);
        m->SetScalarModeToUsePointData();
        vtkNew<vtkActor> a;
        a->SetMapper(m);
        a->GetProperty()->SetLineWidth(2.0);
        ren->AddActor(a);
        ren->AddActor2D(scalar_bar(lut, scene.line_title, 0.85, 0.12));
    }
    const Centerline& cl = scene.centerline;
    if (cl.points.rows() > 1 && cl.offsets.size() > 1) {
        vtkNew<vtkPolyData> lines;
        vtkNew<vtkPoints> pts;
        for (Eigen::Index i = 0; i < cl.points.rows(); ++i) {
            pts->InsertNextPoint(cl.points(i, 0), cl.points(i, 1), cl.points(i, 2));
            all.push_back(cl.points.row(i).transpose());
        }
        vtkNew<vtkCellArray> cells;
        for (Eigen::Index l = 0; l + 1 < cl.offsets.size(); ++l) {
            cells->InsertNextCell(cl.offsets[l + 1] - cl.offsets[l]);
            for (int i = cl.offsets[l]; i < cl.offsets[l + 1]; ++i) cells->InsertCellPoint(i);
        }
        lines->SetPoints(pts);
        lines->SetLines(cells);
        vtkNew<vtkTubeFilter> tube;
        tube->SetInputData(lines);
        tube->SetRadius(0.12);
        tube->SetNumberOfSides(10);
        vtkNew<vtkPolyDataMapper> m;
        m->SetInputConnection(tube->GetOutputPort());
        m->ScalarVisibilityOff();
        vtkNew<vtkActor> a;
        a->SetMapper(m);
        a->GetProperty()->SetColor(0.1, 0.1, 0.1);
        ren->AddActor(a);
        const double black[3] = {0.15, 0.15, 0.15};
        legend("centerline", black);
    }
    for (const auto& p : scene.planes) {
        vtkNew<vtkDiskSource> disk;
        disk->SetInnerRadius(0);
        disk->SetOuterRadius(1.3 * p.radius_mm);
        disk->SetCircumferentialResolution(48);
        vtkNew<vtkTransform> tr;
        tr->Translate(p.point.data());
        const Eigen::Vector3d z(0, 0, 1), axis = z.cross(p.normal);
        const double angle = std::atan2(axis.norm(), z.dot(p.normal))  / DEG;
        if (axis.norm() > 1e-12) tr->RotateWXYZ(angle, axis.x(), axis.y(), axis.z());
        else if (p.normal.z() < 0) tr->RotateWXYZ(180, 1, 0, 0);
        vtkNew<vtkTransformPolyDataFilter> tf;
        tf->SetInputConnection(disk->GetOutputPort());
        tf->SetTransform(tr);
        vtkNew<vtkPolyDataMapper> m;
        m->SetInputConnection(tf->GetOutputPort());
        vtkNew<vtkActor> a;
        a->SetMapper(m);
        a->GetProperty()->SetColor(0.2, 0.7, 0.3);
        a->GetProperty()->SetOpacity(0.6);
        ren->AddActor(a);
        all.push_back(p.point);
    }
    if (!scene.planes.empty()) {
        const double green[3] = {0.2, 0.7, 0.3};
        legend("end planes", green);
    }
    if (!scene.title.empty()) {
        vtkNew<vtkTextActor> t;
        t->SetInput(scene.title.c_str());
        t->GetTextProperty()->SetFontSize(22);
        t->GetTextProperty()->SetColor(0.1, 0.1, 0.1);
        t->SetDisplayPosition(12, height - 32);
        ren->AddActor2D(t);
    }
    vtkNew<vtkRenderWindow> win;
    win->SetOffScreenRendering(1);
    win->AddRenderer(ren);
    win->SetSize(width, height);
    // Camera along the geometry's thinnest principal direction (largest projected extent), slightly tilted.
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& x : all) mean += x;
    if (!all.empty()) mean /= static_cast<double>(all.size());
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (const auto& x : all) C += (x - mean) * (x - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
    Eigen::Vector3d view = es.eigenvectors().col(0), up = es.eigenvectors().col(1);
    if (view.dot(Eigen::Vector3d(0.3, -1.0, 0.2)) < 0) view = -view;  // prefer looking from anterior (−y), as radiologists do
    // ... unless the aneurysm sac is on the other side: the picture is there to show it.
    for (const auto& layer : scene.layers) {
        const SurfaceData& sf = layer.surface;
        const auto it = std::find(sf.label_names.begin(), sf.label_names.end(), "aneurysm");
        if (it == sf.label_names.end() || sf.face_label.size() != sf.F.rows()) continue;
        const int sac = static_cast<int>(it - sf.label_names.begin());
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        int n = 0;
        for (Eigen::Index f = 0; f < sf.F.rows(); ++f)
            if (sf.face_label[f] == sac) {
                c += (sf.V.row(sf.F(f, 0)) + sf.V.row(sf.F(f, 1)) + sf.V.row(sf.F(f, 2))).transpose() / 3.0;
                ++n;
            }
        if (n > 0 && (c / n - mean).dot(view) < 0) view = -view;
        break;
    }
    if (up.z() < 0) up = -up;
    const Eigen::Vector3d dir = (view + 0.25 * up.cross(view) + 0.25 * up).normalized();
    vtkCamera* cam = ren->GetActiveCamera();
    cam->SetFocalPoint(mean.data());
    const Eigen::Vector3d pos = mean + 100.0 * dir;
    cam->SetPosition(pos.data());
    cam->SetViewUp(up.data());
    ren->ResetCamera();
    cam->Zoom(1.15);
    win->Render();
    vtkNew<vtkWindowToImageFilter> grab;
    grab->SetInput(win);
    grab->Update();
    AtomicPath out(png);
    vtkNew<vtkPNGWriter> w;
    w->SetFileName(out.tmp().c_str());
    w->SetInputConnection(grab->GetOutputPort());
    w->Write();
    if (w->GetErrorCode() != 0) throw IoError(png + ": cannot write the PNG");
    out.commit();
}

void snapshot_surface(const SurfaceData& s, ColorBy by, const std::string& png, int width, int height, const std::string& field) {
    SnapshotScene scene;
    scene.layers.push_back({s, by, 1.0, true, field});
    snapshot_scene(scene, png, width, height);
}

}  // namespace aneu::pipeline
