// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A clip as a spring (issue #15, item 3). Two flat rigid blades hinged at one point open symmetrically by the
/// angle θ between them; a torsion spring closes them with the torque
///
///     τ(θ) = k (θ + θ₀)        [N·mm], θ in radians, θ = 0: closed (the blades' inner faces `closed_gap` apart)
///
/// so the force one blade applies at distance r from the hinge is τ / r: the hyperbola along the blade that Ooka
/// 1997 measured on aneurysm clips, and the label convention of ISO 9713 (the closing force at 1 mm opening, a
/// third of the blade from the tip) fixes one point of it. ClipBody adds the blades to an ElasticBody as one more
/// unknown, θ, and the blade faces as a barrier on the body's surface nodes: the total potential
///
///     Π(u, θ) = Ψ(u) + Σ κ d̂² b(D_i(u, θ)/d̂)  [D_i < d̂]  + k (θ²/2 + θ₀ θ),   b(x) = −(x − 1)² ln x
///
/// (D_i: how far node i lies in front of a blade, the blades being solids whose sides and tip are rounded to a
/// 0.1 mm radius, so that tissue pressed past an edge is pushed off it along the rounded surface's normal; the
/// barrier is zero from d̂ outward, C2 there and infinite on the face (incremental potential contact, Li et al.
/// 2020, as for the inner walls), and every Newton step is bounded by continuous collision detection, so no node
/// passes a blade; with friction, the grips' energy, ClipContactParams::friction) is minimised by
/// the same Newton solve (solve_neo_hookean). ∂Π/∂θ = 0 is the blades' moment balance, so a
/// released clip (θ free) stops where the tissue pushes back as hard as its spring; a clip held open by the
/// forceps has θ prescribed, and the solve's reaction on θ is the torque the forceps holds.
#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include <mutex>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem {

/// τ(θ) = k (θ + θ₀): a linear torsion spring with a preload.
struct ClipSpring {
    double k_nmm_per_rad = 0;  ///< stiffness [N·mm/rad]
    double preload_rad = 0;    ///< θ₀ > 0: the torque at θ = 0 is k θ₀
    double torque(double theta) const { return k_nmm_per_rad * (theta + preload_rad); }
    double energy(double theta) const { return k_nmm_per_rad * (0.5 * theta * theta + preload_rad * theta); }
    /// Closing force at distance r [mm] from the hinge at opening θ (a point load there balancing the spring).
    double force_at(double r_mm, double theta) const { return torque(theta) / r_mm; }
    /// From two closing forces at the same distance r from the hinge: f1 at opening θ1 and f2 at θ2 (θ2 > θ1).
    /// @throws InputError unless 0 < f1 < f2 and 0 <= θ1 < θ2 (a spring that closes harder when opened, with a preload)
    static ClipSpring from_forces(double r_mm, double theta1, double f1, double theta2, double f2);
};

/// The opening a spring clip's next frame prescribes, approaching the balance of spring and tissue by a secant step:
/// θ − R / k, R = τ(θ) − M(θ) the spring's torque less the tissue's moment at this frame's θ, k > 0 the secant
/// dR/dθ. Opening, at most 1° a frame; closing, at most 1° a frame once released (`held`: the applier lets go as
/// fast as it opens its forceps) and, while the blades touch tissue, at most half the opening left: a prescribed
/// opening the tissue between the blades cannot fit in has an infinite barrier energy (a clip with twice the
/// placeholder spring stepped from 0.58° to its stop in one frame on the sample, and its blades reported 6e14 N).
/// (The simulator takes no step on a frame whose solve did not converge: its R is not the tissue's.)
double next_spring_opening(double theta, double R, double k, bool held, bool touching);

/// Opening angle [rad] at which a point at distance r from the hinge has its blades `opening_mm` apart, for
/// blades whose inner faces are `closed_gap_mm` apart when closed: 2 r sin(θ/2) + closed_gap = opening.
double opening_angle(double r_mm, double opening_mm, double closed_gap_mm);

