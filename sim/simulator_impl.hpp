// SPDX-License-Identifier: MIT
#pragma once
// The simulator's state and steps, private to aneu_sim, split by concept:
//   simulator.cpp    construction and the public interface;
//   sim_frame.cpp    the physics frame, a sequence of named steps: contacts → node states → prescribed
//                    displacements → solve → clips and contact areas;
//   sim_clips.cpp    the instruments' actions (load, release, grasp, suction), clip jaws and clip springs;
//   sim_haptics.cpp  contact areas and the contact-plane haptic force;
//   assessment.cpp   the assessment (neck occlusion, the neck between closed jaws, the clips at the end).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "aneu/core/common.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/compliance.hpp"
#include "aneu/fem/patch.hpp"
#include "aneu/sim/simulator.hpp"

namespace aneu::sim {

/// A clip's jaws as the blades of fem::ClipBody, at its pose (collision, spring balance, the nonlinear patch).
inline fem::ClipBlades blades_of(const Clip& c, const ClipModel& cm) { return cm.blades(c.pose); }

/// A compliance patch's linearisation made on its own thread (threaded mode): the state it was made at, the result
/// (null with `failed` set: refused, e.g. an element inverted there), its time, and whether it is done.
struct Refresh {
    double t = 0;  ///< the frame whose state it linearises [s]
    std::unique_ptr<fem::Linearisation> lin;
    std::string failed;
    double seconds = 0;
    double back = 1;  ///< made this much of the way to that state from the last linearisation's (an element inverted there)
    /// The candidates it keeps, selected again for the jaws as they were at that frame (fem::compliant_setup), the
    /// wall faces between them and the opening and hinge they were selected at.
    fem::CompliantSetup setup;
    double theta_sel = 0;
    Eigen::Vector3d hinge_sel = Eigen::Vector3d::Zero();
    std::vector<double> more_theta_sel;  ///< the same for a patch's further clips
    std::vector<Eigen::Vector3d> more_hinge_sel;
    std::atomic<bool> done{false};
};

struct Simulator::Impl {
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
    // A held clip's jaws as blades, at this frame's opening and the last frame's (collision detection).
    struct Jaws {
        bool on = false;
        int clip = -1;                  // the clip the instrument holds (taken under the lock)
        double max_opening_deg = 0;     // its model's
        fem::ClipBlades blades;
        double theta = 0, theta_prev = 0;
    };
    // What the steps of one physics frame share.
    struct Frame {
        Frame(double t_, std::mutex* m) : t(t_), mx(m) {
            if (mx) lock = std::unique_lock<std::mutex>(*mx);
            fs.t = t_;
        }
        double t;
        std::mutex* mx;
        std::unique_lock<std::mutex> lock;
        FrameStats fs;
        Stopwatch t0;
        double dt = 0;
        std::vector<std::vector<std::pair<int, Shape>>> parts;  // each instrument's parts (part ids i·2 + j)
        std::vector<Eigen::Vector3d> tips;
        std::vector<NodeState> st_seen;      // copies taken under the lock (begin_frame)
        std::vector<int> owner_seen;
        std::vector<char> gap_seen;
        std::vector<Jaws> jaws;
        std::vector<char> candidate;         // nodes the grid holds (in the region, not held by a clip)
        std::vector<double> depth;           // per node: penetration, push direction, part hit (−1: none)
        std::vector<Eigen::Vector3d> push_dir;
        std::vector<int> hit;
        std::vector<char> kept, from_gap;
        std::vector<Prescribed> p;           // prescribed displacements, deposited clips' groups
        std::map<int, int> group_of_clip;
        std::vector<int> vertices;
        GroupMethod method = GroupMethod::EXACT;
    };

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
    // Per clip, what the physics frames carry from one to the next (not part of the public Clip).
    struct ClipTrack {
        double collided_deg = -1;     // the opening its jaws had in the last collision detection (−1: none yet)
        double prev_theta = 0;        // the opening [rad] of the last spring balance (for the secant)
        double tissue_k = 0;          // the tissue's rotational stiffness from that secant [N·mm/rad]
    };
    std::vector<ClipTrack> clip_track;
    // The nonlinear patch under a clip (Scene::wall_model = PATCH; sim_patch.cpp).
    struct PatchRun {
        int clip = -1;
        /// Shared: a solve running without the lock (threaded mode) keeps its own reference, so a clip that falls away
        /// meanwhile (the haptic thread drops its patch) does not free the model under it.
        std::shared_ptr<fem::PatchModel> pm;
        int tets = 0;
        bool quadratic = false;               // 10-node elements: the contacts act on the quadratic surface
        Eigen::MatrixX3d X;                   // rest positions of the patch's nodes
        /// patch nodes the blades can touch: the simulated surface's vertices (cand_vertex: their vertex), then with
        /// 10-node elements the mid-edge nodes of its edges between them
        std::vector<int> cand, cand_vertex;
        Eigen::MatrixXi elements;             // the patch's elements (vol.tets' rows) in patch numbering
        /// The patch's nodes where its last solve holds them (X + v).
        Eigen::MatrixX3d positions() const {
            Eigen::MatrixX3d x = X;
            for (Eigen::Index a = 0; a < x.rows(); ++a) x.row(a) += v.segment<3>(3 * a).transpose();
            return x;
        }
        /// The patch's tissue overlapping itself where it is now (fem::nodes_inside_elements over the nodes off the
        /// interface): per patch node whether it lies more than TISSUE_ROUNDOFF_MM inside an element not its own, how
        /// many do, the deepest. Shared by the assessment and ANEU_WALL_TRACE (assessment.cpp).
        struct TissueOverlap {
            std::vector<char> inside;
            int nodes = 0;
            double deepest_mm = 0;
        };
        TissueOverlap tissue_overlap() const;
        Eigen::MatrixX3i inner;               // lumen triangles in the patch (patch nodes; 10-node elements: split at
                                              // their mid-edge nodes), normals into the lumen
        Eigen::MatrixX3i outer;               // the outer surface's triangles in the patch (as inner), normals outward
        std::vector<int> map_vertex;          // vertices whose displacement the patch maps (in-region, outside it)
        Eigen::VectorXd v;                    // patch DOFs, then the opening θ [rad]
        /// The Newton solves' analysis of the patch's tangent, kept from frame to frame while its pattern stays
        std::shared_ptr<fem::NewtonWorkspace> newton = fem::make_newton_workspace();
        /// The wall contact's and the blades' merged tangent patterns, kept from frame to frame while they hold
        /// every pair the frame needs (fem::PatternCache)
        std::shared_ptr<fem::PatternCache> wall_patterns = fem::make_pattern_cache(), clip_patterns = fem::make_pattern_cache();
        double kappa_wall = 0, kappa_blade = 0;
        /// Inner-wall vertices paired with every face near them (a frame's solve took them through a face their
        /// ordinary pairs left out): carried to the following frames (fem::CrossingFreeSolve::close_vertices).
        std::vector<int> close_vertices;
        Eigen::Vector3d hinge_prev = Eigen::Vector3d::Zero();  // the clip's hinge at the last solve
        double t_map = -1;                    // when the map vertices were last updated
        Eigen::Vector3d force = Eigen::Vector3d::Zero();  // the tissue's net force on the clip [N]
        int contacts = 0;                     // nodes pressing on the blades at the last solve
        std::vector<fem::BladeGrip> grips;    // where patch nodes grip the blades after the last solve (with friction)
        bool gripped = false;                 // grips holds the last solve's (false: none solved yet)
        /// The last converged frame's state (empty: none yet; the patch's start counts as one) and its grips. Two
        /// frames in a row that do not converge go back to it (solve_patches).
        Eigen::VectorXd v_ok;
        std::vector<fem::BladeGrip> grips_ok;
        bool gripped_ok = false;
        /// The course of the frames, carried as it is when the patch is remade.
        struct Course {
            double theta_bal = -1;            // a spring clip: the opening the frames approach (−1: not yet)
            double prev_theta = -1, prev_R = 0, tissue_k = 0;  // the last frame's θ and τ − M, the secant dR/dθ
            // What the last converged frame reported (a restart reports it again).
            fem::BladeLoads loads_ok;
            double wall_min_ok = std::numeric_limits<double>::infinity();
            int touching_ok = 0;
            // What the last frame reported (a compliance frame not taken reports it again).
            fem::BladeLoads loads_shown;
            double wall_min_shown = std::numeric_limits<double>::infinity();
            int touching_shown = 0;
            int failed_in_row = 0;            // frames in a row that did not converge
            double theta_failed = 0;          // the opening the first of them was asked for [rad]
            /// The most the opening may change in a frame [rad]: unbounded until a restart sets it to half the
            /// change that failed; doubled by every converged frame after that (unbounded again past 1 rad).
            double theta_step = std::numeric_limits<double>::infinity();
        } course;
        /// Further clips the patch solves with its first (PatchSpec::Solver::COMPLIANCE; tandem clips on one neck: a
        /// clip whose patch would share tissue with this one's joins it, and the patch is remade over every member's
        /// jaws). Each holds its own opening in the frames (fem::CompliantClip) and approaches its own spring's balance;
        /// the restart bookkeeping (course.failed_in_row, theta_step) is the frame's, shared.
        struct Member {
            int clip = -1;
            double theta = 0;                 // its opening where the last frame left it [rad]
            double theta_ok = 0;              // ... at the last converged frame
            Course course;                    // its balance: theta_bal, prev_theta, prev_R, tissue_k, loads_ok
            int contacts = 0;                 // nodes pressing on its blades at the last solve
        };
        std::vector<Member> more;
        /// Where the patch was grown (PatchSpec::grow): the rest positions of lumen vertices that met the opposite wall
        /// outside it; a remade patch keeps them (the tetrahedra with a corner within radius_mm of one are its too).
        std::vector<Eigen::Vector3d> grown;
        bool alive = true;                    // false once its clip fell away
        /// PatchSpec::Solver::COMPLIANCE: the linearisation the frames solve on and what they carry between frames
        /// (made at the first frame, again every refresh_frames frames and when the patch is remade).
        struct Compliant {
            /// (shared: a frame solved again for the linear range keeps the attempt it started from until a later one
            /// does better, PatchRun's range re-solves)
            std::shared_ptr<const fem::Linearisation> lin;
            Eigen::MatrixX3d Xc;              // its candidates' rest positions (patch nodes: Compliant::cand)
            std::vector<int> cand;            // the blades' candidates, then the wall faces' other corners
            Eigen::MatrixX3i faces;           // the inner walls near the jaws or about to meet, then the outer surface's
                                              // about to meet, in candidate numbering (search.params.face_surface: which)
            size_t approach_faces = 0;        // of them, those taken for walls about to meet away from the jaws
            fem::CompliantWallSearch search;
            fem::CompliantFrame last;         // the warm start
            bool warm = false;
            /// The next frame starts where the patch stands, not at the last solve's end (set where the patch went back:
            /// a frame not taken, a restart; the last solve's end is then a state the patch did not keep)
            bool from_state = false;
            /// The opening and hinge the candidates were selected at: the wedge the blades sweep closing from there
            /// (a refresh selects them again for the jaws as they are; opened past theta_sel, or the hinge moved,
            /// the frames are due for one).
            double theta_sel = 0;
            Eigen::Vector3d hinge_sel = Eigen::Vector3d::Zero();
            std::vector<int> clips;                      // the clips its rows are for, first to last (fem::compliant_row_kind)
            std::vector<double> more_theta_sel;          // the same for the further clips (PatchRun::more)
            std::vector<Eigen::Vector3d> more_hinge_sel;
            int since = 0;                    // frames on lin that pressed something (refresh_frames counts these)
            int borrowed = 0;                 // linearisations in a row that borrowed W (PatchSpec::compliance_reuse)
            double own_w_flops = 0, own_factor_flops = 0;  // the last linearisation that made its W: W's and the factorisation's work
            /// Linearisations still to project their element tangents from the start (sim_patch.cpp, PROJECTED_RUN),
            /// counted by note_projection from the linearisation just taken
            int project_next = 0;
            void note_projection(int run) { project_next = !lin->projected ? 0 : lin->projected_first ? project_next - 1 : run; }
            bool warned_lag = false;          // the frames' reach from their linearisation past Scene::linear_limit was warned
            /// Threaded mode: a refresh being made on another thread (the second core) while the frames go on with lin;
            /// the first frame after it is done takes it (null: none under way).
            std::shared_ptr<struct Refresh> pending;
        };
        std::shared_ptr<Compliant> compliant;
        Assessment::PatchEnd stats;
        double iterations_sum = 0, solve_ms_sum = 0;
    };
    std::vector<PatchRun> patches;
    std::atomic<bool> cancel_frames{false};  // Simulator::cancel_physics
    /// The refreshes' threads (threaded mode), joined once done (solve_patches) and at the end: a patch dropped while its
    /// refresh is under way leaves the thread to finish on the model it holds.
    std::vector<std::pair<std::shared_ptr<Refresh>, std::thread>> refresh_jobs;
    ~Impl() {
        for (auto& [q, th] : refresh_jobs)
            if (th.joinable()) th.join();
    }
    std::vector<int> patch_of_clip;           // per clip: index into patches, −1
    Eigen::MatrixX3d d_patch;                 // the patches' part of d (d = the linear solve's + this)
    std::vector<Eigen::Vector3d> patch_force; // per instrument: the net force of the tissue on its clip's blades [N]
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

