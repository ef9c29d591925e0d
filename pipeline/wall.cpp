// SPDX-License-Identifier: MIT
// `wall`: the closed vessel-wall surface around a lumen surface. A signed distance field to the lumen in
// the blocks of a regular grid that meet a narrow band around it (distances by CGAL AABB queries, OpenMP;
// inside/outside by scan-line parity against the capped lumen), an iso-value — the local wall thickness —
// that goes from the artery's to the sac's thickness across the neck: with d_A, d_S the distances to the
// lumen's artery and sac parts (split at the label border), the sac weight is the smoothstep of
// (d_A − d_S)/(2·blend) + ½, which on the lumen is the signed distance to the border, so the change spans
// ±blend/2 about it (narrowed to a quarter of its depth for a shallow sac piece; QA blend_used_min_mm). The outer
// isosurface (VTK flying edges per block) cut at the end planes and remeshed, annular caps joining the inner
// and outer loops, then checks (closed, manifold, oriented, no self-intersection).
//
// The lumen is extended straight beyond each end plane before the field is computed, so the offset
// surface meets each plane at right angles and the cut gives an outer loop at the wall thickness.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <queue>
#include <set>

#include <Eigen/Geometry>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "aneu/pipeline/tetmesh.hpp"

namespace aneu::pipeline {

namespace {


/// Per-vertex signed geodesic (edge-graph) distance to the artery/sac label border [mm]: positive on the sac,
/// negative on the artery, ±1e9 where no border is reachable.
Eigen::VectorXd border_distance(const SurfaceData& s) {
    const Eigen::Index nv = s.V.rows();
    std::vector<char> art(static_cast<size_t>(nv), 0), sac(static_cast<size_t>(nv), 0);
    std::vector<std::vector<std::pair<int, double>>> adj(static_cast<size_t>(nv));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        for (int k = 0; k < 3; ++k) {
            const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
            (s.face_label[f] ? sac : art)[static_cast<size_t>(a)] = 1;
            const double L = (s.V.row(a) - s.V.row(b)).norm();
            adj[static_cast<size_t>(a)].push_back({b, L});
            adj[static_cast<size_t>(b)].push_back({a, L});
        }
    }
    std::vector<double> d(static_cast<size_t>(nv), std::numeric_limits<double>::infinity());
    using Item = std::pair<double, int>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> q;
    for (Eigen::Index v = 0; v < nv; ++v)
        if (art[static_cast<size_t>(v)] && sac[static_cast<size_t>(v)]) {
            d[static_cast<size_t>(v)] = 0;
            q.push({0.0, static_cast<int>(v)});
        }
    while (!q.empty()) {
        const auto [c, u] = q.top();
        q.pop();
        if (c > d[static_cast<size_t>(u)]) continue;
        for (const auto& [w, L] : adj[static_cast<size_t>(u)])
            if (c + L < d[static_cast<size_t>(w)]) {
                d[static_cast<size_t>(w)] = c + L;
                q.push({c + L, w});
            }
    }
    Eigen::VectorXd sd(nv);
    for (Eigen::Index v = 0; v < nv; ++v) {
        const bool on_sac = sac[static_cast<size_t>(v)] && !art[static_cast<size_t>(v)];
        sd[v] = std::isfinite(d[static_cast<size_t>(v)]) ? (on_sac ? 1 : -1) * d[static_cast<size_t>(v)] : (on_sac ? 1e9 : -1e9);
    }
    return sd;
}

/// Per-vertex sac weight in [0,1]: smoothstep of the signed border distance over `blend` mm (0 on the artery
/// far from the neck, 1 on the sac from blend/2 inside the border).
Eigen::VectorXd sac_weight(const Eigen::VectorXd& border_mm, double blend) {
    Eigen::VectorXd w(border_mm.size());
    for (Eigen::Index v = 0; v < w.size(); ++v) {
        const double x = std::clamp(border_mm[v] / blend + 0.5, 0.0, 1.0);
        w[v] = x * x * (3 - 2 * x);
    }
    return w;
}

/// The lumen continued straight past each boundary loop by `len` along its plane's normal (a band per
/// loop), and the far ends capped. Faces: [0, nf) lumen, then the bands, then (if `capped`) the caps.
SurfaceData extend_lumen(const SurfaceData& s, const std::vector<EndPlane>& planes, double len, bool capped, Eigen::VectorXd* weight) {
    SurfaceData e = s;
    const Eigen::Index nl = s.loop_end_id.size();
    std::vector<std::vector<int>> far_loops;
    for (Eigen::Index l = 0; l < nl; ++l) {
        const auto it = std::find_if(planes.begin(), planes.end(), [&](const EndPlane& p) { return p.id == s.loop_end_id[l]; });
        if (it == planes.end()) throw InputError("wall: boundary loop " + std::to_string(l) + " has end id " + std::to_string(s.loop_end_id[l]) + " but no such end plane");
        const int a0 = s.loop_offsets[l], a1 = s.loop_offsets[l + 1];
        const Eigen::Index v0 = e.V.rows();
        e.V.conservativeResize(v0 + (a1 - a0), 3);
        if (weight) weight->conservativeResize(v0 + (a1 - a0));
        for (int i = a0; i < a1; ++i) {
            e.V.row(v0 + (i - a0)) = s.V.row(s.loop_vertices[i]) + len * it->normal.transpose();
            if (weight) (*weight)[v0 + (i - a0)] = (*weight)[s.loop_vertices[i]];
        }
        const Eigen::Index f0 = e.F.rows();
        const int n = a1 - a0;
        e.F.conservativeResize(f0 + 2 * n, 3);
        e.face_label.conservativeResize(f0 + 2 * n);
        std::vector<int> far;
        for (int i = 0; i < n; ++i) {
            // Loop edge a→b belongs to a lumen face; the band continues beyond it with the same orientation.
            const int a = s.loop_vertices[a0 + i], b = s.loop_vertices[a0 + (i + 1) % n];
            const int A = static_cast<int>(v0 + i), B = static_cast<int>(v0 + (i + 1) % n);
            e.F.row(f0 + 2 * i) << b, a, A;
            e.F.row(f0 + 2 * i + 1) << b, A, B;
            e.face_label[f0 + 2 * i] = e.face_label[f0 + 2 * i + 1] = 0;
            far.push_back(A);
        }
        far_loops.push_back(far);
    }
    if (capped) {
        // The far loops run along the band faces' edges A→B? The band face (b, A, B) has edge A→B: the
        // loop direction is that of `far`, as boundary_loops would give it.
        cap_loops(e, far_loops, std::vector<int>(far_loops.size(), 0));
    }
    e.face_region.resize(0);
    e.loop_offsets.resize(0);
    e.loop_vertices.resize(0);
    e.loop_end_id.resize(0);
    return e;
}

/// Inside/outside of a closed surface at the voxels of a grid, by scan-line parity along x (rows offset by an
/// irrational fraction of a voxel so that no ray meets an edge or a vertex exactly): per row, the sorted x of
/// its crossings; a voxel is inside when an odd number of crossings lie before it. Memory: the crossings.
class ParityRows {
public:
    ParityRows(const SurfaceData& s, const ImageGrid& g) : m_g(g), m_rows(static_cast<size_t>(g.size[1] * g.size[2])) {
        const std::int64_t ny = g.size[1], nz = g.size[2];
        const double h = g.spacing[0];
        const double ey = 1.4142135e-4 * h, ez = 1.7320508e-4 * h;
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
            const double ylo = std::min({a.y(), b.y(), c.y()}), yhi = std::max({a.y(), b.y(), c.y()});
            const double zlo = std::min({a.z(), b.z(), c.z()}), zhi = std::max({a.z(), b.z(), c.z()});
            const auto j0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil((ylo - g.origin[1] - ey) / h)));
            const auto j1 = std::min<std::int64_t>(ny - 1, static_cast<std::int64_t>(std::floor((yhi - g.origin[1] - ey) / h)));
            const auto k0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil((zlo - g.origin[2] - ez) / h)));
            const auto k1 = std::min<std::int64_t>(nz - 1, static_cast<std::int64_t>(std::floor((zhi - g.origin[2] - ez) / h)));
            const Eigen::Vector3d n = (b - a).cross(c - a);
            if (std::abs(n.x()) < 1e-300) continue;  // parallel to the rays
            for (std::int64_t k = k0; k <= k1; ++k)
                for (std::int64_t j = j0; j <= j1; ++j) {
                    const double y = g.origin[1] + static_cast<double>(j) * h + ey, z = g.origin[2] + static_cast<double>(k) * h + ez;
                    // Point-in-triangle in the yz projection by edge signs.
                    auto edge = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& q) { return (q.y() - p.y()) * (z - p.z()) - (q.z() - p.z()) * (y - p.y()); };
                    const double s0 = edge(a, b), s1 = edge(b, c), s2 = edge(c, a);
                    if (!((s0 > 0 && s1 > 0 && s2 > 0) || (s0 < 0 && s1 < 0 && s2 < 0))) continue;
                    m_rows[static_cast<size_t>(j + ny * k)].push_back(a.x() - (n.y() * (y - a.y()) + n.z() * (z - a.z())) / n.x());
                }
        }
        for (auto& row : m_rows) std::sort(row.begin(), row.end());
    }
    bool inside(std::int64_t i, std::int64_t j, std::int64_t k) const {
        const auto& row = m_rows[static_cast<size_t>(j + m_g.size[1] * k)];
        const double x = m_g.origin[0] + static_cast<double>(i) * m_g.spacing[0];
        return (std::upper_bound(row.begin(), row.end(), x) - row.begin()) % 2 == 1;
    }