/// Where the blades are: hinge, the blades' direction when closed (`axis`), the direction they open in (`up`,
/// perpendicular to axis); blade +1 opens towards +up, blade −1 towards −up. The blades are `length` long from
/// the hinge, `width` wide (across axis and up), `thickness` thick behind their inner face (for display; contact
/// is with the inner faces).
struct ClipBlades {
    Eigen::Vector3d hinge = Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
    Eigen::Vector3d up = Eigen::Vector3d::UnitY();
    double length_mm = 7.0, width_mm = 1.0, thickness_mm = 0.5, closed_gap_mm = 0.0;
    /// A blade curved in its face plane (as curved aneurysm clips are): from `curve_from_mm` along it (the heel, where
    /// the blade begins beyond a fulcrum's arms) its centre line bends on a circle of radius |curve_radius_mm| towards
    /// +w (= axis × up) when positive, towards −w when negative; 0: straight. Its face stays one plane (the blade
    /// turns rigidly with θ), so only where the face ends changes: its width W is measured across the centre line and
    /// its length along it. Valid for |R| ≥ 2 mm, > W, and an arc of at most 90° (check_curve()).
    double curve_radius_mm = 0.0, curve_from_mm = 0.0;
    bool curved() const { return curve_radius_mm != 0.0; }
    /// Where the blades' inner faces begin along them, from the hinge [mm] (0: at the hinge). A clip that turns about
    /// a fulcrum behind its heel has its box and arms there, which do not clamp tissue as faces do: its faces begin
    /// at the heel, fulcrum_mm out (sim::ClipModel::blades). Before it the blade's solid ends in an edge rounded as
    /// at its tip (ClipBody and the compliance frames' blade distance, the linear model's jaws, the assessment).
    double face_from_mm = 0.0;
    /// Where the core of a blade whose edges are rounded to ρ begins along it (its solid is the set within ρ of that
    /// rectangle, ending at `tip`): face_from_mm + ρ where the faces begin past the hinge, else the hinge itself.
    double core_from(double rho, double tip) const { return face_from_mm > 0 ? std::min(face_from_mm + rho, tip) : 0.0; }
    /// A point's place on the face plane in the blade's own coordinates: s, the length along the centre line from
    /// the hinge end, and a, the offset across it (along w; the straight blade's r and a), with their first (ds, da)
    /// and second (hs, ha) derivatives on the straight coordinates (r = rel·t, a = rel·w). A straight blade: s = r,
    /// a = a. Where the blade curves: the polar coordinates about its centre of curvature, s = r₀ + R φ, a = R − ρ.
    struct FaceCoords {
        double s = 0, a = 0;
        Eigen::Vector2d ds = Eigen::Vector2d(1, 0), da = Eigen::Vector2d(0, 1);
        Eigen::Matrix2d hs = Eigen::Matrix2d::Zero(), ha = Eigen::Matrix2d::Zero();
        double rho_c = std::numeric_limits<double>::infinity();  ///< in the face plane from the centre of curvature (∞: straight)
    };
    FaceCoords face_coords(double r, double a) const;
    /// The centre line at arc length s from the hinge end: its point (r along the axis, a along w) in the closed
    /// blade's frame, and its direction there (for drawing the blades and their outline).
    void centre_line(double s, double& r, double& a, double& dr, double& da) const;
    /// @throws InputError a curve that is too tight for the blade (|R| < 2 mm or ≤ W) or bends it past 90°
    void check_curve() const;
    /// Blade s (±1) at opening θ: its direction t, inner-face normal n (towards the other blade) and the
    /// across-blade direction w.
    void frame(int s, double theta, Eigen::Vector3d& t, Eigen::Vector3d& n, Eigen::Vector3d& w) const;
    /// Whether p lies within `margin` of the jaws' wedge at opening θ: along the jaws, across their width, and
    /// between (or on) the blades (the simulator's patch and the tissue a closing clip can reach).
    bool near_wedge(double theta, const Eigen::Vector3d& p, double margin) const;
};

