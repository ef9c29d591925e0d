// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Exports of stage files for other tools: ParaView (VTU, VTP, XDMF), 3D Slicer (NRRD label map, STL, VTP),
/// and Abaqus/CalculiX (.inp) to cross-check the model in another FEM code; and the static solve that the
/// .inp is checked against.
#include <string>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

enum class ExportFormat { VTU, VTP, STL, NRRD, XDMF, INP };

/// "vtu", "vtp", ... @throws InputError for another name
ExportFormat export_format_from_name(const std::string& name);

struct ExportParams {
    ExportFormat format = ExportFormat::VTU;
    std::string surface;       ///< vtp/stl: which /surface/<name> (default: wall if present, else lumen)
    std::string label;         ///< stl: only faces with this label (e.g. "outer", "aneurysm"); empty = all
    double pressure_mpa = 0;   ///< inp: a test load, this pressure on the faces of `pressure_set` (0 = none)
    std::string pressure_set = "inner";
};

/// Writes `input`'s data in `params.format` to `output` (atomically: a temporary name, then renamed).
///  - vtu:  /volume tetrahedra (VTK_TETRA or VTK_QUADRATIC_TETRA) with cell data `region` and point data
///          `set_<name>` (1 in the node set);
///  - vtp/stl: a surface with cell data `label`, `region` and point data `thickness` (vtp);
///  - nrrd: /image/mask as a label map in the physical frame (3D Slicer: load as segmentation);
///  - xdmf: an XDMF file describing /volume of `input` in place (ParaView reads the HDF5 datasets from it); for a
///          flow stage's file (no /volume) the /flow cell centres as points with velocity and pressure;
///  - inp:  nodes, C3D4/C3D10 elements with one ELSET and material per region, NSETs, the fixed DOFs as
///          *BOUNDARY, a *STATIC step with the optional pressure as *CLOAD, and *NODE PRINT of U.
/// @throws InputError when the input lacks what the format needs
void export_file(const std::string& input, const std::string& output, const ExportParams& params, Reporter& rep);

/// The static displacement of the model in `input` (/volume and /fem) under a pressure on a node set's faces,
/// written as CSV: node (0-based), x, y, z, ux, uy, uz [mm]. Atomic. Returns the largest |u| [mm].
double solve_file(const std::string& input, const std::string& output_csv, double pressure_mpa,
                  const std::string& pressure_set, Reporter& rep);

}  // namespace aneu::pipeline
