// SPDX-License-Identifier: MIT
// Measures of a clipping's result: the neck occlusion (assessment.hpp).
#include "aneu/sim/assessment.hpp"
#include "simulator_impl.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <set>
#include <vector>

#include <Eigen/Geometry>

namespace aneu::sim {

NeckOcclusion neck_occlusion(const SimLumen& lumen, const Eigen::MatrixX3d& y, double gap_tol_mm, const Eigen::VectorXd& wall_mm) {
    NeckOcclusion out;
    if (lumen.neck_loops.empty()) return out;
    const Eigen::MatrixX3i& F = lumen.F;
    const Eigen::Index L = y.rows(), NF = F.rows();
    // Deformed normals (out of the lumen; area weighted at the vertices).
    Eigen::MatrixX3d fn(NF, 3), vn = Eigen::MatrixX3d::Zero(L, 3);
    std::vector<std::vector<int>> faces_of(static_cast<size_t>(L));
    for (Eigen::Index f = 0; f < NF; ++f) {
        const Eigen::Vector3d a = y.row(F(f, 0)), b = y.row(F(f, 1)), c = y.row(F(f, 2));
        const Eigen::Vector3d n = (b - a).cross(c - a);
        for (int k = 0; k < 3; ++k) {
            vn.row(F(f, k)) += n.transpose();
            faces_of[static_cast<size_t>(F(f, k))].push_back(static_cast<int>(f));
        }
        const double len = n.norm();
        fn.row(f) = len > 0 ? Eigen::RowVector3d((n / len).transpose()) : Eigen::RowVector3d::Zero();
    }
    for (Eigen::Index v = 0; v < L; ++v) {
        const double len = vn.row(v).norm();
        if (len > 0) vn.row(v) /= len;
    }
    constexpr double SEARCH_MM = 12.0;  // across the widest neck
    const double inf = std::numeric_limits<double>::infinity();
    // The gap at a neck vertex: along the ray from it across the lumen (against its normal), the nearest crossing
    // of an opposite face (facing it: normals more than 120° apart), in front (the gap) or behind (the walls pass
    // through each other, looked for no deeper than the vertex's own wall: beyond it lies another vessel or the
    // sac overhanging the parent, not an interpenetration). Its own faces and its one ring's are not "opposite".
    auto gap_at = [&](int v) {
        const double behind = v < wall_mm.size() ? wall_mm[v] : 0.0;
        const Eigen::Vector3d yv = y.row(v).transpose(), dir = -vn.row(v).transpose();
        std::set<int> own;
        for (int f : faces_of[static_cast<size_t>(v)])
            for (int k = 0; k < 3; ++k)
                for (int g : faces_of[static_cast<size_t>(F(f, k))]) own.insert(g);
        double gap = inf;
        for (Eigen::Index f = 0; f < NF; ++f) {
            if (fn.row(f).dot(dir) < 0.5 || own.count(static_cast<int>(f))) continue;
            const Eigen::Vector3d a = y.row(F(f, 0)), b = y.row(F(f, 1)), c = y.row(F(f, 2));
            if ((a - yv).norm() > SEARCH_MM + (b - a).norm() + (c - a).norm()) continue;  // cheap reject
            // Möller–Trumbore, both directions along the ray.
            const Eigen::Vector3d e1 = b - a, e2 = c - a, pv = dir.cross(e2);
            const double det = e1.dot(pv);
            if (std::abs(det) < 1e-14) continue;
            const Eigen::Vector3d tv = yv - a;
            const double u = tv.dot(pv) / det;
            if (u < 0 || u > 1) continue;
            const Eigen::Vector3d qv = tv.cross(e1);
            const double w = dir.dot(qv) / det;
            if (w < 0 || u + w > 1) continue;
            const double hit = e2.dot(qv) / det;
            if (hit <= SEARCH_MM && hit >= -behind && std::abs(hit) < std::abs(gap)) gap = hit;
        }
        return gap;
    };
    out.min_gap_mm = inf;
    for (const auto& loop : lumen.neck_loops) {
        std::vector<double> g(loop.size());
        for (size_t k = 0; k < loop.size(); ++k) {
            g[k] = gap_at(loop[k]);
            out.min_gap_mm = std::min(out.min_gap_mm, g[k]);
            if (g[k] < 0) out.max_interpenetration_mm = std::max(out.max_interpenetration_mm, -g[k]);
        }
        out.gap_mm.push_back(g);
        for (size_t k = 0; k < loop.size(); ++k) {
            const size_t l = (k + 1) % loop.size();
            const double len = (y.row(loop[l]) - y.row(loop[k])).norm();
            out.length_mm += len;
            if (g[k] <= gap_tol_mm && g[l] <= gap_tol_mm) out.closed_mm += len;
        }
    }
    out.fraction = out.length_mm > 0 ? out.closed_mm / out.length_mm : 0.0;
    return out;
}

Assessment Simulator::Impl::assess() {
    Assessment out = a;
    out.total_time_s = t_phys;
    out.clips_deposited = 0;
    for (const Clip& c : clips)
        if (c.state == Clip::State::DEPOSITED && !c.model.empty()) ++out.clips_deposited;
    out.clip_ends.clear();
    for (const Clip& c : clips) {
        if (c.model.empty()) continue;
        const ClipModel& cm = scene.clip_models.at(c.model);
        out.clip_ends.push_back({c.id, c.model, c.state == Clip::State::DEPOSITED, cm.spring.has_value(), cm.spring_placeholder, c.opening_deg,
                                 c.grip_force_n, c.spring_torque_nmm, c.tissue_moment_nmm});
    }
    const Eigen::MatrixX3d x = deformed();
    const SimLumen& lumen = model.surface.lumen;
    Eigen::MatrixX3d y = lumen.deformed(x, model.surface.X);
    // Inside a nonlinear patch the lumen's vertices are the patch's own nodes: their displacement (the wall's
    // compression under the clip included), plus the linear solve's part at the vertex they are bound to.
    for (const PatchRun& P : patches) {
        if (!P.alive) continue;
        for (Eigen::Index l = 0; l < y.rows(); ++l) {
            const int p = P.pm->local(lumen.node[l]);
            if (p < 0) continue;
            const Eigen::Index b = lumen.bind[l];
            y.row(l) = lumen.X.row(l) + P.v.segment<3>(3 * p).transpose() + (d.row(b) - d_patch.row(b));
        }
    }
    const NeckOcclusion occ = neck_occlusion(lumen, y, scene.neck_gap_mm, lumen.wall_mm);
    out.neck_closed_fraction = occ.fraction;
    out.neck_length_mm = occ.length_mm;
    out.neck_min_gap_mm = std::isfinite(occ.min_gap_mm) ? occ.min_gap_mm : -1.0;
    out.neck_interpenetration_mm = occ.max_interpenetration_mm;
    out.neck_line.clear();
    for (size_t l = 0; l < lumen.neck_loops.size(); ++l) {
        const auto& loop = lumen.neck_loops[l];
        for (size_t k = 0; k < loop.size(); ++k) out.neck_line.push_back({y.row(loop[k]).transpose(), occ.gap_mm[l][k], static_cast<int>(l)});
    }
    // Debugging: the deformed lumen as a Wavefront OBJ (neck vertices listed after it as comments).
    if (const char* obj = std::getenv("ANEU_LUMEN_OBJ")) {
        if (std::FILE* fo = std::fopen(obj, "w")) {
            for (Eigen::Index v = 0; v < y.rows(); ++v) std::fprintf(fo, "v %.6f %.6f %.6f\n", y(v, 0), y(v, 1), y(v, 2));
            for (Eigen::Index f = 0; f < lumen.F.rows(); ++f) std::fprintf(fo, "f %d %d %d\n", lumen.F(f, 0) + 1, lumen.F(f, 1) + 1, lumen.F(f, 2) + 1);
            for (size_t l = 0; l < lumen.neck_loops.size(); ++l)
                for (size_t k = 0; k < lumen.neck_loops[l].size(); ++k) std::fprintf(fo, "# neck %zu %d %.6g\n", l, lumen.neck_loops[l][k] + 1, occ.gap_mm[l][k]);
            std::fclose(fo);
        }
    }
    // The neck line lying between the jaws of a closed clip (where the clip is, not what it achieved).
    double total = 0, closed = 0;
    for (const auto& loop : model.surface.neck_loops) {
        for (size_t k = 0; k < loop.size(); ++k) {
            const Eigen::Vector3d p = x.row(loop[k]), q = x.row(loop[(k + 1) % loop.size()]);
            const double len = (q - p).norm();
            total += len;
            const Eigen::Vector3d mid = 0.5 * (p + q);
            for (const Clip& c : clips) {
                if (c.model.empty()) continue;
                const ClipModel& cm = scene.clip_models.at(c.model);
                if (c.opening_deg > 1.0) continue;  // not closed
                const Eigen::Vector3d r = mid - c.pose.position;
                const Eigen::Vector3d ax = c.pose.axis, up = c.pose.up, side = ax.cross(up);
                const double along = r.dot(ax), across = std::abs(r.dot(up)), wide = std::abs(r.dot(side));
                if (along >= 0 && along <= cm.jaw_length_mm && wide <= 0.5 * cm.jaw_width_mm + scene.neck_tolerance_mm &&
                    across <= 0.5 * cm.closed_gap_mm + scene.neck_tolerance_mm) {
                    closed += len;
                    break;
                }
            }
        }
    }
    out.neck_between_jaws_fraction = total > 0 ? closed / total : 0.0;
    out.patches.clear();
    for (const PatchRun& P : patches) {
        out.patches.push_back(P.stats);  // min_wall_distance_mm stays +inf when no opposite walls came within reach
    }
    return out;
}

}  // namespace aneu::sim