struct ClipContactParams {
    double gap_mm = 0.01;      ///< d̂: the barrier acts on nodes nearer a blade face than this; pressed nodes end between 0 and d̂
    double stiffness = 0;      ///< κ [N/mm]; 0 = the largest diagonal entry of the body's tangent at rest
    /// μ: Coulomb friction between the blades' faces and the tissue, 0 = frictionless. A node pressed on a blade
    /// grips a point there: its tangential force rises smoothly with its slip from that point, reaching μ λ at
    /// `stick_mm` (λ: its normal force when the grip was last renewed, lagged as in incremental-potential friction,
    /// Li et al. 2020), and stays μ λ beyond, where the node slides and its grip point follows it.
    double friction = 0;
    /// ε: the slip at which a grip lets go and slides (the friction's regularisation): the elastic give of the tissue
    /// in the blades' serrations. Much smaller, and Newton's steps overshoot the narrow valley of ψ where a node's
    /// slip reverses.
    double stick_mm = 1e-2;
    /// Kept between the ClipBodies of successive solves (make_pattern_cache); null: each merges its own pattern.
    std::shared_ptr<PatternCache> pattern_cache;
};

namespace detail {
struct MergedPattern;
}

/// Where a node grips a blade: its place on the blade's face in the blade's own frame (r from the hinge along
/// the blade, a across it), which moves with the clip, and the normal force λ [N] that bounds the hold (μ λ).
struct BladeGrip {
    int node = -1;  ///< the body's node
    int blade = 1;  ///< +1 / −1
    double r = 0, a = 0, normal_n = 0;
};

/// Loads on the blades at a state.
struct BladeLoads {
    std::array<double, 2> force_n{0, 0};     ///< Σ normal force on blade +1 / −1 [N] (the tissue pushing it open)
    std::array<double, 2> moment_nmm{0, 0};  ///< the tissue's moment on each blade about the hinge [N·mm]: Σ normal force ×
                                             ///< distance from the hinge, and the grips' friction forces' moments
    std::array<int, 2> contacts{0, 0};       ///< nodes pressing on each blade
    std::array<double, 2> friction_n{0, 0};  ///< Σ |tangential force| of the grips on blade +1 / −1 [N]
    std::array<int, 2> sliding{0, 0};        ///< grips at their friction limit (sliding), per blade
    double opening_rad = 0;
    double spring_torque_nmm = 0;
    /// The tissue's net force on the clip [N]: the blades' barrier and friction forces (−Σ the forces the
    /// blades apply to the body's nodes).
    Eigen::Vector3d net_force = Eigen::Vector3d::Zero();
};

