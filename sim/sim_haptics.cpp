// SPDX-License-Identifier: MIT
// Contact areas and the contact-plane haptic force (simulator_impl.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>

#include "aneu/core/error.hpp"
#include "aneu/sim/assessment.hpp"
#include "simulator_impl.hpp"

namespace aneu::sim {

void Simulator::Impl::update_areas(const std::vector<int>& touching, const std::vector<std::vector<std::pair<int, Shape>>>& parts) {
    const SimSurface& sf = model.surface;
    std::map<int, std::vector<int>> by_part;
    for (Eigen::Index v = 0; v < S; ++v)
        if (touching[static_cast<size_t>(v)] >= 0) by_part[touching[static_cast<size_t>(v)]].push_back(static_cast<int>(v));
    std::map<int, Shape> shapes;  // the parts as this frame's collision saw them
    for (const auto& pi : parts)
        for (const auto& [part, sh] : pi) shapes.emplace(part, sh);
    // A part that touches no node yet but is within the approach margin of the surface gets the plane of
    // its nearest node and that node's one-ring now, so that contact starts on the plane at the haptic
    // rate (the force grows from zero) instead of when a node is first found inside the part.
    const double margin = std::max(2.0 * cell, scene.approach_margin_mm);
    std::vector<int> cand;
    for (const auto& [part, sh] : shapes) {
        if (by_part.count(part)) continue;
        grid.query(sh.bounds().grown(margin), cand);
        int best = -1;
        double bd = margin;
        for (int v : cand) {
            const double sd = sh.sdf(sf.X.row(v).transpose() + d.row(v).transpose());
            if (sd < bd) {
                bd = sd;
                best = v;
            }
        }
        if (best < 0) continue;
        std::vector<int>& ring = by_part[part];
        ring.push_back(best);
        for (int k = sf.adj_offsets[static_cast<size_t>(best)]; k < sf.adj_offsets[static_cast<size_t>(best) + 1]; ++k)
            ring.push_back(sf.adj[static_cast<size_t>(k)]);
    }
    for (Area& ar : areas) {  // the interpolation restarts from where it ended
        ar.n0 = ar.n1;
        ar.o0 = ar.o1;
        ar.r0 = ar.r1;
    }
    auto centroid = [&](const std::vector<int>& nodes) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int v : nodes) c += sf.X.row(v).transpose();
        return nodes.empty() ? c : Eigen::Vector3d(c / static_cast<double>(nodes.size()));
    };
    std::vector<Area> next;
    std::vector<char> matched(areas.size(), 0);
    for (auto& [part, nodes] : by_part) {
        std::set<int> todo(nodes.begin(), nodes.end());
        std::vector<std::vector<int>> comps;
        while (!todo.empty()) {
            std::vector<int> comp{*todo.begin()};
            todo.erase(todo.begin());
            for (size_t q = 0; q < comp.size(); ++q) {
                const int v = comp[q];
                for (int k = sf.adj_offsets[static_cast<size_t>(v)]; k < sf.adj_offsets[static_cast<size_t>(v) + 1]; ++k) {
                    const auto it = todo.find(sf.adj[static_cast<size_t>(k)]);
                    if (it != todo.end()) {
                        comp.push_back(*it);
                        todo.erase(it);
                    }
                }
            }
            std::sort(comp.begin(), comp.end());
            comps.push_back(std::move(comp));
        }
        // Patches of one part closer than 1.5 mm are one contact area (node sets fragment under a jaw).
        std::vector<std::vector<int>> merged;
        std::vector<Eigen::Vector3d> centres;
        for (auto& cp : comps) {
            const Eigen::Vector3d cc = centroid(cp);
            size_t q = 0;
            while (q < merged.size() && (centres[q] - cc).norm() >= 1.5) ++q;
            if (q == merged.size()) {
                merged.push_back(cp);
                centres.push_back(cc);
            } else {
                merged[q].insert(merged[q].end(), cp.begin(), cp.end());
                std::sort(merged[q].begin(), merged[q].end());
                centres[q] = centroid(merged[q]);
            }
        }
        for (auto& comp : merged) {
            Eigen::Vector3d n = Eigen::Vector3d::Zero();
            for (int v : comp) n += sf.N.row(v).transpose();
            n.normalize();
            double o = -1e300;
            for (int v : comp) o = std::max(o, n.dot(sf.X.row(v).transpose()));
            const Eigen::Vector3d c = centroid(comp);
            int found = -1;
            double best = 1.5;
            for (size_t q = 0; q < areas.size(); ++q) {
                if (matched[q] || areas[q].part != part || !areas[q].alive) continue;
                std::vector<int> common;
                std::set_intersection(areas[q].nodes.begin(), areas[q].nodes.end(), comp.begin(), comp.end(),
                                      std::back_inserter(common));
                const double dist = common.empty() ? (centroid(areas[q].nodes) - c).norm() : 0.0;
                if (dist < best || (dist == 0.0 && found < 0)) {
                    best = dist;
                    found = static_cast<int>(q);
                }
            }
            Area ar;
            if (found >= 0) {
                matched[static_cast<size_t>(found)] = 1;
                ar = areas[static_cast<size_t>(found)];
            } else {
                ar.part = part;
                ar.n0 = n;
                ar.o0 = o;
                // Already below the new plane (a fast approach): ramp in over one period, else start on it.
                const auto sit = shapes.find(part);
                ar.r0 = sit != shapes.end() && o - n.dot(sit->second.support(n)) > 0 ? 0.0 : 1.0;
            }
            ar.nodes = comp;
            ar.n1 = n;
            ar.o1 = o;
            ar.r1 = 1;
            ar.alive = true;
            next.push_back(ar);
        }
    }
    for (size_t q = 0; q < areas.size(); ++q) {
        if (matched[q] || areas[q].r0 <= 0) continue;
        Area ar = areas[q];
        const auto it = shapes.find(ar.part);
        // Lives on only while its part touches nothing else (the flicker of a sliding tool), never piles up.
        const bool below = ar.alive && it != shapes.end() && !by_part.count(ar.part) &&
                           ar.o1 - ar.n1.dot(it->second.support(ar.n1)) > 0;
        if (!below) {
            ar.r1 = 0;
            ar.alive = false;
        }
        next.push_back(ar);
    }
    areas.swap(next);
}

