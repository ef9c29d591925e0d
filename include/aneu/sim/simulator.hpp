// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The clipping simulator: instrument and clip contacts → prescribed displacements → forces → deformation
/// (ContactSolver), deposited clips, suction, contact-plane haptic force, and the assessment.
#include <atomic>
#include <iosfwd>
#include <functional>
#include <optional>
#include <memory>
#include <mutex>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"
#include "aneu/sim/scene.hpp"
#include "aneu/sim/solver.hpp"

namespace aneu::sim {

/// A clip in the scene.
struct Clip {
    enum class State { HELD, DEPOSITED };
    int id = 0;
    std::string model;
    State state = State::HELD;
    int holder = -1;                ///< instrument holding it (HELD)
    Pose pose;                      ///< hinge frame now (deposited: at release, moved by `shift`)
    Pose release_pose;
    double opening_deg = 0.0;       ///< the jaws' opening now
    double forceps_deg = 0.0;       ///< what the applier holds (the jaws' opening unless the clip has a spring)
    /// Clips with a spring (ClipModel::spring), while held: the opening at which the tissue's moment balances the
    /// spring's torque, updated each physics frame; the jaws open to max(forceps_deg, spring_deg). A deposited
    /// clip keeps the opening it had when released.
    double spring_deg = 0.0;
    double spring_torque_nmm = 0.0;  ///< τ(opening) [N·mm]
    double tissue_moment_nmm = 0.0;  ///< Σ ½ r f·n of its contact forces about the hinge, last frame [N·mm]
    /// The clip's force as its label states it (ISO 9713): tissue_moment_nmm / ClipModel::label_arm_mm(), the force
    /// at the label point that the tissue's moment on a blade amounts to [N]. (The blade's total normal force,
    /// grip_force_n, is larger where the tissue presses nearer the fulcrum: F = τ / r along the blade.)
    double label_force_n = 0.0;
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();  ///< translation since release (moves with the vessel)
    Eigen::Vector3d net_force = Eigen::Vector3d::Zero();  ///< Σ contact forces on the vessel [N]
    double grip_force_n = 0.0;      ///< ½ Σ |f_i| over its nodes [N]
    double friction_n = 0.0;        ///< the blades' friction on the tissue, mean over the two [N] (a patch's clip)
    int n_nodes = 0;
};

/// The two jaws of a clip model at a pose and opening, as shapes (index 0: +up side, 1: −up side).
std::array<Shape, 2> clip_jaws(const ClipModel& m, const Pose& p, double opening_deg);

/// Figures of one physics frame.
struct FrameStats {
    double t = 0.0;
    int contact_nodes = 0;          ///< nodes penetrating an instrument or clip jaw
    int prescribed_nodes = 0;       ///< all nodes with a prescribed displacement (contacts, neighbours, held, relaxing)
    int updated_rows = 0;           ///< rows of the deformation computed this frame (near the instruments, or the region)
    bool refactored = false;
    double collision_s = 0.0, factor_s = 0.0, solve_s = 0.0, smvm_s = 0.0;
};

/// The assessment of a session.
struct Assessment {
    double total_time_s = 0.0;
    /// The scene time at which RunOptions::stop ended the run before the scene's end (−1: it ran to its end).
    double stopped_at_s = -1.0;
    int clips_used = 0;
    int clips_deposited = 0;        ///< clips left on the vessel at the end
    int repositionings = 0;         ///< deposited clips picked up again
    int force_exceedances = 0;      ///< rising edges of |haptic force| above the threshold (any instrument)
    int velocity_exceedances = 0;   ///< rising edges of instrument speed above the threshold while in contact
    double peak_force_n = 0.0;      ///< largest haptic force
    double max_condition_estimate = 0.0;  ///< largest cond₁(W_CC) estimated (twice a second when the set changed)
    /// Largest prescribed displacement / local wall thickness over the session (0: no thickness in the bundle),
    /// with that displacement and thickness [mm]: the linear model's validity (Scene::linear_limit).
    double max_displacement_to_thickness = 0.0, max_displacement_mm = 0.0, max_displacement_thickness_mm = 0.0;
    double peak_vessel_force_n = 0.0;  ///< largest ½ Σ|f| on the vessel over all frames
    /// The largest clip force at the label point over all frames and clips (Clip::label_force_n: the figure a clip
    /// model's closing-force range is stated for; clips whose moment is computed: held ones with a spring, and
    /// every clip in a nonlinear patch)
    double peak_clip_label_force_n = 0.0;
    /// Fraction of the neck line (by length on the lumen) whose opposite inner walls touch or lie within
    /// Scene::neck_gap_mm (neck_occlusion, assessment.hpp): the occlusion.
    double neck_closed_fraction = 0.0;
    double neck_length_mm = 0.0;
    double neck_min_gap_mm = 0.0;             ///< smallest lumen gap across the neck line (negative: walls pass through)
    double neck_interpenetration_mm = 0.0;    ///< deepest inner wall through the opposite one on the neck line
    /// The lumen through itself anywhere (lumen_crossing, assessment.hpp): the deepest lumen vertex behind a lumen face
    /// (0: none), how many vertices are through one, where the deepest is.
    double lumen_crossing_mm = 0.0;
    int lumen_crossing_vertices = 0;
    Eigen::Vector3d lumen_crossing_at = Eigen::Vector3d::Zero();
    /// Lumen vertices behind a lumen face where a patch holds the tissue, but in none of it: beside the wall or beyond
    /// it, not through it (not counted above); the deepest, how many.
    double lumen_beside_tissue_mm = 0.0;
    int lumen_beside_tissue_vertices = 0;
    /// Nodes of the patches (off their interfaces) lying in one of the patch's elements that is not their own, deeper
    /// than 1 µm: the tissue overlapping itself anywhere in a patch (0: nowhere; −1: no patch at the end); the deepest
    /// (fem::nodes_inside_elements' depth: to the holding element's faces on the boundary).
    int patch_nodes_in_other_tissue = -1;
    double patch_tissue_overlap_mm = 0.0;
    double neck_between_jaws_fraction = 0.0;  ///< fraction of the neck line (outer surface) lying between closed clip jaws
    /// Where the neck line ended up against the clips' jaws, held or deposited, at any opening: the fraction of it (by
    /// length on the deformed lumen, as neck_closed_fraction) lying within a clip's jaws (along their length, within
    /// their width), and the farthest beside their width that a point along their length lies (0: none beside). A neck
    /// line the closing jaws squeezed out sideways stays open beside them whatever the clip's force. NaN: no clip.
    double neck_in_jaws_fraction = std::numeric_limits<double>::quiet_NaN();
    double neck_beside_jaws_mm = std::numeric_limits<double>::quiet_NaN();
    /// The widest channel of the deformed lumen still joining the sac to the parent (neck_channel, assessment.hpp;
    /// at most 2 mm: wide open; NaN: no neck), and where it is narrowest. The sac is sealed where it is at most
    /// Scene::neck_gap_mm.
    double neck_channel_mm = std::numeric_limits<double>::quiet_NaN();
    Eigen::Vector3d neck_channel_at = Eigen::Vector3d::Zero();
    /// Fraction of the neck line (by length on the lumen, as neck_closed_fraction) cut off from the parent: its
    /// widest channel to the parent's lumen (NeckChannel::reach_mm) at most Scene::neck_gap_mm, because its walls
    /// touch there or because it lies on the sac's side of walls that touch. What stays open is the part of the neck
    /// the parent's blood still reaches (a neck remnant); where the clip sits a little above the border on the sac's
    /// side, the border there is cut off without its own walls touching. −1: not measured (no neck, or no parent).
    double neck_cut_off_fraction = -1.0;
    /// The parent artery under the clip (parent_channel, assessment.hpp): of its ends' pairs, the one narrowed most — the
    /// widest channel between them deformed and at rest [mm] and 1 − their ratio (0: as open as at rest; negative: wider,
    /// the wall pushed out beside the jaws; a clip set towards the parent narrows it), where it is narrowest. NaN: fewer
    /// than two ends of the parent found (the lumen ends within 6 mm of the neck line), or no neck.
    double parent_channel_mm = std::numeric_limits<double>::quiet_NaN();
    double parent_channel_rest_mm = std::numeric_limits<double>::quiet_NaN();
    double parent_narrowing = std::numeric_limits<double>::quiet_NaN();
    Eigen::Vector3d parent_channel_at = Eigen::Vector3d::Zero();
    /// The lumen's edge there at rest (its corner triangles': lumen_edges_mm, assessment.hpp): the resolution a fold's
    /// channel depends on (bench/bench_fold.cpp).
    double neck_channel_edge_mm = std::numeric_limits<double>::quiet_NaN();
    /// The neck measured on the quadratic surface of a 10-node patch (split_lumen, model.hpp), not the corner triangles.
    bool neck_on_quadratic_surface = false;
    /// The neck line on the deformed lumen, vertex by vertex: where it stays open after the clipping.
    struct NeckPoint {
        Eigen::Vector3d x = Eigen::Vector3d::Zero();
        double gap_mm = 0;  ///< the lumen gap there (+inf: no opposite wall within reach; < 0: walls through)
        int loop = 0;
    };
    std::vector<NeckPoint> neck_line;
    int skipped_inputs = 0;         ///< live lines refused
    /// Each clip at the end: its opening and, with a spring, the spring's torque against the tissue's moment.
    struct ClipEnd {
        int id = 0;
        std::string model;
        bool deposited = false, spring = false, placeholder = false;
        double opening_deg = 0, grip_force_n = 0, spring_torque_nmm = 0, tissue_moment_nmm = 0;
        double label_force_n = 0;  ///< Clip::label_force_n at the end
    };
    std::vector<ClipEnd> clip_ends;
    /// Each nonlinear patch (Scene::wall_model = PATCH) over the session.
    struct PatchEnd {
        int clip = 0;                        ///< the clip it was made for (its first; one that fell away handed it on)
        /// the further clips it solved with the first (tandem clips on the same tissue, compliance solver), in the
        /// order they joined (a clip that fell away stays listed)
        std::vector<int> more_clips;
        int nodes = 0, interface_nodes = 0, tets = 0;
        int builds = 0;                      ///< made, then remade when the jaws moved out of it
        double setup_s = 0;                  ///< the last build's factorisation and interface solves
        long frames = 0, unconverged_frames = 0;
        int max_iterations = 0;              ///< Newton iterations in one frame, at most
        double mean_iterations = 0;
        double mean_solve_ms = 0, max_solve_ms = 0;
        double peak_blade_force_n = 0;       ///< mean normal force on one blade, largest over the session
        double peak_label_force_n = 0;       ///< Clip::label_force_n, largest over the session
        double min_wall_distance_mm = 0;     ///< smallest signed distance between opposite inner walls (< 0: through;
                                             ///< +inf: none came within reach)
        int wall_pairs_touching = 0;         ///< at the end
        long wall_resolves = 0;              ///< frames solved again: a vertex went through a face its pairs left out
        /// Second unconverged frames in a row: the patch went back to the last converged frame's state and the
        /// opening's change a frame was halved (sim_patch.cpp)
        long restarts = 0;
        /// PatchSpec::Solver::COMPLIANCE: linearisations made (the first, refreshes, remade patches) and their time
        int linearisations = 0;
        double linearise_s = 0;
        int linearisations_failed = 0;       ///< refreshes refused (an element inverted at the state reached): the frames
                                             ///< went on with the last one
        /// Frames solved again on a linearisation made where they got to, having gone past Scene::linear_limit from
        /// theirs (inline mode; each is one of the linearisations)
        int range_refreshes = 0;
        /// PatchSpec::compliance_reuse: of the linearisations, those that borrowed the last one's W; frames on a
        /// borrowed W whose passes did not converge to the tangent's (solved again on a linearisation with its own W)
        int linearisations_borrowed = 0, borrow_fallbacks = 0;
        /// ... of those frames, the ones that ended with an earlier attempt than their last, the last having gone further
        /// from its linearisation (the re-solves diverging; halfway re-solves damp them)
        int range_earlier_kept = 0;
        /// Frames whose re-solves stopped early: an attempt went over 4 times as far from its linearisation as the
        /// frame's nearest attempt, or over 10 wall thicknesses (Newton's steps gone off; the nearest kept)
        int range_hopeless = 0;
        /// Frames still over 10 wall thicknesses from their linearisation after their re-solves: not taken (counted as
        /// not converged; the patch stays where the frame started)
        int range_absurd = 0;
        /// Compliance frames that ended with the walls over 0.1 mm through each other: not taken (counted as not
        /// converged, as range_absurd's)
        int walls_absurd = 0;
        /// Compliance frames that ended with the walls over PatchSpec::walls_reject_mm through each other and were taken
        /// shortened (PatchSpec::walls_shorten)
        int walls_shortened = 0;
        /// ... and of those past it only where they started (no pair further through than at the frame's start by more
        /// than the limit, nothing through a face deeper): taken whole (PatchSpec::walls_shorten)
        int walls_within_start = 0;
        /// Frames whose walls went past walls_reject_mm solved as Newton frames instead (PatchSpec::walls_newton), and
        /// those whose Newton solve did not converge (then shortened or not taken).
        int walls_newton_frames = 0, walls_newton_failed = 0;
        /// Of the Newton frames (range_newton's, walls_newton's), those taken at the residual they reached when their
        /// iterations ran out (at most 1e-2 of the force, the frame's whole opening reached: sim_patch.cpp, NEWTON_FRAME_LOOSE)
        int newton_frames_loose = 0;
        /// The most re-solves one frame took (at most PatchSpec::range_resolves)
        int max_frame_resolves = 0;
        /// Frames (or halves of them) still beyond the range after their re-solves, solved again in two halves of their
        /// opening's change; the most halvings one frame took (at most PatchSpec::range_splits)
        int range_splits = 0;
        int max_frame_splits = 0;
        /// Frames still beyond the range after all that, solved as Newton frames instead (PatchSpec::range_newton), and
        /// those whose Newton solve did not converge in its iterations (their compliance frame kept, and warned)
        int range_newton_frames = 0, range_newton_failed = 0;
        /// Threaded mode: refreshes made on another thread that the patch had left by more than the linear range by
        /// the time they were done (dropped; another begun from where the frames were)
        int refreshes_stale = 0;
        /// The candidates (nodes whose compliance a linearisation keeps) of the first linearisation and of the last:
        /// a refresh selects them again for the jaws as they are (the wedge they sweep closing from there)
        int first_candidates = 0, last_candidates = 0;
        /// Where along the blades the tissue pushes back, at the last frame: per millimetre of blade length from the
        /// hinge, the normal force on it, the two blades' mean [N] (compliance frames; empty: not measured)
        std::vector<double> blade_profile_n;
        /// The same across the blades' width, per 0.1 mm from 0.1 mm beyond one edge to 0.1 mm beyond the other,
        /// along w = axis × up (fem::ClipBlades::frame)
        std::vector<double> blade_profile_across_n;
        /// The compliance frames' reach from their linearisation: the largest displacement of the patch's surface from
        /// the state the frame's linearisation was made at, over the wall's thickness there (the linear model's
        /// measure, Scene::linear_limit: the frames are linear about that state, so past the limit their forces are
        /// too large as the linear model's are), where and when it was largest. 0: not measured (Newton frames).
        /// Relinearised every frame, it is one frame's step (corrected by the next frame's relinearisation).
        double max_lag_to_thickness = 0, max_lag_mm = 0, max_lag_thickness_mm = 0, max_lag_t = 0;
        Eigen::Vector3d max_lag_at = Eigen::Vector3d::Zero();
        /// The same at the last frame: where the frames left the patch (a patch relinearised every frame settles on its
        /// linearisation as the clip stops moving; one never relinearised carries its whole deformation).
        double end_lag_to_thickness = 0;
    };
    std::vector<PatchEnd> patches;
    long frames = 0, haptic_ticks = 0;
};

class Simulator {
public:
    Simulator(Scene scene, SimModel model);
    ~Simulator();
    Simulator(const Simulator&) = delete;
    Simulator& operator=(const Simulator&) = delete;