private:
    const ImageGrid& m_g;
    std::vector<std::vector<double>> m_rows;
};

constexpr std::int64_t BLOCK = 16;                 ///< cells per block edge of the narrow-band field
constexpr std::int64_t BLOCKS_PER_BATCH = 4096;    ///< blocks whose distance queries are made together (memory bound)
constexpr double MAX_BAND_SAMPLES = 6e8;          ///< 2.4 GB of float samples
constexpr float QUERY_MARK = -1e30F;               ///< a sample outside the lumen that needs a distance query
constexpr float QUERY_MARK_INSIDE = -2e30F;        ///< ... inside the lumen

/// The blocks of the virtual grid `g` that meet the box of some face grown by `band` (sorted keys
/// bx + nbx·(by + nby·bz)), and for each the faces' boxes in it (to mark the samples that need a distance).
struct BandBlocks {
    std::array<std::int64_t, 3> nb{};
    std::vector<std::int64_t> keys;
    std::vector<std::vector<std::array<std::int64_t, 6>>> boxes;  ///< per block: global voxel boxes i0,j0,k0,i1,j1,k1
};
BandBlocks band_blocks(const SurfaceData& s, const ImageGrid& g, double band) {
    BandBlocks bb;
    for (size_t d = 0; d < 3; ++d) bb.nb[d] = std::max<std::int64_t>(1, (g.size[d] - 1 + BLOCK - 1) / BLOCK);
    const double h = g.spacing[0];
    std::vector<std::array<std::int64_t, 6>> face_box(static_cast<size_t>(s.F.rows()));
    std::vector<std::int64_t> keys;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        Eigen::Vector3d a = s.V.row(s.F(f, 0)).transpose(), b = a;
        for (int k = 1; k < 3; ++k) {
            a = a.cwiseMin(s.V.row(s.F(f, k)).transpose());
            b = b.cwiseMax(s.V.row(s.F(f, k)).transpose());
        }
        auto& bx = face_box[static_cast<size_t>(f)];
        for (size_t d = 0; d < 3; ++d) {
            bx[d] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((a[static_cast<Eigen::Index>(d)] - band - g.origin[d]) / h)));
            bx[d + 3] = std::min<std::int64_t>(g.size[d] - 1, static_cast<std::int64_t>(std::ceil((b[static_cast<Eigen::Index>(d)] + band - g.origin[d]) / h)));
        }
        // A sample on a block border belongs to both blocks: voxel i lies in blocks (i−1)/B … i/B.
        for (std::int64_t bz = std::max<std::int64_t>(0, (bx[2] - 1) / BLOCK); bz <= std::min(bb.nb[2] - 1, bx[5] / BLOCK); ++bz)
            for (std::int64_t by = std::max<std::int64_t>(0, (bx[1] - 1) / BLOCK); by <= std::min(bb.nb[1] - 1, bx[4] / BLOCK); ++by)
                for (std::int64_t bxi = std::max<std::int64_t>(0, (bx[0] - 1) / BLOCK); bxi <= std::min(bb.nb[0] - 1, bx[3] / BLOCK); ++bxi)
                    keys.push_back(bxi + bb.nb[0] * (by + bb.nb[1] * bz));
    }
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    bb.keys = std::move(keys);
    bb.boxes.resize(bb.keys.size());
    for (const auto& bx : face_box)
        for (std::int64_t bz = std::max<std::int64_t>(0, (bx[2] - 1) / BLOCK); bz <= std::min(bb.nb[2] - 1, bx[5] / BLOCK); ++bz)
            for (std::int64_t by = std::max<std::int64_t>(0, (bx[1] - 1) / BLOCK); by <= std::min(bb.nb[1] - 1, bx[4] / BLOCK); ++by)
                for (std::int64_t bxi = std::max<std::int64_t>(0, (bx[0] - 1) / BLOCK); bxi <= std::min(bb.nb[0] - 1, bx[3] / BLOCK); ++bxi) {
                    const std::int64_t key = bxi + bb.nb[0] * (by + bb.nb[1] * bz);
                    const auto it = std::lower_bound(bb.keys.begin(), bb.keys.end(), key);
                    bb.boxes[static_cast<size_t>(it - bb.keys.begin())].push_back(bx);
                }
    return bb;
}

