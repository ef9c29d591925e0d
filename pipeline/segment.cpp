// SPDX-License-Identifier: MIT
// `segment`: ROI crop, edge-preserving smoothing, half-maximum threshold, seeded region growing, hole
// filling (ITK filters, image_filters_itk.cpp), then the centerline by minimal paths through the lumen's
// distance map and one end plane per place where the lumen leaves the ROI.
//
// Why minimal paths rather than voxel thinning: thinning of a noisy mask gives spurs that need pruning
// heuristics, and the sac becomes part of the skeleton; a path of least cost 1/d² between the vessel
// ends follows the medial axis of the tubes, never enters the sac (it has no end), and is the centerline
// the aneurysm labelling needs (the method of VMTK, here on the voxel graph).
#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>
#include <queue>

#include <Eigen/Dense>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/image_filters.hpp"
#include "aneu/pipeline/image_io.hpp"

namespace aneu::pipeline {

namespace {

std::string vec3(const std::array<double, 3>& x) { return "(" + shortest(x[0]) + ", " + shortest(x[1]) + ", " + shortest(x[2]) + ")"; }

Eigen::Vector3d phys(const ImageGrid& g, double i, double j, double k) {
    const auto p = g.point(i, j, k);
    return {p[0], p[1], p[2]};
}

struct Ijk {
    std::int64_t i, j, k;
};
Ijk ijk_of(const ImageGrid& g, std::size_t lin) {
    const auto nx = static_cast<std::size_t>(g.size[0]), ny = static_cast<std::size_t>(g.size[1]);
    return {static_cast<std::int64_t>(lin % nx), static_cast<std::int64_t>((lin / nx) % ny), static_cast<std::int64_t>(lin / (nx * ny))};
}


/// Physical bounding box of the grid's voxel centres, for messages.
std::string grid_extent(const ImageGrid& g) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (int c = 0; c < 8; ++c) {
        const Eigen::Vector3d p = phys(g, (c & 1) ? g.size[0] - 1 : 0, (c & 2) ? g.size[1] - 1 : 0, (c & 4) ? g.size[2] - 1 : 0);
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    return "x " + shortest(lo.x()) + ".." + shortest(hi.x()) + ", y " + shortest(lo.y()) + ".." + shortest(hi.y()) + ", z " +
           shortest(lo.z()) + ".." + shortest(hi.z()) + " mm";
}

/// Crops `v` to the index box covering the physical ROI box; `roi` flags the voxels whose centre lies in it.
Volume<float> crop(const Volume<float>& v, const std::array<double, 6>& box, std::vector<std::uint8_t>& roi) {
    const ImageGrid& g = v.grid;
    std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (int c = 0; c < 8; ++c) {
        const auto ci = g.continuous_index({box[(c & 1) ? 3 : 0], box[(c & 2) ? 4 : 1], box[(c & 4) ? 5 : 2]});
        for (int d = 0; d < 3; ++d) {
            lo[static_cast<size_t>(d)] = std::min(lo[static_cast<size_t>(d)], ci[static_cast<size_t>(d)]);
            hi[static_cast<size_t>(d)] = std::max(hi[static_cast<size_t>(d)], ci[static_cast<size_t>(d)]);
        }
    }
    std::array<std::int64_t, 3> a{}, b{};
    for (size_t d = 0; d < 3; ++d) {
        a[d] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(lo[d] - 1e-9)));
        b[d] = std::min<std::int64_t>(g.size[d] - 1, static_cast<std::int64_t>(std::floor(hi[d] + 1e-9)));
        if (b[d] - a[d] < 2) {
            throw InputError("segment: ROI box x " + shortest(box[0]) + ".." + shortest(box[3]) + ", y " + shortest(box[1]) + ".." +
                             shortest(box[4]) + ", z " + shortest(box[2]) + ".." + shortest(box[5]) +
                             " mm lies outside the image (or covers fewer than 3 voxels along an axis); the image covers " +
                             grid_extent(g));
        }
    }
    Volume<float> out;
    out.grid = g;
    for (size_t d = 0; d < 3; ++d) out.grid.size[d] = b[d] - a[d] + 1;
    const auto o = g.point(static_cast<double>(a[0]), static_cast<double>(a[1]), static_cast<double>(a[2]));
    out.grid.origin = o;
    out.data.resize(out.grid.voxel_count());
    roi.assign(out.data.size(), 0);
    for (std::int64_t k = 0; k < out.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < out.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < out.grid.size[0]; ++i) {
                const size_t l = out.grid.linear(i, j, k);
                out.data[l] = v.data[g.linear(i + a[0], j + a[1], k + a[2])];
                const auto p = out.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                roi[l] = p[0] >= box[0] && p[0] <= box[3] && p[1] >= box[1] && p[1] <= box[4] && p[2] >= box[2] && p[2] <= box[5];
            }
    return out;
}

