// SPDX-License-Identifier: MIT
// The instruments' actions (load, release, grasp, suction), clip jaws and clip springs (simulator_impl.hpp).
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

std::array<Shape, 2> clip_jaws(const ClipModel& m, const Pose& p, double opening_deg) {
    fem::ClipBlades bl;  // the jaws' frame, shared with their contact rules and fem::ClipBody
    bl.axis = p.axis;
    bl.up = p.up;
    std::array<Shape, 2> jaws;
    for (int j = 0; j < 2; ++j) {
        const double s = j == 0 ? 1.0 : -1.0;
        Eigen::Vector3d d, n, c;  // along the jaw, its inner normal (towards the other jaw), across it
        bl.frame(j == 0 ? 1 : -1, std::clamp(opening_deg, 0.0, m.max_opening_deg) * DEG, d, n, c);
        const Eigen::Vector3d e = -s * n;  // the jaw normal on the +up side
        Shape& sh = jaws[static_cast<size_t>(j)];
        const Eigen::Vector3d base = p.position + s * 0.5 * m.closed_gap_mm * e;
        if (m.jaw_mesh) {
            sh.kind = Shape::Kind::MESH;
            sh.mesh = *m.jaw_mesh;
            for (Eigen::Index v = 0; v < sh.mesh.V.rows(); ++v) {
                const Eigen::Vector3d q = sh.mesh.V.row(v);
                sh.mesh.V.row(v) = (base + q.x() * d + q.y() * c + s * q.z() * e).transpose();
            }
            if (s < 0) sh.mesh.F.col(1).swap(sh.mesh.F.col(2));  // the mirror flips orientation
            sh.mesh.finish();
        } else {
            sh.kind = Shape::Kind::BOX;
            sh.axes.col(0) = d;
            sh.axes.col(1) = c;
            sh.axes.col(2) = s * e;
            sh.half = Eigen::Vector3d(0.5 * m.reach_mm(), 0.5 * m.jaw_width_mm, 0.5 * m.jaw_thickness_mm);
            sh.centre = base + 0.5 * m.reach_mm() * d + s * 0.5 * m.jaw_thickness_mm * e;
            sh.bend_radius = m.jaw_curve_radius_mm;  // a curved clip's jaw bends from the heel towards c (= axis × up)
            sh.bend_from = m.fulcrum_mm;
        }
    }
    return jaws;
}

std::vector<std::pair<int, Shape>> Simulator::Impl::parts_of(size_t i) const {
    std::vector<std::pair<int, Shape>> out;
    const auto& spec = scene.instruments[i];
    const Keyframe& k = ins[i].in;
    if (spec.kind == InstrumentSpec::Kind::SUCTION) {
        Shape sh;
        sh.kind = Shape::Kind::CAPSULE;
        sh.radius = spec.radius_mm;
        sh.a = k.pose.position - spec.radius_mm * k.pose.axis;  // the tube's rounded tip ends at `position`
        sh.b = k.pose.position - spec.length_mm * k.pose.axis;
        out.emplace_back(static_cast<int>(2 * i), sh);
    } else if (ins[i].clip >= 0) {
        const Clip& c = clips[static_cast<size_t>(ins[i].clip)];
        const auto jaws = clip_jaws(scene.clip_models.at(c.model), c.pose, c.opening_deg);
        out.emplace_back(static_cast<int>(2 * i), jaws[0]);
        out.emplace_back(static_cast<int>(2 * i + 1), jaws[1]);
    }
    return out;
}

void Simulator::Impl::set_input(int i, const Keyframe& k, double t) {
    Instrument& I = ins[static_cast<size_t>(i)];
    const auto& spec = scene.instruments[static_cast<size_t>(i)];
    if (I.prev_t >= 0 && t > I.prev_t) I.velocity = (k.pose.position - I.prev_pos) / (t - I.prev_t);
    I.prev_pos = k.pose.position;
    I.prev_t = t;
    const bool was_button = I.in.button;
    I.in = k;
    if (spec.kind == InstrumentSpec::Kind::SUCTION && was_button && !k.button) unstick(i);
    if (!k.load.empty()) {
        if (I.clip >= 0) {
            warn(spec.name + " at t=" + std::to_string(t) + ": load ignored, a clip is already held");
        } else {
            Clip c;
            c.id = static_cast<int>(clips.size());
            c.model = k.load;
            c.holder = i;
            clips.push_back(c);
            clip_nodes.emplace_back();
            clip_u.emplace_back();
            clip_track.emplace_back();
            I.clip = c.id;
            ++a.clips_used;
        }
    }
    if (k.grasp) grasp(i, t);
    if (I.clip >= 0) {
        Clip& c = clips[static_cast<size_t>(I.clip)];
        c.pose = k.pose;
        const ClipModel& cm = scene.clip_models.at(c.model);
        c.forceps_deg = std::min(k.opening_deg, cm.max_opening_deg);
        c.opening_deg = cm.spring ? std::max(c.forceps_deg, c.spring_deg) : c.forceps_deg;
    }
    if (k.release) release(i, t);
}

