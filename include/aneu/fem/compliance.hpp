// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Contact on a precomputed compliance (issue #15, item 2 and the rate acceptance): the contact loop that can run
/// at haptic rates while the nonlinear patch is re-linearised on the other core (Courtecuisse et al. 2015: the
/// factorisation of the tangent refreshed asynchronously, the contact forces solved every step on the compliance
/// of the contact DOFs only).
///
/// A Linearisation freezes a body at a state u0: its tangent K0 (factorised once), the free step
/// Δu_free = K0⁻¹ r0 (r0 = −f_int(u0) on the free DOFs: what Newton would do next with no contact) and the
/// compliance of the candidate nodes, W = (K0⁻¹)_CC (3|C| × 3|C|, dense; by fem::condense's sparse route). Then a clip
/// frame is a small problem on the candidates only:
///
///     minimise over Δu, θ:  ½ Δuᵀ K0 Δu − r0ᵀ Δu + k (θ²/2 + θ₀ θ)
///     subject to            D_i(x_i, θ) ≥ 0 for every candidate i and blade it faces (linearised at the free state)
///                           θ ≥ 0 (the closed stop; a released clip) or θ = the forceps' (a held one)
///
/// whose dual is a linear complementarity problem on the Delassus matrix A = J W Jᵀ (+ b bᵀ / k for a free θ),
/// solved by projected Gauss–Seidel warm-started from the last frame's forces, finished where it converges
/// slowly (θ couples every row) by block principal pivoting. The inner walls' contact (CompliantWalls: vertex–face
/// pairs of the lumen, whose corners are candidates too) adds rows on the face's plane, in the same problem. The
/// gaps are linear in the motion only to first order: a frame takes a few passes, each re-linearising them where
/// the last ended, on the same compliance. The contact is hard (D = 0 where a node presses; ClipBody's barrier
/// leaves pressed nodes between 0 and d̂) and frictionless. Repeating linearise → frame from the state a frame
/// ends at is a sequential-quadratic Newton method: it converges to the same equilibrium as solve_neo_hookean on
/// ClipBody (less the barrier's d̂); run asynchronously, the frames use the newest linearisation the other core has
/// finished, and how far they lag is the trade the benchmark (bench/bench_compliance.cpp) measures.
#include <array>
#include <memory>
#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "aneu/fem/clip.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem {

class Linearisation {
public:
    /// @param fixed_dofs DOFs held at zero displacement change (their u0 values stay)
    /// @param candidates body nodes that can touch (their compliance is kept); distinct
    /// @throws InputError bad sizes or indices; NumericalError a tangent that is not positive definite even
    ///         projected onto positive semidefinite element tangents
    /// @param project_first the element tangents projected from the start, without trying the tangent itself first:
    ///        for a caller that expects it to be indefinite (the last linearisation's was; a failed attempt costs a whole
    ///        factorisation, CHOLMOD failing at the top separator's pivots: C0024's patch 6 of its 13 s)
    Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                  const std::vector<int>& candidates, bool project_first = false);
    /// A linearisation at u0 that borrows its compliance from `from` (made at another state, on the same candidates):
    /// the tangent is assembled and factorised (by CHOLMOD alone, no condensation), the free step made, and W is
    /// `from`'s, shared. A frame on it (solve_compliant_clip) takes W for an approximation of this tangent's and corrects
    /// every pass's end by one back substitution with this factor, until the ends agree (CompliantOptions::
    /// borrow_tolerance_mm): a quasi-Newton step on the contact problem whose fixed point is the exact one's. Costs
    /// the factorisation (C0001's joined patch: ~7 s) instead of factorisation and W (~37 s; W is ~80 % of a refresh).
    /// @throws InputError `from` on other candidates, or with another body's DOFs; NumericalError as above
    Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                  const Linearisation& from, bool project_first = false);
    /// The same on other candidates: W's blocks between candidates that `from` has are `from`'s; the columns of the
    /// candidates it lacks (added_candidates of them) are made on the tangent `from`'s W was made on (its factor is
    /// kept while W is lent), 3 per added node, one CHOLMOD solve per 64, their rows by symmetry: W is that tangent's
    /// inverse on the new candidates (made on this tangent instead, W next to the old columns is indefinite).
    /// Candidates of `from` not among `candidates` are left out. On `from`'s candidates in `from`'s order W is shared,
    /// as above. A refresh whose selection adds a few nodes to the last W's (C0024: 169 of 176 did) then costs the
    /// factorisation and those columns, not a new W.
    /// @throws as the constructors above
    Linearisation(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
                  const std::vector<int>& candidates, const Linearisation& from, bool project_first = false);
    ~Linearisation();
    Linearisation(const Linearisation&) = delete;
    Linearisation& operator=(const Linearisation&) = delete;

    const Eigen::VectorXd& u0() const;
    /// The candidates' positions at the free state: X + u0 + Δu_free, one row per candidate.
    const Eigen::MatrixX3d& free_positions() const;
    /// The candidates' displacement at the free state, u0 + Δu_free (3|C|).
    const Eigen::VectorXd& free_candidate_u() const;
    const std::vector<int>& candidates() const;
    /// W's block of candidates a and b: the displacement of candidate a per unit force on candidate b [mm/N].
    Eigen::Matrix3d compliance(int a, int b) const;
    /// All of W, in 3 x 3 blocks: block (a, b) is the 9 values from 9 (b |C| + a), column-major.
    const double* compliance_blocks() const;
    /// The body's displacement (all DOFs) for forces f on the candidates' DOFs (3|C|): u0 + K0⁻¹ (r0 + Hᵀ f). One
    /// back substitution; none for f = 0 (the free state, kept).
    Eigen::VectorXd displacement(const Eigen::VectorXd& candidate_forces) const;
    /// The candidates' part of displacement(f) (3|C|): exact on this tangent, whatever W is (one back substitution).
    Eigen::VectorXd candidate_displacement(const Eigen::VectorXd& candidate_forces) const;
    /// W is another linearisation's (the borrowing constructor), not this tangent's inverse
    bool borrowed() const;
    /// Where W was made: the state of the linearisation that computed it (this one's u0 unless borrowed)
    const Eigen::VectorXd& compliance_u0() const;
    /// Seconds spent: tangent assembly, the factorisation (fem::condense's ordering, analysis and numeric factorisation,
    /// the one factor the free step and the frames' displacements use too), the compliance (condense's forward solve and
    /// SYRK, the free step, W's blocks).
    double tangent_s = 0, factorise_s = 0, compliance_s = 0;
    /// The last condensation's sizes and work: free DOFs, kept DOFs (3 per candidate), nnz(L), the factorisation's and
    /// W's floating-point operations and W's rate [GFLOP/s] (fem::condense's diagnostics; zeros without candidates).
    double free_dofs = 0, kept_dofs = 0, nnz_L = 0, factor_flops = 0, w_flops = 0, w_gflops_per_s = 0;
    /// The tangent was not positive definite (a buckling patch) and was factorised again with its element tangents
    /// projected onto positive semidefinite ones (factorise_s counts both factorisations).
    bool projected = false;
    /// Made with project_first: projected without the tangent itself tried (whether it was indefinite is not known)
    bool projected_first = false;
    /// Borrowed on other candidates: how many of them `from` lacked (W's columns made for them on this factor)
    int added_candidates = 0;
    /// The free step's length as a fraction of the Newton step from u0 (1: the full step; shorter where the full step
    /// would invert an element: the residual is scaled with it, so displacement() is the damped step's).
    double free_step = 1;

private:
    struct Impl;
    std::unique_ptr<Impl> m;
    void init(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::VectorXi& fixed_dofs, const Eigen::VectorXd& u0,
              const std::vector<int>& candidates, const Linearisation* from, bool project_first);
};

/// How deep a wall vertex may lie behind an opposite face, over it, and still have come through it (when it lay in
/// front of the face's plane at rest): the frames' crossing depth (ContactParams::depth_mm's 0.25 mm). Deeper it is on
/// the face's far side. CompliantOptions::wall_through_mm's default and compliant_setup's limit with the rest shape.
constexpr double WALL_THROUGH_MM = 0.25;

