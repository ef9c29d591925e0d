// SPDX-License-Identifier: MIT
// VTK writers of `aneuprep export`: .vtu (tetrahedra), .vtp and .stl (surfaces).
#include "export_vtk.hpp"

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDoubleArray.h>
#include <vtkIntArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSTLWriter.h>
#include <vtkStringArray.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLPolyDataWriter.h>
#include <vtkXMLUnstructuredGridWriter.h>

#include "aneu/core/error.hpp"

namespace aneu::pipeline {

namespace {

vtkNew<vtkStringArray> names_array(const char* name, const std::vector<std::string>& names) {
    vtkNew<vtkStringArray> a;
    a->SetName(name);
    for (const auto& n : names) a->InsertNextValue(n);
    return a;
}

vtkNew<vtkIntArray> int_array(const char* name, const Eigen::VectorXi& v) {
    vtkNew<vtkIntArray> a;
    a->SetName(name);
    a->SetNumberOfValues(v.size());
    for (Eigen::Index i = 0; i < v.size(); ++i) a->SetValue(i, v[i]);
    return a;
}

}  // namespace

void write_vtu(const VolumeData& vol, const std::string& path) {
    vtkNew<vtkUnstructuredGrid> g;
    vtkNew<vtkPoints> pts;
    pts->SetDataTypeToDouble();
    pts->SetNumberOfPoints(vol.nodes.rows());
    for (Eigen::Index i = 0; i < vol.nodes.rows(); ++i) pts->SetPoint(i, vol.nodes(i, 0), vol.nodes(i, 1), vol.nodes(i, 2));
    g->SetPoints(pts);
    const bool quad = vol.tets.cols() == 10;  // aneuclip's 10-node order is VTK_QUADRATIC_TETRA's
    g->Allocate(vol.tets.rows());
    std::vector<vtkIdType> ids(static_cast<size_t>(vol.tets.cols()));
    for (Eigen::Index t = 0; t < vol.tets.rows(); ++t) {
        for (Eigen::Index k = 0; k < vol.tets.cols(); ++k) ids[static_cast<size_t>(k)] = vol.tets(t, k);
        g->InsertNextCell(quad ? VTK_QUADRATIC_TETRA : VTK_TETRA, static_cast<vtkIdType>(ids.size()), ids.data());
    }
    g->GetCellData()->AddArray(int_array("region", vol.tet_region));
    g->GetFieldData()->AddArray(names_array("region_names", vol.region_names));
    for (const auto& [name, set] : vol.node_sets) {
        vtkNew<vtkUnsignedCharArray> a;
        a->SetName(("set_" + name).c_str());
        a->SetNumberOfValues(vol.nodes.rows());
        a->Fill(0);
        for (Eigen::Index k = 0; k < set.size(); ++k) a->SetValue(set[k], 1);
        g->GetPointData()->AddArray(a);
    }
    vtkNew<vtkXMLUnstructuredGridWriter> w;
    w->SetFileName(path.c_str());
    w->SetInputData(g);
    w->SetDataModeToBinary();
    w->SetCompressorTypeToZLib();
    if (w->Write() != 1) throw IoError(path + ": VTK could not write the unstructured grid");
}

void write_surface_vtk(const SurfaceData& s, bool stl, const std::string& label, const std::string& path) {
    int want = -1;
    if (!label.empty()) {
        for (size_t k = 0; k < s.label_names.size(); ++k) {
            if (s.label_names[k] == label) want = static_cast<int>(k);
        }
        if (want < 0) {
            std::string names;
            for (const auto& n : s.label_names) names += (names.empty() ? "" : ", ") + n;
            throw InputError("--label '" + label + "': not a label of this surface (" + names + ")");
        }
    }
    vtkNew<vtkPolyData> poly;
    vtkNew<vtkPoints> pts;
    pts->SetDataTypeToDouble();
    pts->SetNumberOfPoints(s.V.rows());
    for (Eigen::Index i = 0; i < s.V.rows(); ++i) pts->SetPoint(i, s.V(i, 0), s.V(i, 1), s.V(i, 2));
    vtkNew<vtkCellArray> tris;
    std::vector<int> kept;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (want >= 0 && s.face_label[f] != want) continue;
        const vtkIdType ids[3] = {s.F(f, 0), s.F(f, 1), s.F(f, 2)};
        tris->InsertNextCell(3, ids);
        kept.push_back(static_cast<int>(f));
    }
    poly->SetPoints(pts);
    poly->SetPolys(tris);
    if (stl) {
        vtkNew<vtkSTLWriter> w;
        w->SetFileName(path.c_str());
        w->SetInputData(poly);
        w->SetFileTypeToBinary();
        if (w->Write() != 1) throw IoError(path + ": VTK could not write the STL file");
        return;
    }
    auto pick = [&](const Eigen::VectorXi& v) {
        Eigen::VectorXi o(static_cast<Eigen::Index>(kept.size()));
        for (size_t k = 0; k < kept.size(); ++k) o[static_cast<Eigen::Index>(k)] = v[kept[k]];
        return o;
    };
    if (s.face_label.size() == s.F.rows()) poly->GetCellData()->AddArray(int_array("label", pick(s.face_label)));
    if (s.face_region.size() == s.F.rows()) poly->GetCellData()->AddArray(int_array("region", pick(s.face_region)));
    poly->GetFieldData()->AddArray(names_array("label_names", s.label_names));
    if (!s.region_names.empty()) poly->GetFieldData()->AddArray(names_array("region_names", s.region_names));
    for (const auto& [fname, m] : s.face_fields) {  // the flow stage's wall shear stress and pressure, per face
        if (m.rows() != s.F.rows()) continue;
        vtkNew<vtkDoubleArray> a;
        a->SetName(fname.c_str());
        a->SetNumberOfComponents(static_cast<int>(m.cols()));
        a->SetNumberOfTuples(static_cast<vtkIdType>(kept.size()));
        for (size_t k = 0; k < kept.size(); ++k)
            for (Eigen::Index c = 0; c < m.cols(); ++c) a->SetComponent(static_cast<vtkIdType>(k), static_cast<int>(c), m(kept[k], c));
        poly->GetCellData()->AddArray(a);
    }
    if (s.vertex_thickness.size() == s.V.rows()) {
        vtkNew<vtkDoubleArray> t;
        t->SetName("thickness");
        t->SetNumberOfValues(s.V.rows());
        for (Eigen::Index i = 0; i < s.V.rows(); ++i) t->SetValue(i, s.vertex_thickness[i]);
        poly->GetPointData()->AddArray(t);
    }
    vtkNew<vtkXMLPolyDataWriter> w;
    w->SetFileName(path.c_str());
    w->SetInputData(poly);
    w->SetDataModeToBinary();
    w->SetCompressorTypeToZLib();
    if (w->Write() != 1) throw IoError(path + ": VTK could not write the polydata");
}

}  // namespace aneu::pipeline
