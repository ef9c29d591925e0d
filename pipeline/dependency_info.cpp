// SPDX-License-Identifier: MIT
// Library versions of the pipeline. Includes ITK, so no Eigen here.
#include <CGAL/version.h>
#include <gdcmVersion.h>
#include <itkVersion.h>
#include <tetgen.h>
#include <vtkVersion.h>

#ifdef ANEU_WITH_NETGEN
namespace nglib {
#include <nglib.h>
}
#endif

#include "aneu/pipeline/dependency_info.hpp"

namespace aneu::pipeline {

std::vector<std::pair<std::string, std::string>> pipeline_dependency_versions() {
    std::vector<std::pair<std::string, std::string>> v{
        {"ITK", itk::Version::GetITKVersion()},
        {"GDCM", gdcm::Version::GetVersion()},
        {"VTK", vtkVersion::GetVTKVersion()},
        {"CGAL", CGAL_VERSION_STR},
    };
    tetgenbehavior tb;  // constructing TetGen's option parser proves libtet is linked and callable
    v.emplace_back("TetGen", tb.quality == 0 ? "1.5 (libtet)" : "1.5 (libtet, unexpected defaults)");
#ifdef ANEU_WITH_NETGEN
    nglib::Ng_Mesh* m = nglib::Ng_NewMesh();
    v.emplace_back("Netgen", m ? "6.2 (nglib)" : "6.2 (nglib: Ng_NewMesh failed)");
    if (m) nglib::Ng_DeleteMesh(m);
#else
    v.emplace_back("Netgen", "disabled (ANEU_WITH_NETGEN=OFF)");
#endif
    return v;
}

}  // namespace aneu::pipeline
