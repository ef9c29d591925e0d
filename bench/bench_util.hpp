// SPDX-License-Identifier: MIT
#pragma once
// Shared by the study's benchmarks.
#include <cstdio>
#include <cstdlib>
#include <string>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"

namespace aneu::bench {

/// The mesh and stiffness of a stage file (/volume and /fem; W is not read). Exits with status 2 when either is
/// missing or the file cannot be read (a benchmark's usage error).
inline Bundle read_model(const std::string& path) {
    BundleParts parts;
    parts.condensed_W = false;
    parts.image = false;
    Bundle b;
    try {
        b = read_bundle(path, parts);
    } catch (const Error& e) {
        std::fprintf(stderr, "%s\n", e.what());
        std::exit(2);
    }
    if (!b.volume || !b.fem) {
        std::fprintf(stderr, "%s: needs /volume and /fem\n", path.c_str());
        std::exit(2);
    }
    return b;
}

}  // namespace aneu::bench