/// An ElasticBody with a clip: DOFs are the body's then θ (the last, index dofs() − 1, in radians).
class ClipBody final : public ElasticBody {
public:
    /// @param X          reference positions of the body's nodes
    /// @param candidates nodes that can touch a blade (the outer surface near the clip); the tangent's pattern
    ///                   couples each to θ
    /// @param v0         the state the solve starts from (body DOFs and θ): a candidate is pushed by a blade only if
    ///                   it lies in front of that blade's face there (not more than 0.02 mm behind it: tissue
    ///                   outside the clip stays outside; one behind it by up to that meets the barrier as if the
    ///                   face were 0.1 d̂ behind it, and is pushed back out). Make a new ClipBody for the next
    ///                   load step.
    /// @param grips      with friction: where nodes grip the blades (grips() of the last solve; the blades' frame
    ///                   moves with the clip, so a rigid move of the clip carries them). Null: taken at v0, the
    ///                   nodes pressing on a blade there gripping where they are. A grip of a node that is not a
    ///                   candidate is an input error.
    /// @throws InputError bad sizes, a non-positive spring or blade dimension, axis and up not orthonormal, a
    ///         negative friction coefficient
    ClipBody(const ElasticBody& body, const Eigen::MatrixX3d& X, const std::vector<int>& candidates, const Eigen::VectorXd& v0,
             const ClipBlades& blades, const ClipSpring& spring, const ClipContactParams& p = {},
             const std::vector<BladeGrip>* grips = nullptr);
    Eigen::Index dofs() const override { return m_body.dofs() + 1; }
    Eigen::Index theta_dof() const { return m_body.dofs(); }
    double energy(const Eigen::VectorXd& v) const override;
    Eigen::VectorXd internal_force(const Eigen::VectorXd& v) const override;
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& v, bool project = false) const override;
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override;
    void add_tangent(const Eigen::VectorXd& v, bool project, double* values, const std::int64_t* where) const override;
    double min_jacobian(const Eigen::VectorXd& v) const override { return m_body.min_jacobian(v.head(m_body.dofs())); }
    /// The largest fraction of the step dv that keeps every node in front of the blades it faces (and the body's
    /// own bound): continuous collision detection of the nodes' and the blades' motion.
    double max_step(const Eigen::VectorXd& v, const Eigen::VectorXd& dv) const override;
    BladeLoads loads(const Eigen::VectorXd& v) const;
    /// v with every node the blades press (nearer a blade it faces than `delta_mm`: its distance from the face itself,
    /// not the barrier's, which sees the face a little behind a node that started on it or just behind it) moved
    /// to `delta_mm` in front of it, along the distance's gradient: a state the barrier can start from, for a start
    /// another contact model left (hard contact: nodes exactly on the faces). Make a ClipBody at the result to solve
    /// from it. delta_mm below gap_mm.
    Eigen::VectorXd separated(const Eigen::VectorXd& v, double delta_mm) const;
    /// The grips after a solve that ended at v, for the next one: a grip that held stays where it was, one that
    /// slid follows its node (ε behind it); nodes that press on a blade at v without a grip take one where they
    /// are; every grip's λ is its node's normal force at v (none: let go).
    std::vector<BladeGrip> grips(const Eigen::VectorXd& v) const;
    double stiffness() const { return m_kappa; }
    const ClipBlades& blades() const { return m_blades; }

