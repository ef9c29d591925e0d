// SPDX-License-Identifier: MIT
// Rounded ends of a closed lumen surface (a segmentation's blind vessel ends, closed by the isosurface where the
// segmented vessel stopped): where to cut each one so that the vessel ends in an open, planar loop.
//
// On a voxelisation of the surface: the tips of the lumen's skeleton are found as in TEASAR (Sato et al. 2000):
// from a first tip A (the voxel geodesically farthest from the deepest voxel), the uncovered voxel farthest from A
// is the next tip; its minimal path to A (step cost length / d², d the distance to the wall, so the path keeps to
// the medial axis) is traced until it meets the part already covered, and the voxels within 1.5 d + a voxel of the
// path are covered. Short side paths (less than two radii to the covered part) are surface bumps, not tips.
// Each tip's path from the tip inwards is then read as a radius profile: a vessel's rounded end grows from 0 to the
// vessel's radius within about a radius, after which the radius stays within ±15 % of its median for 3 radii (the
// vessel is tubular again). The cut is half a radius inside the start of that stretch, perpendicular to the path
// there. A sac, a bleb or a junction never gives such a stretch near its tip, so it is kept whole.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <queue>

#include <Eigen/Dense>

#include "aneu/core/common.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/image_filters.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace aneu::pipeline {

namespace {

struct Grid26 {
    std::array<std::array<int, 3>, 26> d{};
    std::array<double, 26> len{};
    explicit Grid26(const ImageGrid& g) {
        int n = 0;
        for (int k = -1; k <= 1; ++k)
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i) {
                    if (!(i || j || k)) continue;
                    d[static_cast<size_t>(n)] = {i, j, k};
                    len[static_cast<size_t>(n)] = std::sqrt(std::pow(i * g.spacing[0], 2) + std::pow(j * g.spacing[1], 2) + std::pow(k * g.spacing[2], 2));
                    ++n;
                }
    }
};

/// Dijkstra over the mask's 26-connected voxels from `src`; the step cost is its length, divided by d² when
/// `penalised` (d = distance to the wall). Returns the cost per voxel (inf outside) and the predecessor.
void dijkstra(const Volume<std::uint8_t>& mask, const Volume<float>& dist, size_t src, bool penalised, std::vector<double>& cost,
              std::vector<std::int64_t>& prev) {
    const ImageGrid& g = mask.grid;
    const Grid26 nb(g);
    const size_t n = g.voxel_count();
    cost.assign(n, std::numeric_limits<double>::infinity());
    prev.assign(n, -1);
    using Item = std::pair<double, size_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> heap;
    cost[src] = 0;
    heap.push({0.0, src});
    const auto nx = static_cast<size_t>(g.size[0]), ny = static_cast<size_t>(g.size[1]);
    while (!heap.empty()) {
        const auto [c, u] = heap.top();
        heap.pop();
        if (c > cost[u]) continue;
        const auto i0 = static_cast<std::int64_t>(u % nx), j0 = static_cast<std::int64_t>((u / nx) % ny), k0 = static_cast<std::int64_t>(u / (nx * ny));
        for (size_t q = 0; q < 26; ++q) {
            const std::int64_t i = i0 + nb.d[q][0], j = j0 + nb.d[q][1], k = k0 + nb.d[q][2];
            if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) continue;
            const size_t v = g.linear(i, j, k);
            if (!mask.data[v]) continue;
            const double dv = std::max<double>(dist.data[v], 1e-3);
            const double nc = c + (penalised ? nb.len[q] / (dv * dv) : nb.len[q]);
            if (nc < cost[v]) {
                cost[v] = nc;
                prev[v] = static_cast<std::int64_t>(u);
                heap.push({nc, v});
            }
        }
    }
}

Eigen::Vector3d centre(const ImageGrid& g, size_t l) {
    const auto nx = static_cast<size_t>(g.size[0]), ny = static_cast<size_t>(g.size[1]);
    const auto p = g.point(static_cast<double>(l % nx), static_cast<double>((l / nx) % ny), static_cast<double>(l / (nx * ny)));
    return {p[0], p[1], p[2]};
}