struct CompliantOptions {
    double reach_mm = 0.05;      ///< candidates nearer a blade than this (where the last frame left them) are constraints:
                                 ///< more than a frame's blade travel (0.384° a frame at 250 Hz moves a 13 mm blade's tip 0.044 mm)
    int max_sweeps = 4;          ///< projected Gauss–Seidel sweeps before block pivoting finishes the solve
    int max_pivots = 200;        ///< block-pivoting solves at most (each a dense Cholesky of the active rows; the sample's
                                 ///< pressed walls took up to 39, session 32)
    /// Where pivoting fails (redundant rows), further sweeps (at most 100) stop at this: a gap or complementarity off
    /// by 0.1 µm
    double accept_mm = 1e-4;
    double tolerance_mm = 1e-10; ///< stop when no constraint's gap or complementarity is off by more than this
    /// A released clip closes at most this much in one frame (θ ≥ θ_start − it): the frames approach the balance of
    /// spring and tissue, each linearising the blades' rotation where the last frame left them.
    double max_closing_rad = 0.02;
    /// A wall pair whose vertex lies further than this behind its face's plane where the frame starts is not a
    /// constraint (a crease of the wall, the far side of a fold); nearer, the frame pushes it back out. With the walls'
    /// rest shape (CompliantWalls::rest), a vertex that was not behind the plane at rest is a crossing, and pushed
    /// back out, up to wall_through_mm behind (session 46: C0024's walls crept 0.004 -> 0.022 mm through each other
    /// over five frames, each frame taking the last one's crossing for a crease). wall_through_mm is the frames' own
    /// crossing depth (ContactParams::depth_mm's 0.25 mm): what a frame's check counts as through a face, its rows push
    /// back out (session 59: at 0.05 mm, C0001's lumen vertex that slid 0.23 mm under a face in one frame was a crease
    /// from the next frame on, and went 0.42 mm through).
    double wall_behind_mm = 0.005;
    double wall_through_mm = WALL_THROUGH_MM;
    /// Wall pairs nearer than this where the frame starts are constraints: more than the two walls' approach in a
    /// frame (each moves as far as a blade)
    double wall_reach_mm = 0.15;
    /// Passes per frame: each re-linearises the gaps where the last ended (a normal turns as its face moves), on the
    /// same compliance; they stop when the candidates move less than 1000 × tolerance_mm between two.
    int geometry_passes = 3;
    /// A frame whose walls end through each other by more than this (a vertex over a face its last pass had no row
    /// on) takes up to wall_extra_passes more passes while they do (the limit is 0.02 mm)
    double wall_crossed_mm = 0.01;
    int wall_extra_passes = 3;
    /// Coulomb friction between the blades and the tissue they press (0: frictionless, as until session 32); held or
    /// released (a released clip's friction rows do not follow θ within the frame: a stick point on a blade face moves
    /// along it by (closed gap / 2) Δθ / 2 as the blade turns, 0 for blades that close flat). aneusim's blades have
    /// 0.3 (scene patch.blade_friction).
    double blade_friction = 0;
    /// With friction: the pressed candidates of a blade share their two friction rows within square cells of this side
    /// on the blade's face, each candidate's share of the cell's friction that of its normal force (compliance.cpp;
    /// BladeLoads::sliding then counts cells); 0: two rows for every pressed candidate
    double friction_cell_mm = 0;
    /// One wall row per vertex: of the faces it lies over within 0.02 mm of the nearest, its face in the last pass or
    /// frame if it is one of them, else the one its projection lies deepest inside (nearly parallel rows of one
    /// vertex over neighbouring faces make the LCP degenerate); and a second row on its other face in the last pass
    /// where the two faces' planes differ by more than 10° (a valley's sides). Either way a face a vertex had a row
    /// on in the last pass keeps it while the vertex lies within 0.5 of the face beyond its edges (others: 0.1). And
    /// every face that pressed the vertex in an earlier pass of the same frame keeps its row in the frame's later
    /// passes, where its plane differs by more than 10° from the vertex's other rows (a vertex over a hollow of the
    /// opposite wall needs the rows of the faces around it; with one face and a second the passes cycled: session 62).
    bool wall_one_face = false;
    /// On a linearisation whose W is borrowed (Linearisation::borrowed): the passes go on, each from the exact end of
    /// the last (its forces' displacement on this tangent), until a pass's predicted end and its exact one differ by
    /// no more than borrow_tolerance_mm at any candidate, at most borrow_passes passes in all (then the frame reports
    /// its mismatch, CompliantFrame::compliance_mismatch_mm, and the caller may make W anew).
    double borrow_tolerance_mm = 1e-4;
    int borrow_passes = 16;
    /// A frame on a borrowed W whose passes stop (converging no further, or at borrow_passes) with its mismatch within
    /// this is kept by the simulator, as the LCP keeps one within accept_mm; beyond it, solved again on a linearisation
    /// with its own W. The passes' mismatch stalls at 0.1-2 µm where the wall rows change between passes (session 57:
    /// 38 of the sample's 47 fallbacks ended there after 3-16 passes): a contact up to this far from where the LCP put it,
    /// a tenth of the 0.02 mm interpenetration limit.
    double borrow_accept_mm = 2e-3;
};

