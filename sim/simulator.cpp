// SPDX-License-Identifier: MIT
#include "aneu/core/common.hpp"
#include "aneu/sim/simulator.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <map>
#include <mutex>
#include <set>

#include "aneu/core/error.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/sim/assessment.hpp"

namespace aneu::sim {
namespace {


enum class NodeState : unsigned char { FREE, CONTACT, NEIGHBOUR, STUCK, RELAX, HELD };

// A contact area for the haptic force: one connected patch of nodes touched by one part.
struct Area {
    int part = 0;                       // instrument·2 + jaw (jaw 0/1; suction 0)
    std::vector<int> nodes;             // sorted
    Eigen::Vector3d n0, n1;             // plane normal at the last two physics frames (interpolated between)
    double o0 = 0, o1 = 0;              // plane offsets n·x = o
    double r0 = 0, r1 = 1;              // ramp (0 → 1 at first contact, 1 → 0 when gone)
    bool alive = true;
};

}  // namespace

std::array<Shape, 2> clip_jaws(const ClipModel& m, const Pose& p, double opening_deg) {
    const double half = 0.5 * std::clamp(opening_deg, 0.0, m.max_opening_deg) * DEG;
    const Eigen::Vector3d a = p.axis, b = p.up, c = a.cross(b);
    std::array<Shape, 2> jaws;
    for (int j = 0; j < 2; ++j) {
        const double s = j == 0 ? 1.0 : -1.0;
        const Eigen::Vector3d d = std::cos(half) * a + s * std::sin(half) * b;  // along the jaw
        const Eigen::Vector3d e = -s * std::sin(half) * a + std::cos(half) * b;  // jaw normal, +up side
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
            sh.half = Eigen::Vector3d(0.5 * m.jaw_length_mm, 0.5 * m.jaw_width_mm, 0.5 * m.jaw_thickness_mm);
            sh.centre = base + 0.5 * m.jaw_length_mm * d + s * 0.5 * m.jaw_thickness_mm * e;
        }
    }
    return jaws;
}

struct Simulator::Impl {
    Scene scene;
    SimModel model;
    ContactSolver solver;
    // Instruments.
    struct Instrument {
        Keyframe in;                    // current input
        Eigen::Vector3d prev_pos = Eigen::Vector3d::Zero();
        Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
        double prev_t = -1;
        int clip = -1;                  // index into clips
        bool over_force = false, over_speed = false;
        Eigen::Vector3d force = Eigen::Vector3d::Zero();
    };
    std::vector<Instrument> ins;
    std::vector<Clip> clips;
    std::vector<std::vector<int>> clip_nodes;       // deposited: held vertices
    std::vector<std::vector<Eigen::Vector3d>> clip_u;  // their relative displacement
    // Nodes.
    Eigen::Index S = 0;
    std::vector<NodeState> st;
    std::vector<int> owner;                         // part (CONTACT/NEIGHBOUR/STUCK) or clip (HELD)
    std::vector<Eigen::Vector3d> u, stick_u, stick_p;
    /// CONTACT nodes a clip jaw took from the space between the jaws: they are pushed back towards it (along the
    /// jaw's inner normal, as deep as they lag behind its inner face), never out through the jaw's back.
    std::vector<char> gap_side;
    Eigen::MatrixX3d d;                             // current displacement of every surface vertex
    std::vector<char> in_region;
    PointGrid grid;
    Eigen::MatrixX3d x_grid;  ///< the positions the grid holds (it keeps a pointer to them between frames)
    double cell = 0.5;
    double update_margin = 0;  ///< effective update margin [mm] (see Scene::update_margin_mm); 0 = whole region
    double t_phys = 0, dt_phys = 0;
    double t_region = -1;  ///< when the whole working region's deformation was last computed (-1: never)
    double t_cond = -1;    ///< when W_CC's condition was last estimated
    bool warned_condition = false;
    bool warned_linear = false;

    static std::string fmt_condition(double cond, int nodes, double eps) {
        char b[320];
        std::snprintf(b, sizeof b,
                      "W_CC is ill-conditioned: cond estimate %.3g with %d prescribed nodes, so the contact forces keep about %.0f "
                      "significant digits in this precision (crowded contact nodes; a float64 working precision keeps 9 more)",
                      cond, nodes, std::max(0.0, -std::log10(cond * eps)));
        return b;
    }
    std::vector<char> fresh;  ///< vertex's d is that of the last solve (updated by it); others lag, up to 1/region_hz
    std::vector<Area> areas;
    std::vector<Shape> obstacles;                   // the scene's obstacles as shapes, built once
    std::vector<Eigen::Vector3d> forces;
    Assessment a;
    std::vector<std::string> messages;
    SolveResult last;
    std::vector<int> last_vertices;                 // vertex of each prescribed entry of the last solve

