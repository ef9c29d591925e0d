// SPDX-License-Identifier: MIT
#pragma once
// Shared plumbing of the command-line tools: logging options, the Reporter that forwards to spdlog,
// and run_guarded, which owns the mapping from exceptions to exit codes (CONVENTIONS.md §3).
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::tools {

/// Exit codes: 0 success, 1 processing failure, 2 invalid input or configuration.
inline constexpr int EXIT_PROCESSING = 1;
inline constexpr int EXIT_INPUT = 2;

/// The one named logger of the tools ("aneu"), writing to stderr.
spdlog::logger& logger();

/// Options of every tool: --log-level, --quiet, --log-file.
struct LoggingOptions {
    std::string level = "info";
    bool quiet = false;
    std::string file;
};
void add_logging_options(CLI::App& app, LoggingOptions& o);
/// Applies the options to logger() (call after parsing).
void apply_logging_options(const LoggingOptions& o);

/// A Reporter that logs messages and rate-limited progress (every 0.5 s, and at completion).
Reporter make_log_reporter();

/// Runs `body` for command `name`: an aneu::InputError prints "<name>: error: <message>" and returns 2,
/// any other aneu::Error or std::exception returns 1; success returns 0.
int run_guarded(const std::string& name, const std::function<void()>& body);

/// Input and output files of a stage subcommand.
struct StageIo {
    std::string input, output;
};

/// What a stage subcommand would do: its validated parameters (as stored in its provenance), inputs and output.
struct StagePlan {
    std::string stage;
    std::vector<std::pair<std::string, std::string>> parameters;
    std::vector<std::string> inputs;
    std::string output;
};
/// While a sink is set, stage subcommands do not run: their action validates the options and hands the plan
/// to the sink (`aneuprep run` uses it to compare a stage's parameters with its output's provenance).
/// An empty function clears it.
void set_plan_sink(std::function<void(const StagePlan&)> sink);
/// The sink set by set_plan_sink (empty when stages run).
const std::function<void(const StagePlan&)>& plan_sink();

/// Registers a stage subcommand with an optional positional input and a required -o output. `run`
/// receives the files and the provenance record; `params` validates the options and lists them.
CLI::App* stage_command(CLI::App& app, const std::vector<std::string>& args, std::function<int()>& action,
                        const std::string& name, const std::string& help, bool has_input,
                        std::function<void(const StageIo&, StageRecord)> run,
                        std::function<std::vector<std::pair<std::string, std::string>>()> params);

/// argv as a vector of strings.
std::vector<std::string> args_of(int argc, char** argv);

}  // namespace aneu::tools
