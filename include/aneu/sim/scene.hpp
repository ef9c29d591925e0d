// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A simulation scene (JSON file in configs/scenes/): the bundle, clip models, instruments with a scripted
/// trajectory or live input, rigid obstacles, the working region, contact/haptic parameters, assessment
/// thresholds and outputs. Format: docs/scene_format.md.
#include <functional>
#include <iosfwd>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "aneu/fem/clip.hpp"
#include "aneu/sim/model.hpp"
#include "aneu/sim/shapes.hpp"
#include "aneu/sim/solver.hpp"

namespace aneu::sim {

/// Instrument pose: position of the tip (suction) or clip hinge (applier), the instrument axis (towards
/// the tips) and the opening direction (the plane the jaws open in is spanned by axis and up).
struct Pose {
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
    Eigen::Vector3d up = Eigen::Vector3d::UnitX();
};

/// A clip model: two straight jaws (boxes) hinged at the clip's origin, or a jaw given as a triangle mesh
/// (in the jaw frame: x along the jaw from the hinge, y across its width, z away from the other jaw).
struct ClipModel {
    std::string name;
    double jaw_length_mm = 7.0;
    double jaw_width_mm = 1.0;
    double jaw_thickness_mm = 0.5;
    double closed_gap_mm = 0.0;     ///< gap between the jaws' inner faces when closed
    double max_opening_deg = 40.0;
    /// How far behind the blades' heel they turn [mm] (0: at the heel). A coil-spring clip's blades open and close
    /// about the base end of its coil as a fulcrum (US patent 5,634,932, background), behind the heel by the coil, the
    /// arms and the box, so its blades close more nearly parallel than a hinge at the heel would let them. The pose's
    /// position is the fulcrum; the clip's arms and box between it and the heel are drawn as blade (the jaws reach
    /// fulcrum_mm + jaw_length_mm from it: reach_mm()) but do not clamp tissue: the blades' faces begin at the heel
    /// (fem::ClipBlades::face_from_mm; arms_press below). The spring's label point lies 2/3 of the blade from the
    /// heel's side, fulcrum_mm + 2/3 jaw_length_mm from the fulcrum. A box jaw only (not with jaw_mesh).
    double fulcrum_mm = 0.0;
    /// Whether the arms between the fulcrum and the heel clamp tissue as the blades' faces do (sessions 42-60's model:
    /// the faces from the fulcrum). A real clip's box and crossed arms there do not close on tissue; the sample's
    /// planned clip put 45 % of its force there (bench/results/study/compliance.md, "Session 61"). Default false.
    bool arms_press = false;
    /// Blades curved in their face plane (a curved clip): from the heel their centre line bends on a circle of this
    /// radius [mm] towards axis × up (positive) or up × axis (negative); 0: straight (fem::ClipBlades::curve_radius_mm:
    /// the width is across the centre line, the length along it). A box jaw only (not with jaw_mesh).
    double jaw_curve_radius_mm = 0.0;
    /// The jaws' length from the fulcrum: fulcrum_mm + jaw_length_mm.
    double reach_mm() const { return fulcrum_mm + jaw_length_mm; }
    /// The ISO 9713 label point's distance from the fulcrum, a third of the blade from its tip: fulcrum_mm + 2/3
    /// jaw_length_mm. A clip's closing force is the force there (what its label gives); a moment M about the fulcrum
    /// is the force M / label_arm_mm() there.
    double label_arm_mm() const { return fulcrum_mm + 2.0 * jaw_length_mm / 3.0; }
    /// Its jaws as fem::ClipBlades with the fulcrum at `at` (the simulator's contact, spring balance and patch; the
    /// faces from the heel unless arms_press, a curved clip's blades bent from the heel).
    fem::ClipBlades blades(const Pose& at) const {
        fem::ClipBlades b;
        b.hinge = at.position;
        b.axis = at.axis;
        b.up = at.up;
        b.length_mm = reach_mm();
        b.width_mm = jaw_width_mm;
        b.thickness_mm = jaw_thickness_mm;
        b.closed_gap_mm = closed_gap_mm;
        b.curve_radius_mm = jaw_curve_radius_mm;
        b.curve_from_mm = fulcrum_mm;
        b.face_from_mm = arms_press ? 0.0 : fulcrum_mm;
        return b;
    }
    /// An opening step's share that gives the blade's middle the travel the same step gives a clip turning at its
    /// heel: (L/2) / (fulcrum + L/2), 1 without a fulcrum (the simulator's per-frame caps on the opening, in degrees
    /// for a clip turning at its heel, are scaled by it).
    double turn_per_heel_turn() const { return 0.5 * jaw_length_mm / (fulcrum_mm + 0.5 * jaw_length_mm); }
    std::string mesh_file;          ///< set: the jaw is this mesh instead of a box
    std::optional<TriMesh> jaw_mesh;
    /// The closing spring (configs/clips/README.md): the applier can only hold the clip open; below what it
    /// holds, the clip's opening is where the tissue's moment balances τ(θ) = k (θ + θ₀). None: the jaws follow
    /// the applier's opening exactly (a clip without a modelled spring).
    std::optional<fem::ClipSpring> spring;
    double label_force_n = 0, open_force_n = 0;  ///< what the spring was made from (ISO 9713 label point, 2/3 of the blade)
    bool spring_placeholder = false;             ///< the two forces are placeholders, not a clip's published figures
    std::string spring_source;
    std::string file;                            ///< the clip file it came from ("" = defined in the scene)
};

/// Reads a clip model file (configs/clips/*.json: the clip_models keys plus "name", "kind"; docs/scene_format.md).
/// @throws InputError naming the file and key
ClipModel read_clip_file(const std::string& path);

/// One keyframe of a scripted instrument.
struct Keyframe {
    double t = 0.0;
    Pose pose;
    double opening_deg = 0.0;       ///< clip applier: jaw opening
    bool button = false;            ///< suction: button held (the tube sticks to the surface)
    std::string load;               ///< clip applier: take a new clip of this model at t
    bool release = false;           ///< clip applier: deposit the held clip at t
    bool grasp = false;             ///< clip applier: pick up the nearest deposited clip at t
};

struct InstrumentSpec {
    enum class Kind { CLIP_APPLIER, SUCTION } kind = Kind::CLIP_APPLIER;
    std::string name;
    double radius_mm = 1.0;         ///< suction tube radius
    double length_mm = 15.0;        ///< suction tube length modelled behind the tip
    std::vector<Keyframe> keys;     ///< sorted by t (scripted mode)
};

struct ObstacleSpec {
    std::string name;
    std::string mesh_file;
    TriMesh mesh;
};

/// Direction of the prescribed displacement of a node inside a clip jaw.
enum class JawPush {
    SHAPE,        ///< the shortest way out of the jaw (across it): a closing clip squeezes the vessel between its jaws
    NODE_NORMAL,  ///< along the node's normal, as published (also what the suction tube always uses)
};

/// The wall's model under a held clip (issue #15, item 2).
enum class WallModel {
    LINEAR,  ///< the condensed linear model everywhere: jaw contacts are prescribed displacements (fast; trusted to
             ///< Scene::linear_limit wall thicknesses)
    PATCH,   ///< a neo-Hookean patch around each clip on the exact linear exterior, with the clip's blades, its spring
             ///< and wall-on-wall contact in one Newton problem per physics frame (fem::PatchModel, fem::ClipBody,
             ///< fem::ContactBody)
};

/// How the patch is made and solved (Scene::wall_model = PATCH).
/// PatchSpec::grow: walls nearer than this at rest are the lumen's own narrow places, not a meeting (twice the
/// approach: they came at least as far again towards each other).
constexpr double PATCH_GROW_APART_MM = 0.6;
struct PatchSpec {
    double radius_mm = 1.5;      ///< the patch: tetrahedra with a corner within this of the clip's jaws (their wedge at the
                                 ///< opening it is made at, along the jaws' length and width)
    double trigger_mm = 1.0;     ///< a held clip's patch is made when its jaws close this near the wall
    /// A patch grows where the lumen meets itself beside it: where opposite lumen walls that lay further apart than
    /// PATCH_GROW_APART_MM at rest come within fem::COMPLIANT_WALL_APPROACH_MM of each other (or through each other)
    /// with one side outside the patch or on its interface (sim::lumen_meeting), the patch is remade to cover the
    /// tetrahedra within radius_mm of those vertices too, and keeps them when remade later. (Session 59: C0001's
    /// lumen went 0.42 mm through itself in the linear exterior, 0.25 mm beyond the patch's interface, where no
    /// contact of the patch reaches.) false: the patch covers the jaws only.
    bool grow = true;
    int newton_per_frame = 12;   ///< Newton iterations a physics frame may take (warm-started from the last frame)
    double tolerance = 1e-6;     ///< relative residual of a converged frame
    bool wall_contact = true;    ///< inner walls touch and do not pass through each other (inside the patch)
    /// μ between the clip's blades and the tissue (fem::ClipContactParams::friction). 0.3: tissue on instrument
    /// steel measures 0.1–0.4 wet (Shacham 2010: 0.29–0.36; Guo 2021: graspers on bowel), and clip blades are
    /// serrated to hold; frictionless blades of a hinged clip squeeze a pressed vessel out of the V, which has no
    /// static equilibrium.
    double blade_friction = 0.3;
    /// How a frame is solved. NEWTON: the neo-Hookean patch with the blades' and walls' barriers, a warm-started
    /// Newton solve a frame. COMPLIANCE (issue #15, the rate acceptance): hard contact (blades with friction, the inner
    /// walls one row a vertex on the quadratic surface) solved as a linear complementarity problem on the patch's
    /// compliance at a linearisation (fem::Linearisation, solve_compliant_clip_walls): the linear model's stiffness
    /// about where the patch was linearised, remade every `refresh_frames` frames at the state reached.
    enum class Solver { NEWTON, COMPLIANCE } solver = Solver::NEWTON;
    /// COMPLIANCE: frames between linearisations (0: the one made with the patch, where it starts), counting those in
    /// which the blades or walls press something. Each is a Newton step of the nonlinear patch with the contact, made in
    /// the frame's thread (seconds on the sample).
    int refresh_frames = 0;
    /// COMPLIANCE, refreshed (refresh_frames > 0), deterministic: a frame that takes the patch's surface beyond the
    /// linear range of its linearisation (Scene::linear_limit) is solved again on a linearisation made where it got
    /// to, at most this many times.
    int range_resolves = 8;
    /// ... and one still beyond it after them is solved again in two halves of its opening's change (each a frame of
    /// its own, with its re-solves), a half still beyond it in halves again, at most this many times (0: not split;
    /// on the real cases' worst frames quarter steps did not help, session 51).
    int range_splits = 0;
    /// ... and one still beyond it after them (and the halvings) is solved as a Newton frame (the NEWTON solver's: the
    /// neo-Hookean patch with the blades' and walls' barriers, from where the frame started), with at most this many
    /// iterations; the frames go on from its state, linearised there. 0: not (the frame ends beyond the range, warned).
    int range_newton = 0;
    /// COMPLIANCE: a frame that ends with the patch's walls more than this far through each other (mm) is not taken: it
    /// counts as not converged, the patch stays where it started, and a second in a row restarts from the last
    /// converged state with a smaller step of the opening (why 0.1 mm: sim_patch.cpp, at the check; 0: every frame taken).
    double walls_reject_mm = 0.1;
    /// COMPLIANCE: such a frame is first shortened, the patch moved 1/2, 1/4, ... of the way from where it started to
    /// where it ended (its opening's change and blade loads alike), at most this many halvings; the longest step that
    /// leaves the walls within walls_reject_mm is taken (a damped step: the frames after go on from there; the whole step
    /// first; a pair or crossing already past the limit where the frame started is measured from there). 0: not
    /// shortened (not taken, as above). One clip's frames only.
    int walls_shorten = 0;
    /// COMPLIANCE: such a frame (one clip's) is first solved as a Newton frame (as range_newton's: the neo-Hookean patch
    /// with the blades' and walls' barriers, from where it started), with at most this many iterations; converged, the
    /// frames go on from its state, linearised there; not, it is shortened or not taken as above. 0: not.
    int walls_newton = 0;
    /// COMPLIANCE: the pressed nodes of a blade share their friction rows within square cells of this side on the
    /// blade's face (fem::CompliantOptions::friction_cell_mm; 0: two rows a node). Fewer rows, faster pressed frames;
    /// what a cell gives up is its nodes' slip relative to one another (bench/results/study/compliance.md).
    double friction_cell_mm = 0;
    /// COMPLIANCE, refreshed: a linearisation made for a refresh due or for a frame's re-solve beyond the linear range
    /// borrows the compliance W of the last that made one (fem::Linearisation's borrowing constructor: the tangent
    /// factorised at the new state, W kept; the frames correct every pass's end on the new tangent), at most this many
    /// in a row, where at most a quarter of the candidates the refresh selects are not among W's (their columns made on the
    /// tangent W was made on, so W stays one tangent's inverse), and while borrowing pays (the factorisations of the
    /// frames that fell back weigh no more than the Ws the converged ones saved, by their operations). A frame
    /// whose passes end with W's prediction further than fem::CompliantOptions::borrow_accept_mm from the tangent's is
    /// solved again on a linearisation with its own W. 0: every linearisation makes its W.
    int compliance_reuse = 0;
};

struct Scene {
    std::string path;               ///< the scene file
    std::string bundle;             ///< resolved against the scene file's directory
    std::optional<RegionSphere> region;
    std::optional<Precision> working_precision;
    std::map<std::string, ClipModel> clip_models;
    std::vector<InstrumentSpec> instruments;
    std::vector<ObstacleSpec> obstacles;
    // contact → displacement
    double displacement_fraction = 0.5;   ///< prescribed displacement = this × penetration (published: about half)
    double neighbour_weight = 0.5;        ///< one-ring neighbours get this × their contact neighbours' push (0: off)
    double release_tolerance_mm = 0.02;   ///< a contact node stays held while within this gap of the shape
    double relax_time_s = 0.05;           ///< released nodes relax to rest with this time constant
    /// Each physics frame computes the deformation of the region's nodes within this distance of an instrument
    /// part and of every prescribed node; the whole region at region_hz (for display and far nodes). Nodes
    /// that lag and come within it are first brought up to date from the last forces, so what a frame reads is
    /// exact. At least max(2 edges, approach_margin_mm) + 1 edge is used. 0: the whole region every frame.
    double update_margin_mm = 1.0;
    /// A prescribed displacement larger than this × the local wall thickness is outside the linear model's range
    /// (measured, linear vs neo-Hookean: a clip's force is 10 % too large once it has pushed 0.31 (0.3 mm artery
    /// wall) to 0.37 (0.1 mm sac wall) wall thicknesses; bench/results/study/study.md); the simulator warns once.
    /// 0: no check.
    double linear_limit = 0.3;
    GroupMethod clip_method = GroupMethod::EXACT;
    JawPush jaw_push = JawPush::SHAPE;
    WallModel wall_model = WallModel::LINEAR;
    PatchSpec patch;
    // haptics (contact-plane method)
    double plane_stiffness_n_per_mm = 0.3;
    double friction_n_s_per_mm = 0.002;
    double obstacle_stiffness_n_per_mm = 1.0;
    double friction_depth_mm = 0.05;      ///< friction fades in over this depth (continuity)
    double approach_margin_mm = 0.5;      ///< a contact plane is set up when a part comes this close (≥ 2 edge lengths)
    // rates [Hz]
    double haptic_hz = 1000.0;
    double physics_hz = 250.0;            ///< collision + solve
    double log_hz = 250.0;
    double series_hz = 25.0;
    double region_hz = 50.0;              ///< the whole working region's deformation (see update_margin_mm)
    double duration_s = 0.0;              ///< scripted: 0 = until the last keyframe
    bool live_input = false;              ///< poses from standard input instead of keyframes
    // assessment
    double force_threshold_n = 0.5;
    double velocity_threshold_mm_s = 30.0;
    double neck_tolerance_mm = 0.5;       ///< the neck line between closed jaws: this far beside them still counts
    double neck_gap_mm = 0.05;            ///< the neck is closed where the opposite inner walls are this close (or touch)
    // outputs ("" = not written); resolved against the scene file's directory unless absolute
    std::string log, haptic_log, series, report;
    /// After the run (never inside it): `aneuprep flow BUNDLE --series SERIES.h5 -o flow` for the last frame, the
    /// residual sac inflow against the pre-clip lumen's, into the report. Needs `series`.
    std::string flow;
};

/// Reads and checks a scene. Relative paths are taken from the scene file's directory.
/// @throws InputError naming the file, the key and what was expected (unknown keys are errors too)
Scene read_scene(const std::string& path);

/// Pose, opening and button of a scripted instrument at time t: positions by a monotone cubic Hermite
/// curve (velocity continuous, no overshoot past a keyframe), directions likewise then re-orthonormalised,
/// opening linear.
Keyframe sample(const InstrumentSpec& ins, double t);

/// One line of the live pose stream: `t name px py pz ax ay az ux uy uz opening button`.
struct LiveSample {
    double t = 0.0;
    std::string instrument;
    Keyframe key;
};
/// Parses a live line; returns nullopt and sets `why` for garbage, NaN/inf, or a zero direction.
std::optional<LiveSample> parse_live_line(const std::string& line, std::string& why);

/// The live pose stream, for every run mode alike: blank lines and `#` comments are passed over; a line that
/// does not parse, names an unknown instrument or goes back in time is skipped, with its line number and why.
class LiveReader {
public:
    /// Where lines come from: LINE (one in `line`), NONE_NOW (none yet: a live device between samples) or END.
    enum class Fetch { LINE, NONE_NOW, END };
    using Source = std::function<Fetch(std::string& line)>;
    /// `instrument_index`: the scene's instrument of a name, −1 if none.
    LiveReader(std::istream& in, std::function<int(const std::string&)> instrument_index);
    LiveReader(Source source, std::function<int(const std::string&)> instrument_index);
    struct Sample {
        LiveSample sample;
        int instrument = -1;
    };
    /// The next valid sample (nullopt at the end of the stream, or when the source has none now: see ended());
    /// `skipped(line_number, why)` for each refused line.
    std::optional<Sample> next(const std::function<void(long, const std::string&)>& skipped);
    bool ended() const { return m_ended; }

private:
    Source m_source;
    std::function<int(const std::string&)> m_index;
    long m_line = 0;
    double m_t = -std::numeric_limits<double>::infinity();
    bool m_ended = false;
};

}  // namespace aneu::sim
