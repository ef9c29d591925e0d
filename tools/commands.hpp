// SPDX-License-Identifier: MIT
#pragma once
// Subcommands of aneuprep. Each add_* registers its options on `app`; when its subcommand is selected,
// its parse callback sets `action`, which main runs after logging is configured.
#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace aneu::tools {

void add_phantom_command(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action);
void add_inspect_command(CLI::App& app, std::function<int()>& action);
void add_snapshot_command(CLI::App& app, std::function<int()>& action);
void add_fem_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action);
void add_geometry_commands(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action);

}  // namespace aneu::tools