constexpr int N26 = 26;
struct Offsets {
    std::array<std::array<int, 3>, N26> d{};
    Offsets() {
        int n = 0;
        for (int k = -1; k <= 1; ++k)
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i)
                    if (i || j || k) d[static_cast<size_t>(n++)] = {i, j, k};
    }
};
const Offsets& offsets26() {
    static const Offsets o;
    return o;
}

}  // namespace



std::vector<std::vector<std::size_t>> border_crossings(const Volume<std::uint8_t>& mask, const std::vector<std::uint8_t>& roi,
                                                       double min_area_mm2) {
    const ImageGrid& g = mask.grid;
    const size_t n = g.voxel_count();
    auto inside = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
        return i >= 0 && j >= 0 && k >= 0 && i < g.size[0] && j < g.size[1] && k < g.size[2] && (roi.empty() || roi[g.linear(i, j, k)]);
    };
    std::vector<std::uint8_t> border(n, 0);
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const size_t l = g.linear(i, j, k);
                if (!mask.data[l] || !inside(i, j, k)) continue;
                border[l] = !inside(i - 1, j, k) || !inside(i + 1, j, k) || !inside(i, j - 1, k) || !inside(i, j + 1, k) ||
                            !inside(i, j, k - 1) || !inside(i, j, k + 1);
            }
    // Each border voxel stands for about one voxel face of the crossing.
    const double face = std::pow(g.voxel_volume(), 2.0 / 3.0);
    std::vector<std::vector<size_t>> patches;
    std::vector<std::uint8_t> seen(n, 0);
    for (size_t s = 0; s < n; ++s) {
        if (!border[s] || seen[s]) continue;
        std::vector<size_t> patch{s};
        seen[s] = 1;
        for (size_t q = 0; q < patch.size(); ++q) {
            const Ijk c = ijk_of(g, patch[q]);
            for (const auto& d : offsets26().d) {
                const std::int64_t i = c.i + d[0], j = c.j + d[1], k = c.k + d[2];
                if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) continue;
                const size_t l = g.linear(i, j, k);
                if (border[l] && !seen[l]) {
                    seen[l] = 1;
                    patch.push_back(l);
                }
            }
        }
        if (static_cast<double>(patch.size()) * face >= min_area_mm2) patches.push_back(std::move(patch));
    }
    std::stable_sort(patches.begin(), patches.end(), [](const auto& a, const auto& b) { return a.size() > b.size(); });
    return patches;
}

namespace {
/// Is the lumen's cross-section through `c` normal to `t` a tube: its piece connected to `c` (sampled at a
/// quarter of the finest spacing in the plane) stays within 2 radii + a voxel of `c`. A sheet or a lump
/// spreads farther (the flood reaches 3 radii + 2 voxels, where sampling stops).
bool tubular_section(const Volume<std::uint8_t>& mask, const Eigen::Vector3d& c, const Eigen::Vector3d& t, double r) {
    const ImageGrid& g = mask.grid;
    const double smin = std::min({g.spacing[0], g.spacing[1], g.spacing[2]}), smax = std::max({g.spacing[0], g.spacing[1], g.spacing[2]});
    const double h = 0.25 * smin, R = 3.0 * r + 2.0 * smax, allowed = 2.0 * r + smax;
    const int m = static_cast<int>(std::ceil(R / h)), w = 2 * m + 1;
    const Eigen::Vector3d u = t.normalized().unitOrthogonal(), v = t.normalized().cross(u);
    auto lumen = [&](int a, int b) {
        const Eigen::Vector3d x = c + (a - m) * h * u + (b - m) * h * v;
        const auto ci = g.continuous_index({x.x(), x.y(), x.z()});
        const std::int64_t i = std::llround(ci[0]), j = std::llround(ci[1]), k = std::llround(ci[2]);
        return i >= 0 && j >= 0 && k >= 0 && i < g.size[0] && j < g.size[1] && k < g.size[2] && mask.data[g.linear(i, j, k)] != 0;
    };
    std::vector<char> seen(static_cast<size_t>(w * w), 0);
    std::vector<std::pair<int, int>> stack;
    // Start at the lumen sample nearest c (the smoothed centerline may sit a little off the voxels).
    for (int rr = 0; rr <= static_cast<int>(std::ceil(r / h)) && stack.empty(); ++rr)
        for (int a = m - rr; a <= m + rr && stack.empty(); ++a)
            for (int b = m - rr; b <= m + rr && stack.empty(); ++b)
                if (std::max(std::abs(a - m), std::abs(b - m)) == rr && lumen(a, b)) stack.emplace_back(a, b);
    if (stack.empty()) return false;
    seen[static_cast<size_t>(stack[0].first * w + stack[0].second)] = 1;
    while (!stack.empty()) {
        const auto [a, b] = stack.back();
        stack.pop_back();
        if (std::hypot(a - m, b - m) * h > allowed) return false;
        for (const auto& [da, db] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
            const int a2 = a + da, b2 = b + db;
            if (a2 < 0 || b2 < 0 || a2 >= w || b2 >= w || seen[static_cast<size_t>(a2 * w + b2)]) continue;
            seen[static_cast<size_t>(a2 * w + b2)] = 1;
            if (lumen(a2, b2)) stack.emplace_back(a2, b2);
        }
    }
    return true;
}
}  // namespace

