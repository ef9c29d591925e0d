// SPDX-License-Identifier: MIT
#pragma once
// Subcommands of aneuprep. Each add_* registers its options on `app`; when its subcommand is selected,
// its parse callback sets `action`, which main runs after logging is configured.
#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli_common.hpp"

namespace aneu::tools {

/// Every stage subcommand (phantom, segment, surface, wall, tetmesh, assemble, condense, tubewall).
void add_stage_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action);
void add_inspect_command(CLI::App& app, std::function<int()>& action);
void add_snapshot_command(CLI::App& app, std::function<int()>& action);
void add_run_command(CLI::App& app, std::function<int()>& action);
void add_report_command(CLI::App& app, std::function<int()>& action);
void add_export_commands(CLI::App& app, std::function<int()>& action);

/// Registers every aneuprep subcommand and option on `app`.
void build_aneuprep(CLI::App& app, LoggingOptions& log, const std::vector<std::string>& args,
                    std::function<int()>& action);
/// Parses argv into `app`: -1 when parsing succeeded, else the exit code (after printing the error).
int parse_aneuprep(CLI::App& app, int argc, const char* const* argv);

}  // namespace aneu::tools