    const Scene& scene() const;
    const SimModel& model() const;
    int instrument_index(const std::string& name) const;  ///< −1 if unknown

    /// Sets an instrument's pose/opening/button at time t and runs its actions (load/release/grasp).
    /// Actions that cannot apply (release with no clip, grasp with no clip near) are logged and counted.
    void set_input(int instrument, const Keyframe& k, double t);
    /// Scripted inputs at time t: every instrument sampled, actions of keyframes in (t_prev, t] fired.
    void apply_script(double t_prev, double t);

    /// Collision detection, prescribed displacements, solve, contact areas (the physics rate).
    /// With `mx`, the state is changed under that lock and the solve runs without it, so a haptic thread
    /// that takes the same lock around set_input/haptic_step is never held up by a solve.
    FrameStats physics_step(double t, std::mutex* mx = nullptr);
    /// Threads of the deformation SMVM (default 2; used only when a product has at least 200,000 entries).
    /// The threaded runner (sim/run.cpp) sets hardware threads − 1, leaving a core to the haptic loop.
    void set_solver_threads(int n);
    /// Threaded mode's end: while set, a physics frame in progress stops its nonlinear patch's build or Newton solve
    /// at the next block or iteration and keeps none of it (the threaded runner sets it when the haptic loop ends, so
    /// that the run does not wait for a patch frame of seconds or minutes). Safe from any thread.
    void cancel_physics(bool on);
    /// Haptic force on each instrument at time t by the contact-plane method (cheap; the haptic rate).
    /// Also accumulates the force/velocity assessment.
    const std::vector<Eigen::Vector3d>& haptic_step(double t);