void Simulator::Impl::unstick(int i) {
    for (Eigen::Index v = 0; v < S; ++v)
        if (st[static_cast<size_t>(v)] == NodeState::STUCK && owner[static_cast<size_t>(v)] / 2 == i)
            st[static_cast<size_t>(v)] = NodeState::RELAX;
}

void Simulator::Impl::release(int i, double t) {
    Instrument& I = ins[static_cast<size_t>(i)];
    if (I.clip < 0) {
        warn(scene.instruments[static_cast<size_t>(i)].name + " at t=" + std::to_string(t) + ": release ignored, no clip held");
        return;
    }
    Clip& c = clips[static_cast<size_t>(I.clip)];
    auto& nodes = clip_nodes[static_cast<size_t>(c.id)];
    auto& rel = clip_u[static_cast<size_t>(c.id)];
    nodes.clear();
    rel.clear();
    const int patch = static_cast<size_t>(c.id) < patch_of_clip.size() ? patch_of_clip[static_cast<size_t>(c.id)] : -1;
    if (patch >= 0) {
        // A clip in a nonlinear patch stays where its blades grip the tissue (the patch solves it, its opening
        // stepped onto the balance of its spring and the tissue); one gripping nothing falls away, and its patch
        // goes with it.
        PatchRun& P = patches[static_cast<size_t>(patch)];
        I.clip = -1;
        c.holder = -1;
        c.state = Clip::State::DEPOSITED;
        for (Area& ar : areas)
            if (ar.part / 2 == i) ar.alive = false;
        // (A patch's further clip, tandem: its own blades' contacts.)
        int gripping = P.contacts;
        for (const PatchRun::Member& m : P.more)
            if (m.clip == c.id) gripping = m.contacts;
        if (gripping > 0) {
            c.release_pose = c.pose;
            c.shift.setZero();
            c.n_nodes = gripping;
            return;
        }
        warn("clip " + std::to_string(c.id) + " released at t=" + std::to_string(t) + " grips no vessel node: it falls away and is not deposited");
        c.n_nodes = 0;
        c.model.clear();
        leave_patch(c.id);  // (its patch goes with it, unless another clip of it stays)
        return;
    }
    for (Eigen::Index v = 0; v < S; ++v) {
        const size_t s = static_cast<size_t>(v);
        if ((st[s] == NodeState::CONTACT || st[s] == NodeState::NEIGHBOUR) && owner[s] / 2 == i) {
            nodes.push_back(static_cast<int>(v));
            rel.push_back(u[s]);
            st[s] = NodeState::HELD;
            owner[s] = c.id;
        }
    }
    if (nodes.empty()) {
        warn("clip " + std::to_string(c.id) + " released at t=" + std::to_string(t) +
             " holds no vessel node: it falls away and is not deposited");
        c.state = Clip::State::DEPOSITED;
        c.holder = -1;
        c.n_nodes = 0;
        I.clip = -1;
        c.model.clear();  // marks a lost clip
        return;
    }
    c.state = Clip::State::DEPOSITED;
    c.holder = -1;
    c.release_pose = c.pose;
    c.shift.setZero();
    c.n_nodes = static_cast<int>(nodes.size());
    I.clip = -1;
    // The areas of its jaws stop giving haptic force.
    for (Area& ar : areas)
        if (ar.part / 2 == i) ar.alive = false;
}

