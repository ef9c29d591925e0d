// SPDX-License-Identifier: MIT
// `aneuprep export` (ParaView, 3D Slicer, Abaqus/CalculiX) and `aneuprep solve` (static check of the model).
#include <memory>

#include "aneu/pipeline/export.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

void add_export_commands(CLI::App& app, std::function<int()>& action) {
    {
        struct Opts {
            std::string input, output, format;
            pipeline::ExportParams p;
        };
        auto o = std::make_shared<Opts>();
        auto* c = app.add_subcommand("export", "write a stage file's mesh, surface or mask for ParaView, 3D Slicer or CalculiX");
        c->add_option("input", o->input, "stage file (.h5)")->required();
        c->add_option("-o,--output", o->output, "output file, written atomically")->required();
        c->add_option("--format", o->format,
                      "vtu (tetrahedra), vtp or stl (a surface), nrrd (the segmentation as a label map), xdmf "
                      "(tetrahedra, data read from the stage file), inp (Abaqus/CalculiX model)")
            ->required();
        c->add_option("--surface", o->p.surface, "vtp/stl: which surface (wall, lumen) [default: wall if present]");
        c->add_option("--label", o->p.label, "stl: only the faces with this label (outer, inner, aneurysm, ...)");
        c->add_option("--pressure-mpa", o->p.pressure_mpa, "inp: a test load, this pressure on the faces of --pressure-set")
            ->capture_default_str();
        c->add_option("--pressure-set", o->p.pressure_set, "inp: node set whose boundary faces carry the pressure")
            ->capture_default_str();
        c->callback([o, &action] {
            action = [o] {
                return run_guarded("aneuprep export", [&] {
                    o->p.format = pipeline::export_format_from_name(o->format);
                    Reporter rep = make_log_reporter();
                    pipeline::export_file(o->input, o->output, o->p, rep);
                });
            };
        });
    }
    {
        struct Opts {
            std::string input, output, set = "inner";
            double pressure = 0.016;
        };
        auto o = std::make_shared<Opts>();
        auto* c = app.add_subcommand("solve", "static displacement of the model under a pressure (a check of the case; CSV)");
        c->add_option("input", o->input, "output of assemble or condense (.h5)")->required();
        c->add_option("-o,--output", o->output, "CSV: node, x, y, z, ux, uy, uz [mm]")->required();
        c->add_option("--pressure-mpa", o->pressure, "pressure [MPa] (0.016 = 120 mmHg)")->capture_default_str();
        c->add_option("--pressure-set", o->set, "node set whose boundary faces carry it")->capture_default_str();
        c->callback([o, &action] {
            action = [o] {
                return run_guarded("aneuprep solve", [&] {
                    Reporter rep = make_log_reporter();
                    pipeline::solve_file(o->input, o->output, o->pressure, o->set, rep);
                });
            };
        });
    }
}

}  // namespace aneu::tools
