// SPDX-License-Identifier: MIT
// Construction and the public interface of the simulator (simulator_impl.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/sim/assessment.hpp"
#include "simulator_impl.hpp"

namespace aneu::sim {

Simulator::Impl::Impl(Scene s, SimModel m) : scene(std::move(s)), model(std::move(m)), solver(model) {
    S = model.surface.size();
    st.assign(static_cast<size_t>(S), NodeState::FREE);
    owner.assign(static_cast<size_t>(S), -1);
    u.assign(static_cast<size_t>(S), Eigen::Vector3d::Zero());
    stick_u = stick_p = u;
    gap_side.assign(static_cast<size_t>(S), 0);
    d.setZero(S, 3);
    d_patch.setZero(S, 3);
    if (scene.wall_model == WallModel::PATCH && (!model.volume || !model.fem)) {
        // The patch needs the mesh and K, which the real-time model does not otherwise read.
        BundleParts parts;
        parts.image = parts.surfaces = parts.condensed_W = parts.flow = false;
        Bundle b = read_bundle(scene.bundle, parts);
        if (!b.volume || !b.fem) throw InputError(scene.bundle + ": no /volume or /fem: the nonlinear patch (model.wall = \"patch\") needs the mesh and K");
        model.volume = std::make_shared<const VolumeData>(std::move(*b.volume));
        model.fem = std::make_shared<const FemData>(std::move(*b.fem));
    }
    in_region.assign(static_cast<size_t>(S), 0);
    for (Eigen::Index v = 0; v < S; ++v)
        in_region[static_cast<size_t>(v)] = model.surface.row.row(v).maxCoeff() < model.n_active;
    // Grid cell: the mean edge length.
    double sum = 0;
    for (Eigen::Index f = 0; f < model.surface.F.rows(); ++f)
        sum += (model.surface.X.row(model.surface.F(f, 0)) - model.surface.X.row(model.surface.F(f, 1))).norm();
    if (model.surface.F.rows()) cell = std::max(0.05, sum / static_cast<double>(model.surface.F.rows()));
    // Everything a frame reads of d must be current: nodes inside the parts (collision), their one-ring
    // (neighbour push) and the nodes within the approach margin (contact planes).
    if (scene.update_margin_mm > 0) update_margin = std::max(scene.update_margin_mm, std::max(2.0 * cell, scene.approach_margin_mm) + cell);
    for (const ObstacleSpec& ob : scene.obstacles) {
        Shape os;
        os.kind = Shape::Kind::MESH;
        os.mesh = ob.mesh;
        obstacles.push_back(std::move(os));
    }
    ins.resize(scene.instruments.size());
    forces.assign(ins.size(), Eigen::Vector3d::Zero());
    dt_phys = 1.0 / scene.physics_hz;
    for (size_t i = 0; i < ins.size(); ++i)
        if (!scene.instruments[i].keys.empty()) {
            ins[i].in = sample(scene.instruments[i], 0.0);
            ins[i].prev_pos = ins[i].in.pose.position;
        }
}

Eigen::MatrixX3d Simulator::Impl::deformed(bool region_only) {
    const SimSurface& sf = model.surface;
    const Eigen::Index M = model.dof_node.size();
    if (!region_only && model.n_active < M && !last_vertices.empty()) {
        const Eigen::VectorXd rest = solver.deformation(model.n_active, M);
        for (Eigen::Index v = 0; v < S; ++v) {
            if (in_region[static_cast<size_t>(v)]) continue;
            for (int ax = 0; ax < 3; ++ax) d(v, ax) = rest[sf.row(v, ax) - model.n_active] + d_patch(v, ax);
        }
    }
    return sf.X + d;
}


Simulator::Simulator(Scene scene, SimModel model) : m_impl(std::make_unique<Impl>(std::move(scene), std::move(model))) {}
Simulator::~Simulator() = default;
const Scene& Simulator::scene() const { return m_impl->scene; }
const SimModel& Simulator::model() const { return m_impl->model; }
int Simulator::instrument_index(const std::string& name) const {
    for (size_t i = 0; i < m_impl->scene.instruments.size(); ++i)
        if (m_impl->scene.instruments[i].name == name) return static_cast<int>(i);
    return -1;
}
void Simulator::set_input(int instrument, const Keyframe& k, double t) { m_impl->set_input(instrument, k, t); }
void Simulator::apply_script(double t_prev, double t) {
    const Scene& s = m_impl->scene;
    for (size_t i = 0; i < s.instruments.size(); ++i) {
        const auto& spec = s.instruments[i];
        if (spec.keys.empty()) continue;
        Keyframe k = sample(spec, t);
        // Actions of the keyframes passed since the last call (the first tick includes t = 0).
        for (const Keyframe& kf : spec.keys) {
            if (kf.t > t_prev && kf.t <= t) {
                if (!kf.load.empty()) k.load = kf.load;
                k.release = k.release || kf.release;
                k.grasp = k.grasp || kf.grasp;
                k.button = kf.button;
            }
        }
        m_impl->set_input(static_cast<int>(i), k, t);
    }
}
FrameStats Simulator::physics_step(double t, std::mutex* mx) { return m_impl->physics_step(t, mx); }
const std::vector<Eigen::Vector3d>& Simulator::haptic_step(double t) { return m_impl->haptic_step(t); }
void Simulator::set_solver_threads(int n) { m_impl->solver.set_threads(n); }
void Simulator::cancel_physics(bool on) { m_impl->cancel_frames = on; }
Eigen::MatrixX3d Simulator::deformed_surface(bool region_only) { return m_impl->deformed(region_only); }
const std::vector<Clip>& Simulator::clips() const { return m_impl->clips; }
std::vector<std::optional<Pose>> Simulator::instrument_poses() const {
    std::vector<std::optional<Pose>> out;
    for (const auto& I : m_impl->ins) out.push_back(I.prev_t >= 0 ? std::optional<Pose>(I.in.pose) : std::nullopt);
    return out;
}
Assessment Simulator::assess() { return m_impl->assess(); }
std::vector<std::string> Simulator::take_messages() {
    std::vector<std::string> out;
    out.swap(m_impl->messages);
    return out;
}
void Simulator::count_skipped_input() { ++m_impl->a.skipped_inputs; }

}  // namespace aneu::sim