const std::vector<Eigen::Vector3d>& Simulator::Impl::haptic_step(double t) {
    const double lam = std::clamp((t - t_phys) / dt_phys, 0.0, 1.0);
    for (auto& f : forces) f.setZero();
    // A clip in a nonlinear patch: the tissue's net force on its blades, from the last physics frame.
    for (size_t i = 0; i < ins.size() && i < patch_force.size(); ++i) forces[i] += patch_force[i];
    std::map<int, Shape> shapes;
    for (size_t i = 0; i < ins.size(); ++i)
        for (auto& [part, sh] : parts_of(i)) shapes.emplace(part, std::move(sh));
    for (const Area& ar : areas) {
        const auto it = shapes.find(ar.part);
        if (it == shapes.end()) continue;  // the part is gone (clip released)
        const double ramp = (1 - lam) * ar.r0 + lam * ar.r1;
        if (ramp <= 0) continue;
        Eigen::Vector3d n = (1 - lam) * ar.n0 + lam * ar.n1;
        if (n.norm() < 1e-12) continue;
        n.normalize();
        const double o = (1 - lam) * ar.o0 + lam * ar.o1;
        const double depth = o - n.dot(it->second.support(n));
        if (depth <= 0) continue;
        const size_t i = static_cast<size_t>(ar.part / 2);
        const Eigen::Vector3d v = ins[i].velocity;
        const Eigen::Vector3d vt = v - v.dot(n) * n;
        const double fade = std::min(1.0, depth / scene.friction_depth_mm);
        forces[i] += ramp * (scene.plane_stiffness_n_per_mm * depth * n - fade * scene.friction_n_s_per_mm * vt);
    }
    // Rigid obstacles push the instruments' tips and jaw corners out (exact distance: continuous).
    if (!obstacles.empty()) {
        for (size_t i = 0; i < ins.size(); ++i) {
            std::vector<Eigen::Vector3d> probes{ins[i].in.pose.position};
            for (const auto& [part, sh] : shapes)
                if (part / 2 == static_cast<int>(i) && sh.kind == Shape::Kind::BOX)
                    for (int s = 0; s < 8; ++s) {
                        Eigen::Vector3d q = sh.centre;
                        for (int k = 0; k < 3; ++k) q += ((s >> k) & 1 ? 1.0 : -1.0) * sh.half[k] * sh.axes.col(k);
                        probes.push_back(q);
                    }
            for (const Shape& os : obstacles) {
                double worst = 0;
                Eigen::Vector3d where = Eigen::Vector3d::Zero();
                for (const auto& q : probes) {
                    const double sd = os.sdf(q);
                    if (sd < worst) {
                        worst = sd;
                        where = q;
                    }
                }
                if (worst < 0) {
                    // Outward direction by the sdf gradient (central differences).
                    Eigen::Vector3d g;
                    const double h = 1e-3;
                    for (int k = 0; k < 3; ++k)
                        g[k] = os.sdf(where + h * Eigen::Vector3d::Unit(k)) - os.sdf(where - h * Eigen::Vector3d::Unit(k));
                    if (g.norm() > 0) forces[i] += scene.obstacle_stiffness_n_per_mm * (-worst) * g.normalized();
                }
            }
        }
    }
    // Assessment: rising edges of force and of speed in contact.
    for (size_t i = 0; i < ins.size(); ++i) {
        const double fn = forces[i].norm();
        a.peak_force_n = std::max(a.peak_force_n, fn);
        const bool over_f = fn > scene.force_threshold_n;
        if (over_f && !ins[i].over_force) ++a.force_exceedances;
        ins[i].over_force = over_f;
        bool touching = false;
        for (const Area& ar : areas)
            if (ar.part / 2 == static_cast<int>(i) && ar.alive) touching = true;
        const bool over_v = touching && ins[i].velocity.norm() > scene.velocity_threshold_mm_s;
        if (over_v && !ins[i].over_speed) ++a.velocity_exceedances;
        ins[i].over_speed = over_v;
        ins[i].force = forces[i];
    }
    ++a.haptic_ticks;
    return forces;
}

}  // namespace aneu::sim