/// A further clip in the same frames (tandem clips over one neck on one patch: a neck line spread wider than one
/// blade needs a second clip beside the first). Its opening is held in the frame (the simulator prescribes every
/// clip's opening in its frames; a spring clip's by its balance's secant steps, each clip on its own R = τ − M).
struct CompliantClip {
    ClipBlades blades;
    double theta = 0;         ///< the opening it holds in this frame [rad], ≥ 0
    double theta_start = 0;   ///< its opening where the last frame left it (what lies behind a blade there stays behind)
    ClipSpring spring{1.0, 0.0};  ///< for its loads' spring torque only (the opening is held)
};

/// CompliantFrame::constraint's row kinds, its second member s: the first clip's blades ±1 (+1, −1) and its friction
/// rows −2 − (2 side + dir) (side 0: blade +1, 1: blade −1; dir 0 along the blade, 1 across); a wall pair 2 + face;
/// a further clip c ≥ 1 (CompliantClip c − 1) its blade side σ −6c − σ, its friction rows −6c − 2 − (2 side + dir).
constexpr int compliant_blade_row(int clip, int side) { return clip == 0 ? (side == 0 ? 1 : -1) : -6 * clip - side; }
constexpr int compliant_friction_row(int clip, int side, int dir) { return -6 * clip - 2 - (2 * side + dir); }
struct CompliantRowKind {
    bool blade = false, friction = false, wall = false;
    int clip = 0, side = 0, dir = 0, face = -1;
};
constexpr CompliantRowKind compliant_row_kind(int s) {
    CompliantRowKind k;
    if (s >= 2) {
        k.wall = true;
        k.face = s - 2;
    } else if (s == 1 || s == -1) {
        k.blade = true;
        k.side = s == 1 ? 0 : 1;
    } else if (s <= -2) {
        k.clip = (-s) / 6;
        const int r = (-s) % 6;
        if (r < 2) {
            k.blade = true;
            k.side = r;
        } else {
            k.friction = true;
            k.side = (r - 2) / 2;
            k.dir = (r - 2) % 2;
        }
    }
    return k;
}

/// The inner walls' contact in the frame (wall-on-wall, as fem::ContactBody, but hard): vertex–face pairs of
/// surface triangles whose corners are all candidates (indices into the linearisation's candidates), found by
/// fem::contact_pairs where the frames are (the caller renews them as they move).
struct CompliantWalls {
    Eigen::MatrixX3i faces;                   ///< triangles, in candidate numbering, normals towards the opposite wall
    std::vector<std::array<int, 2>> pairs;    ///< (vertex, face)
    /// the candidates' rest positions (one row each; empty: none known, every vertex behind its face's plane where the
    /// frame starts is a crease, CompliantOptions::wall_behind_mm)
    Eigen::MatrixX3d rest;
};