    void warn(const std::string& m) { messages.push_back(m); }

    Impl(Scene s, SimModel m);

    // sim_clips.cpp
    // Shapes of the parts of instrument i (suction: its tube; applier: the held clip's jaws). Part ids i·2+j.
    std::vector<std::pair<int, Shape>> parts_of(size_t i) const;
    void set_input(int i, const Keyframe& k, double t);
    void unstick(int i);
    void release(int i, double t);
    void grasp(int i, double t);
    // Held clips with a spring: the applier can only hold the clip open. The opening at which the tissue's moment
    // about the hinge (Σ ½ r f·n over the jaws' contact nodes, f the force on the vessel, r along the jaw, n the
    // jaw's inner normal) balances the spring's torque is found over the physics frames by Newton steps on
    // R(θ) = τ(θ) − M(θ), with the tissue's stiffness −dM/dθ from the secant of the last two frames (at most 2° a
    // frame). The jaws then open to max(what the applier holds, that balance).
    void balance_springs();

    // sim_patch.cpp: the nonlinear patch (Scene::wall_model = PATCH). make_patches: a held clip whose jaws come
    // within trigger_mm of the wall gets its patch (remade, carrying the state, when the jaws leave it);
    // solve_patches: each patch's Newton solve with the clip's blades, spring and wall contact, then d.
    bool patch_holds_instrument(size_t i) const;
    void make_patches(Frame& fr);
    // (join: the patch the clip joins, −1: its own, made or remade; a compliance patch's new clip whose tissue another
    // patch holds joins that one)
    // (grow: rest positions the remade patch covers too, besides its jaws and the old patch's grown ones)
    void build_patch(size_t instrument, const Jaws& jaws, std::mutex* mx, const std::string& why = {}, int join = -1,
                     const std::vector<Eigen::Vector3d>& grow = {});
    // The lumen where it is now (one row a SimLumen vertex): a patch's own nodes where the patch holds them, the rest
    // at the displacement of the surface vertex each is bound to (the assessment's, and make_patches' growth check).
    Eigen::MatrixX3d lumen_now(const Eigen::MatrixX3d& x) const;
    // A clip of a patch gone (fallen away): a further clip leaves it, the first hands it to the next (none: dropped).
    void leave_patch(int clip);
    void solve_patches(Frame& fr);
    void set_patch_part(Eigen::Index v, const Eigen::Vector3d& value);
    void drop_patch(int index);  // its clip fell away: the wall returns to what the linear model gives