    /// Deformed positions of the simulated surface: region rows from the last physics step; the rest
    /// computed now from the same forces, or (region_only) as last computed — the solver belongs to the
    /// physics thread, so other threads ask for region_only.
    Eigen::MatrixX3d deformed_surface(bool region_only = false);
    const std::vector<Clip>& clips() const;
    /// Each instrument's pose as last set (scene order); none before its first input.
    std::vector<std::optional<Pose>> instrument_poses() const;
    /// Final assessment (neck closure evaluated now).
    Assessment assess();
    std::vector<std::string> take_messages();  ///< warnings since the last call (skipped actions, ...)
    void count_skipped_input();

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
};

/// Outputs of a run.
struct RunOptions {
    bool deterministic = true;      ///< single thread, fixed timeline; false: threads at wall-clock rates
    std::istream* live = nullptr;   ///< pose stream (scene.live_input)
    LiveReader::Source live_source; ///< instead of `live`: lines from a device server (aneusim serve)
    std::function<void(const std::string&)> on_message;  ///< warnings (skipped input, ignored actions)
    std::function<void(const FrameStats&)> on_frame;     ///< after each physics frame
    /// After each haptic tick: its time and the force per instrument (real-time: on the haptic thread, so it must
    /// not block).
    std::function<void(double t, const std::vector<Eigen::Vector3d>& F)> on_haptic;
    /// The deformed surface (all vertices), the clips and the instruments' poses at `surface_hz` (deterministic: at
    /// the ticks that cross each period; real-time: on the output thread).
    double surface_hz = 0.0;
    std::function<void(double t, const Eigen::MatrixX3d& x, const std::vector<Clip>& clips, const std::vector<std::optional<Pose>>& instruments)> on_surface;
    /// Set (by a signal handler: `aneusim run` on SIGINT/SIGTERM) to end the run at the next haptic tick: the
    /// outputs and the report are written for the time reached, the report saying so (`stopped_at_s`).
    const std::atomic<bool>* stop = nullptr;
};

/// Runs a scene to its end and writes the outputs the scene asks for (log, haptic log, series, report).
/// @return the assessment
Assessment run_scene(Simulator& sim, const RunOptions& opt);

/// Timing of a run: the haptic loop's ticks (threaded mode) and the output of each series frame.
struct HapticTiming {
    std::vector<double> tick_s;    ///< start of each haptic tick [s] (threaded mode)
    std::vector<double> step_s;    ///< duration of each tick's input + force computation [s]
    std::vector<double> output_s;  ///< writing one frame of the surface series (and the log line with it) [s]
};

/// The residual blood flow of a session (scene output "flow"): `aneuprep flow` on the series' last frame.
struct ResidualFlow {
    std::string file;                  ///< FLOW.h5
    double ratio = -1;                 ///< residual sac inflow / pre-clip sac inflow (-1: none)
    double sac_inflow_ml_s = 0, pre_clip_sac_inflow_ml_s = 0;
    double sac_volume_mm3 = 0;         ///< the sac's volume blood still reaches
    double ends_closed_off = 0;        ///< vessel ends no longer reachable from the inlet
    double seconds = 0;
    std::string error;                 ///< non-empty: aneuprep flow failed (its message went to the terminal)
    std::vector<std::string> pictures; ///< streamlines and wall shear stress (PNG, when a display was there)
    std::string pictures_note;         ///< why there are none, and the command that makes them
};

/// Runs `aneuprep flow BUNDLE --series SERIES.h5 -o FLOW` (the aneuprep beside this executable, else on PATH) after
/// a session and reads its figures back. Offline: minutes, never inside the real-time loop.
ResidualFlow residual_flow(const Scene& scene);

/// Writes the assessment as JSON and a readable summary (report path; the summary goes to path + ".txt").
/// `haptic` adds the output time per series frame and (threaded runs) the haptic loop's rate, period
/// percentiles and step times; `flow` the residual flow.
void write_report(const std::string& path, const Scene& scene, const SimModel& model, const Assessment& a,
                  const std::vector<FrameStats>& frames, const HapticTiming* haptic = nullptr, const ResidualFlow* flow = nullptr);

}  // namespace aneu::sim
