// SPDX-License-Identifier: MIT
// The physics frame (simulator_impl.hpp): contacts → node states → prescribed displacements → solve → clips.
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

// One physics frame as a sequence of named steps. Frame carries what they share; in threaded mode `mx` is held
// while the haptic thread's state is read or written, and let go for the collision detection and the solve.
FrameStats Simulator::Impl::physics_step(double t, std::mutex* mx) {
    Frame fr(t, mx);
    begin_frame(fr);
    refresh_lagging_rows(fr);
    make_patches(fr);
    detect_contacts(fr);
    update_node_states(fr);
    build_prescribed(fr);
    solve_frame(fr);
    solve_patches(fr);
    update_clips_and_areas(fr);
    return fr.fs;
}

// This frame's instrument parts and tips, and copies of what the haptic thread may change (node states, through
// clip and suction actions), taken under the lock; then the lock is let go: collision detection runs without it.
// d, the grid and the solver belong to this thread (d is written under the lock, for the output thread).
void Simulator::Impl::begin_frame(Frame& fr) {
    fr.dt = t_phys > 0 || fr.t > 0 ? std::max(fr.t - t_phys, 0.0) : dt_phys;
    auto& parts = fr.parts;  // this frame's instrument parts
    auto& tips = fr.tips;
    parts.resize(ins.size());
    tips.resize(ins.size());
    for (size_t i = 0; i < ins.size(); ++i) {
        parts[i] = parts_of(i);
        tips[i] = ins[i].in.pose.position;
    }
    if (scene.wall_model == WallModel::PATCH) patch_of_clip.resize(clips.size(), -1);  // (the haptic thread may add clips)
    fr.st_seen = st;
    fr.owner_seen = owner;
    fr.gap_seen = gap_side;
    // The held clips' jaws as blades, at this frame's opening and the last frame's.
    auto& jaws = fr.jaws;
    jaws.assign(ins.size(), {});
    for (size_t i = 0; i < ins.size(); ++i) {
        if (ins[i].clip < 0) continue;
        Clip& c = clips[static_cast<size_t>(ins[i].clip)];
        const ClipModel& cm = scene.clip_models.at(c.model);
        if (cm.jaw_mesh) continue;  // a jaw mesh keeps the shape push
        Jaws& J = jaws[i];
        J.on = true;
        J.clip = ins[i].clip;
        J.max_opening_deg = cm.max_opening_deg;
        J.blades = blades_of(c, cm);
        J.theta = std::clamp(c.opening_deg, 0.0, cm.max_opening_deg) * DEG;
        double& collided = clip_track[static_cast<size_t>(c.id)].collided_deg;
        J.theta_prev = collided < 0 ? J.theta : collided * DEG;
        collided = J.theta / DEG;
    }
    if (fr.mx) fr.lock.unlock();
}

void Simulator::Impl::refresh_lagging_rows(Frame& fr) {
    // Vertices coming within the update margin of an instrument whose d lags (not updated by the last solve)
    // get it now from the last solve's forces (a few rows of the SMVM): collisions and prescribed values then
    // see exactly the deformation a whole-region update would have given them.
    const SimSurface& sf = model.surface;
    const auto& parts = fr.parts;
    std::vector<int> cand;
    if (update_margin > 0 && !fresh.empty()) {
        std::vector<char> want(static_cast<size_t>(S), 0);
        for (size_t i = 0; i < ins.size(); ++i) {
            for (const auto& [part, shape] : parts[i]) {
                grid.query(shape.bounds().grown(update_margin), cand);  // last frame's grid
                for (int v : cand) want[static_cast<size_t>(v)] = !fresh[static_cast<size_t>(v)];
            }
        }
        std::vector<int> lagging;
        for (Eigen::Index v = 0; v < S; ++v)
            if (want[static_cast<size_t>(v)]) lagging.push_back(static_cast<int>(v));
        if (!lagging.empty()) {
            const RowRanges r = rows_of_vertices(model, lagging);
            const Eigen::VectorXd dr = solver.deformation(r);
            std::unique_lock<std::mutex> write;
            if (fr.mx) write = std::unique_lock<std::mutex>(*fr.mx);
            for (int v : lagging) {
                for (int ax = 0; ax < 3; ++ax) d(v, ax) = dr[sf.row(v, ax)] + d_patch(v, ax);
                fresh[static_cast<size_t>(v)] = 1;
            }
        }
    }
}

