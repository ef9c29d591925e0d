// SPDX-License-Identifier: MIT
// Exports without heavy headers: format dispatch, Abaqus/CalculiX .inp, XDMF, the static solve (CSV).
#include "aneu/pipeline/export.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <tuple>

#include <fmt/format.h>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/pipeline/image_io.hpp"
#include "export_vtk.hpp"

namespace aneu::pipeline {

namespace fs = std::filesystem;

ExportFormat export_format_from_name(const std::string& name) {
    static const std::vector<std::pair<std::string, ExportFormat>> names{
        {"vtu", ExportFormat::VTU}, {"vtp", ExportFormat::VTP}, {"stl", ExportFormat::STL},
        {"nrrd", ExportFormat::NRRD}, {"xdmf", ExportFormat::XDMF}, {"inp", ExportFormat::INP}};
    for (const auto& [n, f] : names) {
        if (n == name) return f;
    }
    throw InputError("--format '" + name + "': expected vtu, vtp, stl, nrrd, xdmf or inp");
}

namespace {

const VolumeData& need_volume(const Bundle& b, const std::string& input, const std::string& what) {
    if (!b.volume) throw InputError(input + ": no /volume (a tetrahedral mesh) to export as " + what + "; give the output of tetmesh, assemble or condense");
    return *b.volume;
}

void write_inp(const Bundle& b, const std::string& input, const std::string& path, const ExportParams& p) {
    const VolumeData& vol = need_volume(b, input, "inp");
    if (!b.fem) throw InputError(input + ": no /fem (materials and fixed DOFs) to export as inp; give the output of assemble or condense");
    const FemData& fem = *b.fem;
    const Eigen::Index nn = vol.nodes.rows();
    if (fem.K.rows() != 3 * nn) throw InputError(input + ": /fem has " + std::to_string(fem.K.rows()) + " DOFs, /volume " + std::to_string(nn) + " nodes");
    const bool quad = vol.tets.cols() == 10;
    Eigen::VectorXd f;
    if (p.pressure_mpa != 0.0) f = fem::set_pressure_loads(vol, p.pressure_set, p.pressure_mpa);

    std::ofstream o(path);
    if (!o) throw IoError(path + ": cannot write");
    o << "** aneuclip export of " << input << " for Abaqus/CalculiX (ccx -i <name without .inp>)\n";
    o << "** units: mm, N, MPa; nodes and elements numbered from 1 (aneuclip's index + 1); numbers with 14\n"
         "** significant digits in at most 20 characters (CalculiX reads no longer fields)\n";
    if (!b.meta.case_id.empty()) o << "** case: " << b.meta.case_id << "\n";
    o << "*HEADING\naneuclip case " << (b.meta.case_id.empty() ? fs::path(input).stem().string() : b.meta.case_id) << "\n";
    o << "*NODE, NSET=NALL\n";
    for (Eigen::Index i = 0; i < nn; ++i) {
        o << fmt::format("{}, {:.13e}, {:.13e}, {:.13e}\n", i + 1, vol.nodes(i, 0), vol.nodes(i, 1), vol.nodes(i, 2));
    }
    // One element set per region, elements numbered in /volume order.
    for (size_t r = 0; r < vol.region_names.size(); ++r) {
        bool any = false;
        for (Eigen::Index t = 0; t < vol.tets.rows(); ++t) {
            if (vol.tet_region[t] != static_cast<int>(r)) continue;
            if (!any) o << "*ELEMENT, TYPE=" << (quad ? "C3D10" : "C3D4") << ", ELSET=E_" << vol.region_names[r] << "\n";
            any = true;
            o << t + 1;
            for (Eigen::Index k = 0; k < vol.tets.cols(); ++k) o << ", " << vol.tets(t, k) + 1;
            o << "\n";
        }
    }
    for (const auto& [name, set] : vol.node_sets) {
        o << "*NSET, NSET=N_" << name << "\n";
        for (Eigen::Index k = 0; k < set.size(); ++k) o << set[k] + 1 << ((k % 16 == 15 || k + 1 == set.size()) ? "\n" : ", ");
    }
    for (const auto& m : fem.materials) {
        o << "*MATERIAL, NAME=M_" << m.region << "\n*ELASTIC\n" << fmt::format("{:.13e}, {:.13e}\n", m.E_mpa, m.nu);
        o << "*SOLID SECTION, ELSET=E_" << m.region << ", MATERIAL=M_" << m.region << "\n";
    }
    o << "*BOUNDARY\n";
    for (Eigen::Index k = 0; k < fem.fixed_dofs.size(); ++k) {
        const int d = fem.fixed_dofs[k];
        o << d / 3 + 1 << ", " << d % 3 + 1 << ", " << d % 3 + 1 << ", 0\n";
    }
    o << "*STEP\n*STATIC\n";
    if (f.size() > 0) {
        o << "** consistent nodal forces of " << p.pressure_mpa << " MPa on the faces of node set " << p.pressure_set << "\n*CLOAD\n";
        for (Eigen::Index d = 0; d < f.size(); ++d) {
            if (f[d] != 0.0) o << fmt::format("{}, {}, {:.13e}\n", d / 3 + 1, d % 3 + 1, f[d]);
        }
    }
    o << "*NODE PRINT, NSET=NALL\nU\n*NODE FILE\nU\n*END STEP\n";
    o.flush();
    if (!o) throw IoError(path + ": write failed");
}

/// The flow stage's cell fields (/flow) as an XDMF point cloud: velocity and pressure at the fluid cells' centres,
/// read by ParaView from the stage file in place (render as Point Gaussian, or resample onto an image).
void write_flow_xdmf(const FlowFieldData& fl, const std::string& input, const std::string& path) {
    const std::string h5 = fs::relative(fs::absolute(input), fs::absolute(path).parent_path()).string();
    const auto n = fl.centre.rows();
    std::ofstream o(path);
    if (!o) throw IoError(path + ": cannot write");
    o << "<?xml version=\"1.0\" ?>\n<!-- aneuclip: the blood flow at the fluid cells' centres of " << input
      << "; the data are read from that file -->\n<Xdmf Version=\"3.0\">\n <Domain>\n  <Grid Name=\"blood\" GridType=\"Uniform\">\n";
    o << fmt::format("   <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{}\" NodesPerElement=\"1\"/>\n", n);
    o << "   <Geometry GeometryType=\"XYZ\">\n";
    o << fmt::format("    <DataItem Dimensions=\"{} 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{}:/flow/cell_centre</DataItem>\n", n, h5);
    o << "   </Geometry>\n";
    const std::tuple<const char*, const char*, const char*, int> fields[] = {{"velocity_mm_s", "Vector", "velocity", 3},
                                                                            {"pressure_pa", "Scalar", "pressure", 1},
                                                                            {"cell_volume_mm3", "Scalar", "cell_volume", 1}};
    for (const auto& [name, type, ds, k] : fields) {
        o << fmt::format("   <Attribute Name=\"{}\" AttributeType=\"{}\" Center=\"Node\">\n", name, type);
        o << fmt::format("    <DataItem Dimensions=\"{}{}\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{}:/flow/{}</DataItem>\n", n,
                         k == 3 ? " 3" : "", h5, ds);
        o << "   </Attribute>\n";
    }
    o << "  </Grid>\n </Domain>\n</Xdmf>\n";
    o.flush();
    if (!o) throw IoError(path + ": write failed");
}

void write_xdmf(const Bundle& b, const std::string& input, const std::string& path) {
    if (!b.volume && b.flow) {
        write_flow_xdmf(*b.flow, input, path);
        return;
    }
    const VolumeData& vol = need_volume(b, input, "xdmf");
    // The datasets stay in the stage file; the XDMF names it relative to itself.
    const fs::path rel = fs::relative(fs::absolute(input), fs::absolute(path).parent_path());
    const std::string h5 = rel.string();
    const bool quad = vol.tets.cols() == 10;
    std::ofstream o(path);
    if (!o) throw IoError(path + ": cannot write");
    o << "<?xml version=\"1.0\" ?>\n<!-- aneuclip: the tetrahedral wall mesh of " << input
      << "; the data are read from that file -->\n<Xdmf Version=\"3.0\">\n <Domain>\n  <Grid Name=\"wall\" GridType=\"Uniform\">\n";
    o << fmt::format("   <Topology TopologyType=\"{}\" NumberOfElements=\"{}\">\n", quad ? "Tetrahedron_10" : "Tetrahedron", vol.tets.rows());
    o << fmt::format("    <DataItem Dimensions=\"{} {}\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">{}:/volume/tets</DataItem>\n",
                     vol.tets.rows(), vol.tets.cols(), h5);
    o << "   </Topology>\n   <Geometry GeometryType=\"XYZ\">\n";
    o << fmt::format("    <DataItem Dimensions=\"{} 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{}:/volume/nodes</DataItem>\n",
                     vol.nodes.rows(), h5);
    o << "   </Geometry>\n   <Attribute Name=\"region\" AttributeType=\"Scalar\" Center=\"Cell\">\n";
    o << fmt::format("    <DataItem Dimensions=\"{}\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">{}:/volume/tet_region</DataItem>\n",
                     vol.tets.rows(), h5);
    o << "   </Attribute>\n  </Grid>\n </Domain>\n</Xdmf>\n";
    o.flush();
    if (!o) throw IoError(path + ": write failed");
}

void write_mask_nrrd(const Bundle& b, const std::string& input, const std::string& path) {
    if (!b.image || b.image->mask.empty()) throw InputError(input + ": no /image/mask to export as nrrd; give the output of segment (or a phantom's truth.h5)");
    Volume<std::uint8_t> v;
    v.grid = b.image->grid;
    v.data = b.image->mask;
    write_image(path, v);
}

}  // namespace

void export_file(const std::string& input, const std::string& output, const ExportParams& p, Reporter& rep) {
    BundleParts parts;
    parts.condensed_W = false;
    const Bundle b = read_bundle(input, parts);
    AtomicPath out(output);
    switch (p.format) {
    case ExportFormat::INP:
        write_inp(b, input, out.tmp(), p);
        break;
    case ExportFormat::XDMF:
        write_xdmf(b, input, out.tmp());
        break;
    case ExportFormat::NRRD:
        write_mask_nrrd(b, input, out.tmp());
        break;
    case ExportFormat::VTU:
        write_vtu(need_volume(b, input, "vtu"), out.tmp());
        break;
    case ExportFormat::VTP:
    case ExportFormat::STL: {
        if (b.surfaces.empty()) throw InputError(input + ": no /surface to export");
        std::string name = p.surface.empty() ? (b.surfaces.count("wall") ? "wall" : b.surfaces.begin()->first) : p.surface;
        auto it = b.surfaces.find(name);
        if (it == b.surfaces.end()) {
            std::string names;
            for (const auto& [k, s] : b.surfaces) names += (names.empty() ? "" : ", ") + k;
            throw InputError("--surface '" + name + "': not in " + input + " (it has " + names + ")");
        }
        write_surface_vtk(it->second, p.format == ExportFormat::STL, p.label, out.tmp());
        break;
    }
    }
    out.commit();
    rep.info("export: wrote " + output);
}

double solve_file(const std::string& input, const std::string& output_csv, double pressure_mpa, const std::string& pressure_set,
                  Reporter& rep) {
    BundleParts parts;
    parts.condensed_W = false;
    parts.image = false;
    parts.surfaces = false;
    const Bundle b = read_bundle(input, parts);
    if (!b.volume || !b.fem) throw InputError(input + ": needs /volume and /fem (the output of assemble or condense)");
    const Eigen::VectorXd f = fem::set_pressure_loads(*b.volume, pressure_set, pressure_mpa);
    const Eigen::VectorXd u = fem::solve_static(*b.fem, f);
    AtomicPath out(output_csv);
    {
        std::ofstream o(out.tmp());
        if (!o) throw IoError(output_csv + ": cannot write");
        o << "node,x,y,z,ux,uy,uz\n";
        const auto& V = b.volume->nodes;
        for (Eigen::Index i = 0; i < V.rows(); ++i) {
            o << fmt::format("{},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g}\n", i, V(i, 0), V(i, 1), V(i, 2), u[3 * i],
                             u[3 * i + 1], u[3 * i + 2]);
        }
        o.flush();
        if (!o) throw IoError(output_csv + ": write failed");
    }
    out.commit();
    double umax = 0;
    for (Eigen::Index i = 0; i < u.size() / 3; ++i) umax = std::max(umax, u.segment<3>(3 * i).norm());
    rep.info(fmt::format("solve: {} MPa on '{}': largest displacement {:.6g} mm; wrote {}", pressure_mpa, pressure_set, umax, output_csv));
    return umax;
}

}  // namespace aneu::pipeline
