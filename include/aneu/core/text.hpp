// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Number formatting for messages and provenance.
#include <charconv>
#include <string>

namespace aneu {

/// The shortest text that reads back to the same double ("0.4", not "0.40000000000000002"): provenance
/// stays exact and messages stay readable.
inline std::string shortest(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

}  // namespace aneu
