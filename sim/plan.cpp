// SPDX-License-Identifier: MIT
// `aneusim plan`: a scene with a clip across the detected neck (plan.hpp).
#include "aneu/core/common.hpp"
#include "aneu/sim/plan.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"

namespace aneu::sim {

namespace {
nlohmann::json vec(const Eigen::Vector3d& x) {
    auto r = [](double v) { return std::round(v * 1e4) / 1e4; };
    return nlohmann::json::array({r(x.x()), r(x.y()), r(x.z())});
}
}  // namespace

std::vector<std::vector<Eigen::Vector3d>> neck_border(const SimLumen& L) {
    std::vector<std::vector<Eigen::Vector3d>> out;
    for (size_t l = 0; l < L.neck_loops.size(); ++l) {
        std::vector<Eigen::Vector3d> line;
        if (l < L.neck_line.size() && !L.neck_line[l].empty()) {
            for (const NeckPointOnLumen& q : L.neck_line[l]) {
                Eigen::Vector3d x = Eigen::Vector3d::Zero();
                for (int k = 0; k < 3; ++k) x += q.weights[k] * L.X.row(L.F(q.face, k)).transpose();
                line.push_back(x);
            }
        } else {
            for (int v : L.neck_loops[l]) line.push_back(L.X.row(v).transpose());
        }
        out.push_back(std::move(line));
    }
    return out;
}

NeckFrame neck_frame(const SimModel& m) {
    const SimLumen& L = m.surface.lumen;
    if (L.neck_loops.empty()) {
        throw InputError(m.case_id + ": no aneurysm neck in the bundle (no border between 'aneurysm' and another region on the lumen under "
                                     "the condensed surface); label the sac (aneuprep surface) and condense around it");
    }
    NeckFrame nf;
    // Centre and covariance by length along the border (the smoothed neck line: the label loop's staircase of
    // mesh edges is half as long again and leans its axes towards its zig-zag), edge midpoints weighted by length.
    const std::vector<std::vector<Eigen::Vector3d>> border = neck_border(L);
    double total = 0;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& line : border)
        for (size_t k = 0; k < line.size(); ++k) {
            const Eigen::Vector3d& a = line[k];
            const Eigen::Vector3d& b = line[(k + 1) % line.size()];
            const double len = (b - a).norm();
            c += 0.5 * len * (a + b);
            total += len;
        }
    c /= total;
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (const auto& line : border)
        for (size_t k = 0; k < line.size(); ++k) {
            const Eigen::Vector3d& a = line[k];
            const Eigen::Vector3d& b = line[(k + 1) % line.size()];
            const Eigen::Vector3d q = 0.5 * (a + b) - c;
            C += (b - a).norm() * q * q.transpose();
        }
    nf.line_mm = total;
    for (const auto& loop : L.neck_loops)
        for (size_t k = 0; k < loop.size(); ++k) nf.label_line_mm += (L.X.row(loop[(k + 1) % loop.size()]) - L.X.row(loop[k])).norm();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);  // ascending
    nf.centre = c;
    nf.normal = es.eigenvectors().col(0);
    nf.short_axis = es.eigenvectors().col(1);
    nf.long_axis = es.eigenvectors().col(2);
    // The normal towards the sac: the sac faces' centroid.
    const auto it = std::find(m.surface.region_names.begin(), m.surface.region_names.end(), "aneurysm");
    const int sac = it == m.surface.region_names.end() ? -1 : static_cast<int>(it - m.surface.region_names.begin());
    Eigen::Vector3d sc = Eigen::Vector3d::Zero();
    int ns = 0;
    for (Eigen::Index f = 0; f < L.F.rows(); ++f)
        if (L.face_region[f] == sac) {
            sc += (L.X.row(L.F(f, 0)) + L.X.row(L.F(f, 1)) + L.X.row(L.F(f, 2))).transpose() / 3.0;
            ++ns;
        }
    if (ns > 0 && nf.normal.dot(sc / ns - c) < 0) nf.normal = -nf.normal;
    nf.short_axis = nf.normal.cross(nf.long_axis).normalized();  // right-handed: long × short = normal
    // The extents from the label loop's vertices (the clip must span every labelled neck vertex).
    double lo = 1e300, hi = -1e300, wlo = 1e300, whi = -1e300;
    for (const auto& loop : L.neck_loops)
        for (int v : loop) {
            const Eigen::Vector3d q = L.X.row(v).transpose() - c;
            lo = std::min(lo, q.dot(nf.long_axis));
            hi = std::max(hi, q.dot(nf.long_axis));
            wlo = std::min(wlo, q.dot(nf.short_axis));
            whi = std::max(whi, q.dot(nf.short_axis));
        }
    nf.length_mm = hi - lo;
    nf.width_mm = whi - wlo;
    return nf;
}

