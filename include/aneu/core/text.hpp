// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Number formatting for messages and provenance.
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <string>

namespace aneu {

/// The shortest text that reads back to the same double ("0.4", not "0.40000000000000002"): provenance
/// stays exact and messages stay readable.
inline std::string shortest(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

/// A byte count for people: "812 B", "3.6 MiB", "1.2 GiB" (powers of 1024, one decimal).
inline std::string human_bytes(std::uint64_t b) {
    const char* unit[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    double v = static_cast<double>(b);
    int u = 0;
    while (v >= 1024.0 && u < 4) {
        v /= 1024.0;
        ++u;
    }
    char buf[32];
    if (u == 0) {
        std::snprintf(buf, sizeof buf, "%llu B", static_cast<unsigned long long>(b));
    } else {
        std::snprintf(buf, sizeof buf, "%.1f %s", v, unit[u]);
    }
    return buf;
}

}  // namespace aneu