/// What the compliance frames of one clip act on: the candidates (the nodes whose compliance a Linearisation keeps)
/// and the inner-wall faces between them.
struct CompliantSetup {
    std::vector<int> candidates;   ///< body nodes: first those the blades reach, then the walls' other corners
    size_t blade_candidates = 0;   ///< how many of them come first, within reach of the blades
    Eigen::MatrixX3i faces;        ///< the walls' faces, in candidate numbering (CompliantWalls::faces)
    size_t approach_faces = 0;     ///< of them, the faces taken for walls about to meet away from the jaws
    /// per face, its surface: 0 the lumen's, 1 the outer surface's (ContactParams::face_surface: a vertex meets only
    /// its own surface's faces)
    std::vector<int> face_surface;
};
/// compliant_setup's default approach: inner walls nearer each other than this are wall faces wherever they are. Twice
/// the frames' row reach (CompliantOptions::wall_reach_mm): a selection is made at most every few frames (aneusim's
/// patch refreshes), and a wall moves at most as far as a blade in a frame.
constexpr double COMPLIANT_WALL_APPROACH_MM = 0.3;
/// ... and a vertex this far behind an opposite face counts as meeting it (hard contact leaves a pressed vertex a hair
/// behind; deeper, the frames take it for a crease, CompliantOptions::wall_behind_mm, and the pair would add nothing).
constexpr double APPROACH_BEHIND_MM = 0.05;
/// ... and, with the rest shape known, one up to WALL_THROUGH_MM behind it that lay in front of the face's plane at
/// rest (it came through the face: the frames' rows push it back out, CompliantOptions::wall_through_mm).
/// The candidates and wall faces for a clip at opening θ, where the body's nodes stand at `x` (one row a node): of
/// `reach` (the nodes a blade can touch: the outer surface's) those within 0.1 mm of the jaws' wedge, and of
/// `inner` (the lumen's triangles, body nodes, normals into the lumen) those whose three corners lie within 0.3 mm
/// of it, where the blades flatten the lumen, their corners candidates too. With approach_mm > 0, also the inner
/// walls about to meet anywhere (walls squeezed out beside or past the blades' tips): every face with a vertex of the
/// opposite wall (beyond one ring, facing it) within approach_mm in front of it or APPROACH_BEHIND_MM behind, and
/// the faces round that vertex. aneusim's patch and aneu_bench_compliance make their frames' problem so. Repeated
/// nodes in `reach` count once.
/// `outer` (the outer surface's triangles, body nodes, normals out of the wall): its faces about to meet each other by
/// the same rule (with approach_mm > 0), after the lumen's, their corners candidates too (session 48: C0001's outer
/// surface, squeezed along the jaws, folded 0.11 mm into its own wall, through faces no frame had). Under the blades
/// the outer surface meets the blades, so it has no wedge rule.
/// `rest` (the nodes' rest positions, as x; null: not known): a vertex up to WALL_THROUGH_MM behind an opposite
/// face that lay in front of its plane at rest meets it too (session 59: C0001's vertex 0.23 mm under a face was
/// beyond the 0.05 mm, no candidate, and no frame saw it go on to 0.42 mm).
/// @throws InputError a node outside x, a rest shape of another size
CompliantSetup compliant_setup(const ClipBlades& blades, double theta, const Eigen::MatrixX3d& x, const std::vector<int>& reach,
                               const Eigen::MatrixX3i& inner, double approach_mm = COMPLIANT_WALL_APPROACH_MM,
                               const Eigen::MatrixX3i& outer = Eigen::MatrixX3i(), const Eigen::MatrixX3d* rest = nullptr);
/// The same for several clips on one patch (tandem clips: CompliantClip's blades at `theta`): a node or face near any
/// clip's wedge is taken, once. The first clip alone gives the single clip's setup.
/// @throws InputError no clip, or a node outside x
CompliantSetup compliant_setup(const std::vector<CompliantClip>& clips, const Eigen::MatrixX3d& x, const std::vector<int>& reach,
                               const Eigen::MatrixX3i& inner, double approach_mm = COMPLIANT_WALL_APPROACH_MM,
                               const Eigen::MatrixX3i& outer = Eigen::MatrixX3i(), const Eigen::MatrixX3d* rest = nullptr);