// New contacts: depth and push direction per node, against each instrument part.
void Simulator::Impl::detect_contacts(Frame& fr) {
    const SimSurface& sf = model.surface;
    const auto& parts = fr.parts;
    const auto& jaws = fr.jaws;
    const auto& st_seen = fr.st_seen;
    const auto& owner_seen = fr.owner_seen;
    const auto& gap_seen = fr.gap_seen;
    std::vector<int> cand;
    x_grid = sf.X + d;
    const Eigen::MatrixX3d& x = x_grid;
    auto& candidate = fr.candidate;
    candidate.assign(static_cast<size_t>(S), 0);
    for (Eigen::Index v = 0; v < S; ++v)
        candidate[static_cast<size_t>(v)] = in_region[static_cast<size_t>(v)] && st_seen[static_cast<size_t>(v)] != NodeState::HELD;
    grid.build(x, cell, &candidate);
    // New contacts: depth per vertex and part.
    auto& depth = fr.depth;
    auto& push_dir = fr.push_dir;
    auto& hit = fr.hit;
    auto& kept = fr.kept;
    auto& from_gap = fr.from_gap;
    depth.assign(static_cast<size_t>(S), 0.0);
    push_dir.assign(static_cast<size_t>(S), Eigen::Vector3d::Zero());
    hit.assign(static_cast<size_t>(S), -1);
    kept.assign(static_cast<size_t>(S), 0);
    from_gap.assign(static_cast<size_t>(S), 0);
    for (size_t i = 0; i < ins.size(); ++i) {
        if (patch_holds_instrument(i)) continue;  // its clip's jaws act in the patch's solve
        for (const auto& [part, shape] : parts[i]) {
            const Jaws& J = jaws[i];
            // This jaw's frame at this frame's opening (along, inner normal, across) and at the last frame's.
            Eigen::Vector3d jt, jn, jw, jt_prev, jn_prev, jw_prev;
            if (J.on) {
                const int sgn = part % 2 == 0 ? 1 : -1;
                J.blades.frame(sgn, J.theta, jt, jn, jw);
                J.blades.frame(sgn, J.theta_prev, jt_prev, jn_prev, jw_prev);
            }
            // A jaw also finds the gap-side nodes that lag behind its inner face by more than its thickness.
            grid.query(shape.bounds().grown(J.on ? scene.release_tolerance_mm + J.blades.thickness_mm + 0.5 : scene.release_tolerance_mm), cand);
            for (int v : cand) {
                const size_t s = static_cast<size_t>(v);
                const Eigen::Vector3d p = x.row(v);
                if (J.on) {
                    // Behind the jaw's inner face, within its length and width: a node that was between the jaws
                    // (last frame's opening) or that this jaw already pushes from there is pushed back along the
                    // inner normal. A jaw that closes faster than half its thickness per frame (the lag of a
                    // displacement fraction of ½) would otherwise carry the wall out through its back.
                    const Eigen::Vector3d rel = p - J.blades.hinge;
                    const fem::ClipBlades::FaceCoords fc = J.blades.face_coords(rel.dot(jt), rel.dot(jw));  // (a curved blade's)
                    const double dn = 0.5 * J.blades.closed_gap_mm + rel.dot(jn);
                    if (rel.dot(jt) >= J.blades.face_from_mm && fc.s <= J.blades.length_mm && std::abs(fc.a) <= 0.5 * J.blades.width_mm && dn < 0) {
                        const bool was_between = 0.5 * J.blades.closed_gap_mm + rel.dot(jn_prev) >= 0;
                        const bool pushed_back = gap_seen[s] && owner_seen[s] == part &&
                                                 (st_seen[s] == NodeState::CONTACT || st_seen[s] == NodeState::NEIGHBOUR);
                        if (was_between || pushed_back) {
                            if (-dn > depth[s]) {
                                depth[s] = -dn;
                                push_dir[s] = jn;
                                hit[s] = part;
                                from_gap[s] = 1;
                            }
                            continue;
                        }
                    }
                }
                const double sd = shape.sdf(p);
                if (sd < 0) {
                    const Eigen::Vector3d n = sf.N.row(v);
                    const bool jaw = scene.instruments[i].kind == InstrumentSpec::Kind::CLIP_APPLIER;
                    Eigen::Vector3d dir = -n;
                    double dep = 0;
                    if (jaw && scene.jaw_push == JawPush::SHAPE) {
                        // The shortest way out of the jaw (sdf gradient): across the jaw, as the jaw squeezes.
                        Eigen::Vector3d gr;
                        const double h = 1e-4;
                        for (int k = 0; k < 3; ++k)
                            gr[k] = shape.sdf(p + h * Eigen::Vector3d::Unit(k)) - shape.sdf(p - h * Eigen::Vector3d::Unit(k));
                        if (gr.norm() > 0) dir = gr.normalized();
                        dep = -sd;
                    } else {
                        dep = shape.exit_distance(p, -n);
                    }
                    if (dep > depth[s]) {
                        depth[s] = dep;
                        push_dir[s] = dir;
                        hit[s] = part;
                        from_gap[s] = 0;
                    }
                } else if (sd < scene.release_tolerance_mm && (st_seen[s] == NodeState::CONTACT || st_seen[s] == NodeState::STUCK) &&
                           owner_seen[s] == part) {
                    kept[s] = 1;
                }
            }
        }
    }
}

