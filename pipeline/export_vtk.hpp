// SPDX-License-Identifier: MIT
#pragma once
// Internal to pipeline/: the VTK writers of export (VTK stays in export_vtk.cpp).
#include <string>

#include "aneu/core/bundle.hpp"

namespace aneu::pipeline {

/// The tetrahedral mesh as a VTK XML unstructured grid (.vtu).
void write_vtu(const VolumeData& vol, const std::string& path);
/// A surface as VTK XML polydata (.vtp) or binary STL (only the faces labelled `label` when it is set).
void write_surface_vtk(const SurfaceData& s, bool stl, const std::string& label, const std::string& path);

}  // namespace aneu::pipeline
