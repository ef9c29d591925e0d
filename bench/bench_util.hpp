// SPDX-License-Identifier: MIT
#pragma once
// Shared by the study's benchmarks.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <Eigen/Core>

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

/// The study's tube (bench/run_study.sh: along z): its extent along z and its outer radius near the ends.
struct TubeExtent {
    double zmin = 1e300, zmax = -1e300, outer_radius = 0;
};
inline TubeExtent tube_extent(const Eigen::MatrixX3d& X, const Eigen::VectorXi& outer) {
    TubeExtent t;
    for (Eigen::Index k = 0; k < X.rows(); ++k) {
        t.zmin = std::min(t.zmin, X(k, 2));
        t.zmax = std::max(t.zmax, X(k, 2));
    }
    for (Eigen::Index k = 0; k < outer.size(); ++k) {
        const Eigen::Vector3d p = X.row(outer[k]);
        if (std::abs(p.z() - t.zmin) < 0.1 * (t.zmax - t.zmin)) t.outer_radius = std::max(t.outer_radius, std::hypot(p.x(), p.y()));
    }
    return t;
}

}  // namespace aneu::bench
