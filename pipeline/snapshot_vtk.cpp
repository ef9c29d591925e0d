// SPDX-License-Identifier: MIT
// VTK lives in this translation unit only.
#include <cstdlib>

#include <vtkActor.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkIntArray.h>
#include <vtkLookupTable.h>
#include <vtkNew.h>
#include <vtkPNGWriter.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderer.h>
#include <vtkWindowToImageFilter.h>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/snapshot.hpp"

namespace aneu::pipeline {

void snapshot_surface(const SurfaceData& s, ColorBy by, const std::string& png, int width, int height) {
    const char* display = std::getenv("DISPLAY");
    if (!display || !*display) {
        throw InputError("snapshot: no X display (DISPLAY is unset); Debian's VTK renders through X11 only: run the "
                         "command under `xvfb-run -a`");
    }
    vtkNew<vtkPoints> pts;
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) pts->InsertNextPoint(s.V(i, 0), s.V(i, 1), s.V(i, 2));
    vtkNew<vtkCellArray> tris;
    vtkNew<vtkIntArray> color;
    const Eigen::VectorXi& c = by == ColorBy::REGION && s.face_region.size() == s.F.rows() ? s.face_region : s.face_label;
    const int ncolors = std::max(1, c.size() ? c.maxCoeff() + 1 : 1);
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const vtkIdType ids[3] = {s.F(f, 0), s.F(f, 1), s.F(f, 2)};
        tris->InsertNextCell(3, ids);
        color->InsertNextValue(c.size() ? c[f] : 0);
    }
    vtkNew<vtkPolyData> poly;
    poly->SetPoints(pts);
    poly->SetPolys(tris);
    poly->GetCellData()->SetScalars(color);
    vtkNew<vtkLookupTable> lut;
    lut->SetNumberOfTableValues(ncolors);
    const double palette[6][3] = {{0.85, 0.33, 0.27}, {0.95, 0.80, 0.35}, {0.30, 0.55, 0.85}, {0.40, 0.75, 0.45}, {0.7, 0.5, 0.8}, {0.6, 0.6, 0.6}};
    for (int k = 0; k < ncolors; ++k) lut->SetTableValue(k, palette[k % 6][0], palette[k % 6][1], palette[k % 6][2], 1.0);
    lut->SetTableRange(0, ncolors - 1);
    lut->Build();
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputData(poly);
    mapper->SetLookupTable(lut);
    mapper->SetScalarRange(0, ncolors - 1);
    mapper->SetScalarModeToUseCellData();
    vtkNew<vtkActor> actor;
    actor->SetMapper(mapper);
    actor->GetProperty()->EdgeVisibilityOn();
    actor->GetProperty()->SetEdgeColor(0.15, 0.15, 0.15);
    actor->GetProperty()->SetLineWidth(0.5);
    vtkNew<vtkRenderer> ren;
    ren->AddActor(actor);
    ren->SetBackground(1, 1, 1);
    vtkNew<vtkRenderWindow> win;
    win->SetOffScreenRendering(1);
    win->AddRenderer(ren);
    win->SetSize(width, height);
    ren->ResetCamera();
    vtkCamera* cam = ren->GetActiveCamera();
    double fp[3];
    cam->GetFocalPoint(fp);
    const double d = cam->GetDistance();
    cam->SetPosition(fp[0] + 0.5 * d, fp[1] - 0.8 * d, fp[2] + 0.3 * d);
    cam->SetViewUp(0, 0, 1);
    ren->ResetCamera();
    win->Render();
    vtkNew<vtkWindowToImageFilter> grab;
    grab->SetInput(win);
    grab->Update();
    vtkNew<vtkPNGWriter> w;
    w->SetFileName(png.c_str());
    w->SetInputConnection(grab->GetOutputPort());
    w->Write();
    if (w->GetErrorCode() != 0) throw IoError(png + ": cannot write the PNG");
}

}  // namespace aneu::pipeline