// Node states from the contacts (under the lock: an action of the haptic thread meanwhile wins).
void Simulator::Impl::update_node_states(Frame& fr) {
    const SimSurface& sf = model.surface;
    const double alpha = scene.displacement_fraction;
    const auto& tips = fr.tips;
    const auto& candidate = fr.candidate;
    const auto& depth = fr.depth;
    const auto& push_dir = fr.push_dir;
    const auto& hit = fr.hit;
    const auto& kept = fr.kept;
    const auto& from_gap = fr.from_gap;
    FrameStats& fs = fr.fs;
    if (fr.mx) fr.lock.lock();
    // Update node states (an action of the haptic thread meanwhile wins: a held node stays held).
    const double decay = std::exp(-fr.dt / scene.relax_time_s);
    for (Eigen::Index v = 0; v < S; ++v) {
        const size_t s = static_cast<size_t>(v);
        const Eigen::Vector3d dv = d.row(v);
        if (st[s] == NodeState::HELD) continue;
        if (st[s] == NodeState::STUCK) {
            const int i = owner[s] / 2;
            u[s] = stick_u[s] + (tips[static_cast<size_t>(i)] - stick_p[s]);
            if (hit[s] >= 0) ++fs.contact_nodes;
            continue;
        }
        gap_side[s] = 0;
        if (hit[s] >= 0) {
            const int i = hit[s] / 2;
            st[s] = NodeState::CONTACT;
            owner[s] = hit[s];
            gap_side[s] = from_gap[s];
            u[s] = dv + alpha * depth[s] * push_dir[s];
            ++fs.contact_nodes;
            const auto& spec = scene.instruments[static_cast<size_t>(i)];
            if (spec.kind == InstrumentSpec::Kind::SUCTION && ins[static_cast<size_t>(i)].in.button) {
                st[s] = NodeState::STUCK;
                stick_u[s] = u[s];
                stick_p[s] = tips[static_cast<size_t>(i)];
            }
        } else if (kept[s]) {
            gap_side[s] = fr.gap_seen[s];
            // stays in contact at its displacement; a suction tube with its button held holds it
            const int i = owner[s] / 2;
            if (scene.instruments[static_cast<size_t>(i)].kind == InstrumentSpec::Kind::SUCTION && ins[static_cast<size_t>(i)].in.button) {
                st[s] = NodeState::STUCK;
                stick_u[s] = u[s];
                stick_p[s] = tips[static_cast<size_t>(i)];
            }
        } else if (st[s] == NodeState::CONTACT || st[s] == NodeState::NEIGHBOUR) {
            st[s] = NodeState::RELAX;
            u[s] *= decay;
        } else if (st[s] == NodeState::RELAX) {
            u[s] *= decay;
            if (u[s].norm() < 1e-4) st[s] = NodeState::FREE;
        }
    }
    // Neighbours of penetrating nodes get a weaker push.
    if (scene.neighbour_weight > 0) {
        std::vector<Eigen::Vector3d> push(static_cast<size_t>(S), Eigen::Vector3d::Zero());
        std::vector<int> cnt(static_cast<size_t>(S), 0), who(static_cast<size_t>(S), -1);
        for (Eigen::Index v = 0; v < S; ++v) {
            if (hit[static_cast<size_t>(v)] < 0) continue;
            for (int k = sf.adj_offsets[static_cast<size_t>(v)]; k < sf.adj_offsets[static_cast<size_t>(v) + 1]; ++k) {
                const size_t w = static_cast<size_t>(sf.adj[static_cast<size_t>(k)]);
                if (hit[w] >= 0 || !candidate[w] || st[w] == NodeState::STUCK || kept[w]) continue;
                push[w] += scene.neighbour_weight * alpha * depth[static_cast<size_t>(v)] * push_dir[static_cast<size_t>(v)];
                ++cnt[w];
                who[w] = hit[static_cast<size_t>(v)];
            }
        }
        for (Eigen::Index w = 0; w < S; ++w) {
            const size_t s = static_cast<size_t>(w);
            if (!cnt[s]) continue;
            st[s] = NodeState::NEIGHBOUR;
            owner[s] = who[s];
            u[s] = d.row(w).transpose() + push[s] / cnt[s];
        }
    }
    fs.collision_s = fr.t0.seconds();
}