/// One clip frame on a linearisation.
struct CompliantFrame {
    double theta = 0;                  ///< the blades' opening [rad]
    Eigen::VectorXd candidate_forces;  ///< the blades' forces on the candidates (3|C|) [N]
    Eigen::VectorXd candidate_u;       ///< the candidates' displacement (3|C|) [mm]
    BladeLoads loads;                  ///< as ClipBody::loads: normal force and moment per blade, spring torque
    std::vector<BladeLoads> more_loads; ///< the further clips' (CompliantClip), in their order
    std::vector<double> lambda;        ///< per constraint: its force, normal (a friction row's: tangential) (warm start of the next frame)
    /// per constraint: (candidate, blade ±1), (vertex, 2 + face) for a wall pair, or (candidate, −2 − (2 side + dir))
    /// for a friction row (side 0: blade +1, 1: blade −1; dir 0 along the blade, 1 across it; a cell's: its first candidate);
    /// a further clip's rows as compliant_row_kind says
    std::vector<std::pair<int, int>> constraint;
    int wall_rows = 0;                 ///< wall pairs within reach (constraints)
    int wall_contacts = 0;             ///< wall pairs pressed together
    double wall_force_n = 0;           ///< Σ their normal forces [N]
    /// the smallest distance from its face's plane of a paired vertex lying over its face, where the frame ended, of
    /// the pairs not behind that plane by more than CompliantOptions::wall_behind_mm where it started (creases; inf: none)
    double wall_min_distance_mm = 0;
    int wall_crossings = 0;            ///< solve_compliant_clip_walls: wall vertices newly behind a face after its last solve
    /// solve_compliant_clip_walls: the deepest wall vertex behind a wall face where the frame ended, whatever its rows
    /// (fem::surface_crossings with the search's rings, deeper than 1 µm; crossings it started with included; 0: none)
    double wall_crossed_mm = 0;
    int sweeps = 0;
    int passes = 0;                    ///< geometry passes (CompliantOptions::geometry_passes)
    int pivots = 0;                    ///< block-pivoting solves that finished the sweeps (0: the sweeps converged)
    int single_pivots = 0;             ///< of them, solves after a single row's flip (the safeguard against cycling)
    double complementarity_mm = 0;     ///< the largest |min(λ_i, D_i)|-type violation left, in mm
    double seconds = 0;                ///< the frame's wall-clock time (constraints, Delassus matrix, sweeps)
    /// Its parts [s], summed over passes (and a walls frame's repeats): making the rows, the Delassus matrix, the LCP
    /// (sweeps, pivoting, forces and displacements), and with the walls the pair search and crossing checks.
    double rows_s = 0, delassus_s = 0, lcp_s = 0, search_s = 0;
    int pair_nodes = 0;                ///< the candidates the last pass's rows touch (its Delassus matrix reads W on their pairs)
    int refactors = 0;                 ///< LcpResult::refactors of the last pass
    /// On a borrowed W: the largest difference at a candidate between the last pass's end on W and its exact end on
    /// the tangent (the frame's gaps are off by up to this); 0 on a linearisation's own W
    double compliance_mismatch_mm = 0;
};

/// The clip's blades (at their pose; `theta_held` the forceps' opening, or none: released, θ free on its spring
/// with the closed stop) against the candidates of a linearisation.
/// @param theta_start the last frame's opening: a candidate more than 0.02 mm behind a blade there is not pushed
///                    by it (tissue beside or behind a blade stays there); a released clip is linearised there
/// @param warm        the last frame, whose forces start the sweeps where its constraints recur (may be null)
/// @param start       the candidates' displacement where the frame starts (3|C|): what the blades' friction holds
///                    them at (turned with the blades from theta_start), what lies behind a blade or a face there.
///                    Null: warm's end (the last frame ended where this one starts), else the free state. A frame
///                    solved again on a new linearisation, warm from its own last attempt, passes where it started:
///                    with the attempt's end taken for the start, every re-solve turned the gripped tissue with the
///                    blades once more (session 49: the re-solves' reach stayed at the blades' step a frame).
/// @param more        further clips in the same frame, each held at its opening (null or empty: one clip); their
///                    rows join the same problem, their loads are the frame's more_loads. The first clip's θ alone
///                    may be free (theta_held none).
/// @throws InputError a further clip's opening below 0
CompliantFrame solve_compliant_clip(const Linearisation& lin, const ClipBlades& blades, const ClipSpring& spring,
                                    std::optional<double> theta_held, double theta_start, const CompliantFrame* warm = nullptr,
                                    const CompliantOptions& opt = {}, const CompliantWalls* walls = nullptr, const Eigen::VectorXd* start = nullptr,
                                    const std::vector<CompliantClip>* more = nullptr);