CenterlineResult centerline_from_ends(const Volume<std::uint8_t>& mask, const Volume<float>& dist, const std::vector<std::uint8_t>& roi,
                                      const std::vector<std::vector<std::size_t>>& ends, double inset_mm) {
    const ImageGrid& g = mask.grid;
    const size_t n = g.voxel_count();
    if (ends.size() < 2) throw InputError("centerline: the lumen has " + std::to_string(ends.size()) + " end(s); a vessel needs at least 2");
    auto centre_of = [&](const std::vector<size_t>& patch) {
        return *std::max_element(patch.begin(), patch.end(), [&](size_t a, size_t b) { return dist.data[a] < dist.data[b]; });
    };
    // Dijkstra from the first end over the 26-connected lumen voxels; step cost = length / d², so the path
    // keeps to the points farthest from the wall.
    const size_t src = centre_of(ends[0]);
    std::vector<double> cost(n, std::numeric_limits<double>::infinity());
    std::vector<std::int64_t> prev(n, -1);
    using Item = std::pair<double, size_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> heap;
    cost[src] = 0;
    heap.push({0.0, src});
    std::array<double, N26> steplen{};
    for (size_t q = 0; q < N26; ++q) {
        const auto& d = offsets26().d[q];
        steplen[q] = std::sqrt(std::pow(d[0] * g.spacing[0], 2) + std::pow(d[1] * g.spacing[1], 2) + std::pow(d[2] * g.spacing[2], 2));
    }
    while (!heap.empty()) {
        const auto [c, u] = heap.top();
        heap.pop();
        if (c > cost[u]) continue;
        const Ijk p = ijk_of(g, u);
        for (size_t q = 0; q < N26; ++q) {
            const auto& d = offsets26().d[q];
            const std::int64_t i = p.i + d[0], j = p.j + d[1], k = p.k + d[2];
            if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) continue;
            const size_t v = g.linear(i, j, k);
            if (!mask.data[v]) continue;
            const double dv = std::max<double>(dist.data[v], 1e-3);
            const double nc = c + steplen[q] / (dv * dv);
            if (nc < cost[v]) {
                cost[v] = nc;
                prev[v] = static_cast<std::int64_t>(u);
                heap.push({nc, v});
            }
        }
    }
    // Paths to every other end, merged into a tree: each new path is cut where it meets the tree.
    const double s_mean = std::cbrt(g.voxel_volume());
    std::vector<std::uint8_t> in_tree(n, 0);
    std::vector<std::vector<size_t>> branches;
    std::vector<std::vector<size_t>> full_paths(ends.size());  // voxel path from each end towards the root
    for (size_t e = 1; e < ends.size(); ++e) {
        const size_t t = centre_of(ends[e]);
        if (!std::isfinite(cost[t])) {
            throw InputError("centerline: end " + std::to_string(e) + " is not connected to end 0 through the lumen");
        }
        std::vector<size_t> path;
        for (std::int64_t v = static_cast<std::int64_t>(t); v >= 0; v = prev[static_cast<size_t>(v)]) path.push_back(static_cast<size_t>(v));
        full_paths[e] = path;
        if (e == 1) full_paths[0].assign(path.rbegin(), path.rend());
        std::vector<size_t> branch;
        for (size_t v : path) {
            branch.push_back(v);
            if (in_tree[v]) break;
        }
        for (size_t v : branch) in_tree[v] = 1;
        std::reverse(branch.begin(), branch.end());  // from the junction (or root) to the end
        branches.push_back(std::move(branch));
    }
    // Smoothed physical polylines with radius = distance map − half a voxel (the wall lies between voxels).
    auto smooth = [&](const std::vector<size_t>& vox, std::vector<Eigen::Vector3d>& pts, std::vector<double>& rad) {
        pts.clear();
        rad.clear();
        for (size_t v : vox) {
            const Ijk c = ijk_of(g, v);
            pts.push_back(phys(g, static_cast<double>(c.i), static_cast<double>(c.j), static_cast<double>(c.k)));
            rad.push_back(std::max(0.5 * s_mean, static_cast<double>(dist.data[v]) - 0.5 * s_mean));
        }
        for (int it = 0; it < 4; ++it) {
            std::vector<Eigen::Vector3d> q = pts;
            std::vector<double> r = rad;
            for (size_t i = 1; i + 1 < pts.size(); ++i) {
                const size_t a = i >= 2 ? i - 2 : 0, b = std::min(pts.size() - 1, i + 2);
                Eigen::Vector3d s = Eigen::Vector3d::Zero();
                double sr = 0;
                for (size_t m = a; m <= b; ++m) {
                    s += pts[m];
                    sr += rad[m];
                }
                q[i] = s / static_cast<double>(b - a + 1);
                r[i] = sr / static_cast<double>(b - a + 1);
            }
            pts.swap(q);
            rad.swap(r);
        }
    };
    CenterlineResult res;
    std::vector<Eigen::Vector3d> all;
    std::vector<double> allr;
    std::vector<int> off{0};
    for (const auto& b : branches) {
        std::vector<Eigen::Vector3d> pts;
        std::vector<double> rad;
        smooth(b, pts, rad);
        all.insert(all.end(), pts.begin(), pts.end());
        allr.insert(allr.end(), rad.begin(), rad.end());
        off.push_back(static_cast<int>(all.size()));
    }
    res.centerline.points.resize(static_cast<Eigen::Index>(all.size()), 3);
    res.centerline.radius.resize(static_cast<Eigen::Index>(all.size()));
    for (size_t i = 0; i < all.size(); ++i) {
        res.centerline.points.row(static_cast<Eigen::Index>(i)) = all[i].transpose();
        res.centerline.radius[static_cast<Eigen::Index>(i)] = allr[i];
    }
    res.centerline.offsets = Eigen::Map<const Eigen::VectorXi>(off.data(), static_cast<Eigen::Index>(off.size()));

    // One plane per end, on the smoothed path from that end inwards.
    auto in_roi = [&](const Eigen::Vector3d& x) {
        const auto ci = g.continuous_index({x.x(), x.y(), x.z()});
        const std::int64_t i = std::llround(ci[0]), j = std::llround(ci[1]), k = std::llround(ci[2]);
        if (ci[0] < 0.5 || ci[1] < 0.5 || ci[2] < 0.5 || ci[0] > static_cast<double>(g.size[0]) - 1.5 ||
            ci[1] > static_cast<double>(g.size[1]) - 1.5 || ci[2] > static_cast<double>(g.size[2]) - 1.5) {
            return false;
        }
        return roi.empty() || roi[g.linear(i, j, k)] != 0;
    };
    const double smax = std::max({g.spacing[0], g.spacing[1], g.spacing[2]});
    for (size_t e = 0; e < ends.size(); ++e) {
        std::vector<Eigen::Vector3d> pts;
        std::vector<double> rad;
        smooth(full_paths[e], pts, rad);  // from the end inwards
        std::vector<double> s(pts.size(), 0.0);
        for (size_t i = 1; i < pts.size(); ++i) s[i] = s[i - 1] + (pts[i] - pts[i - 1]).norm();
        auto tangent_at = [&](size_t i, double half) {  // PCA direction of the points within ±half of s[i], pointing to the end
            Eigen::Vector3d mean = Eigen::Vector3d::Zero();
            int cnt = 0;
            for (size_t m = 0; m < pts.size(); ++m)
                if (std::abs(s[m] - s[i]) <= half) {
                    mean += pts[m];
                    ++cnt;
                }
            mean /= cnt;
            Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
            for (size_t m = 0; m < pts.size(); ++m)
                if (std::abs(s[m] - s[i]) <= half) C += (pts[m] - mean) * (pts[m] - mean).transpose();
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
            Eigen::Vector3d t = es.eigenvectors().col(2);
            const size_t a = i > 0 ? i - 1 : 0;
            if (t.dot(pts[a] - pts[std::min(i + 1, pts.size() - 1)]) < 0) t = -t;
            return t;
        };
        size_t at = 0;
        if (inset_mm > 0) {
            while (at + 1 < pts.size() && s[at] < inset_mm) ++at;
        } else {
            // The first point whose cross-section disc (1.2 radii) lies wholly inside the ROI, plus two voxels.
            for (; at + 1 < pts.size(); ++at) {
                const double r = 1.2 * rad[at];
                const Eigen::Vector3d t = tangent_at(at, std::max(rad[at], 2 * smax));
                const Eigen::Vector3d u = t.unitOrthogonal(), w = t.cross(u);
                bool ok = true;
                for (int q = 0; q < 16 && ok; ++q) {
                    const double th = 2 * PI * q / 16;
                    ok = in_roi(pts[at] + r * (std::cos(th) * u + std::sin(th) * w));
                }
                if (ok) break;
            }
            const double target = s[at] + 2 * smax;
            while (at + 1 < pts.size() && s[at] < target) ++at;
            // Where a vessel leaves the image through the skull base, its lumen there can be a sheet or a lump
            // (the carotid against bone and the venous sinus), not a tube: the plane moves on inwards to the
            // first cross-section that is tubular, up to MAX_WALK_MM (then it stays, and the count says so).
            constexpr double MAX_WALK_MM = 12.0;
            if (!tubular_section(mask, pts[at], tangent_at(at, std::max(rad[at], 2 * smax)), std::max(rad[at], 0.5 * smax))) {
                const double limit = std::min(s[at] + MAX_WALK_MM, 0.5 * s.back());
                size_t k = at + 1;
                for (; k + 1 < pts.size() && s[k] <= limit; ++k)
                    if (tubular_section(mask, pts[k], tangent_at(k, std::max(rad[k], 2 * smax)), std::max(rad[k], 0.5 * smax))) break;
                if (k + 1 < pts.size() && s[k] <= limit) {
                    at = k;
                    ++res.ends_moved_to_tubular;
                } else {
                    ++res.ends_not_tubular;
                }
            }
        }
        EndPlane pl;
        pl.id = static_cast<int>(e);
        pl.point = pts[at];
        pl.normal = tangent_at(at, std::max(rad[at], 2 * smax));
        pl.radius_mm = rad[at];
        res.planes.push_back(pl);
    }
    return res;
}