    // sim_frame.cpp: the physics frame (collision, solve, contact areas) and its steps, in order.
    FrameStats physics_step(double t, std::mutex* mx);
    void begin_frame(Frame& fr);
    void refresh_lagging_rows(Frame& fr);
    void detect_contacts(Frame& fr);
    void update_node_states(Frame& fr);
    void build_prescribed(Frame& fr);
    void solve_frame(Frame& fr);
    void update_clips_and_areas(Frame& fr);

    // sim_haptics.cpp
    // Contact areas per part: connected patches of nodes touching the part (penetrating, held within the
    // release tolerance, or stuck). An area continues the area of the same part that shares a node or lies
    // within 1.5 mm; an area that no node touches any more lives on while the part is still below its plane
    // (the node set of a sliding tool flickers, its plane must not), and fades out over one physics period
    // once the part is above it.
    void update_areas(const std::vector<int>& touching, const std::vector<std::vector<std::pair<int, Shape>>>& parts);
    const std::vector<Eigen::Vector3d>& haptic_step(double t);

    // simulator.cpp: the deformed surface (region rows of the last frame; the rest from its forces unless region_only)
    Eigen::MatrixX3d deformed(bool region_only = false);
    // assessment.cpp
    Assessment assess();
};

}  // namespace aneu::sim
