// SPDX-License-Identifier: MIT
#pragma once
// Internal to pipeline/: a SurfaceData as a vtkPolyData (points and triangles only). VTK translation units only.
#include <vtkCellArray.h>
#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>

#include "aneu/core/bundle.hpp"

namespace aneu::pipeline {

inline vtkSmartPointer<vtkPolyData> to_vtk(const SurfaceData& s) {
    auto poly = vtkSmartPointer<vtkPolyData>::New();
    vtkNew<vtkPoints> pts;
    pts->SetDataTypeToDouble();
    pts->SetNumberOfPoints(s.V.rows());
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) pts->SetPoint(i, s.V(i, 0), s.V(i, 1), s.V(i, 2));
    vtkNew<vtkCellArray> tris;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const vtkIdType ids[3] = {s.F(f, 0), s.F(f, 1), s.F(f, 2)};
        tris->InsertNextCell(3, ids);
    }
    poly->SetPoints(pts);
    poly->SetPolys(tris);
    return poly;
}

}  // namespace aneu::pipeline