    Impl(Scene s, SimModel m) : scene(std::move(s)), model(std::move(m)), solver(model) {
        S = model.surface.size();
        st.assign(static_cast<size_t>(S), NodeState::FREE);
        owner.assign(static_cast<size_t>(S), -1);
        u.assign(static_cast<size_t>(S), Eigen::Vector3d::Zero());
        stick_u = stick_p = u;
        gap_side.assign(static_cast<size_t>(S), 0);
        d.setZero(S, 3);
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

    void warn(const std::string& m) { messages.push_back(m); }

    // Shapes of the parts of instrument i (suction: its tube; applier: the held clip's jaws). Part ids i·2+j.
    std::vector<std::pair<int, Shape>> parts_of(size_t i) const {
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

    void set_input(int i, const Keyframe& k, double t) {
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

    void unstick(int i) {
        for (Eigen::Index v = 0; v < S; ++v)
            if (st[static_cast<size_t>(v)] == NodeState::STUCK && owner[static_cast<size_t>(v)] / 2 == i)
                st[static_cast<size_t>(v)] = NodeState::RELAX;
    }

    void release(int i, double t) {
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

    void grasp(int i, double t) {
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

    FrameStats physics_step(double t, std::mutex* mx) {
        std::unique_lock<std::mutex> lock;
        if (mx) lock = std::unique_lock<std::mutex>(*mx);
        FrameStats fs;
        fs.t = t;
        const Stopwatch t0;
        const double dt = t_phys > 0 || t > 0 ? std::max(t - t_phys, 0.0) : dt_phys;
        const double alpha = scene.displacement_fraction;
        const SimSurface& sf = model.surface;
        // Vertices coming within the update margin of an instrument whose d lags (not updated by the last solve)
        // get it now from the last solve's forces (a few rows of the SMVM): collisions and prescribed values then
        // see exactly the deformation a whole-region update would have given them.
        std::vector<std::vector<std::pair<int, Shape>>> parts(ins.size());  // this frame's instrument parts
        std::vector<Eigen::Vector3d> tips(ins.size());
        for (size_t i = 0; i < ins.size(); ++i) {
            parts[i] = parts_of(i);
            tips[i] = ins[i].in.pose.position;
        }
        // Collision detection runs on copies of what the haptic thread may change (node states through clip and
        // suction actions), without the lock: the haptic loop is not kept waiting for it. d, the grid and the
        // solver belong to this thread (d is written under the lock, for the output thread).
        const std::vector<NodeState> st_seen = st;
        const std::vector<int> owner_seen = owner;
        const std::vector<char> gap_seen = gap_side;
        // The held clips' jaws as blades, at this frame's opening and the last frame's.
        struct Jaws {
            bool on = false;
            fem::ClipBlades blades;
            double theta = 0, theta_prev = 0;
        };
        std::vector<Jaws> jaws(ins.size());
        for (size_t i = 0; i < ins.size(); ++i) {
            if (ins[i].clip < 0) continue;
            Clip& c = clips[static_cast<size_t>(ins[i].clip)];
            const ClipModel& cm = scene.clip_models.at(c.model);
            if (cm.jaw_mesh) continue;  // a jaw mesh keeps the shape push
            Jaws& J = jaws[i];
            J.on = true;
            J.blades.hinge = c.pose.position;
            J.blades.axis = c.pose.axis;
            J.blades.up = c.pose.up;
            J.blades.length_mm = cm.jaw_length_mm;
            J.blades.width_mm = cm.jaw_width_mm;
            J.blades.thickness_mm = cm.jaw_thickness_mm;
            J.blades.closed_gap_mm = cm.closed_gap_mm;
            J.theta = std::clamp(c.opening_deg, 0.0, cm.max_opening_deg) * DEG;
            J.theta_prev = c.collided_deg < 0 ? J.theta : c.collided_deg * DEG;
            c.collided_deg = J.theta / DEG;
        }
        if (mx) lock.unlock();
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
                if (mx) write = std::unique_lock<std::mutex>(*mx);
                for (int v : lagging) {
                    for (int ax = 0; ax < 3; ++ax) d(v, ax) = dr[sf.row(v, ax)];
                    fresh[static_cast<size_t>(v)] = 1;
                }
            }
        }
        x_grid = sf.X + d;
        const Eigen::MatrixX3d& x = x_grid;
        std::vector<char> candidate(static_cast<size_t>(S), 0);
        for (Eigen::Index v = 0; v < S; ++v)
            candidate[static_cast<size_t>(v)] = in_region[static_cast<size_t>(v)] && st_seen[static_cast<size_t>(v)] != NodeState::HELD;
        grid.build(x, cell, &candidate);
        // New contacts: depth per vertex and part.
        std::vector<double> depth(static_cast<size_t>(S), 0.0);
        std::vector<Eigen::Vector3d> push_dir(static_cast<size_t>(S), Eigen::Vector3d::Zero());
        std::vector<int> hit(static_cast<size_t>(S), -1);
        std::vector<char> kept(static_cast<size_t>(S), 0), from_gap(static_cast<size_t>(S), 0);
        for (size_t i = 0; i < ins.size(); ++i) {
            for (const auto& [part, shape] : parts[i]) {
                const Jaws& J = jaws[i];
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
                        const int sgn = part % 2 == 0 ? 1 : -1;
                        Eigen::Vector3d t, n, w;
                        J.blades.frame(sgn, J.theta, t, n, w);
                        const Eigen::Vector3d rel = p - J.blades.hinge;
                        const double r = rel.dot(t), dn = 0.5 * J.blades.closed_gap_mm + rel.dot(n);
                        if (r >= 0 && r <= J.blades.length_mm && std::abs(rel.dot(w)) <= 0.5 * J.blades.width_mm && dn < 0) {
                            Eigen::Vector3d tp, np, wp;
                            J.blades.frame(sgn, J.theta_prev, tp, np, wp);
                            const bool was_between = 0.5 * J.blades.closed_gap_mm + rel.dot(np) >= 0;
                            const bool pushed_back = gap_seen[s] && owner_seen[s] == part &&
                                                     (st_seen[s] == NodeState::CONTACT || st_seen[s] == NodeState::NEIGHBOUR);
                            if (was_between || pushed_back) {
                                if (-dn > depth[s]) {
                                    depth[s] = -dn;
                                    push_dir[s] = n;
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
        if (mx) lock.lock();
        // Update node states (an action of the haptic thread meanwhile wins: a held node stays held).
        const double decay = std::exp(-dt / scene.relax_time_s);
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
                gap_side[s] = gap_seen[s];
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
        fs.collision_s = t0.seconds();

        // Prescribed list (sorted by vertex) and groups of deposited clips.
        std::vector<Prescribed> p;
        last_vertices.clear();
        std::map<int, int> group_of_clip;
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
                                  t, q.u.norm(), sf.X(v, 0), sf.X(v, 1), sf.X(v, 2), ratio, th, scene.linear_limit);
                    warn(b);
                    warned_linear = true;
                }
            }
        }
        fs.prescribed_nodes = static_cast<int>(p.size());
        const std::vector<int> vertices = last_vertices;
        const GroupMethod method = scene.clip_method;
        if (mx) lock.unlock();  // the rows to update and the solve run while the haptic loop goes on
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
        SolveResult res = solver.solve(p, static_cast<int>(group_of_clip.size()), method, rows);
        // Conditioning of W_CC, at most twice a second when the set changed (O(n²)): crowded contact nodes make it
        // nearly singular, and the forces then keep fewer digits of the working precision.
        double cond = 0;
        if (res.refactored && (t_cond < 0 || t - t_cond >= 0.5)) {
            t_cond = t;
            cond = solver.condition_estimate();
        }
        if (mx) lock.lock();
        if (cond > 0) {
            a.max_condition_estimate = std::max(a.max_condition_estimate, cond);
            const double eps = model.is_float() ? 6e-8 : 1.1e-16;
            if (cond * eps > 1e-4 && !warned_condition) {
                warn(fmt_condition(cond, static_cast<int>(p.size()), eps));
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
            for (int ax = 0; ax < 3; ++ax) d(v, ax) = last.d[sf.row(v, ax)];
        }
        // Clips: shift of deposited ones, forces of all.
        for (Clip& c : clips) {
            c.net_force.setZero();
            c.grip_force_n = 0;
        }
        for (const auto& [cid, g] : group_of_clip) {
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
            if (hit[q] >= 0) touching[q] = hit[q];
            else if ((kept[q] && st[q] == NodeState::CONTACT) || st[q] == NodeState::STUCK) touching[q] = owner[q];
        }
        update_areas(touching, parts);
        t_phys = t;
        ++a.frames;
        return fs;
    }

    // Held clips with a spring: the applier can only hold the clip open. The opening at which the tissue's moment
    // about the hinge (Σ ½ r f·n over the jaws' contact nodes, f the force on the vessel, r along the jaw, n the
    // jaw's inner normal) balances the spring's torque is found over the physics frames by Newton steps on
    // R(θ) = τ(θ) − M(θ), with the tissue's stiffness −dM/dθ from the secant of the last two frames (at most 2° a
    // frame). The jaws then open to max(what the applier holds, that balance).
    void balance_springs() {
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
            fem::ClipBlades bl;
            bl.hinge = c.pose.position;
            bl.axis = c.pose.axis;
            bl.up = c.pose.up;
            Eigen::Vector3d t, n, w;
            bl.frame(owner[s] % 2 == 0 ? 1 : -1, c.opening_deg * DEG, t, n, w);
            const Eigen::Vector3d x = sf.X.row(static_cast<Eigen::Index>(s)).transpose() + d.row(static_cast<Eigen::Index>(s)).transpose();
            const Eigen::Vector3d f = last.f.segment<3>(3 * static_cast<Eigen::Index>(k));
            moment[static_cast<size_t>(cid)] += 0.5 * (x - bl.hinge).dot(t) * f.dot(n);
        }
        for (Clip& c : clips) {
            if (c.state != Clip::State::HELD || c.model.empty()) continue;
            const ClipModel& cm = scene.clip_models.at(c.model);
            if (!cm.spring) continue;
            const double theta = c.opening_deg * DEG, M = moment[static_cast<size_t>(c.id)];
            if (c.spring_torque_nmm != 0 && std::abs(theta - c.prev_theta) > 1e-4) {
                const double k = (M - c.tissue_moment_nmm) / (c.prev_theta - theta);
                c.tissue_k_nmm_per_rad = std::clamp(k, 0.0, 1e4);
            }
            c.prev_theta = theta;
            c.tissue_moment_nmm = M;
            c.spring_torque_nmm = cm.spring->torque(theta);
            const double R = c.spring_torque_nmm - M;
            double step = -R / (cm.spring->k_nmm_per_rad + c.tissue_k_nmm_per_rad);
            step = std::clamp(step, -2.0 * DEG, 2.0 * DEG);
            c.spring_deg = std::clamp((theta + step) / DEG, 0.0, cm.max_opening_deg);
            c.opening_deg = std::max(c.forceps_deg, c.spring_deg);
        }
    }

    // Contact areas per part: connected patches of nodes touching the part (penetrating, held within the
    // release tolerance, or stuck). An area continues the area of the same part that shares a node or lies
    // within 1.5 mm; an area that no node touches any more lives on while the part is still below its plane
    // (the node set of a sliding tool flickers, its plane must not), and fades out over one physics period
    // once the part is above it.
    void update_areas(const std::vector<int>& touching, const std::vector<std::vector<std::pair<int, Shape>>>& parts) {
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

    const std::vector<Eigen::Vector3d>& haptic_step(double t) {
        const double lam = std::clamp((t - t_phys) / dt_phys, 0.0, 1.0);
        for (auto& f : forces) f.setZero();
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

    Eigen::MatrixX3d deformed(bool region_only = false) {
        const SimSurface& sf = model.surface;
        const Eigen::Index M = model.dof_node.size();
        if (!region_only && model.n_active < M && !last_vertices.empty()) {
            const Eigen::VectorXd rest = solver.deformation(model.n_active, M);
            for (Eigen::Index v = 0; v < S; ++v) {
                if (in_region[static_cast<size_t>(v)]) continue;
                for (int ax = 0; ax < 3; ++ax) d(v, ax) = rest[sf.row(v, ax) - model.n_active];
            }
        }
        return sf.X + d;
    }

    Assessment assess() {
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
        const NeckOcclusion occ = neck_occlusion(lumen, lumen.deformed(x, model.surface.X), scene.neck_gap_mm, lumen.wall_mm);
        out.neck_closed_fraction = occ.fraction;
        out.neck_length_mm = occ.length_mm;
        out.neck_min_gap_mm = std::isfinite(occ.min_gap_mm) ? occ.min_gap_mm : -1.0;
        out.neck_interpenetration_mm = occ.max_interpenetration_mm;
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
        return out;
    }
};

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
Eigen::MatrixX3d Simulator::deformed_surface(bool region_only) { return m_impl->deformed(region_only); }
const std::vector<Clip>& Simulator::clips() const { return m_impl->clips; }
Assessment Simulator::assess() { return m_impl->assess(); }
std::vector<std::string> Simulator::take_messages() {
    std::vector<std::string> out;
    out.swap(m_impl->messages);
    return out;
}
void Simulator::count_skipped_input() { ++m_impl->a.skipped_inputs; }

}  // namespace aneu::sim
