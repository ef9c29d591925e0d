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
inline constexpr int EXIT_UNKNOWN_OPTION = 109;  ///< CLI11::ExtrasError's code

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

/// The top-level handler (CONVENTIONS.md §3): runs `body` for command `name`; an exception prints one line
/// "<name>: error: <message>" and gives the exit code: 2 for aneu::InputError, 109 for an UnknownOptionError
/// (CLI11's code for an unknown option), 1 for every other aneu::Error, filesystem error or std::exception.
/// Success returns 0.
int run_guarded(const std::string& name, const std::function<void()>& body);

/// What the program needs in its environment before the libraries load, set and the program executed again once
/// (Linux: /proc/self/exe, the same argv) where anything changed, before anything else runs; returns where nothing
/// changed or exec failed.
/// - With `huge_pages`: glibc's malloc gives large blocks to the kernel 4 KiB page by page, and on a virtual machine
///   every first touch of a page is a costly fault: the stiffness matrix, the factor (1.1 GB for C0001) and W are
///   written once each. With the tunable glibc.malloc.hugetlb=1 (glibc ≥ 2.35), malloc asks for transparent huge
///   pages (madvise) for them; a tunable is read at start-up only. Only where the kernel's THP mode is "madvise";
///   never when GLIBC_TUNABLES names the tunable already; ANEU_HUGE_PAGES=0 turns it off. Measured on C0001 (2
///   cores): assemble 9.4 -> 3.7 s, condense 26.4 -> 16.6 s, same peak memory (bench/results/huge_pages.md).
/// - Always: OPENBLAS_CORETYPE where OpenBLAS fell back to its SSE3 kernels on a CPU it does not know
///   (aneu::set_blas_kernels_env: dgemm 5x faster on this project's Xeon).
void reexec_for_this_machine(char** argv, bool huge_pages);

/// argv as a vector of strings.
std::vector<std::string> args_of(int argc, char** argv);

}  // namespace aneu::tools