/// What a sequence of wall frames keeps between frames: the pair rules (their close vertices grow as crossings are
/// found), the last pair search and where it was made, the crossings where the last frame ended.
///
/// The pair rules leave out only the faces within one ring of a vertex (ContactBody's default is two). Two rings hid
/// the walls crossing at a flattened slit's end fold, where the two walls are surface neighbours: session 45 found
/// C0054's lumen 0.198 mm through itself there and the sample's 0.279 mm 1.4 mm before the heel, with every frame's rows
/// within 0.009 mm; with one ring both end within 0.008 mm. Same-wall neighbours beyond the ring still make no pair:
/// they do not face each other, and one lying behind a face where the search starts is a crease, not a pair.
struct CompliantWallSearch {
    ContactParams params = [] {
        ContactParams p;
        p.exclude_rings = 1;
        return p;
    }();
    std::vector<std::array<int, 2>> pairs;
    Eigen::VectorXd searched_at;
    int searches = 0;  ///< pair searches so far
    Eigen::VectorXd ended_at;
    std::vector<std::pair<int, int>> ended_behind;
    double ended_deepest = 0;  ///< the deepest of them
};

/// A frame with the inner walls' contact: the pairs (fem::contact_pairs with ws.params, its close vertices included;
/// faces in candidate numbering, Xc the candidates' reference positions; searched again only when the candidates
/// have moved half the search distance beyond the rows' reach since the last search), the frame solved, and where
/// a wall vertex ends behind a face it was not behind at the start (fem::surface_crossings, deeper than 1 µm: it
/// went through a face its pairs left out) the frame solved again with it and its ring paired with every face in
/// reach, up to 3 times, as fem::solve_without_crossings does. The close vertices stay in ws for the frames after.
/// @param repeats frames solved again (null: not counted)
/// @param start   where the frame starts, as solve_compliant_clip's (also where its pairs are searched and what is
///                behind a face there is not a crossing)
CompliantFrame solve_compliant_clip_walls(const Linearisation& lin, const Eigen::MatrixX3d& Xc, const Eigen::MatrixX3i& faces, CompliantWallSearch& ws,
                                          const ClipBlades& blades, const ClipSpring& spring, std::optional<double> theta_held, double theta_start,
                                          const CompliantFrame* warm = nullptr, const CompliantOptions& opt = {}, int* repeats = nullptr,
                                          const Eigen::VectorXd* start = nullptr, const std::vector<CompliantClip>* more = nullptr);

/// Where the inner walls stand with the candidates displaced by u (3|C|), as a walls frame's end reports them: the
/// closest of the search's pairs (ws.pairs: the last frame's) over their face, creases where `start` has them left
/// out (CompliantFrame::wall_min_distance_mm; inf: none over its face), and the deepest vertex behind a face whatever
/// the pairs (CompliantFrame::wall_crossed_mm; 0: none). For a state between a frame's start and its end (aneusim's
/// shortened frame, PatchSpec::walls_shorten).
/// @throws InputError positions, u or start that do not fit the candidates
struct CompliantWallsAt {
    double min_distance_mm = std::numeric_limits<double>::infinity();
    double crossed_mm = 0;
    /// The closest of the pairs over their face, a pair that was further than `beyond_mm` behind its face's plane at
    /// `start` measured from there (how much further through it went; inf: none)
    double deepened_mm = std::numeric_limits<double>::infinity();
    /// The deepest vertex behind a face, one that was deeper than `beyond_mm` behind it at `start` measured from there
    double deepened_crossed_mm = 0;
};
CompliantWallsAt compliant_walls_at(const Linearisation& lin, const Eigen::MatrixX3d& Xc, const Eigen::MatrixX3i& faces, const CompliantWallSearch& ws,
                                    const Eigen::VectorXd& u, const Eigen::VectorXd& start, const CompliantOptions& opt = {},
                                    double beyond_mm = std::numeric_limits<double>::infinity());

