// SPDX-License-Identifier: MIT
// Exact Euclidean distance transform (Felzenszwalb & Huttenlocher 2012: lower envelope of parabolas, one
// pass per axis), spacing-aware, OpenMP over the lines of each pass.
#include <cmath>
#include <limits>
#include <vector>

#include "aneu/pipeline/image_filters.hpp"

namespace aneu::pipeline {

namespace {

/// 1-D squared distance transform of f (sample spacing h) into d; v, z are work arrays of size n, n+1.
void dt1d(const double* f, double* d, std::int64_t n, double h, std::vector<std::int64_t>& v, std::vector<double>& z) {
    const double inf = std::numeric_limits<double>::infinity();
    std::int64_t k = -1;
    for (std::int64_t q = 0; q < n; ++q) {
        if (!std::isfinite(f[q])) continue;
        const double xq = static_cast<double>(q) * h;
        while (k >= 0) {
            const double xv = static_cast<double>(v[static_cast<size_t>(k)]) * h;
            const double s = ((f[q] + xq * xq) - (f[v[static_cast<size_t>(k)]] + xv * xv)) / (2 * (xq - xv));
            if (s <= z[static_cast<size_t>(k)]) {
                --k;
            } else {
                ++k;
                v[static_cast<size_t>(k)] = q;
                z[static_cast<size_t>(k)] = s;
                z[static_cast<size_t>(k + 1)] = inf;
                break;
            }
        }
        if (k < 0) {
            k = 0;
            v[0] = q;
            z[0] = -inf;
            z[1] = inf;
        }
    }
    if (k < 0) {
        for (std::int64_t q = 0; q < n; ++q) d[q] = inf;
        return;
    }
    std::int64_t j = 0;
    for (std::int64_t q = 0; q < n; ++q) {
        const double xq = static_cast<double>(q) * h;
        while (z[static_cast<size_t>(j + 1)] < xq) ++j;
        const double xv = static_cast<double>(v[static_cast<size_t>(j)]) * h;
        d[q] = (xq - xv) * (xq - xv) + f[v[static_cast<size_t>(j)]];
    }
}

}  // namespace

Volume<float> inside_distance_mm(const Volume<std::uint8_t>& m) {
    const ImageGrid& g = m.grid;
    const std::int64_t n[3] = {g.size[0], g.size[1], g.size[2]};
    std::vector<double> sq(g.voxel_count());
    for (size_t l = 0; l < sq.size(); ++l) sq[l] = m.data[l] ? std::numeric_limits<double>::infinity() : 0.0;
    const std::int64_t stride[3] = {1, n[0], n[0] * n[1]};
    for (int axis = 0; axis < 3; ++axis) {
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        const std::int64_t lines = n[a1] * n[a2];
#pragma omp parallel
        {
            std::vector<double> f(static_cast<size_t>(n[axis])), d(static_cast<size_t>(n[axis]));
            std::vector<std::int64_t> v(static_cast<size_t>(n[axis]));
            std::vector<double> z(static_cast<size_t>(n[axis] + 1));
#pragma omp for schedule(static)
            for (std::int64_t line = 0; line < lines; ++line) {
                const std::int64_t base = (line % n[a1]) * stride[a1] + (line / n[a1]) * stride[a2];
                for (std::int64_t q = 0; q < n[axis]; ++q) f[static_cast<size_t>(q)] = sq[static_cast<size_t>(base + q * stride[axis])];
                dt1d(f.data(), d.data(), n[axis], g.spacing[static_cast<size_t>(axis)], v, z);
                for (std::int64_t q = 0; q < n[axis]; ++q) sq[static_cast<size_t>(base + q * stride[axis])] = d[static_cast<size_t>(q)];
            }
        }
    }
    Volume<float> out{g, std::vector<float>(sq.size())};
    for (size_t l = 0; l < sq.size(); ++l) {
        // A mask with no background voxel at all has infinite distances: report the largest finite float.
        out.data[l] = m.data[l] ? static_cast<float>(std::isfinite(sq[l]) ? std::sqrt(sq[l]) : std::numeric_limits<float>::max()) : 0.0f;
    }
    return out;
}

}  // namespace aneu::pipeline
