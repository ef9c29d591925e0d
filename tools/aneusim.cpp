// SPDX-License-Identifier: MIT
// aneusim: the real-time clipping simulator. Links aneu_sim + aneu_core only (no offline stack).
#include <CLI/CLI.hpp>

#include "aneu/core/error.hpp"
#include "aneu/core/version.hpp"
#include "aneu/sim/model.hpp"
#include "cli_common.hpp"

int main(int argc, char** argv) {
    using namespace aneu::tools;
    CLI::App app{"aneuclip real-time clipping simulator", "aneusim"};
    app.set_version_flag("--version", std::string("aneusim ") + aneu::tool_version() + " (" + aneu::git_revision() + ")");
    std::string bundle;
    std::vector<double> sphere;
    LoggingOptions log;
    app.add_option("bundle", bundle, "case bundle (.h5) made by `aneuprep condense`")->required();
    app.add_option("--region-sphere", sphere, "working region x,y,z,radius [mm]: load only W's columns there")
        ->delimiter(',')
        ->expected(4);
    add_logging_options(app, log);
    CLI11_PARSE(app, argc, argv);
    apply_logging_options(log);
    return run_guarded("aneusim", [&] {
        std::optional<aneu::sim::RegionSphere> region;
        if (!sphere.empty()) {
            if (!(sphere[3] > 0)) throw aneu::InputError("--region-sphere: radius = " + std::to_string(sphere[3]) + ", must be > 0");
            region = aneu::sim::RegionSphere{{sphere[0], sphere[1], sphere[2]}, sphere[3]};
        }
        const auto m = aneu::sim::load_model(bundle, region);
        const bool f32 = m.precision == aneu::Precision::FLOAT32;
        logger().info("loaded {}: {} nodes, W {} rows x {} of {} columns ({}) in {:.3f} s", bundle, m.nodes.rows(),
                      m.dof_node.size(), m.active.size(), m.dof_node.size(), f32 ? "float32" : "float64", m.load_seconds);
        fmt::print("bundle {}\nnodes {}\nW_rows {}\nW_columns_loaded {}\nprecision {}\nload_seconds {:.3f}\n", bundle,
                   m.nodes.rows(), m.dof_node.size(), m.active.size(), f32 ? "float32" : "float64", m.load_seconds);
    });
}