/// Covers the voxels within 1.5 d + h of each path voxel (d its distance to the wall), flooding from the path.
void cover(const Volume<std::uint8_t>& mask, const Volume<float>& dist, const std::vector<size_t>& path, double h, std::vector<std::uint8_t>& covered) {
    const ImageGrid& g = mask.grid;
    const Grid26 nb(g);
    const auto nx = static_cast<size_t>(g.size[0]), ny = static_cast<size_t>(g.size[1]);
    std::vector<std::pair<size_t, size_t>> queue;  // (voxel, its path voxel)
    for (size_t p : path)
        if (!covered[p]) {
            covered[p] = 1;
            queue.push_back({p, p});
        }
    for (size_t q = 0; q < queue.size(); ++q) {
        const auto [u, s] = queue[q];
        const Eigen::Vector3d xs = centre(g, s);
        const double reach = 1.5 * dist.data[s] + h;
        const auto i0 = static_cast<std::int64_t>(u % nx), j0 = static_cast<std::int64_t>((u / nx) % ny), k0 = static_cast<std::int64_t>(u / (nx * ny));
        for (size_t m = 0; m < 26; ++m) {
            const std::int64_t i = i0 + nb.d[m][0], j = j0 + nb.d[m][1], k = k0 + nb.d[m][2];
            if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) continue;
            const size_t v = g.linear(i, j, k);
            if (!mask.data[v] || covered[v] || (centre(g, v) - xs).norm() > reach) continue;
            covered[v] = 1;
            queue.push_back({v, s});
        }
    }
}

/// Reads the radius profile of a path from a tip inwards; fills `plane` and returns true when the vessel becomes
/// tubular near the tip (see the file comment).
bool tubular_cut(const std::vector<Eigen::Vector3d>& x0, const std::vector<double>& r0, EndPlane& plane) {
    const size_t n = x0.size();
    if (n < 5) return false;
    // Moving averages over 5 points, twice: voxel steps and the distance map's half-voxel noise.
    std::vector<Eigen::Vector3d> x = x0;
    std::vector<double> r = r0;
    for (int it = 0; it < 2; ++it) {
        std::vector<Eigen::Vector3d> xs = x;
        std::vector<double> rs = r;
        for (size_t i = 0; i < n; ++i) {
            const size_t a = i >= 2 ? i - 2 : 0, b = std::min(n - 1, i + 2);
            Eigen::Vector3d sx = Eigen::Vector3d::Zero();
            double sr = 0;
            for (size_t m = a; m <= b; ++m) {
                sx += x[m];
                sr += r[m];
            }
            if (i > 0) xs[i] = sx / static_cast<double>(b - a + 1);  // the tip stays where it is
            rs[i] = sr / static_cast<double>(b - a + 1);
        }
        x.swap(xs);
        r.swap(rs);
    }
    std::vector<double> s(n, 0.0);
    for (size_t i = 1; i < n; ++i) s[i] = s[i - 1] + (x[i] - x[i - 1]).norm();
    double rmax = 0;
    for (size_t i = 0; i < n; ++i) {
        rmax = std::max(rmax, r[i]);
        if (s[i] > 4.0 * rmax) return false;  // longer than any rounded end: the tip is not a vessel's
        // The stretch of 3 local radii from here.
        size_t e = i;
        while (e < n && s[e] - s[i] < 3.0 * std::max(r[i], 1e-9)) ++e;
        if (e >= n) return false;
        const double med = percentile(std::vector<double>(r.begin() + static_cast<std::ptrdiff_t>(i), r.begin() + static_cast<std::ptrdiff_t>(e) + 1), 0.5);
        const auto [lo, hi] = std::minmax_element(r.begin() + static_cast<std::ptrdiff_t>(i), r.begin() + static_cast<std::ptrdiff_t>(e) + 1);
        if (*lo < 0.85 * med || *hi > 1.15 * med) continue;
        if (s[i] > 3.0 * med) return false;
        size_t c = i;
        while (c < e && s[c] - s[i] < 0.5 * med) ++c;
        size_t f = c;
        while (f < e && s[f] - s[c] < 2.0 * med) ++f;
        if (f == c) return false;
        plane.point = x[c];
        plane.normal = (x[c] - x[f]).normalized();  // out of the vessel, towards the tip
        plane.radius_mm = med;
        return true;
    }
    return false;
}

}  // namespace