private:
    /// A candidate against a blade: d, its distance in front of the blade (blade_distance); r, along the blade t
    /// from the hinge; a, across it.
    struct Touch {
        double d = 0, r = 0, a = 0, q = 0;  // a: across the blade, along w; q = rel·n
        Eigen::Vector3d t, n, w;
        Eigen::Vector3d u = Eigen::Vector3d(0, 0, 1);  // ∂D/∂(r, a, p): the unit vector from the blade's core
        double dist = 0;                               // beside the core: |v|, the distance from its edge (0: over it)
        double mr = 0, ma = 0, md = 0;                 // which of v's components follow r, a, p (1) or are 0
        bool curved = false;                           // a curved blade's: u, mr, ma follow fc's (s, a), not (r, a)
        ClipBlades::FaceCoords fc;
    };
    static constexpr double EDGE_MM = 0.1;  ///< the blades' edge radius ρ (less on blades too thin or narrow for it)
    /// D: how far the point hinge + rel lies in front of the blade whose frame c holds (its face flat over the
    /// blade's core, its sides and tip rounded to the radius ρ), and in c.u its derivative in the blade's frame.
    double blade_distance(const Eigen::Vector3d& rel, Touch& c) const;
    /// The blade's barrier on a node at distance D: energy, push f = −∂e/∂D ≥ 0 and stiffness ∂²e/∂D² (zero from
    /// d̂ on; infinite energy at D ≤ 0).
    struct Press {
        double e = 0, f = 0, k = 0;
    };
    Press press(double D) const;
    /// One candidate against one blade: energy, gradient on (its x, y, z, θ) and (H ≠ null) the 4 × 4 tangent.
    bool pair_terms(const Eigen::VectorXd& v, size_t k, int s, Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H,
                    bool project) const;
    /// pair_terms' energy, gradient and tangent on a curved blade (c measured).
    bool pair_terms_curved(const Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H, bool project) const;
    /// Both blades' frames at v's opening (index 0: blade +1), once per evaluation.
    std::array<Touch, 2> touches(const Eigen::VectorXd& v) const;
    /// Candidate k against blade s at v (c holds that blade's frame from touches()): true when it presses on it
    /// (d < gap, ω > 0, and in front of it at v0).
    bool measure(const Eigen::VectorXd& v, size_t k, int s, Touch& c) const;
    /// Candidate k's grip on blade s (c: that blade's frame): the friction energy ψ(|Δ|) of its slip Δ from the grip
    /// point (convex, C2; ψ' = μλ beyond ε), its gradient on (x, y, z, θ) and (H ≠ null) tangent. False when there
    /// is no grip. slid: |Δ| ≥ ε.
    bool grip_terms(const Eigen::VectorXd& v, size_t k, int s, const Touch& c, double& e, Eigen::Vector4d& grad, Eigen::Matrix4d* H,
                    bool project, bool* slid = nullptr) const;
    /// The tangent's pattern (the body's, each candidate's DOFs coupled to θ), made when first needed (a frame whose
    /// blades touch nothing needs none; a patch's has millions of entries).
    void build_pattern() const;
    struct Grip {
        bool on = false;
        double r = 0, a = 0, lambda = 0;
    };
    const ElasticBody& m_body;
    Eigen::MatrixX3d m_X;
    std::vector<int> m_nodes;
    std::vector<std::array<bool, 2>> m_front;     // per candidate: in front of blade +1 / −1 at v0
    std::vector<std::array<double, 2>> m_offset;  // per candidate: where its distance from blade +1 / −1 counts from
    std::vector<std::array<Grip, 2>> m_grip;   // per candidate: its grip on blade +1 / −1
    ClipBlades m_blades;
    ClipSpring m_spring;
    ClipContactParams m_p;
    double m_kappa = 0, m_stop = 0;  // the barrier's κ; the closed stop's penalty on θ < 0 [N·mm/rad]
    double m_rho = EDGE_MM;          // edge radius [mm]
    mutable std::once_flag m_pattern_once;
    mutable std::shared_ptr<const detail::MergedPattern> m_merged;  // the pattern, and where the body's entries lie in it
    mutable std::vector<std::array<std::int64_t, 16>> m_slots;  // per candidate: its 3 DOFs and θ, 4 × 4 entries
    // add_tangent into a caller's matrix: the body's entries' places there (a buffer kept between calls).
    mutable std::mutex m_compose_mutex;
    mutable std::vector<std::int64_t> m_compose;
    /// The spring's and the blades' terms at v, added into values at where[slot] (where null: the slots themselves).
    void add_own_tangent(const Eigen::VectorXd& v, bool project, double* values, const std::int64_t* where) const;
};

/// A linear elastic body: Ψ = ½ uᵀ K u (K symmetric, both triangles). The linear model in the same contact
/// problems as the nonlinear ones, and a known stiffness for tests.
class LinearBody final : public ElasticBody {
public:
    /// @param upper_only K holds its upper triangle only (a bundle's /fem/K: FemData::K_upper_only): mirrored here.
    /// @throws InputError K not square, or (both triangles given) not symmetric
    explicit LinearBody(Eigen::SparseMatrix<double, Eigen::RowMajor> K, bool upper_only = false);
    Eigen::Index dofs() const override { return m_K.rows(); }
    double energy(const Eigen::VectorXd& u) const override { return 0.5 * u.dot(m_K * u); }
    Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const override { return m_K * u; }
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd&, bool = false) const override { return m_K; }
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override { return m_K; }
    double min_jacobian(const Eigen::VectorXd&) const override { return 1.0; }

private:
    Eigen::SparseMatrix<double, Eigen::RowMajor> m_K;
};

}  // namespace aneu::fem