/// Samples of block `b`: within a face box of the band QUERY_MARK (outside the lumen) or QUERY_MARK_INSIDE;
/// elsewhere `inside_value` inside the lumen and `far_value` outside.
void fill_block(FieldBlock& fb, const BandBlocks& bb, size_t b, const ImageGrid& g, const ParityRows& rows, double inside_value, double far_value) {
    const std::int64_t key = bb.keys[b];
    const std::array<std::int64_t, 3> bi{key % bb.nb[0], (key / bb.nb[0]) % bb.nb[1], key / (bb.nb[0] * bb.nb[1])};
    for (size_t d = 0; d < 3; ++d) {
        fb.first[d] = bi[d] * BLOCK;
        fb.size[d] = std::min(BLOCK + 1, g.size[d] - fb.first[d]);
    }
    const std::int64_t sx = fb.size[0], sy = fb.size[1], sz = fb.size[2];
    std::vector<std::uint8_t> mark(static_cast<size_t>(sx * sy * sz), 0);
    for (const auto& bx : bb.boxes[b]) {
        const std::int64_t i0 = std::max(bx[0], fb.first[0]) - fb.first[0], i1 = std::min(bx[3], fb.first[0] + sx - 1) - fb.first[0];
        const std::int64_t j0 = std::max(bx[1], fb.first[1]) - fb.first[1], j1 = std::min(bx[4], fb.first[1] + sy - 1) - fb.first[1];
        const std::int64_t k0 = std::max(bx[2], fb.first[2]) - fb.first[2], k1 = std::min(bx[5], fb.first[2] + sz - 1) - fb.first[2];
        for (std::int64_t k = k0; k <= k1; ++k)
            for (std::int64_t j = j0; j <= j1; ++j)
                for (std::int64_t i = i0; i <= i1; ++i) mark[static_cast<size_t>(i + sx * (j + sy * k))] = 1;
    }
    fb.values.assign(mark.size(), static_cast<float>(far_value));
    for (std::int64_t k = 0; k < sz; ++k)
        for (std::int64_t j = 0; j < sy; ++j)
            for (std::int64_t i = 0; i < sx; ++i) {
                const size_t l = static_cast<size_t>(i + sx * (j + sy * k));
                const bool in = rows.inside(fb.first[0] + i, fb.first[1] + j, fb.first[2] + k);
                if (mark[l]) {
                    fb.values[l] = in ? QUERY_MARK_INSIDE : QUERY_MARK;
                } else if (in) {
                    fb.values[l] = static_cast<float>(inside_value);
                }
            }
}

/// Annulus between an inner and an outer loop lying in one plane, oriented along the plane's normal. Both
/// loops run counter-clockwise about the normal (signed area), the outer starts at the vertex nearest the
/// inner's first, and the strip advances on whichever loop is behind in arc-length fraction. Real ends are not
/// round (an elliptic or dented cross-section): matching by angle about the centroid there made 2 mm
/// triangles across the cap with 6° angles, and flat tetrahedra on them.
void zip_annulus(const Eigen::MatrixX3d& V, std::vector<int> in, std::vector<int> out, const Eigen::Vector3d& n, std::vector<Eigen::Vector3i>& faces) {
    auto signed_area = [&](const std::vector<int>& l) {
        Eigen::Vector3d a = Eigen::Vector3d::Zero();
        for (size_t i = 0; i < l.size(); ++i) a += V.row(l[i]).transpose().cross(V.row(l[(i + 1) % l.size()]).transpose());
        return 0.5 * a.dot(n);
    };
    if (signed_area(in) < 0) std::reverse(in.begin(), in.end());
    if (signed_area(out) < 0) std::reverse(out.begin(), out.end());
    {
        size_t best = 0;
        double bd = 1e300;
        for (size_t o = 0; o < out.size(); ++o) {
            const double d = (V.row(out[o]) - V.row(in[0])).squaredNorm();
            if (d < bd) {
                bd = d;
                best = o;
            }
        }
        std::rotate(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(best), out.end());
    }
    auto fractions = [&](const std::vector<int>& l) {  // arc-length fraction at each vertex, and 1 at the end
        std::vector<double> s(l.size() + 1, 0.0);
        for (size_t i = 1; i <= l.size(); ++i) s[i] = s[i - 1] + (V.row(l[i % l.size()]) - V.row(l[i - 1])).norm();
        for (double& x : s) x /= s.back();
        return s;
    };
    const std::vector<double> ai = fractions(in), ao = fractions(out);
    size_t i = 0, o = 0;
    const size_t ni = in.size(), no = out.size();
    std::vector<Eigen::Vector3i> strip;
    while (i < ni || o < no) {
        // Advance the loop whose next vertex comes first; on a tie, the one giving the shorter diagonal.
        bool adv_in;
        if (o >= no) {
            adv_in = true;
        } else if (i >= ni) {
            adv_in = false;
        } else {
            const double di = (V.row(in[(i + 1) % ni]) - V.row(out[o % no])).norm(), dout = (V.row(out[(o + 1) % no]) - V.row(in[i % ni])).norm();
            adv_in = ai[i + 1] < ao[o + 1] - 1e-9 || (std::abs(ai[i + 1] - ao[o + 1]) <= 1e-9 && di <= dout);
        }
        if (adv_in) {
            strip.emplace_back(in[i % ni], in[(i + 1) % ni], out[o % no]);
            ++i;
        } else {
            strip.emplace_back(in[i % ni], out[(o + 1) % no], out[o % no]);
            ++o;
        }
    }
    // One orientation for the whole strip (a per-face choice would break consistency where a face folds;
    // the self-intersection check reports such a face).
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const auto& f : strip) sum += (V.row(f[1]) - V.row(f[0])).transpose().cross((V.row(f[2]) - V.row(f[0])).transpose());
    for (auto f : strip) {
        if (sum.dot(n) < 0) std::swap(f[1], f[2]);
        faces.push_back(f);
    }
}

NamedValues stats(const std::string& prefix, std::vector<double> v) {
    if (v.empty()) return {};
    std::sort(v.begin(), v.end());
    auto pct = [&](double q) { return percentile(v, q); };
    double mean = 0;
    for (double x : v) mean += x;
    mean /= static_cast<double>(v.size());
    return {{prefix + "_median_mm", pct(0.5)}, {prefix + "_mean_mm", mean}, {prefix + "_p05_mm", pct(0.05)},
            {prefix + "_p95_mm", pct(0.95)}, {prefix + "_min_mm", v.front()}, {prefix + "_max_mm", v.back()},
            {prefix + "_samples", static_cast<double>(v.size())}};
}

}  // namespace