namespace {
/// @throws InputError when a voxel is NaN or infinite, naming how many and the first one's index
void check_finite(const Volume<float>& v, const std::string& what) {
    size_t bad = 0, first = 0;
    for (size_t l = 0; l < v.data.size(); ++l)
        if (!std::isfinite(v.data[l]) && bad++ == 0) first = l;
    if (bad == 0) return;
    const auto nx = static_cast<size_t>(v.grid.size[0]), ny = static_cast<size_t>(v.grid.size[1]);
    throw InputError(what + ": " + std::to_string(bad) + " voxel(s) are NaN or infinite, the first at index (" + std::to_string(first % nx) + ", " +
                     std::to_string((first / nx) % ny) + ", " + std::to_string(first / (nx * ny)) + "); expected finite intensities (HU)");
}
}  // namespace

/// segment_volume on an image already checked for finite voxels.
Segmentation segment_finite(const Volume<float>& ct_in, const SegmentParams& p, Reporter& rep);

Segmentation segment_volume(const Volume<float>& ct_in, const SegmentParams& p, Reporter& rep) {
    check_finite(ct_in, "segment: the image");
    return segment_finite(ct_in, p, rep);
}

Segmentation segment_finite(const Volume<float>& ct_in, const SegmentParams& p, Reporter& rep) {
    validate(p);
    Segmentation out;
    std::vector<std::uint8_t> roi;
    Volume<float> ct = p.roi_mm ? crop(ct_in, *p.roi_mm, roi) : ct_in;
    if (roi.empty()) roi.assign(ct.data.size(), 1);
    const ImageGrid& g = ct.grid;
    const size_t n = g.voxel_count();
    const auto n_roi = static_cast<double>(std::count(roi.begin(), roi.end(), 1));
    out.qa.emplace_back("roi_voxels", n_roi);

    Volume<float> sm = anisotropic_diffusion(ct, p.smoothing_iterations, p.conductance_hu_per_mm);
    std::vector<float> roi_vals;
    roi_vals.reserve(n);
    for (size_t l = 0; l < n; ++l)
        if (roi[l]) roi_vals.push_back(sm.data[l]);
    const double background = percentile(roi_vals, 0.5);
    const double roi_max = *std::max_element(roi_vals.begin(), roi_vals.end());
    const float below = static_cast<float>(std::min(background, static_cast<double>(*std::min_element(roi_vals.begin(), roi_vals.end()))) - 1.0);
    for (size_t l = 0; l < n; ++l)
        if (!roi[l]) sm.data[l] = below;  // voxels of the index box outside the physical ROI box are never lumen
    out.qa.emplace_back("background_hu", background);

    // Seeds in mm → voxels; each must lie in the ROI.
    std::vector<Index3> seeds;
    for (const auto& s : p.seeds_mm) {
        const auto ci = g.continuous_index(s);
        const std::int64_t i = std::llround(ci[0]), j = std::llround(ci[1]), k = std::llround(ci[2]);
        if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2] || !roi[g.linear(i, j, k)]) {
            throw InputError("segment: --seed " + vec3(s) + " mm is outside the " + std::string(p.roi_mm ? "ROI" : "image") + " (" +
                             grid_extent(g) + ")");
        }
        seeds.push_back({i, j, k});
    }

    // Automatic intensities from the vessels themselves: Frangi's vesselness picks the voxels along bright
    // tubes; their median intensity is the vessel plateau. Bone is brighter than contrast in every head CTA
    // and air darker than tissue, so a histogram split of the whole ROI (Otsu) lands between air and tissue
    // or between vessels and bone (measured on real CTAs: 479 HU against a 420 HU lumen; −425 HU, air against
    // the rest, on the TopCoW crop in sample_data/real). Voxels much
    // brighter than the vessels (bone) are kept out of the lumen by an automatic upper bound.
    std::optional<double> upper = p.upper_hu;
    Volume<float> tube;
    double t0 = 0;
    if (!p.threshold_hu) {
        const double smax = std::max({g.spacing[0], g.spacing[1], g.spacing[2]});
        tube = vesselness(sm, std::max(0.5, smax), std::max(2.0, 2 * smax), 4);
        std::vector<float> tv;
        for (size_t l = 0; l < n; ++l)
            if (roi[l] && sm.data[l] > background) tv.push_back(tube.data[l]);
        const double vmax = tv.empty() ? 0.0 : percentile(tv, 0.999);
        std::vector<float> vessel_vals;
        for (size_t l = 0; l < n; ++l)
            if (roi[l] && sm.data[l] > background && vmax > 0 && tube.data[l] >= 0.5 * vmax) vessel_vals.push_back(sm.data[l]);
        if (vessel_vals.size() >= 10) {
            const double plateau_v = percentile(vessel_vals, 0.5);
            t0 = 0.5 * (background + plateau_v);
            out.qa.emplace_back("vessel_plateau_hu", plateau_v);
            out.qa.emplace_back("vessel_voxels", static_cast<double>(vessel_vals.size()));
            const double bone_above = plateau_v + 1.5 * (plateau_v - background);
            if (!upper && roi_max > bone_above) {
                upper = bone_above;
                out.qa.emplace_back("auto_upper_hu", bone_above);
                rep.info("segment: voxels up to " + shortest(roi_max) + " HU, brighter than the vessels' " + shortest(plateau_v) +
                         " HU (bone): the lumen is limited to " + shortest(bone_above) + " HU");
            }
        } else {
            t0 = otsu_threshold(sm, roi);  // no tubular structure found: the histogram split
            out.qa.emplace_back("otsu_hu", t0);
        }
    }
    // Bone: above the upper bound, grown by one voxel (its partial-volume rim has vessel-like intensities
    // and would join a vessel that touches it).
    std::vector<std::uint8_t> near_bone(n, 0);
    if (upper && !p.upper_hu) {
        const std::int64_t nx = g.size[0], ny = g.size[1], nz = g.size[2];
        for (std::int64_t k = 0; k < nz; ++k)
            for (std::int64_t j = 0; j < ny; ++j)
                for (std::int64_t i = 0; i < nx; ++i) {
                    if (!(sm.data[g.linear(i, j, k)] > *upper)) continue;
                    for (std::int64_t c = std::max<std::int64_t>(0, k - 1); c <= std::min(nz - 1, k + 1); ++c)
                        for (std::int64_t b = std::max<std::int64_t>(0, j - 1); b <= std::min(ny - 1, j + 1); ++b)
                            for (std::int64_t a = std::max<std::int64_t>(0, i - 1); a <= std::min(nx - 1, i + 1); ++a) near_bone[g.linear(a, b, c)] = 1;
                }
        out.qa.emplace_back("bone_voxels_excluded", static_cast<double>(std::count(near_bone.begin(), near_bone.end(), 1)));
        // Thin skull-base bone is blurred by its thinness into the vessels' intensities (300–600 HU on the TopCoW
        // CTA, the lumen 150–400) and touches the carotid; a voxel's intensity cannot tell them apart, its place
        // can: no lumen within bone_clearance_mm of bone (above the upper bound) nor within air_clearance_mm of air
        // (< −300 HU in the unsmoothed CT: the sinuses, whose walls are such bone). Measured on the TopCoW CTA
        // (bench/results/real/corpus.md): one voxel of clearance kept a sinus wall and a bone plate in the lumen;
        // 2 and 1.5 mm leave the Circle of Willis. The vessels lose their lumen where they run in bone (the petrous
        // and cavernous carotid), far from any clip.
        const auto clear_of = [&](const std::function<bool(size_t)>& in, double mm) {
            Volume<std::uint8_t> outside{g, std::vector<std::uint8_t>(n, 1)};
            size_t count = 0;
            for (size_t l = 0; l < n; ++l)
                if (in(l)) {
                    outside.data[l] = 0;
                    ++count;
                }
            size_t ex = 0;
            if (count == 0 || !(mm > 0)) return ex;
            const Volume<float> d = inside_distance_mm(outside);
            for (size_t l = 0; l < n; ++l)
                if (outside.data[l] && d.data[l] <= mm && !near_bone[l]) {
                    near_bone[l] = 1;
                    ++ex;
                }
            return ex;
        };
        out.qa.emplace_back("bone_clearance_voxels", static_cast<double>(clear_of([&](size_t l) { return sm.data[l] > *upper; }, p.bone_clearance_mm)));
        out.qa.emplace_back("air_clearance_voxels", static_cast<double>(clear_of([&](size_t l) { return ct.data[l] < -300.0f; }, p.air_clearance_mm)));
    }
    // The lumen component at a threshold: seed-connected or the automatic choice.
    auto components_at = [&](double t) {
        Volume<std::uint8_t> m{g, std::vector<std::uint8_t>(n, 0)};
        for (size_t l = 0; l < n; ++l) m.data[l] = sm.data[l] >= t && (!upper || sm.data[l] <= *upper) && !near_bone[l];
        return connected_components(m);
    };
    // Automatic vessel choice: among components leaving the ROI at two or more ends (a vessel passes
    // through; bone and calcifications mostly do not), the most tubular (largest sum of vesselness; the
    // largest when there is none); if none leaves at two ends, the most tubular of all.
    auto auto_component = [&](const Components& cc) {
        std::vector<double> mass(cc.sizes.size(), 0.0);
        for (size_t c = 0; c < cc.sizes.size(); ++c) mass[c] = static_cast<double>(cc.sizes[c]);
        if (!tube.data.empty()) {
            std::fill(mass.begin(), mass.end(), 0.0);
            for (size_t l = 0; l < n; ++l)
                if (cc.labels.data[l] > 0) mass[static_cast<size_t>(cc.labels.data[l] - 1)] += tube.data[l];
        }
        std::vector<size_t> order(mass.size());
        for (size_t c = 0; c < order.size(); ++c) order[c] = c;
        std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return mass[a] > mass[b]; });
        for (size_t q = 0; q < order.size() && q < 8; ++q) {
            Volume<std::uint8_t> m{g, std::vector<std::uint8_t>(n, 0)};
            for (size_t l = 0; l < n; ++l) m.data[l] = cc.labels.data[l] == static_cast<int>(order[q] + 1);
            if (border_crossings(m, roi, p.min_end_area_mm2).size() >= 2) return static_cast<int>(order[q] + 1);
        }
        return order.empty() ? 1 : static_cast<int>(order.front() + 1);
    };
    double threshold;
    if (p.threshold_hu) {
        threshold = *p.threshold_hu;
    } else {
        // Half maximum: midway between the background and the lumen plateau of the chosen vessel.
        const Components cc = components_at(t0);
        if (cc.sizes.empty()) throw InputError("segment: no voxel above the automatic threshold " + shortest(t0) + " HU");
        int label = 0;
        for (const auto& s : seeds) {
            const int lab = cc.labels.data[g.linear(s[0], s[1], s[2])];
            if (lab > 0) label = lab;
        }
        if (label == 0) label = seeds.empty() ? auto_component(cc) : -1;
        if (label < 0) {
            const auto& s0 = seeds.front();
            throw InputError("segment: --seed " + vec3(p.seeds_mm.front()) + " mm is not in the lumen: its smoothed intensity " +
                             shortest(sm.data[g.linear(s0[0], s0[1], s0[2])]) + " HU is below the automatic threshold " + shortest(t0) +
                             " HU (no seed is above it); move the seeds or give --threshold-hu");
        }
        std::vector<float> vals;
        for (size_t l = 0; l < n; ++l)
            if (cc.labels.data[l] == label) vals.push_back(sm.data[l]);
        const double plateau = percentile(vals, 0.9);
        threshold = 0.5 * (background + plateau);
        out.qa.emplace_back("initial_threshold_hu", t0);
        out.qa.emplace_back("lumen_plateau_hu", plateau);
    }
    out.qa.emplace_back("threshold_hu", threshold);
    if (!(roi_max >= threshold)) {
        throw InputError("segment: --threshold-hu " + shortest(threshold) + " selects no voxel (the smoothed ROI's maximum is " + shortest(roi_max) +
                         " HU)");
    }
    for (size_t q = 0; q < seeds.size(); ++q) {
        const float v = sm.data[g.linear(seeds[q][0], seeds[q][1], seeds[q][2])];
        if (v < threshold || (upper && v > *upper)) {
            throw InputError("segment: --seed " + vec3(p.seeds_mm[q]) + " mm is not in the lumen: its smoothed intensity " + shortest(v) +
                             " HU is outside the lumen range [" + shortest(threshold) + ", " + (upper ? shortest(*upper) : "inf") +
                             "] HU");
        }
    }
    const Components cc = components_at(threshold);
    out.qa.emplace_back("components_above_threshold", static_cast<double>(cc.sizes.size()));
    int label = 0;
    if (p.select == "largest") {
        label = 1;
    } else if (!seeds.empty()) {
        label = -1;  // union of the seeds' components
    } else {
        label = auto_component(cc);
        // Report the automatic seed: the component's brightest voxel.
        size_t best = 0;
        float bv = -1e30f;
        for (size_t l = 0; l < n; ++l)
            if (cc.labels.data[l] == label && sm.data[l] > bv) {
                bv = sm.data[l];
                best = l;
            }
        const Ijk c = ijk_of(g, best);
        const auto x = g.point(static_cast<double>(c.i), static_cast<double>(c.j), static_cast<double>(c.k));
        rep.info("segment: automatic seed " + vec3(x) + " mm (" + shortest(bv) + " HU)");
        for (int d = 0; d < 3; ++d) out.qa.emplace_back(std::string("auto_seed_") + "xyz"[d] + "_mm", x[static_cast<size_t>(d)]);
    }
    Volume<std::uint8_t> mask{g, std::vector<std::uint8_t>(n, 0)};
    std::vector<std::uint8_t> keep(cc.sizes.size() + 1, 0);  // component labels that form the lumen
    if (label > 0) keep[static_cast<size_t>(label)] = 1;
    if (label == -1)
        for (const auto& s : seeds) keep[static_cast<size_t>(cc.labels.data[g.linear(s[0], s[1], s[2])])] = 1;
    keep[0] = 0;
    for (size_t l = 0; l < n; ++l) mask.data[l] = keep[static_cast<size_t>(cc.labels.data[l])];
    if (p.fill_holes) {
        const auto before = std::count(mask.data.begin(), mask.data.end(), 1);
        mask = fill_holes(mask);
        out.qa.emplace_back("hole_voxels_filled", static_cast<double>(std::count(mask.data.begin(), mask.data.end(), 1) - before));
    }
    const auto n_lumen = static_cast<double>(std::count(mask.data.begin(), mask.data.end(), 1));
    out.qa.emplace_back("lumen_voxels", n_lumen);
    out.qa.emplace_back("lumen_volume_mm3", n_lumen * g.voxel_volume());

    // Centerline and ends.
    const Volume<float> dist = inside_distance_mm(mask);
    const auto ends = border_crossings(mask, roi, p.min_end_area_mm2);
    out.qa.emplace_back("ends_detected", static_cast<double>(ends.size()));
    if (ends.size() < 2) {
        throw InputError("segment: the lumen leaves the " + std::string(p.roi_mm ? "ROI" : "image") + " at " + std::to_string(ends.size()) +
                         " place(s); a vessel needs at least 2 ends (enlarge --roi-mm, move the seed, or check --threshold-hu)");
    }
    CenterlineResult cl = centerline_from_ends(mask, dist, roi, ends, p.end_inset_mm);
    double length = 0;
    for (Eigen::Index l = 0; l + 1 < cl.centerline.offsets.size(); ++l)
        for (int i = cl.centerline.offsets[l]; i + 1 < cl.centerline.offsets[l + 1]; ++i)
            length += (cl.centerline.points.row(i + 1) - cl.centerline.points.row(i)).norm();
    out.qa.emplace_back("centerline_length_mm", length);
    out.qa.emplace_back("centerline_branches", static_cast<double>(cl.centerline.offsets.size() - 1));
    if (!p.planes.empty()) {
        cl.planes = p.planes;
        rep.info("segment: using the " + std::to_string(p.planes.size()) + " given end plane(s) instead of the " + std::to_string(ends.size()) +
                 " detected");
    }
    out.qa.emplace_back("planes", static_cast<double>(cl.planes.size()));
    out.qa.emplace_back("ends_moved_to_tubular", static_cast<double>(cl.ends_moved_to_tubular));
    out.qa.emplace_back("ends_not_tubular", static_cast<double>(cl.ends_not_tubular));
    if (cl.ends_moved_to_tubular > 0 || cl.ends_not_tubular > 0)
        rep.info("segment: " + std::to_string(cl.ends_moved_to_tubular) + " end plane(s) moved inwards past a cross-section that is not tubular" +
                 (cl.ends_not_tubular ? ", " + std::to_string(cl.ends_not_tubular) + " found none within reach" : std::string()));

    ImageData& im = out.image;
    im.grid = g;
    im.mask = std::move(mask.data);
    im.mask_label_names = {"background", "lumen"};
    im.intensity = std::move(sm.data);
    im.threshold_hu = threshold;
    im.centerline = std::move(cl.centerline);
    im.planes = std::move(cl.planes);
    rep.info("segment: threshold " + shortest(threshold) + " HU, " + std::to_string(static_cast<long long>(n_lumen)) + " lumen voxels (" +
             shortest(n_lumen * g.voxel_volume()) + " mm³), " + std::to_string(im.planes.size()) + " end planes, centerline " +
             shortest(length) + " mm");
    return out;
}

Segmentation segment(const std::string& image_path, const SegmentParams& p, Reporter& rep) {
    validate(p);
    const Volume<float> ct = read_image<float>(image_path);
    check_finite(ct, image_path);
    return segment_finite(ct, p, rep);
}

}  // namespace aneu::pipeline