/// A sequence of frames carried over to another candidate set (a refresh that selects the candidates again for the
/// jaws as they are now: aneusim's patch): the last frame's constraints and their forces, and the candidates'
/// displacements and forces, renumbered from `from_cand`/`from_faces` to `to_cand`/`to_faces` (candidates are body
/// nodes; a face is the same face when its three nodes are). A row whose candidate or face is no longer kept is
/// dropped; a new candidate's displacement is the body's `u` at its node (3 per node), its force 0. The wall search
/// starts again at the next frame (its close vertices renumbered, the ones no longer kept dropped).
/// @throws InputError faces or `u` that do not fit the candidates
void carry_compliant_frames(const std::vector<int>& from_cand, const Eigen::MatrixX3i& from_faces, const std::vector<int>& to_cand,
                            const Eigen::MatrixX3i& to_faces, const Eigen::VectorXd& u, CompliantFrame& last, CompliantWallSearch& ws);

/// The frames' linear complementarity problem: find z with w = q + A z ≥ 0, z ≥ 0, zᵀ w = 0, A symmetric positive
/// definite (the Delassus matrix with its constraint force mixing).
struct LcpOptions {
    int max_sweeps = 4;       ///< projected Gauss–Seidel sweeps (from the given z) before block pivoting finishes the solve
    int max_pivots = 200;     ///< block-pivoting solves at most
    double tolerance = 1e-10; ///< done when no row's w or complementarity is off by more than this
    double accept = 1e-4;     ///< where pivoting did not finish, further sweeps (at most 100) until no row is off by more than this
};
struct LcpResult {
    int sweeps = 0;
    int pivots = 0;         ///< block-pivoting solves (each a dense Cholesky of the active rows)
    int single_pivots = 0;  ///< of them, after a single row's flip (Júdice & Pires' safeguard against cycling)
    int refactors = 0;      ///< Cholesky factorisations of the active rows from scratch (the others updated it row by row)
    double violation = 0;   ///< the largest |w_i| where z_i > 0, or −w_i where w_i < 0, left
};
/// Projected Gauss–Seidel from z (the warm start), finished by block principal pivoting with Júdice & Pires (1994)'s
/// safeguard: every wrong row flipped at once while their count falls, a single one (Murty's rule) after three
/// solves without a fall. z is the best solution found (the smaller violation of the sweeps' and the pivoting's).
/// @throws InputError sizes that do not match
LcpResult solve_lcp(const Eigen::Ref<const Eigen::MatrixXd>& A, const Eigen::VectorXd& q, Eigen::VectorXd& z, const LcpOptions& opt = {});
/// The same with bounds lo ≤ z ≤ hi per row (a box-constrained LCP, the bound-constrained QP min ½ zᵀ A z + qᵀ z):
/// w ≥ 0 where z = lo, w ≤ 0 where z = hi, w = 0 between. What Coulomb friction rows need (|λ_t| ≤ μ λ_n, the
/// bound taken from the last pass's normal force); solve_lcp is lo = 0, hi = ∞.
/// @throws InputError sizes that do not match, lo > hi, lo = ∞ or hi = −∞
LcpResult solve_box_lcp(const Eigen::Ref<const Eigen::MatrixXd>& A, const Eigen::VectorXd& q, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi, Eigen::VectorXd& z,
                        const LcpOptions& opt = {});

/// How far in front of blade s (±1) at opening θ the point x lies, the blade a solid whose sides and tip are rounded
/// (ClipBody's geometry and edge radius): negative behind its face.
double blade_distance(const ClipBlades& blades, int s, double theta, const Eigen::Vector3d& x);

}  // namespace aneu::fem