void Simulator::Impl::grasp(int i, double t) {
    Instrument& I = ins[static_cast<size_t>(i)];
    if (I.clip >= 0) {
        warn(scene.instruments[static_cast<size_t>(i)].name + " at t=" + std::to_string(t) + ": grasp ignored, a clip is already held");
        return;
    }
    int best = -1;
    double bd = 2.0;  // mm from the hinge
    for (const Clip& c : clips) {
        if (c.state != Clip::State::DEPOSITED || c.model.empty()) continue;
        const double dist = (c.pose.position - I.in.pose.position).norm();
        if (dist < bd) {
            bd = dist;
            best = c.id;
        }
    }
    if (best < 0) {
        warn(scene.instruments[static_cast<size_t>(i)].name + " at t=" + std::to_string(t) +
             ": grasp ignored, no deposited clip within 2 mm");
        return;
    }
    Clip& c = clips[static_cast<size_t>(best)];
    c.state = Clip::State::HELD;
    c.holder = i;
    I.clip = best;
    ++a.repositionings;
    // Its nodes become ordinary contacts of the applier's jaws (kept while the jaws touch them).
    for (size_t q = 0; q < clip_nodes[static_cast<size_t>(best)].size(); ++q) {
        const size_t s = static_cast<size_t>(clip_nodes[static_cast<size_t>(best)][q]);
        st[s] = NodeState::CONTACT;
        owner[s] = 2 * i;
        gap_side[s] = 1;  // they were squeezed between its jaws
        u[s] = d.row(static_cast<Eigen::Index>(s)).transpose();
    }
    clip_nodes[static_cast<size_t>(best)].clear();
    clip_u[static_cast<size_t>(best)].clear();
}

void Simulator::Impl::balance_springs() {
    const SimSurface& sf = model.surface;
    std::vector<double> moment(clips.size(), 0.0);
    for (size_t k = 0; k < last_vertices.size(); ++k) {
        const size_t s = static_cast<size_t>(last_vertices[k]);
        if (st[s] != NodeState::CONTACT && st[s] != NodeState::NEIGHBOUR) continue;
        const int i = owner[s] / 2;
        if (scene.instruments[static_cast<size_t>(i)].kind != InstrumentSpec::Kind::CLIP_APPLIER) continue;
        const int cid = ins[static_cast<size_t>(i)].clip;
        if (cid < 0) continue;
        const Clip& c = clips[static_cast<size_t>(cid)];
        const fem::ClipBlades bl = blades_of(c, scene.clip_models.at(c.model));
        Eigen::Vector3d t, n, w;
        bl.frame(owner[s] % 2 == 0 ? 1 : -1, c.opening_deg * DEG, t, n, w);
        const Eigen::Vector3d x = sf.X.row(static_cast<Eigen::Index>(s)).transpose() + d.row(static_cast<Eigen::Index>(s)).transpose();
        const Eigen::Vector3d f = last.f.segment<3>(3 * static_cast<Eigen::Index>(k));
        moment[static_cast<size_t>(cid)] += 0.5 * (x - bl.hinge).dot(t) * f.dot(n);
    }
    for (Clip& c : clips) {
        if (c.state != Clip::State::HELD || c.model.empty()) continue;
        if (static_cast<size_t>(c.id) < patch_of_clip.size() && patch_of_clip[static_cast<size_t>(c.id)] >= 0) continue;  // its patch balances it
        const ClipModel& cm = scene.clip_models.at(c.model);
        if (!cm.spring) continue;
        const double theta = c.opening_deg * DEG, M = moment[static_cast<size_t>(c.id)];
        ClipTrack& tr = clip_track[static_cast<size_t>(c.id)];
        if (c.spring_torque_nmm != 0 && std::abs(theta - tr.prev_theta) > 1e-4) {
            const double k = (M - c.tissue_moment_nmm) / (tr.prev_theta - theta);
            tr.tissue_k = std::clamp(k, 0.0, 1e4);
        }
        tr.prev_theta = theta;
        c.tissue_moment_nmm = M;
        c.label_force_n = M / cm.label_arm_mm();
        a.peak_clip_label_force_n = std::max(a.peak_clip_label_force_n, c.label_force_n);
        c.spring_torque_nmm = cm.spring->torque(theta);
        const double R = c.spring_torque_nmm - M;
        double step = -R / (cm.spring->k_nmm_per_rad + tr.tissue_k);
        step = std::clamp(step, -2.0 * DEG, 2.0 * DEG);
        c.spring_deg = std::clamp((theta + step) / DEG, 0.0, cm.max_opening_deg);
        c.opening_deg = std::max(c.forceps_deg, c.spring_deg);
    }
}

}  // namespace aneu::sim