// The prescribed displacements (sorted by vertex), the deposited clips' groups and the linear-range check.
void Simulator::Impl::build_prescribed(Frame& fr) {
    // Prescribed list (sorted by vertex) and groups of deposited clips.
    const SimSurface& sf = model.surface;
    auto& p = fr.p;
    p.clear();
    last_vertices.clear();
    auto& group_of_clip = fr.group_of_clip;
    group_of_clip.clear();
    for (const Clip& c : clips)
        if (c.state == Clip::State::DEPOSITED && !clip_nodes[static_cast<size_t>(c.id)].empty()) {
            const int g = static_cast<int>(group_of_clip.size());
            group_of_clip[c.id] = g;
        }
    std::vector<int> held_index(static_cast<size_t>(S), -1);
    for (const auto& [cid, g] : group_of_clip)
        for (size_t q = 0; q < clip_nodes[static_cast<size_t>(cid)].size(); ++q)
            held_index[static_cast<size_t>(clip_nodes[static_cast<size_t>(cid)][q])] = static_cast<int>(q);
    for (Eigen::Index v = 0; v < S; ++v) {
        const size_t s = static_cast<size_t>(v);
        if (st[s] == NodeState::FREE) continue;
        Prescribed q;
        q.cols = sf.row.row(v).transpose();
        if (st[s] == NodeState::HELD) {
            q.group = group_of_clip.at(owner[s]);
            q.u = clip_u[static_cast<size_t>(owner[s])][static_cast<size_t>(held_index[s])];
        } else {
            q.u = u[s];
        }
        p.push_back(q);
        last_vertices.push_back(static_cast<int>(v));
        // The linear model's range: a prescribed displacement of a few tenths of the local wall thickness
        // already makes its forces too large (bench/results/study: clip closing, linear vs neo-Hookean).
        const double th = model.surface.thickness.size() ? model.surface.thickness[v] : std::nan("");
        if (std::isfinite(th) && th > 0) {
            const double ratio = q.u.norm() / th;
            if (ratio > a.max_displacement_to_thickness) {
                a.max_displacement_to_thickness = ratio;
                a.max_displacement_mm = q.u.norm();
                a.max_displacement_thickness_mm = th;
            }
            if (scene.linear_limit > 0 && ratio > scene.linear_limit && !warned_linear) {
                char b[400];
                std::snprintf(b, sizeof b,
                              "beyond the linear model's range at t=%.3f s: a prescribed displacement of %.3g mm at (%.2f, %.2f, %.2f) is "
                              "%.2g times the local wall thickness (%.3g mm); past %.2g times the linear model's forces there are "
                              "too large by more than 10 %% (contact.linear_limit)",
                              fr.t, q.u.norm(), sf.X(v, 0), sf.X(v, 1), sf.X(v, 2), ratio, th, scene.linear_limit);
                warn(b);
                warned_linear = true;
            }
        }
    }
    fr.fs.prescribed_nodes = static_cast<int>(p.size());
    fr.vertices = last_vertices;
    fr.method = scene.clip_method;
    if (fr.mx) fr.lock.unlock();  // the rows to update and the solve run while the haptic loop goes on
}

