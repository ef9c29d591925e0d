// SPDX-License-Identifier: MIT
// aneuprep: the offline stages of aneuclip, one subcommand each.
#include <CLI/CLI.hpp>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/version.hpp"
#include "aneu/pipeline/dependency_info.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

void build_aneuprep(CLI::App& app, LoggingOptions& log, const std::vector<std::string>& args,
                    std::function<int()>& action) {
    app.require_subcommand(1);
    app.fallthrough();  // --log-level/--quiet/--log-file are accepted after the subcommand too
    app.set_version_flag("--version", std::string("aneuprep ") + aneu::tool_version() + " (" +
                                          aneu::git_revision() + ")");
    app.set_config("--config", "", "TOML file with one [section] per subcommand; command-line flags override it");
    app.allow_config_extras(CLI::config_extras_mode::error);
    add_logging_options(app, log);
    add_stage_commands(app, args, action);
    add_inspect_command(app, action);
    add_snapshot_command(app, action);
    add_run_command(app, action);
    add_export_commands(app, action);
    add_report_command(app, action);

    auto* ver = app.add_subcommand("version", "print versions of aneuclip and of every library it uses");
    ver->callback([&action] {
        action = [] {
            fmt::print("aneuprep {} ({})\n", aneu::tool_version(), aneu::git_revision());
            for (const auto& [k, v] : aneu::core_dependency_versions()) fmt::print("  {:<18} {}\n", k, v);
            for (const auto& [k, v] : aneu::pipeline::pipeline_dependency_versions()) {
                fmt::print("  {:<18} {}\n", k, v);
            }
            return 0;
        };
    });
}

int parse_aneuprep(CLI::App& app, int argc, const char* const* argv) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::ConfigError& e) {
        // CLI11 says "INI was not able to parse phantom.seeed": name the file and what is expected.
        const auto* cfg = app.get_config_ptr();
        fmt::print(stderr, "aneuprep: error: config file '{}': {} (keys are the subcommand's long option names, "
                           "e.g. [phantom] spacing-mm = [0.4, 0.4, 0.5])\n",
                   cfg ? cfg->as<std::string>() : std::string("?"), e.what());
        return e.get_exit_code();
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    }
    return -1;
}

}  // namespace aneu::tools

int main(int argc, char** argv) {
    using namespace aneu::tools;
    reexec_for_this_machine(argv, true);
    CLI::App app{"aneuclip offline pipeline: CT angiography -> case bundle", "aneuprep"};
    LoggingOptions log;
    const auto args = args_of(argc, argv);
    std::function<int()> action;
    build_aneuprep(app, log, args, action);
    if (const int rc = parse_aneuprep(app, argc, argv); rc >= 0) return rc;
    apply_logging_options(log);
    return action ? action() : 0;
}
