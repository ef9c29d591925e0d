// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Messages and progress from library code without a logging dependency (CONVENTIONS.md §4).
#include <cstdint>
#include <functional>
#include <string>

namespace aneu {

/// Severity of a Reporter message; mirrors the logger's levels.
enum class Level { DEBUG, INFO, WARN };

/// Callback sink for library code: a message callback and a progress callback, both optional.
/// The progress callback may throw to cancel the operation (the operation then cleans up, e.g. removes
/// its temporary file, and the exception propagates).
struct Reporter {
    std::function<void(Level, const std::string&)> on_message;
    std::function<void(const std::string& stage, std::int64_t done, std::int64_t total)> on_progress;

    void info(const std::string& m) const { emit(Level::INFO, m); }
    void warn(const std::string& m) const { emit(Level::WARN, m); }
    void debug(const std::string& m) const { emit(Level::DEBUG, m); }
    void progress(const std::string& stage, std::int64_t done, std::int64_t total) const {
        if (on_progress) on_progress(stage, done, total);
    }

private:
    void emit(Level l, const std::string& m) const {
        if (on_message) on_message(l, m);
    }
};

/// A Reporter that drops everything (the default argument of library functions).
inline Reporter& null_reporter() {
    static Reporter r;
    return r;
}

}  // namespace aneu