WallResult make_wall(const SurfaceData& lumen, const std::vector<EndPlane>& planes, const WallParams& p, Reporter& rep) {
    validate(p);
    const Stopwatch t0;
    WallResult r;
    if (lumen.loop_end_id.size() == 0) throw InputError("wall: the lumen surface has no labelled boundary loops (run `aneuprep surface`)");
    const double t_art = p.artery_thickness_mm, t_sac = p.aneurysm_thickness_mm > 0 ? p.aneurysm_thickness_mm : t_art / 3.0;
    const double t_max = std::max(t_art, t_sac), t_min = std::min(t_art, t_sac);
    double edge = p.edge_mm;
    if (!(edge > 0)) {
        for (const auto& [k, v] : triangle_quality(lumen))
            if (k == "edge_mean_mm") edge = v;
    }
    // The field is a signed distance on both sides of the lumen and the remeshed outer surface is projected
    // onto the exact offset afterwards, so the grid only has to resolve the offset's shape: half the outer
    // edge, and no coarser than the thinnest wall.
    const double h = p.grid_spacing_mm > 0 ? p.grid_spacing_mm : std::min(t_min, 0.5 * edge);
    r.qa.emplace_back("thickness_artery_target_mm", t_art);
    r.qa.emplace_back("thickness_aneurysm_target_mm", t_sac);
    r.qa.emplace_back("grid_spacing_mm", h);

    // The lumen extended past its ends (distance surface: open; sign surface: closed).
    // The blend spans ±blend/2 about the label border (narrowed per sac piece below).
    const Eigen::VectorXd border_mm = border_distance(lumen);
    const double blend = p.blend_mm;
    r.qa.emplace_back("blend_mm", blend);
    Eigen::VectorXd w = sac_weight(border_mm, blend);
    const double ext = 2 * t_max + 4 * h;
    Eigen::VectorXd w_ext = w;
    const SurfaceData dist_surf = extend_lumen(lumen, planes, ext, false, &w_ext);
    const SurfaceData sign_surf = extend_lumen(lumen, planes, ext, true, nullptr);

    // A virtual grid around the extended lumen: never allocated. The field lives only in blocks of BLOCK³
    // cells that meet the narrow band around the lumen, so memory and time follow the surface's area, not
    // its bounding box (a dense box grid at a third of the sac's wall took 8 GB on a 78×34×23 mm tree).
    const double margin = t_max + 3 * h;
    const Eigen::Vector3d lo = dist_surf.V.colwise().minCoeff().transpose().array() - margin;
    const Eigen::Vector3d hi = dist_surf.V.colwise().maxCoeff().transpose().array() + margin;
    ImageGrid g;
    for (int d = 0; d < 3; ++d) {
        g.size[static_cast<size_t>(d)] = static_cast<std::int64_t>(std::ceil((hi[d] - lo[d]) / h)) + 1;
        g.origin[static_cast<size_t>(d)] = lo[d];
        g.spacing[static_cast<size_t>(d)] = h;
    }
    r.qa.emplace_back("grid_voxels", static_cast<double>(g.voxel_count()));
    const double band = t_max + 2 * h;
    const BandBlocks bb = band_blocks(dist_surf, g, band);
    const double samples = static_cast<double>(bb.keys.size()) * static_cast<double>(BLOCK + 1) * static_cast<double>(BLOCK + 1) * static_cast<double>(BLOCK + 1);
    r.qa.emplace_back("band_blocks", static_cast<double>(bb.keys.size()));
    r.qa.emplace_back("band_samples", samples);
    if (samples > MAX_BAND_SAMPLES) {
        throw InputError("wall: the distance field's narrow band would hold " + shortest(samples) + " samples at " + shortest(h) + " mm spacing (at most " +
                         shortest(MAX_BAND_SAMPLES) + "); raise --grid-spacing-mm or the wall thicknesses");
    }
    rep.info("wall: distance field in " + std::to_string(bb.keys.size()) + " blocks of " + std::to_string(BLOCK) + "³ voxels of " + shortest(h) +
             " mm (narrow band of " + shortest(band) + " mm; the box would be " + std::to_string(g.size[0]) + "×" + std::to_string(g.size[1]) + "×" +
             std::to_string(g.size[2]) + ")");
    const ParityRows rows(sign_surf, g);

    // The lumen split at its label border (vertex weight ½): the artery part A and the sac part S. The iso-value
    // at a voxel blends from the distances to both, x = (d_A − d_S)/(2·blend) + ½: on the lumen that is the
    // signed distance to the border, and in space it is continuous — taking the weight at the nearest lumen point
    // instead made a step on the outer surface at the concave neck, where that point jumps across the crease.
    // |∇(d_A − d_S)| ≤ 2, so the iso-value's slope stays within 1.5·|t_sac − t_art|/blend.
    std::vector<Eigen::Vector3i> fa, fs;
    for (Eigen::Index f = 0; f < dist_surf.F.rows(); ++f) {
        const double wf = (w_ext[dist_surf.F(f, 0)] + w_ext[dist_surf.F(f, 1)] + w_ext[dist_surf.F(f, 2)]) / 3.0;
        (wf < 0.5 ? fa : fs).push_back(dist_surf.F.row(f).transpose());
    }
    auto as_matrix = [](const std::vector<Eigen::Vector3i>& v) {
        Eigen::MatrixX3i M(static_cast<Eigen::Index>(v.size()), 3);
        for (size_t i = 0; i < v.size(); ++i) M.row(static_cast<Eigen::Index>(i)) = v[i].transpose();
        return M;
    };
    const Eigen::MatrixX3i FA = as_matrix(fa), FS = as_matrix(fs);
    // Each sac piece (a connected part of S) has its own blend: in a piece shallower than four times the blend (a
    // 2 mm bleb, a small second lobe) most of the sac would lie in the transition and its thickness median would
    // not reach the sac's (C0070's bleb: 0.182 mm against 0.133 at half its depth), so its blend narrows to a
    // quarter of its depth from its border (said in the log; QA blend_used_min_mm).
    std::vector<double> piece_blend;
    double blend_min = blend;
    std::vector<int> piece_of_fs(fs.size(), 0);
    {
        std::vector<int> parent(static_cast<size_t>(dist_surf.V.rows()));
        std::iota(parent.begin(), parent.end(), 0);
        const std::function<int(int)> find = [&](int x) { return parent[static_cast<size_t>(x)] == x ? x : parent[static_cast<size_t>(x)] = find(parent[static_cast<size_t>(x)]); };
        for (const auto& f : fs)
            for (int k = 1; k < 3; ++k) parent[static_cast<size_t>(find(f[k]))] = find(f[0]);
        std::map<int, int> piece;  // root → piece
        std::vector<double> depth;
        for (size_t i = 0; i < fs.size(); ++i) {
            const int root = find(fs[i][0]);
            const auto [it, fresh] = piece.emplace(root, static_cast<int>(depth.size()));
            if (fresh) depth.push_back(0.0);
            piece_of_fs[i] = it->second;
            for (int k = 0; k < 3; ++k) {
                const int v = fs[i][k];
                if (v < border_mm.size() && border_mm[v] > 0 && border_mm[v] < 1e9) depth[static_cast<size_t>(it->second)] = std::max(depth[static_cast<size_t>(it->second)], border_mm[v]);
            }
        }
        double narrowest = blend;
        int narrowed = 0;
        for (double d : depth) {
            piece_blend.push_back(d > 0 ? std::min(blend, 0.25 * d) : blend);
            narrowed += piece_blend.back() < blend ? 1 : 0;
            narrowest = std::min(narrowest, piece_blend.back());
        }
        if (narrowed > 0)
            rep.info("wall: " + std::to_string(narrowed) + " of " + std::to_string(depth.size()) + " sac piece(s) shallower than four times the " + shortest(blend) +
                     " mm thickness blend: their blend narrowed to a quarter of their depth (down to " + shortest(narrowest) + " mm)");
        r.qa.emplace_back("sac_pieces", static_cast<double>(depth.size()));
        r.qa.emplace_back("blend_used_min_mm", narrowest);
        blend_min = narrowest;
    }
    // The distance to S and the blend of the nearest sac piece, at each point.
    auto sac_distance = [&](const Eigen::MatrixX3d& X, Eigen::VectorXd& bl) {
        Eigen::VectorXi nf;
        Eigen::VectorXd d = distance_to_faces(dist_surf.V, FS, X, &nf);
        bl.resize(X.rows());
        for (Eigen::Index m = 0; m < X.rows(); ++m) bl[m] = nf[m] >= 0 ? piece_blend[static_cast<size_t>(piece_of_fs[static_cast<size_t>(nf[m])])] : blend;
        return d;
    };
    auto local_thickness = [&](double dA, double dS, double bl) {
        double ws = fs.empty() ? 0.0 : fa.empty() ? 1.0 : std::clamp((dA - dS) / (2 * bl) + 0.5, 0.0, 1.0);
        ws = ws * ws * (3 - 2 * ws);
        return t_art + (t_sac - t_art) * ws;
    };
    // φ = signed distance − local thickness; negative in the wall and the lumen. Per block: inside the lumen
    // −t_min, in the band (outside, within `band` of a face's box) the blended distance, elsewhere `band`.
    std::vector<FieldBlock> blocks(bb.keys.size());
    double queries = 0;
    const auto nbk = static_cast<std::int64_t>(bb.keys.size());
    for (std::int64_t b0 = 0; b0 < nbk; b0 += BLOCKS_PER_BATCH) {
        const std::int64_t b1 = std::min(nbk, b0 + BLOCKS_PER_BATCH);
        std::vector<std::pair<std::int64_t, std::int64_t>> where;  // (block, local sample) of each query
#pragma omp parallel for schedule(dynamic)
        for (std::int64_t b = b0; b < b1; ++b) fill_block(blocks[static_cast<size_t>(b)], bb, static_cast<size_t>(b), g, rows, -t_min, band);
        for (std::int64_t b = b0; b < b1; ++b) {
            const auto& fb = blocks[static_cast<size_t>(b)];
            for (size_t l = 0; l < fb.values.size(); ++l)
                if (fb.values[l] == QUERY_MARK || fb.values[l] == QUERY_MARK_INSIDE) where.emplace_back(b, static_cast<std::int64_t>(l));
        }
        Eigen::MatrixX3d q(static_cast<Eigen::Index>(where.size()), 3);
        for (size_t m = 0; m < where.size(); ++m) {
            const auto& fb = blocks[static_cast<size_t>(where[m].first)];
            const auto l = where[m].second;
            const std::int64_t i = l % fb.size[0], j = (l / fb.size[0]) % fb.size[1], k = l / (fb.size[0] * fb.size[1]);
            q.row(static_cast<Eigen::Index>(m)) << g.origin[0] + static_cast<double>(fb.first[0] + i) * h, g.origin[1] + static_cast<double>(fb.first[1] + j) * h,
                g.origin[2] + static_cast<double>(fb.first[2] + k) * h;
        }
        queries += static_cast<double>(where.size());
        const Eigen::VectorXd dA = distance_to_faces(dist_surf.V, FA, q);
        Eigen::VectorXd bl;
        const Eigen::VectorXd dS = sac_distance(q, bl);
#pragma omp parallel for schedule(static)
        for (Eigen::Index m = 0; m < static_cast<Eigen::Index>(where.size()); ++m) {
            const auto& [b, l] = where[static_cast<size_t>(m)];
            float& v = blocks[static_cast<size_t>(b)].values[static_cast<size_t>(l)];
            const double sign = v == QUERY_MARK_INSIDE ? -1.0 : 1.0;
            v = static_cast<float>(sign * std::min(std::min(dA[m], dS[m]), band) - local_thickness(dA[m], dS[m], bl[m]));
        }
    }
    r.qa.emplace_back("distance_queries", queries);
    const double t_field = t0.seconds();
    r.qa.emplace_back("time_distance_field_s", t_field);

    // Outer surface: isosurface φ = 0 (outward = towards φ > 0), cut at the planes, remeshed.
    auto lap = [&, step = Stopwatch()](const std::string& what) mutable { r.qa.emplace_back("time_" + what + "_s", step.lap()); };
    SurfaceData outer = isosurface_blocks(g, blocks, 0.0);
    blocks.clear();
    blocks.shrink_to_fit();
    lap("isosurface");
    r.qa.emplace_back("outer_isosurface_triangles", static_cast<double>(outer.F.rows()));
    // Not decimated before remeshing: VTK's quadric and DecimatePro decimations were both measured to leave
    // non-manifold edges on this surface; CGAL remeshes the fine isosurface directly.
    // Each plane removes the outer surface's stub round the lumen's extension (it ends about ext + t beyond the
    // plane on the axis), and nothing else: next to a short branch, its parent's wall can bulge beyond the
    // branch's plane inside the disc (C0095).
    std::vector<Eigen::Vector3d> stub_ends;
    for (const auto& pl : planes) stub_ends.push_back(pl.point + ext * pl.normal);
    outer = clip_at_planes(outer, planes, 3.0, t_max + 2 * h, stub_ends);
    std::vector<std::vector<int>> outer_loops;
    try {
        outer_loops = boundary_loops(outer);
    } catch (const InputError& e) {  // the stage's own surface, not the input, is at fault
        throw MeshingError(std::string("wall: check 'cut outer surface is a manifold' failed: ") + e.what());
    }
    if (outer_loops.size() != static_cast<size_t>(lumen.loop_end_id.size())) {
        // Where: the end planes that got no outer loop or more than one (each loop counted at its nearest plane).
        const auto mm = [](double x) { return shortest(std::round(x * 100) / 100); };
        const auto at = [&](const Eigen::Vector3d& x) { return "(" + mm(x.x()) + ", " + mm(x.y()) + ", " + mm(x.z()) + ")"; };
        std::vector<int> count(planes.size(), 0);
        std::vector<std::string> seen(planes.size());  // per plane: its loops' centres and sizes
        for (const auto& l : outer_loops) {
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int v : l) c += outer.V.row(v).transpose();
            c /= static_cast<double>(l.size());
            double rl = 0;
            for (int v : l) rl = std::max(rl, (outer.V.row(v).transpose() - c).norm());
            size_t best = 0;
            for (size_t q = 1; q < planes.size(); ++q)
                if ((c - planes[q].point).norm() < (c - planes[best].point).norm()) best = q;
            if (planes.empty()) continue;
            ++count[best];
            seen[best] += std::string(seen[best].empty() ? "" : ", ") + "loop at " + at(c) + " of radius " + mm(rl) + " mm";
        }
        std::string where;
        for (size_t q = 0; q < planes.size(); ++q)
            if (count[q] != 1)
                where += std::string(where.empty() ? "" : "; ") + "end " + std::to_string(planes[q].id) + " at " + at(planes[q].point) + " mm (lumen radius " +
                         mm(planes[q].radius_mm) + " mm) has " + std::to_string(count[q]) + " outer loop(s)" + (seen[q].empty() ? "" : ": " + seen[q]);
        throw MeshingError("wall: check 'outer ends' failed: the cut outer surface has " + std::to_string(outer_loops.size()) + " open ends, the lumen " +
                           std::to_string(lumen.loop_end_id.size()) + (where.empty() ? "" : ": " + where) +
                           " (are two vessels, or a branch and its parent, closer than the wall thickness near that end?)");
    }
    // The outer surface: the cut isosurface remeshed (with a finer zone on a retry), projected onto the exact
    // offset, refined where it still meets the lumen. Returns where it still does.
    const SurfaceData iso = std::move(outer);
    bool remesher_fallback = false;
    double largest_move = 0;
    int refined = 0;
    std::vector<int> plane_of;
    Eigen::VectorXd t_at_lumen(lumen.V.rows());  // the wall's thickness at each lumen vertex
    {
        Eigen::VectorXd bl;
        const Eigen::VectorXd dA = distance_to_faces(dist_surf.V, FA, lumen.V), dS = sac_distance(lumen.V, bl);
        for (Eigen::Index v = 0; v < lumen.V.rows(); ++v) t_at_lumen[v] = local_thickness(dA[v], dS[v], bl[v]);
    }
    int near_faces = 0;
    auto shape_outer = [&](const RemeshZone* zone) -> std::vector<Eigen::Vector3d> {
        {
            RemeshOutcome rm = remesh_checked(iso, edge, p.remesher, p.timeout_s, zone);
            if (!rm.fallback_why.empty()) rep.warn("wall: outer surface remeshed with " + rm.method + " instead of " + p.remesher + " (" + rm.fallback_why + ")");
            remesher_fallback = !rm.fallback_why.empty();
            outer = std::move(rm.surface);
        }
        // Onto the exact offset: Newton steps along the distance gradient on φ(x) = d(x) − t(x) with exact
        // distances, so the wall's thickness does not depend on the grid; cut-end vertices stay in their planes
        // (the lumen runs straight through them, so the gradient lies in the plane there).
        plane_of.assign(static_cast<size_t>(outer.V.rows()), -1);
        for (const auto& l : boundary_loops(outer)) {
            Eigen::Vector3d c = Eigen::Vector3d::Zero();
            for (int v : l) c += outer.V.row(v).transpose();
            c /= static_cast<double>(l.size());
            int best = 0;
            for (size_t q = 1; q < planes.size(); ++q)
                if (std::abs(planes[q].normal.dot(c - planes[q].point)) + 1e-3 * (c - planes[q].point).norm() <
                    std::abs(planes[static_cast<size_t>(best)].normal.dot(c - planes[static_cast<size_t>(best)].point)) + 1e-3 * (c - planes[static_cast<size_t>(best)].point).norm())
                    best = static_cast<int>(q);
            for (int v : l) plane_of[static_cast<size_t>(v)] = best;
        }
        auto project = [&](const std::vector<Eigen::Index>& which) {
            Eigen::MatrixX3d X(static_cast<Eigen::Index>(which.size()), 3);
            for (size_t m = 0; m < which.size(); ++m) X.row(static_cast<Eigen::Index>(m)) = outer.V.row(which[m]);
            double moved = 0;
            for (int it = 0; it < 3; ++it) {
                const NearestOnSurface near = nearest_on_surface(dist_surf, X);
                Eigen::VectorXd bl;
                const Eigen::VectorXd dA = distance_to_faces(dist_surf.V, FA, X), dS = sac_distance(X, bl);
                for (Eigen::Index m = 0; m < X.rows(); ++m) {
                    const Eigen::Vector3d x = X.row(m).transpose(), dir = x - near.point.row(m).transpose();
                    if (!(dir.norm() > 1e-9)) continue;
                    const double phi = near.distance[m] - local_thickness(dA[m], dS[m], bl[m]);
                    Eigen::Vector3d step = -phi * dir.normalized();
                    const int pq = plane_of[static_cast<size_t>(which[static_cast<size_t>(m)])];
                    if (pq >= 0) step -= planes[static_cast<size_t>(pq)].normal.dot(step) * planes[static_cast<size_t>(pq)].normal;
                    X.row(m) += step.transpose();
                    if (it == 0) moved = std::max(moved, step.norm());
                }
            }
            for (size_t m = 0; m < which.size(); ++m) outer.V.row(which[m]) = X.row(static_cast<Eigen::Index>(m));
            return moved;
        };
        {
            std::vector<Eigen::Index> all(static_cast<size_t>(outer.V.rows()));
            for (size_t v = 0; v < all.size(); ++v) all[v] = static_cast<Eigen::Index>(v);
            largest_move = project(all);
        }
        // Where two vessels run closer than twice the wall, the offset has a sharp crease between them and an outer
        // surface remeshed at the lumen's edge length cuts across it, through the inner wall (a real Circle of
        // Willis): split the longest edge of every outer face that meets the lumen, project the new vertices onto the
        // offset, and repeat while such faces are left and their number falls (at most 8 rounds).
        int last_bad = 0;
        std::set<int> bad;
        for (int round = 0; round < 8; ++round) {
            SurfaceData both;
            both.V.resize(lumen.V.rows() + outer.V.rows(), 3);
            both.V << lumen.V, outer.V;
            both.F.resize(lumen.F.rows() + outer.F.rows(), 3);
            both.F << lumen.F, (outer.F.array() + static_cast<int>(lumen.V.rows())).matrix();
            both.face_label = Eigen::VectorXi::Zero(both.F.rows());
            const auto pairs = self_intersections(both, 1000000);
            bad.clear();
            const int nl = static_cast<int>(lumen.F.rows());
            for (const auto& [fa2, fb2] : pairs)
                if ((fa2 < nl) != (fb2 < nl)) bad.insert(std::max(fa2, fb2) - nl);  // outer against inner only
            // Also an outer face that passes within half the local thickness of a lumen vertex without crossing
            // (the same chord across a crease; a TOF-MRA's thin sac wall: 0.007 mm where 0.14 was meant, and every
            // tetrahedron through it flat).
            {
                Eigen::VectorXi nf;
                const Eigen::VectorXd d = distance_to_faces(outer.V, outer.F, lumen.V, &nf);
                for (Eigen::Index v = 0; v < lumen.V.rows(); ++v)
                    if (d[v] < 0.5 * t_at_lumen[v] && nf[v] >= 0 && !bad.count(nf[v])) {
                        bad.insert(nf[v]);
                        if (round == 0) ++near_faces;
                    }
            }
            if (bad.empty() || (round > 0 && static_cast<int>(bad.size()) >= last_bad)) break;  // done, or not converging
            last_bad = static_cast<int>(bad.size());
            rep.debug("wall: refinement round " + std::to_string(round) + ": " + std::to_string(bad.size()) + " outer faces meet the lumen");
            refined += static_cast<int>(bad.size());
            std::map<std::pair<int, int>, int> mid;  // edge → its new midpoint vertex
            std::vector<Eigen::Vector3i> F2;
            std::vector<Eigen::Index> fresh;
            for (int f : bad) {
                int k_long = 0;
                double L = -1;
                for (int k = 0; k < 3; ++k) {
                    const double lk = (outer.V.row(outer.F(f, k)) - outer.V.row(outer.F(f, (k + 1) % 3))).norm();
                    if (lk > L) {
                        L = lk;
                        k_long = k;
                    }
                }
                const int a = outer.F(f, k_long), b = outer.F(f, (k_long + 1) % 3);
                const std::pair<int, int> e{std::min(a, b), std::max(a, b)};
                if (mid.count(e)) continue;
                const Eigen::Index m = outer.V.rows();
                outer.V.conservativeResize(m + 1, 3);
                outer.V.row(m) = 0.5 * (outer.V.row(a) + outer.V.row(b));
                const int pa = plane_of[static_cast<size_t>(a)], pb = plane_of[static_cast<size_t>(b)];
                plane_of.push_back(pa >= 0 && pa == pb ? pa : -1);
                mid[e] = static_cast<int>(m);
                fresh.push_back(m);
            }
            // Every face with split edges is divided conformingly (1, 2 or 3 of its edges).
            for (Eigen::Index f = 0; f < outer.F.rows(); ++f) {
                int v[3], mm[3], n_split = 0;
                for (int k = 0; k < 3; ++k) {
                    v[k] = outer.F(f, k);
                    const int b = outer.F(f, (k + 1) % 3);
                    const auto it = mid.find({std::min(v[k], b), std::max(v[k], b)});
                    mm[k] = it == mid.end() ? -1 : it->second;  // midpoint of edge v[k] → v[k+1]
                    n_split += mm[k] >= 0;
                }
                if (n_split == 0) {
                    F2.emplace_back(v[0], v[1], v[2]);
                } else if (n_split == 3) {
                    F2.emplace_back(v[0], mm[0], mm[2]);
                    F2.emplace_back(mm[0], v[1], mm[1]);
                    F2.emplace_back(mm[2], mm[1], v[2]);
                    F2.emplace_back(mm[0], mm[1], mm[2]);
                } else {
                    // Rotate so that edge 0 is split and, with two splits, edge 1 too.
                    int r0 = 0;
                    for (int k = 0; k < 3; ++k)
                        if (mm[k] >= 0 && (n_split == 1 || mm[(k + 1) % 3] >= 0)) r0 = k;
                    const int a = v[r0], b = v[(r0 + 1) % 3], c = v[(r0 + 2) % 3], m0 = mm[r0], m1 = mm[(r0 + 1) % 3];
                    if (n_split == 1) {
                        F2.emplace_back(a, m0, c);
                        F2.emplace_back(m0, b, c);
                    } else {
                        F2.emplace_back(m0, b, m1);
                        F2.emplace_back(a, m0, m1);
                        F2.emplace_back(a, m1, c);
                    }
                }
            }
            outer.F.resize(static_cast<Eigen::Index>(F2.size()), 3);
            for (size_t f = 0; f < F2.size(); ++f) outer.F.row(static_cast<Eigen::Index>(f)) = F2[f].transpose();
            project(fresh);
        }
        std::vector<Eigen::Vector3d> left;  // centroids of the outer faces that still meet the lumen
        for (int f : bad) left.push_back((outer.V.row(outer.F(f, 0)) + outer.V.row(outer.F(f, 1)) + outer.V.row(outer.F(f, 2))).transpose() / 3.0);
        return left;
    };
    std::vector<Eigen::Vector3d> left = shape_outer(nullptr);
    // A sac tip or a thin stub sharper than the outer surface's edge (a wall of a third of a millimetre round a
    // tip of a few tenths: a TOF-MRA's faded branches) is cut across by the remeshed triangles, and splitting them
    // does not converge: remesh again with a finer zone round those places, at most twice.
    int zone_faces = 0;
    double zone_edge = edge;
    for (int attempt = 0; attempt < 2 && !left.empty(); ++attempt) {
        zone_edge = std::min(zone_edge, 1.5 * t_min) * (attempt == 0 ? 1.0 : 0.7);
        const double rho = 4 * edge;
        RemeshZone zone;
        zone.fine_edge_mm = zone_edge;
        zone.fine.assign(static_cast<size_t>(iso.F.rows()), 0);
        zone_faces = 0;
        for (Eigen::Index f = 0; f < iso.F.rows(); ++f) {
            const Eigen::Vector3d c = (iso.V.row(iso.F(f, 0)) + iso.V.row(iso.F(f, 1)) + iso.V.row(iso.F(f, 2))).transpose() / 3.0;
            for (const auto& x : left)
                if ((c - x).norm() < rho) {
                    zone.fine[static_cast<size_t>(f)] = 1;
                    ++zone_faces;
                    break;
                }
        }
        rep.info("wall: " + std::to_string(left.size()) + " outer faces still meet the lumen (a tip sharper than the outer edge); remeshing " +
                 shortest(rho) + " mm round them at " + shortest(zone_edge) + " mm");
        left = shape_outer(&zone);
    }
    r.qa.emplace_back("remesher_fallback", remesher_fallback ? 1.0 : 0.0);
    r.qa.emplace_back("projection_largest_move_mm", largest_move);
    r.qa.emplace_back("outer_faces_refined", static_cast<double>(refined));
    r.qa.emplace_back("outer_faces_too_near_lumen", static_cast<double>(near_faces));
    r.qa.emplace_back("outer_fine_zone_faces", static_cast<double>(zone_faces));
    r.qa.emplace_back("outer_fine_zone_edge_mm", zone_faces > 0 ? zone_edge : 0.0);
    lap("remesh_and_projection");

    const auto loops_out = boundary_loops(outer);

    // Assemble: inner (lumen, reversed), outer, annular caps.
    const Eigen::Index nvi = lumen.V.rows(), nvo = outer.V.rows(), nfi = lumen.F.rows(), nfo = outer.F.rows();
    SurfaceData wall;
    wall.V.resize(nvi + nvo, 3);
    wall.V << lumen.V, outer.V;
    std::vector<Eigen::Vector3i> faces;
    std::vector<int> labels;
    for (Eigen::Index f = 0; f < nfi; ++f) {
        faces.emplace_back(lumen.F(f, 0), lumen.F(f, 2), lumen.F(f, 1));
        labels.push_back(0);
    }
    for (Eigen::Index f = 0; f < nfo; ++f) {
        faces.emplace_back(outer.F(f, 0) + static_cast<int>(nvi), outer.F(f, 1) + static_cast<int>(nvi), outer.F(f, 2) + static_cast<int>(nvi));
        labels.push_back(1);
    }
    wall.label_names = {"inner", "outer"};
    std::vector<char> used(loops_out.size(), 0);
    for (Eigen::Index l = 0; l < lumen.loop_end_id.size(); ++l) {
        const int id = lumen.loop_end_id[l];
        const auto pit = std::find_if(planes.begin(), planes.end(), [&](const EndPlane& e) { return e.id == id; });
        std::vector<int> in(lumen.loop_vertices.data() + lumen.loop_offsets[l], lumen.loop_vertices.data() + lumen.loop_offsets[l + 1]);
        Eigen::Vector3d ci = Eigen::Vector3d::Zero();
        for (int v : in) ci += lumen.V.row(v).transpose();
        ci /= static_cast<double>(in.size());
        // The outer loop of the same end: nearest centroid.
        size_t best = 0;
        double bd = 1e300;
        for (size_t o = 0; o < loops_out.size(); ++o) {
            Eigen::Vector3d co = Eigen::Vector3d::Zero();
            for (int v : loops_out[o]) co += outer.V.row(v).transpose();
            co /= static_cast<double>(loops_out[o].size());
            if ((co - ci).norm() < bd) {
                bd = (co - ci).norm();
                best = o;
            }
        }
        if (used[best]) throw MeshingError("wall: check 'caps' failed: two lumen ends match the same outer loop near (" + shortest(ci.x()) + ", " + shortest(ci.y()) + ", " + shortest(ci.z()) + ") mm");
        used[best] = 1;
        std::vector<int> out;
        for (int v : loops_out[best]) out.push_back(v + static_cast<int>(nvi));
        std::vector<Eigen::Vector3i> cap;
        zip_annulus(wall.V, in, out, pit->normal, cap);
        const int label = static_cast<int>(wall.label_names.size());
        wall.label_names.push_back("cap:" + std::to_string(id));
        for (const auto& f : cap) {
            faces.push_back(f);
            labels.push_back(label);
        }
    }
    wall.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
    wall.face_label.resize(static_cast<Eigen::Index>(faces.size()));
    for (size_t f = 0; f < faces.size(); ++f) {
        wall.F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
        wall.face_label[static_cast<Eigen::Index>(f)] = labels[f];
    }

    // Checks: closed, 2-manifold, consistently and outward oriented; no self-intersection.
    try {
        check_closed_surface(wall, "wall");
    } catch (const InputError& e) {
        throw MeshingError(std::string("wall: check 'closed, manifold, oriented' failed: ") + e.what());
    }
    const auto inter = self_intersections(wall, 4);
    r.qa.emplace_back("self_intersections", static_cast<double>(inter.size()));
    if (!inter.empty()) {
        const auto [fa, fb] = inter.front();
        const Eigen::Vector3d c = (wall.V.row(wall.F(fa, 0)) + wall.V.row(wall.F(fa, 1)) + wall.V.row(wall.F(fa, 2))).transpose() / 3.0;
        throw MeshingError("wall: check 'self-intersection' failed: faces " + std::to_string(fa) + " (" + wall.label_names[static_cast<size_t>(wall.face_label[fa])] +
                           ") and " + std::to_string(fb) + " (" + wall.label_names[static_cast<size_t>(wall.face_label[fb])] + ") intersect near (" +
                           shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) + ") mm (thin wall against a tight curvature?)");
    }

    lap("checks");
    // Regions by the nearest lumen face; thickness: outer vertex → lumen, inner vertex → outer surface.
    Eigen::MatrixX3d cents(wall.F.rows(), 3);
    for (Eigen::Index f = 0; f < wall.F.rows(); ++f) cents.row(f) = (wall.V.row(wall.F(f, 0)) + wall.V.row(wall.F(f, 1)) + wall.V.row(wall.F(f, 2))) / 3.0;
    const NearestOnSurface nf = nearest_on_surface(lumen, cents);
    wall.region_names = {"artery", "aneurysm"};
    wall.face_region.resize(wall.F.rows());
    for (Eigen::Index f = 0; f < wall.F.rows(); ++f) wall.face_region[f] = f < nfi ? lumen.face_label[f] : lumen.face_label[nf.face[f]];
    const NearestOnSurface to_inner = nearest_on_surface(lumen, outer.V);
    const NearestOnSurface to_outer = nearest_on_surface(outer, lumen.V);
    wall.vertex_thickness.resize(wall.V.rows());
    wall.vertex_thickness << to_outer.distance, to_inner.distance;
    std::vector<double> th[2];
    std::vector<char> outer_on_cap(static_cast<size_t>(nvo), 0);
    for (const auto& l : loops_out)
        for (int v : l) outer_on_cap[static_cast<size_t>(v)] = 1;
    for (Eigen::Index v = 0; v < nvo; ++v) {
        if (outer_on_cap[static_cast<size_t>(v)]) continue;  // the cut ends are not the wall's thickness
        th[lumen.face_label[to_inner.face[v]] ? 1 : 0].push_back(to_inner.distance[v]);
    }
    for (auto& s : stats("thickness_artery", th[0])) r.qa.push_back(s);
    for (auto& s : stats("thickness_aneurysm", th[1])) r.qa.push_back(s);
    // Largest thickness change per mm along outer edges (the blend allows about 1.5 (t_art − t_sac) / blend).
    double grad = 0;
    for (Eigen::Index f = 0; f < nfo; ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = outer.F(f, k), b = outer.F(f, (k + 1) % 3);
            const double L = (outer.V.row(a) - outer.V.row(b)).norm();
            if (L > 0) grad = std::max(grad, std::abs(to_inner.distance[a] - to_inner.distance[b]) / L);
        }
    r.qa.emplace_back("thickness_gradient_max", grad);
    r.qa.emplace_back("thickness_gradient_blend_allows", 1.5 * std::abs(t_art - t_sac) / blend_min);
    for (auto& qv : triangle_quality(wall)) r.qa.emplace_back("wall_" + qv.first, qv.second);
    {  // smallest triangle angle on the inner, outer and cap faces (thin triangles there make flat tetrahedra)
        double amin[3] = {180, 180, 180};
        for (Eigen::Index f = 0; f < wall.F.rows(); ++f) {
            const int part = wall.face_label[f] == 0 ? 0 : wall.face_label[f] == 1 ? 1 : 2;
            for (int k = 0; k < 3; ++k) {
                const Eigen::Vector3d a = wall.V.row(wall.F(f, k)), b = wall.V.row(wall.F(f, (k + 1) % 3)), c = wall.V.row(wall.F(f, (k + 2) % 3));
                const double cosang = (b - a).normalized().dot((c - a).normalized());
                amin[part] = std::min(amin[part], std::acos(std::clamp(cosang, -1.0, 1.0)) * 180.0 / PI);
            }
        }
        r.qa.emplace_back("min_angle_inner_deg", amin[0]);
        r.qa.emplace_back("min_angle_outer_deg", amin[1]);
        r.qa.emplace_back("min_angle_caps_deg", amin[2]);
    }
    r.qa.emplace_back("enclosed_volume_mm3", enclosed_volume(wall));
    r.qa.emplace_back("time_total_s", t0.seconds());
    r.wall = std::move(wall);
    rep.info("wall: " + std::to_string(r.wall.F.rows()) + " triangles; thickness median artery " + (th[0].empty() ? "-" : shortest(stats("a", th[0])[0].second)) +
             " mm, aneurysm " + (th[1].empty() ? "-" : shortest(stats("a", th[1])[0].second)) + " mm");
    return r;
}

}  // namespace aneu::pipeline