RoundedEnds find_rounded_ends(const SurfaceData& closed, double spacing_mm) {
    RoundedEnds out;
    const double h = spacing_mm;
    const Volume<std::uint8_t> mask = voxelize(closed, h, 2 * h);
    const Volume<float> dist = inside_distance_mm(mask);
    const ImageGrid& g = mask.grid;
    const size_t n = g.voxel_count();
    size_t deepest = 0;
    bool any = false;
    for (size_t l = 0; l < n; ++l)
        if (mask.data[l] && (!any || dist.data[l] > dist.data[deepest])) {
            deepest = l;
            any = true;
        }
    if (!any) return out;
    std::vector<double> cost, a_geo, a_pen;
    std::vector<std::int64_t> prev, a_prev;
    dijkstra(mask, dist, deepest, false, cost, prev);
    size_t a = deepest;
    for (size_t l = 0; l < n; ++l)
        if (std::isfinite(cost[l]) && cost[l] > cost[a]) a = l;
    dijkstra(mask, dist, a, false, a_geo, prev);
    dijkstra(mask, dist, a, true, a_pen, a_prev);
    std::vector<size_t> order;
    for (size_t l = 0; l < n; ++l)
        if (std::isfinite(a_geo[l])) order.push_back(l);
    std::stable_sort(order.begin(), order.end(), [&](size_t u, size_t v) { return a_geo[u] > a_geo[v]; });
    std::vector<std::uint8_t> covered(n, 0);
    std::vector<std::vector<size_t>> tip_paths;  // tip → A
    for (size_t t : order) {
        if (covered[t]) continue;
        std::vector<size_t> path;
        for (std::int64_t v = static_cast<std::int64_t>(t); v >= 0; v = a_prev[static_cast<size_t>(v)]) path.push_back(static_cast<size_t>(v));
        size_t m = 0;
        while (m < path.size() && !covered[path[m]]) ++m;
        double len = 0;
        for (size_t i = 1; i < m; ++i) len += (centre(g, path[i]) - centre(g, path[i - 1])).norm();
        const bool first = tip_paths.empty();
        const bool bump = !first && m < path.size() && len < 2.0 * dist.data[path[m]];
        cover(mask, dist, std::vector<size_t>(path.begin(), path.begin() + static_cast<std::ptrdiff_t>(m)), h, covered);
        if (bump) continue;
        if (first) tip_paths.emplace_back(path.rbegin(), path.rend());  // A itself, inwards along the first path
        tip_paths.push_back(std::move(path));
    }
    for (const auto& path : tip_paths) {
        std::vector<Eigen::Vector3d> x;
        std::vector<double> r;
        for (size_t v : path) {
            x.push_back(centre(g, v));
            r.push_back(std::max(0.5 * h, static_cast<double>(dist.data[v]) - 0.5 * h));
        }
        EndPlane pl;
        if (tubular_cut(x, r, pl)) {
            bool twice = false;  // two tips of one blunt end give the same plane
            for (const auto& q : out.planes) twice = twice || (q.point - pl.point).norm() < std::max(q.radius_mm, pl.radius_mm);
            if (twice) continue;
            pl.id = static_cast<int>(out.planes.size());
            out.planes.push_back(pl);
            out.tips.push_back(x.front());
        } else {
            out.kept_tips.push_back(x.front());
        }
    }
    return out;
}

}  // namespace aneu::pipeline