// Forces and deformation of the rows to update (without the lock), then the results (with it).
void Simulator::Impl::solve_frame(Frame& fr) {
    const SimSurface& sf = model.surface;
    const auto& parts = fr.parts;
    const auto& vertices = fr.vertices;
    const double t = fr.t;
    FrameStats& fs = fr.fs;
    std::vector<int> cand;
    // Rows to update: the whole region at region_hz, else the nodes near an instrument and the prescribed ones.
    std::vector<char> update(static_cast<size_t>(S), 0);
    RowRanges rows;
    const bool whole = update_margin <= 0 || t_region < 0 || t - t_region >= 1.0 / scene.region_hz - 1e-9;
    if (whole) {
        t_region = t;
        rows.emplace_back(0, model.n_active);
        for (Eigen::Index v = 0; v < S; ++v) update[static_cast<size_t>(v)] = in_region[static_cast<size_t>(v)];
    } else {
        for (size_t i = 0; i < ins.size(); ++i) {
            for (const auto& [part, shape] : parts[i]) {
                grid.query(shape.bounds().grown(update_margin), cand);
                for (int v : cand) update[static_cast<size_t>(v)] = 1;
            }
        }
        for (int v : vertices) update[static_cast<size_t>(v)] = in_region[static_cast<size_t>(v)];
        std::vector<int> uv;
        for (Eigen::Index v = 0; v < S; ++v)
            if (update[static_cast<size_t>(v)]) uv.push_back(static_cast<int>(v));
        rows = rows_of_vertices(model, uv);
    }
    fs.updated_rows = 0;
    for (const auto& [a0, b0] : rows) fs.updated_rows += static_cast<int>(b0 - a0);
    SolveResult res = solver.solve(fr.p, static_cast<int>(fr.group_of_clip.size()), fr.method, rows);
    // Conditioning of W_CC, at most twice a second when the set changed (O(n²)): crowded contact nodes make it
    // nearly singular, and the forces then keep fewer digits of the working precision.
    double cond = 0;
    if (res.refactored && (t_cond < 0 || t - t_cond >= 0.5)) {
        t_cond = t;
        cond = solver.condition_estimate();
    }
    if (fr.mx) fr.lock.lock();
    if (cond > 0) {
        a.max_condition_estimate = std::max(a.max_condition_estimate, cond);
        const double eps = model.is_float() ? 6e-8 : 1.1e-16;
        if (cond * eps > 1e-4 && !warned_condition) {
            warn(fmt_condition(cond, static_cast<int>(fr.p.size()), eps));
            warned_condition = true;
        }
    }
    last = std::move(res);
    last_vertices = vertices;
    fs.refactored = last.refactored;
    fs.factor_s = last.factor_s;
    fs.solve_s = last.solve_s;
    fs.smvm_s = last.smvm_s;
    // Deformation of the vertices updated this frame; the others now lag.
    fresh = update;
    for (Eigen::Index v = 0; v < S; ++v) {
        if (!update[static_cast<size_t>(v)]) continue;
        for (int ax = 0; ax < 3; ++ax) d(v, ax) = last.d[sf.row(v, ax)] + d_patch(v, ax);
    }
}

// Deposited clips move with the vessel; each clip's forces and spring; the haptic contact areas.
void Simulator::Impl::update_clips_and_areas(Frame& fr) {
    // Clips: shift of deposited ones, forces of all.
    for (Clip& c : clips) {
        if (static_cast<size_t>(c.id) < patch_of_clip.size() && patch_of_clip[static_cast<size_t>(c.id)] >= 0) continue;  // set by its patch
        c.net_force.setZero();
        c.grip_force_n = 0;
    }
    for (const auto& [cid, g] : fr.group_of_clip) {
        Clip& c = clips[static_cast<size_t>(cid)];
        c.shift = last.group_shift[static_cast<size_t>(g)];
        c.pose = c.release_pose;
        c.pose.position += c.shift;
    }
    double vessel = 0;
    for (size_t k = 0; k < last_vertices.size(); ++k) {
        const size_t s = static_cast<size_t>(last_vertices[k]);
        const Eigen::Vector3d f = last.f.segment<3>(3 * static_cast<Eigen::Index>(k));
        vessel += 0.5 * f.norm();
        int cid = -1;
        if (st[s] == NodeState::HELD) {
            cid = owner[s];
        } else if (st[s] == NodeState::CONTACT || st[s] == NodeState::NEIGHBOUR) {
            cid = ins[static_cast<size_t>(owner[s] / 2)].clip;
        }
        if (cid >= 0) {
            clips[static_cast<size_t>(cid)].net_force += f;
            clips[static_cast<size_t>(cid)].grip_force_n += 0.5 * f.norm();
        }
    }
    a.peak_vessel_force_n = std::max(a.peak_vessel_force_n, vessel);
    balance_springs();
    std::vector<int> touching(static_cast<size_t>(S), -1);
    for (size_t q = 0; q < static_cast<size_t>(S); ++q) {
        if (fr.hit[q] >= 0) touching[q] = fr.hit[q];
        else if ((fr.kept[q] && st[q] == NodeState::CONTACT) || st[q] == NodeState::STUCK) touching[q] = owner[q];
    }
    update_areas(touching, fr.parts);
    t_phys = fr.t;
    ++a.frames;
}

}  // namespace aneu::sim