std::string plan_scene(const SimModel& m, const std::string& bundle_ref, const std::string& stem, const PlanOptions& o) {
    const NeckFrame nf = neck_frame(m);
    const SimSurface& s = m.surface;
    double t_max = 0;
    for (Eigen::Index v = 0; v < s.thickness.size(); ++v)
        if (std::isfinite(s.thickness[v])) t_max = std::max(t_max, s.thickness[v]);
    constexpr double JAW_W = 1.0, JAW_T = 0.5, CLEAR = 0.2;
    const Eigen::Vector3d n = nf.normal;
    // A clip whose blades turn about a fulcrum F behind their heel (PlanOptions::fulcrum_mm; ClipModel::fulcrum_mm):
    // everything below is measured from where the blades turn (the "hinge": the heel when F = 0, the fulcrum
    // otherwise), the arms between it and the heel count as blade (as the simulator takes them), and the heel stands
    // at least 1 mm before the neck. Its openings are the heel-hinged clip's scaled so that the open jaws are as wide
    // at the neck's far end at rest (the heel 1 mm before a neck of its length): tan(θ_F/2) = tan(θ/2)·(1 + len) /
    // (F + 1 + len); F = 0 gives θ.
    const double F = o.fulcrum_mm;
    if (o.tandem && o.curve_radius_mm > 0)
        throw InputError("--tandem: tandem clips are planned straight (a curved clip's neighbour would need its own bend); drop --curve-radius-mm");
    // A curved clip (PlanOptions::curve_radius_mm): a point's place along and across a blade bent by `bend` (+1 towards
    // +a, −1 away, 0 straight) from the heel, in the blade's frame (r along it from the hinge, a across it).
    const double CR = o.curve_radius_mm;
    if (!(CR == 0 || CR >= 2) || !std::isfinite(CR)) throw InputError("plan: --curve-radius-mm " + std::to_string(CR) + ", expected 0 (straight) or a radius >= 2 mm");
    std::array<fem::ClipBlades, 2> bends;  // bent towards +a, away (made once: `bent` runs for every vertex of every pose)
    for (int k = 0; k < 2; ++k) {
        bends[static_cast<size_t>(k)].curve_radius_mm = (k == 0 ? 1.0 : -1.0) * CR;
        bends[static_cast<size_t>(k)].curve_from_mm = F;
    }
    auto bent = [&](double bend, double r, double a) {
        if (bend == 0 || CR == 0) return std::pair<double, double>(r, a);
        const fem::ClipBlades::FaceCoords fc = bends[bend > 0 ? 0 : 1].face_coords(r, a);
        return std::pair<double, double>(fc.s, fc.a);
    };
    // The standard blades (3 … 15 mm) a curved clip can have: bent 90° at most (fem::ClipBlades::check_curve, asked
    // once per length, not per pose).
    std::array<bool, 16> fits{};
    for (int l = 3; l <= 15; l += 2) {
        fem::ClipBlades cb = bends[0];
        cb.length_mm = F + l;
        cb.width_mm = 1.0;
        try {
            cb.check_curve();
            fits[static_cast<size_t>(l)] = true;
        } catch (const InputError&) {
        }
    }
    auto blade_fits = [&](double l) { return CR == 0 || fits[static_cast<size_t>(l)]; };
    // How far along the axis a blade of length l reaches from the hinge (bent: its chord).
    auto reach_along = [&](double l) { return CR == 0 ? F + l : F + CR * std::sin(std::min(l / CR, 0.5 * PI)); };
    auto at_fulcrum = [&](double heel_deg) {
        if (F == 0) return heel_deg;  // exactly (the round trip through tan and atan is not)
        const double len = nf.length_mm;
        return 2.0 * std::atan(std::tan(0.5 * heel_deg * PI / 180.0) * (1.0 + len) / (F + 1.0 + len)) * 180.0 / PI;
    };
    // The border's edges (the smoothed neck line, which the occlusion is measured on): midpoint (from the centre)
    // and length. The jaws' width is placed to cover it, not the label loop's staircase around it.
    std::vector<std::pair<Eigen::Vector3d, double>> seg;
    double h_lo = 1e300, h_hi = -1e300;
    for (const auto& line : neck_border(s.lumen))
        for (size_t k = 0; k < line.size(); ++k) {
            const Eigen::Vector3d& a = line[k];
            const Eigen::Vector3d& b = line[(k + 1) % line.size()];
            seg.emplace_back(0.5 * (a + b) - nf.centre, (b - a).norm());
            h_lo = std::min(h_lo, seg.back().first.dot(n));
            h_hi = std::max(h_hi, seg.back().first.dot(n));
        }
    // The blades run along u (the neck's long axis turned by a yaw ψ about the normal), close across w, open to
    // `opening`. The hinge stands before the neck's near end (along u) so far that every neck point passes between
    // the open jaws with its wall and 0.5 mm to spare, at least 1 mm; `near` and `far` are the neck's ends along
    // the way in (from its centre, forwards positive).
    struct Way {
        Eigen::Vector3d u, w;
        double yaw, opening, heel_opening, side, margin, near, far;  // opening: at the hinge; heel_opening: the heel-hinged one it was scaled from
    };
    auto way_of = [&](double yaw, double heel_opening, double side) {
        const double opening = at_fulcrum(heel_opening);
        Way f;
        f.yaw = yaw;
        f.opening = opening;
        f.heel_opening = heel_opening;
        f.side = side;
        f.u = std::cos(yaw) * nf.long_axis + std::sin(yaw) * nf.short_axis;
        f.w = n.cross(f.u).normalized();
        const double tan_half = std::tan(0.5 * opening * PI / 180.0);
        f.near = 1e300;
        f.far = -1e300;
        for (const auto& loop : s.lumen.neck_loops)
            for (int v : loop) {
                const double a = side * (s.lumen.X.row(v).transpose() - nf.centre).dot(f.u);
                f.near = std::min(f.near, a);
                f.far = std::max(f.far, a);
            }
        f.margin = F + 1.0;
        for (const auto& loop : s.lumen.neck_loops)
            for (int v : loop) {
                const Eigen::Vector3d q = s.lumen.X.row(v).transpose() - nf.centre;
                f.margin = std::max(f.margin, (std::abs(q.dot(f.w)) + t_max + 0.5) / tan_half - (side * q.dot(f.u) - f.near));
            }
        return f;
    };
    // The domain's clamped ends (the bundle's "fixed" nodes: where the mesh was cut, held at zero). Jaws that close
    // on one press tissue that cannot give: on C0095 the planned jaws straddled the cut end of a branch beside the
    // neck, a blade met the clamped ring at 18° and the spring's balance held the clip open there with 13-27 kN on
    // it. The end is where the model stops, not where the vessel does: a pose with a clamped node in the space the
    // closing jaws sweep (between the open blades, along their length and width) or within about a wall's thickness
    // (EDGE_MM) of it is never taken (clamped_gripped), and a clamped node within CLEAR of the open blades on the
    // way in counts as a vertex in the way.
    constexpr double EDGE_MM = 0.5;
    std::vector<Eigen::Vector3d> clamped;
    {
        const double reach = nf.length_mm + 15.0 + o.approach_mm + 5.0;
        for (Eigen::Index k = 0; k < m.fixed_nodes.size(); ++k) {
            const Eigen::Vector3d x = m.nodes.row(m.fixed_nodes[k]).transpose();
            if ((x - nf.centre).norm() <= reach) clamped.push_back(x);
        }
    }
    // Outer-surface vertices within CLEAR of either open blade (boxes: length, width, thickness) with the hinge at
    // `hinge`, anywhere along the approach (the hinge every 0.25 mm back to approach_mm before it).
    auto approach_hits = [&](const Way& f, const Eigen::Vector3d& hinge, const Eigen::Vector3d& axis, double length, double bend_sac) {
        fem::ClipBlades bl;
        bl.axis = axis;
        bl.up = f.w;
        bl.length_mm = length;
        bl.width_mm = JAW_W;
        bl.thickness_mm = JAW_T;
        int hits = 0;
        for (int sb : {1, -1}) {
            Eigen::Vector3d t, nn, ww;
            bl.frame(sb, f.opening * PI / 180.0, t, nn, ww);
            const double dr = axis.dot(t), da = axis.dot(ww), dp = axis.dot(nn);
            // a bent blade's curve, towards the sac (bend_sac > 0) or away, in this frame's across (ww)
            Eigen::Vector3d sac_side = axis.cross(f.w);
            if (sac_side.dot(n) < 0) sac_side = -sac_side;
            const double bend = bend_sac * (ww.dot(sac_side) >= 0 ? 1.0 : -1.0);
            for (Eigen::Index v = 0; v < s.size() + static_cast<Eigen::Index>(clamped.size()); ++v) {
                // Along the approach the hinge is at hinge − b·axis: the vertex's coordinates in the blade's frame
                // shift by b·(axis·t, axis·ww, axis·nn). The clamped nodes after the surface's vertices.
                const Eigen::Vector3d rel0 = (v < s.size() ? Eigen::Vector3d(s.X.row(v).transpose()) : clamped[static_cast<size_t>(v - s.size())]) - hinge;
                const double r0 = rel0.dot(t), a0 = rel0.dot(ww), p0 = rel0.dot(nn);
                for (double b = 0; b <= o.approach_mm + 1e-9; b += 0.25) {
                    const double p = p0 + b * dp;
                    if (!(p < CLEAR && p > -JAW_T - CLEAR)) continue;
                    const auto [r, across] = bent(bend, r0 + b * dr, a0 + b * da);
                    if (r >= -CLEAR && r <= length + CLEAR && std::abs(across) <= 0.5 * JAW_W + CLEAR) {
                        ++hits;
                        break;
                    }
                }
            }
        }
        return hits;
    };
    // The parent's lumen the closing jaws would cut into: lumen vertices of the vessel (none of their faces the
    // sac's) more than PARENT_MM from the neck's border that lie between the open jaws, within their length, in the
    // half of their width band towards the sac — the band then reaches at least half a jaw width (0.5 mm) into the
    // parent's lumen. A tilted clip whose tips dive past the neck into the parent (C0043's first clear pose before
    // this check: tilted 27°) would occlude it; a band that grazes the top of a straight parent beyond a sidewall
    // neck (the tube's: 0.03-0.14 mm deep) pinches a sliver of its wall and is allowed, as is the neck's own vessel
    // side next to the border.
    constexpr double PARENT_MM = 1.0;
    std::vector<Eigen::Vector3d> parent;
    {
        const SimLumen& L = s.lumen;
        const auto it = std::find(s.region_names.begin(), s.region_names.end(), "aneurysm");
        const int sac = it == s.region_names.end() ? -1 : static_cast<int>(it - s.region_names.begin());
        std::vector<char> on_sac(static_cast<size_t>(L.X.rows()), 0);
        for (Eigen::Index f = 0; f < L.F.rows(); ++f)
            if (L.face_region[f] == sac)
                for (int k = 0; k < 3; ++k) on_sac[static_cast<size_t>(L.F(f, k))] = 1;
        std::vector<Eigen::Vector3d> near;
        for (const auto& line : neck_border(L)) near.insert(near.end(), line.begin(), line.end());
        for (const auto& loop : L.neck_loops)
            for (int v : loop) near.push_back(L.X.row(v).transpose());
        for (Eigen::Index v = 0; v < L.X.rows(); ++v) {
            if (on_sac[static_cast<size_t>(v)]) continue;
            const Eigen::Vector3d x = L.X.row(v).transpose();
            bool close = false;
            for (const Eigen::Vector3d& q : near)
                if ((x - q).squaredNorm() <= PARENT_MM * PARENT_MM) {
                    close = true;
                    break;
                }
            if (!close) parent.push_back(x);
        }
    }
    auto parent_pinched = [&](const Way& f, const Eigen::Vector3d& hinge, const Eigen::Vector3d& axis, double length, double bend_sac) {
        Eigen::Vector3d side = axis.cross(f.w).normalized();
        if (side.dot(n) < 0) side = -side;  // towards the sac
        const double tan_half = std::tan(0.5 * f.opening * PI / 180.0);
        const double h_from = o.parent_whole_band ? -0.5 * JAW_W : 0.0;  // the band's half towards the sac, or all of it
        int n_in = 0;
        for (const Eigen::Vector3d& x : parent) {
            const Eigen::Vector3d r = x - hinge;
            const double up = r.dot(axis);
            const auto [along, h] = bent(bend_sac, up, r.dot(side));
            if (up >= 0 && along <= length && h >= h_from && h <= 0.5 * JAW_W && std::abs(r.dot(f.w)) <= up * tan_half) ++n_in;
        }
        return n_in;
    };
    auto clamped_gripped = [&](const Way& f, const Eigen::Vector3d& hinge, const Eigen::Vector3d& axis, double length, double bend_sac) {
        if (clamped.empty()) return 0;
        const Eigen::Vector3d side = axis.cross(f.w).normalized();
        const double bend = bend_sac * (side.dot(n) >= 0 ? 1.0 : -1.0);
        const double tan_half = std::tan(0.5 * f.opening * PI / 180.0);
        int n_in = 0;
        for (const Eigen::Vector3d& x : clamped) {
            const Eigen::Vector3d r = x - hinge;
            const double up = r.dot(axis);
            const auto [along, across] = bent(bend, up, r.dot(side));
            if (up < -EDGE_MM || along > length + EDGE_MM || std::abs(across) > 0.5 * JAW_W + EDGE_MM) continue;
            if (std::abs(r.dot(f.w)) <= std::max(up, 0.0) * tan_half + JAW_T + EDGE_MM) ++n_in;
        }
        return n_in;
    };
    // Where the jaws go: their width spans the normal direction and their mid-plane should hold the neck line, so
    // that the blades pinch the line itself. A neck line is seldom flat (a saddle between the sac and the parent's
    // curve), the parent artery runs on under the hinge (a blade lying on the neck plane cuts into it there) and a
    // dome wider than the neck overhangs it. So the candidates are: the way in (the side to come from along the
    // long axis, turned by a yaw ψ of 0, ±15°, … ±75° or 90° — a round neck has no long axis worth keeping to, and
    // a wide one is spanned across its short axis —, open to 80 % of the clip's largest or to all of it), the
    // blades' tilt α about w (0–45°: the hinge raised, the tips down to the neck), the mid-plane's height c at the neck's
    // centre, and how much further back the hinge stands (the open jaws wider at the neck). Kept: the one whose open
    // blades touch no vessel along the approach and whose width covers the most neck line (in steps of 5 %); of
    // equals the smaller tilt, the hinge nearer, the smaller yaw and opening, the side with fewer vertices in the
    // way, the more covered, the higher c.
    struct Candidate {
        int way;
        double alpha, c, extra, covered;
        int order;
        double inside;  // how far inside the nearer edge of the jaws' width the line they cover comes at its closest
        double bend = 0;  // a curved clip's: +1 its blades bend towards the sac, −1 away from it
    };
    auto corridor = [&](const Way& f) {  // the simulated-surface vertices in the way of the approach
        const double back = f.margin - f.near;
        int count = 0;
        for (Eigen::Index v = 0; v < s.size(); ++v) {
            const Eigen::Vector3d q = s.X.row(v).transpose() - nf.centre;
            const double along = f.side * q.dot(f.u), across = std::abs(q.dot(f.w)), up = q.dot(n);
            if (along < -back && along > -(back + o.approach_mm) && across < 0.5 * nf.width_mm + 2.0 && std::abs(up) < 2.0) ++count;
        }
        return count;
    };
    std::vector<Way> ways;
    for (double opening : {0.8 * o.max_opening_deg, o.max_opening_deg})
        for (double yaw_deg : {0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0, 60.0, -60.0, 75.0, -75.0, 90.0}) {
            Way a = way_of(yaw_deg * PI / 180.0, opening, 1.0), b = way_of(yaw_deg * PI / 180.0, opening, -1.0);
            if (corridor(b) < corridor(a)) std::swap(a, b);
            ways.push_back(a);
            ways.push_back(b);
        }
    std::vector<Candidate> cands;
    for (size_t wi = 0; wi < ways.size(); ++wi)
        for (int ia = 0; ia <= 15; ++ia) {
            const double alpha = ia * 3.0 * PI / 180.0;
            const Way& f = ways[wi];
            const Eigen::Vector3d nprime = std::sin(alpha) * f.side * f.u + std::cos(alpha) * n;  // the tilted mid-plane's normal
            const Eigen::Vector3d axis_a = std::cos(alpha) * f.side * f.u - std::sin(alpha) * n;
            for (double c = h_lo - 0.5 * JAW_W; c <= h_hi + 0.5 * JAW_W + 3.0 + 1e-9; c += 0.05) {
                if (CR == 0) {
                    double in = 0, widest = 0;
                    for (const auto& [q, len] : seg)
                        if (const double h = std::abs((q - c * n).dot(nprime)); h <= 0.5 * JAW_W) {
                            in += len;
                            widest = std::max(widest, h);
                        }
                    for (double extra = 0; extra <= 6; extra += 1)
                        cands.push_back({static_cast<int>(wi), alpha, c, extra, in / nf.line_mm, static_cast<int>(cands.size()), 0.5 * JAW_W - widest});
                    continue;
                }
                // Bent blades: where the line lies across them depends on how far along them it is, so on how far back
                // the hinge stands (pose_of: back along u from the neck's centre, on the tilted mid-plane).
                for (double extra = 0; extra <= 6; extra += 1) {
                    const double back = f.margin + extra - f.near;
                    const Eigen::Vector3d hinge_rel = c * n - back * f.side * f.u + back * std::tan(alpha) * n;  // from the neck's centre
                    for (double bend : {1.0, -1.0}) {
                        double in = 0, widest = 0;
                        for (const auto& [q, len] : seg) {
                            const Eigen::Vector3d rel = q - hinge_rel;
                            const double h = std::abs(bent(bend, rel.dot(axis_a), rel.dot(nprime)).second);
                            if (h <= 0.5 * JAW_W) {
                                in += len;
                                widest = std::max(widest, h);
                            }
                        }
                        cands.push_back({static_cast<int>(wi), alpha, c, extra, in / nf.line_mm, static_cast<int>(cands.size()), 0.5 * JAW_W - widest, bend});
                    }
                }
            }
        }
    auto depth_step = [&](const Candidate& k) {
        return static_cast<int>(std::floor((ways[static_cast<size_t>(k.way)].margin + k.extra) / 0.5 + 1e-9));
    };
    std::stable_sort(cands.begin(), cands.end(), [&](const Candidate& a, const Candidate& b) {
        // Coverage in steps of 5 % first: a pose covering 1 % more is not worth a turn or a tilt.
        const int ba = static_cast<int>(std::floor(20 * a.covered + 1e-9)), bb = static_cast<int>(std::floor(20 * b.covered + 1e-9));
        if (ba != bb) return ba > bb;
        if (a.alpha != b.alpha) return a.alpha < b.alpha;
        // The neck deep in the jaws (the hinge near its near end, in 0.5 mm steps): a hinged clip closes least at
        // its tips, and a neck held nearer the hinge is both pressed harder by the same spring and left less gap.
        const int da = depth_step(a), db = depth_step(b);
        if (da != db) return da < db;
        if (a.extra != b.extra) return a.extra < b.extra;
        if (a.way != b.way) return a.way < b.way;  // smaller yaw and opening first, the freer side first
        if (std::abs(a.covered - b.covered) > 1e-9) return a.covered > b.covered;
        // The line as far inside both edges of the jaws' width as it can be (centred): the closing jaws squeeze what
        // lies at an edge out sideways. (Before: the highest such pose, the line at the jaws' lower edge, on the
        // parent's side: the sample's neck line, refreshed every frame, ended 36 of 62 points beside the jaws, 15.8 %
        // closed; with the jaws 0.2 mm lower 53.3 %; bench/results/study/compliance.md, session 39.)
        if (std::abs(a.inside - b.inside) > 1e-9) return a.inside > b.inside;
        return a.c > b.c;
    });
    // The clip for a candidate: its axis, hinge and the shortest standard blade (3 … 15 mm in 2 mm steps) whose
    // tip passes the far end of the neck as the closing jaws leave it. Flattened, a neck's border of length P lies
    // along the jaws as a slit P / 2 long about its centre (the sample's 5.2 mm neck, border 13.9 mm: 7 mm), and
    // its far fold is a wall thickness beyond that: the tip must reach max(far end, P / 4) + wall + 0.5 mm from
    // the centre. (0.5 mm past the far end at rest left the sample's fold round the tip of a 13 mm clip, an open
    // channel 0.18 mm wide.) If no standard blade reaches that, the longest that passes the far end at rest by
    // 0.5 mm, and the scene's header says the tips stop short.
    const double flat_half = 0.25 * nf.line_mm / std::max<size_t>(1, s.lumen.neck_loops.size());
    auto pose_of = [&](const Candidate& k, Eigen::Vector3d& axis, Eigen::Vector3d& hinge, double& blade, bool& short_out) {
        const Way& f = ways[static_cast<size_t>(k.way)];
        axis = std::cos(k.alpha) * f.side * f.u - std::sin(k.alpha) * n;
        const double back = f.margin + k.extra - f.near;  // along u, from the neck's centre to below the hinge
        hinge = nf.centre + k.c * n - back * f.side * f.u + back * std::tan(k.alpha) * n;
        blade = 0;
        short_out = false;
        // (A bent blade: its chord along the axis, and no longer than bends it 90°.)
        for (double l = 3; l <= 15; l += 2)
            if (blade_fits(l) && reach_along(l) * std::cos(k.alpha) >= back + std::max(f.far, flat_half) + t_max + 0.5) {
                blade = l;
                return true;
            }
        double longest = 15;
        while (longest > 3 && !blade_fits(longest)) longest -= 2;
        if (blade_fits(longest) && reach_along(longest) * std::cos(k.alpha) >= back + f.far + 0.5) {
            blade = longest;
            short_out = true;
        }
        return blade > 0;
    };
    // The first clear one; if none of the best-covering 60000 that a standard blade spans is clear, the one that
    // touches the fewest vertices. (6000 and yaws to ±30° left C0043's basilar sidewall with 9-26 vertices in the
    // way; its first clear pose is the 10^4th or so, tilted 27°: 12 s of planning.)
    const Candidate* chosen = nullptr;
    const Candidate* widest = nullptr;  // the best-covering pose a standard blade spans, clear or not
    int fewest = std::numeric_limits<int>::max(), checked = 0, widest_hits = 0, chosen_in_way = 0, chosen_pinched = 0;
    const Candidate* first_gripped = nullptr;  // the best-covering pose that closes on a clamped node
    int first_gripped_nodes = 0;
    Eigen::Vector3d axis, hinge;
    double blade = 0;
    bool short_tips = false;
    for (const Candidate& k : cands) {
        Eigen::Vector3d ax, hi;
        double l = 0;
        bool short_k = false;
        if (!pose_of(k, ax, hi, l, short_k)) continue;
        // A pose that closes on a clamped node is never taken, clear or not: its scene would press tissue that
        // cannot give (C0095: 13-27 kN on the blade, the clip held open).
        // (The arms between a fulcrum and the heel close as blade: the checks run from the hinge to the tips.)
        const int gripped = clamped_gripped(ways[static_cast<size_t>(k.way)], hi, ax, F + l, k.bend);
        if (gripped > 0) {
            if (!first_gripped) {
                first_gripped = &k;
                first_gripped_nodes = gripped;
            }
            if (++checked >= 60000) break;
            continue;
        }
        const int in_way = approach_hits(ways[static_cast<size_t>(k.way)], hi, ax, F + l, k.bend);
        const int pinched = parent_pinched(ways[static_cast<size_t>(k.way)], hi, ax, F + l, k.bend);
        const int h = in_way + pinched;
        if (!widest) {
            widest = &k;
            widest_hits = h;
        }
        if (h < fewest) {
            fewest = h;
            chosen = &k;
            axis = ax;
            hinge = hi;
            blade = l;
            short_tips = short_k;
            chosen_in_way = in_way;
            chosen_pinched = pinched;
        }
        if (h == 0 || ++checked >= 60000) break;
    }
    if (!chosen && first_gripped) {
        char why[768];
        std::snprintf(why, sizeof why,
                      "%s: every %s clip pose that spans the neck (%.2f x %.2f mm) closes on the domain's clamped ends: the best-covering one (%.0f %% of the "
                      "neck line) has %d clamped nodes (the bundle's 'fixed' set, where the vessels were cut) within %.1f mm of the space its jaws close on. "
                      "The model ends there and a clip would press tissue that cannot give; build the case with the vessels cut further from the neck, or plan it by hand (docs/scene_format.md)",
                      m.case_id.c_str(), CR > 0 ? "curved" : "straight", nf.length_mm, nf.width_mm, 100.0 * first_gripped->covered, first_gripped_nodes, EDGE_MM);
        throw InputError(why);
    }
    if (!chosen) {
        throw InputError(m.case_id + ": the neck is " + std::to_string(nf.length_mm) + " x " + std::to_string(nf.width_mm) +
                         " mm; the longest " + std::string(CR > 0 ? "curved" : "straight") + " clip planned (15 mm, open up to " + std::to_string(o.max_opening_deg) + " deg) does not span it");
    }
    // A pose whose jaws cover less than min_cover of the border is not across the neck (on a wide neck at a
    // bifurcation the only clear way may lie over the dome or the parents): refused, with what the best-covering
    // pose would touch, rather than a scene that clips beside the neck.
    if (chosen->covered < o.min_cover) {
        char best[200];
        if (fewest == 0)
            std::snprintf(best, sizeof best, "the clear poses cover at most %.0f %%", 100.0 * chosen->covered);
        else
            std::snprintf(best, sizeof best, "no pose is clear, the one with the fewest vertices in the way or between the jaws (%d) covers %.0f %%", fewest, 100.0 * chosen->covered);
        char why[1024];
        std::snprintf(why, sizeof why,
                      "%s: no %s clip of the set (3-15 mm, open up to %.0f deg) covers %.0f %% of the neck's border (%.1f mm; neck %.2f x %.2f mm) "
                      "without cutting into the vessel on the way in or between its closing jaws: %s; the best-covering pose (%.0f %%) has %d outer-surface vertices within %.1f mm "
                      "of its open blades or parent lumen vertices between its jaws. Plan this neck by hand (docs/scene_format.md) or lower --min-cover",
                      m.case_id.c_str(), CR > 0 ? "curved" : "straight", o.max_opening_deg, 100.0 * o.min_cover, nf.line_mm, nf.length_mm, nf.width_mm, best,
                      widest ? 100.0 * widest->covered : 0.0, widest_hits, CLEAR);
        throw InputError(why);
    }
    const Way& way = ways[static_cast<size_t>(chosen->way)];
    const Eigen::Vector3d w = way.w;
    const double opening = way.opening, yaw_deg = way.yaw * 180.0 / PI;
    const double lift = chosen->c, covered = chosen->covered, tilt_deg = chosen->alpha * 180.0 / PI;
    const Eigen::Vector3d start = hinge - o.approach_mm * axis;
    // The suction tube parked beside the neck, 3 mm clear of the vessel, pointing at it.
    Eigen::Vector3d park = nf.centre - (0.5 * nf.width_mm + 4.0) * w + 2.0 * n;
    for (int it = 0; it < 40; ++it) {
        double dmin = std::numeric_limits<double>::infinity();
        for (Eigen::Index v = 0; v < s.size(); ++v) dmin = std::min(dmin, (s.X.row(v).transpose() - park).norm());
        if (dmin >= 3.0) break;
        park -= 0.5 * w;
    }
    const double t_in = 0.8, t_close = 1.3, t_release = 1.5, t_out = 1.9;
    nlohmann::ordered_json j;
    j["bundle"] = bundle_ref;
    const std::string model = std::string(CR > 0 ? "curved_" : "straight_") + std::to_string(static_cast<int>(blade)) + "mm";
    j["clip_models"][model] = {
        {"jaw_length_mm", blade}, {"jaw_width_mm", JAW_W}, {"jaw_thickness_mm", JAW_T}, {"closed_gap_mm", 0.0}, {"max_opening_deg", at_fulcrum(o.max_opening_deg)},
        // The standard permanent clip's closing spring of configs/clips (placeholder figures: configs/clips/README.md).
        {"spring", {{"label_force_n", 1.5}, {"open_force_n", 2.5}, {"placeholder", true},
                    {"source", "configs/clips/README.md: placeholder within the 1-2.5 N of issue #15"}}}};
    if (F > 0) j["clip_models"][model]["fulcrum_mm"] = F;  // the pose below is the fulcrum's (docs/scene_format.md)
    // A curved clip bends towards axis × up when its radius is positive (the scene's up is w)
    const double curve = CR == 0 ? 0.0 : chosen->bend * CR * (axis.cross(w).dot(n) >= 0 ? 1.0 : -1.0);
    if (CR > 0) j["clip_models"][model]["jaw_curve_radius_mm"] = curve;
    j["outputs"] = {{"log", stem + "_log.csv"}, {"series", stem + "_series"}, {"report", stem + "_report.json"}};
    if (o.flow) j["outputs"]["flow"] = stem + "_flow.h5";
    nlohmann::ordered_json ap;
    ap["name"] = "applier";
    ap["kind"] = "clip_applier";
    ap["keyframes"] = nlohmann::ordered_json::array();
    ap["keyframes"].push_back({{"t", 0.0}, {"position", vec(start)}, {"axis", vec(axis)}, {"up", vec(w)}, {"opening_deg", opening}, {"load", model}});
    ap["keyframes"].push_back({{"t", t_in}, {"position", vec(hinge)}, {"opening_deg", opening}});
    ap["keyframes"].push_back({{"t", t_close}, {"position", vec(hinge)}, {"opening_deg", 0.0}});
    ap["keyframes"].push_back({{"t", t_release}, {"position", vec(hinge)}, {"opening_deg", 0.0}, {"release", true}});
    ap["keyframes"].push_back({{"t", t_out}, {"position", vec(start)}, {"opening_deg", 0.0}});
    nlohmann::ordered_json su;
    su["name"] = "suction";
    su["kind"] = "suction";
    su["radius_mm"] = 0.75;
    su["keyframes"] = nlohmann::ordered_json::array();
    su["keyframes"].push_back({{"t", 0.0}, {"position", vec(park)}, {"axis", vec(w)}, {"up", vec(n)}});
    su["keyframes"].push_back({{"t", t_out}, {"position", vec(park)}});
    // Tandem clips (PlanOptions::tandem): the second beside the first, across the blades (axis × up, the scene's
    // width direction), on the side where more of the neck line lies beside the first's jaws within the second's.
    std::string tandem_note;
    nlohmann::ordered_json ap2;
    if (o.tandem) {
        const Eigen::Vector3d acr = axis.cross(w).normalized();
        const double step = JAW_W + TANDEM_GAP_MM;
        double beside[2] = {0, 0};  // line length beside the first's jaws: [0] towards −acr, [1] towards +acr
        for (const auto& [q, len] : seg) {
            const Eigen::Vector3d rel = q + nf.centre - hinge;
            const double r = rel.dot(axis), h = rel.dot(acr);
            if (r < F || r > F + blade) continue;
            if (h > 0.5 * JAW_W && h <= step + 0.5 * JAW_W) beside[1] += len;
            if (h < -0.5 * JAW_W && h >= -step - 0.5 * JAW_W) beside[0] += len;
        }
        const double to_parent = acr.dot(n) < 0 ? 1.0 : -1.0;  // the sign of acr towards the parent
        const bool any = beside[0] + beside[1] > 0;
        const double preferred = !any ? to_parent : (beside[1] >= beside[0] ? 1.0 : -1.0);
        // The preferred side, or where the second clip would close there on the domain's clamped ends, the other.
        const Way& wy = ways[static_cast<size_t>(chosen->way)];
        double sign = preferred;
        int gripped2 = clamped_gripped(wy, hinge + sign * step * acr, axis, F + blade, 0.0), gripped_first = gripped2;
        if (gripped2 > 0) {
            sign = -preferred;
            gripped2 = clamped_gripped(wy, hinge + sign * step * acr, axis, F + blade, 0.0);
        }
        const Eigen::Vector3d off = sign * step * acr;
        auto towards = [&](double sg) { return sg == to_parent ? "parent" : "sac"; };
        char b[1200];
        if (gripped2 > 0) {
            std::snprintf(b, sizeof b,
                          "// Tandem clips asked for: a second clip %.1f mm across the blades would close on the domain's clamped nodes on either side\n"
                          "// (%d towards the %s, %d towards the %s); not planned (one clip).\n",
                          step, gripped_first, towards(preferred), gripped2, towards(-preferred));
            tandem_note = b;
        } else {
            const int in_way2 = approach_hits(wy, hinge + off, axis, F + blade, 0.0);
            const int pinched2 = parent_pinched(wy, hinge + off, axis, F + blade, 0.0);
            std::snprintf(b, sizeof b,
                          "// Tandem clips: a second applier (\"applier 2\", the same clip) beside the first, its path moved %.1f mm across the blades\n"
                          "// (%s axis x up: towards the %s), closing with it. Beside the first clip's jaws at rest lie %.2f mm of the neck line on that side\n"
                          "// (%.2f mm on the other)%s. Its path: %d outer-surface vertices within %.1f mm of its open blades along the approach,\n"
                          "// %d lumen vertices of the parent between its jaws (as for the first).\n",
                          step, sign > 0 ? "along" : "against", towards(sign), beside[sign > 0 ? 1 : 0], beside[sign > 0 ? 0 : 1],
                          sign != preferred ? ", not the other: there it would close on the domain's clamped ends"
                          : any ? "" : ": none, so towards the parent, where the closing jaws squeeze the line",
                          in_way2, CLEAR, pinched2);
            tandem_note = b;
            if (sign != preferred) {
                std::snprintf(b, sizeof b, "// (Towards the %s it would have closed on %d of the domain's clamped nodes.)\n", towards(preferred), gripped_first);
                tandem_note += b;
            }
            ap2 = ap;
            ap2["name"] = "applier 2";
            for (auto& k : ap2["keyframes"]) {
                const Eigen::Vector3d p(k["position"][0].get<double>(), k["position"][1].get<double>(), k["position"][2].get<double>());
                k["position"] = vec(p + off);
            }
        }
    }
    j["instruments"] = ap2.is_null() ? nlohmann::ordered_json::array({ap, su}) : nlohmann::ordered_json::array({ap, ap2, su});
    char head[1280];
    std::snprintf(head, sizeof head,
                  "// Planned by `aneusim plan` for %s: neck centre (%.2f, %.2f, %.2f) mm, %.2f x %.2f mm (border %.1f mm, label edges %.1f mm),\n"
                  "// normal towards the sac (%.3f, %.3f, %.3f). A %s %g mm clip comes in along the neck (turned and tilted as below), open %.0f deg,\n"
                  "// closes across the neck at t = %.1f s and is released. Its jaws (%.1f mm wide) lie %.2f mm above the neck's centre,\n"
                  "// turned %.0f deg from its long axis and tilted %.0f deg (the hinge up), where they cover %.0f %% of the neck line (its border);\n"
                  "// %d outer-surface vertices lie within %.1f mm of the open blades along the approach; %d lumen vertices of the parent\n"
                  "// (over %.0f mm from the neck) lie %s between them; no clamped node (the domain's cut ends) lies within\n"
                  "// %.1f mm of the space the jaws close on. The suction tube is parked 3 mm clear. Format: docs/scene_format.md.\n",
                  m.case_id.c_str(), nf.centre.x(), nf.centre.y(), nf.centre.z(), nf.length_mm, nf.width_mm, nf.line_mm, nf.label_line_mm, n.x(), n.y(), n.z(),
                  CR > 0 ? "curved" : "straight", blade, opening, t_close, JAW_W, lift, yaw_deg, tilt_deg, 100.0 * covered, chosen_in_way, CLEAR, chosen_pinched, PARENT_MM,
                  o.parent_whole_band ? "anywhere across the jaws' width" : "half the jaws' width or more", EDGE_MM);
    std::string header(head);
    if (CR > 0) {
        char cu[320];
        std::snprintf(cu, sizeof cu,
                      "// Its blades are curved: from the heel they bend on a circle of %g mm %s the sac (the model's jaw_curve_radius_mm, %g);\n"
                      "// the cover, the approach and the parent are measured along and across the bent blades.\n",
                      CR, chosen->bend > 0 ? "towards" : "away from", curve);
        header += cu;
    }
    if (F > 0) {
        char fu[320];
        std::snprintf(fu, sizeof fu,
                      "// Its blades turn about a fulcrum %g mm behind their heel (the model's fulcrum_mm): the applier's position is the fulcrum's,\n"
                      "// its opening the angle there (%.1f deg: the jaws as wide at the neck's far end as a clip hinged at its heel open %.0f deg).\n",
                      F, opening, way.heel_opening);
        header += fu;
    }
    // How much of the jaws' width the neck line fills, and how near an edge it comes: a saddle that fills the band is
    // squeezed out of it as the jaws close (the sample's 0.88 of 1.0 mm, then at the lower edge: 36 of the line's 62
    // points ended beside the jaws; bench/results/study/compliance.md, sessions 37 and 39).
    {
        const Eigen::Vector3d nprime = std::sin(chosen->alpha) * way.side * way.u + std::cos(chosen->alpha) * n;
        double lo = 1e300, hi = -1e300;
        for (const auto& [q, len] : seg) {
            const Eigen::Vector3d rel = q + nf.centre - hinge;
            const double h = CR == 0 ? (q - lift * n).dot(nprime) : bent(chosen->bend, rel.dot(axis), rel.dot(nprime)).second;
            if (std::abs(h) > 0.5 * JAW_W) continue;  // not between the jaws
            lo = std::min(lo, h);
            hi = std::max(hi, h);
        }
        if (hi >= lo) {
            char span[320];
            std::snprintf(span, sizeof span,
                          "// Across the jaws' width the neck line they cover spans %.2f mm of their %.1f mm, %.2f mm inside the nearer edge at its closest:\n"
                          "// a line that nearly fills the width is partly squeezed out of the jaws as they close.\n",
                          hi - lo, JAW_W, 0.5 * JAW_W - std::max(hi, -lo));
            header += span;
        }
    }
    header += tandem_note;
    if (short_tips)
        header += "// No standard blade reaches past the far fold of the neck flattened between the jaws: the 15 mm clip's tips stop short,\n"
                  "// expect the far end of the neck to stay open (a longer clip, or a second one, would close it).\n";
    return header + j.dump(2) + "\n";
}

}  // namespace aneu::sim
