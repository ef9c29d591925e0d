// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Running another program as a child process (the flow stage's OpenFOAM tools; the simulator's `aneuprep flow`
/// after a session): its output to a log file or to this process's terminal, a deadline, its log's lines as they come.
#include <chrono>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace aneu {

/// One run of a program.
struct ProgramRun {
    std::vector<std::string> argv;  ///< argv[0] searched on PATH unless it names a path
    std::string dir;                ///< working directory ("" = this process's)
    std::string log;                ///< stdout and stderr into this file ("" = this process's terminal)
    std::optional<std::chrono::steady_clock::time_point> deadline;  ///< killed (its process group) past it
    std::function<void(const std::string&)> on_line;               ///< each complete line of `log` while it runs
};

/// How a run ended.
struct ProgramExit {
    int code = 0;            ///< exit status; 127: not found (or not executable); 128 + signal when killed
    bool timed_out = false;  ///< killed at the deadline
};

/// Runs the program and waits for it (polling every 200 ms when it has a deadline or a line callback).
/// @throws Error the process cannot be started or waited for
ProgramExit run_program(const ProgramRun& run);

}  // namespace aneu
