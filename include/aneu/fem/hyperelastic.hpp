// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Large deformation, offline: a compressible neo-Hookean solid on the same 4-node / 10-node tetrahedra, the
/// same quadrature and the same materials as assemble_stiffness, and a static Newton solve with prescribed
/// displacements. It is the reference the linear model is measured against (bench/bench_closure.cpp, issue #6):
/// at small strain the two coincide — the tangent at u = 0 *is* K — so every difference is large-deformation
/// physics, not a different discretisation.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/bundle.hpp"

namespace aneu::fem {

/// What the Newton solve needs of an elastic body: its energy, internal force and tangent on a fixed pattern.
/// NeoHookeanSolid is one; fem::PatchModel (patch.hpp), a neo-Hookean patch on a linear exterior, another.
class ElasticBody {
public:
    virtual ~ElasticBody() = default;
    virtual Eigen::Index dofs() const = 0;
    /// +∞ when inverted.
    virtual double energy(const Eigen::VectorXd& u) const = 0;
    /// @throws NumericalError when inverted
    virtual Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const = 0;
    /// Both triangles, on pattern(); `project`: positive semidefinite element tangents. @throws NumericalError
    virtual Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& u, bool project = false) const = 0;
    virtual const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const = 0;
    /// Adds tangent(u, project) into `values`, the value array of a larger matrix whose pattern holds this body's:
    /// this body's p-th stored pattern entry goes to values[where[p]]. A decorator (contact, clip) fills its own
    /// tangent so, with no copy of the body's (a patch's has millions of entries: its dense exterior block).
    /// The default makes tangent(u, project) and scatters it.
    virtual void add_tangent(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const {
        const Eigen::SparseMatrix<double, Eigen::RowMajor> K = tangent(u, project);
        for (Eigen::Index p = 0; p < K.nonZeros(); ++p) values[where[p]] += K.valuePtr()[p];
    }
    virtual double min_jacobian(const Eigen::VectorXd& u) const = 0;
    /// The largest fraction α ≤ 1 of the step du from u that the body admits (a contact's barrier must not be
    /// stepped through: continuous collision detection); 1 for a body without contact.
    virtual double max_step(const Eigen::VectorXd& u, const Eigen::VectorXd& du) const {
        (void)u;
        (void)du;
        return 1.0;
    }
};

/// Ψ(F) = μ/2 (tr FᵀF − 3) − μ ln J + λ/2 (ln J)² per unit reference volume (Bonet & Wood's compressible
/// neo-Hookean), μ and λ the Lamé constants of each region's E and ν. Total Lagrangian: first Piola stress
/// P = μ (F − F⁻ᵀ) + λ ln J F⁻ᵀ. Units: mm, N, MPa; energy in N·mm.
class NeoHookeanSolid final : public ElasticBody {
public:
    /// @param[in] V #N×3 reference nodes [mm]; T #T×4 or #T×10 (element.hpp ordering); region #T → materials
    /// @throws InputError bad sizes, indices or materials; MeshingError a reference element with Jacobian ≤ 0
    NeoHookeanSolid(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& region,
                    const std::vector<Material>& materials);

    Eigen::Index dofs() const override { return 3 * n_nodes_; }
    /// Stored strain energy at displacement u (3#N); +∞ when J ≤ 0 at some integration point (inverted).
    double energy(const Eigen::VectorXd& u) const override;
    /// Internal nodal forces ∂Ψ/∂u [N] (3#N). @throws NumericalError when an element is inverted
    Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const override;
    /// Tangent stiffness ∂²Ψ/∂u² [N/mm], both triangles, on a fixed pattern (the element graph). With `project`,
    /// each element's tangent loses its negative eigenvalues (positive semidefinite: projected Newton).
    /// @throws NumericalError when an element is inverted
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& u, bool project = false) const override;
    /// The tangent's sparsity pattern (values zero).
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override { return pattern_; }
    /// Smallest J = det F over the integration points (≤ 0: inverted).
    double min_jacobian(const Eigen::VectorXd& u) const override;

private:
    template <int NN>
    void init(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T);
    /// ∇u = Σ_a u_a ⊗ ∇₀N_a of element e at the integration point whose ∂N/∂X rows start at g (nn_×3).
    Eigen::Matrix3d displacement_gradient(const Eigen::VectorXd& u, Eigen::Index e, const double* g) const;

    Eigen::Index n_nodes_ = 0;
    int nn_ = 4;                        ///< nodes per element
    Eigen::MatrixXi T_;
    std::vector<double> mu_, lambda_;   ///< per element
    // Per integration point q (element q / points_per_element_): weight·det J₀ and ∂N/∂X (nn_×3, row-major).
    int points_per_element_ = 1;
    std::vector<double> w_;
    std::vector<double> dN_;
    // Tangent pattern: RowMajor 3#N×3#N, and for every element entry (3nn × 3nn, row-major) its value index.
    Eigen::SparseMatrix<double, Eigen::RowMajor> pattern_;
    std::vector<std::int64_t> slot_;
};

/// What one Newton solve leaves for the next on the same body: the free tangent's pattern, CHOLMOD's fill-reducing
/// ordering and symbolic factorisation. A solve whose free tangent has the same pattern as the last one's (the same
/// body pattern, the same fixed and prescribed DOFs) refactorises numerically only; any difference re-analyses.
/// (A simulator's patch: its pattern, with the dense block of the linear exterior, changes only when its contacts'
/// pairs do, and its analysis took 2.7-3.6 s of every sample frame.) One per body and thread; opaque.
struct NewtonWorkspace;
std::shared_ptr<NewtonWorkspace> make_newton_workspace();

/// Kept between the contact or clip decorators (ContactBody, ClipBody) made for successive solves on one body (a
/// simulator's frames): their merged tangent pattern. A new decorator takes the cached pattern when it was merged
/// over the same body pattern and holds every entry its pairs need; otherwise it merges the cached entries and its
/// own. (Each sample frame merged the patch's ~10⁷-entry pattern twice afresh: 4-6 s; and a pattern that stays
/// lets NewtonWorkspace keep its analysis.) Extra entries are structural zeros. One per decorator kind and body;
/// opaque.
struct PatternCache;
std::shared_ptr<PatternCache> make_pattern_cache();
/// How often a cache built a pattern and served one (for logs).
std::pair<int, int> pattern_cache_counts(const PatternCache& cache);

/// Options of the Newton solve.
struct NewtonOptions {
    double tolerance = 1e-9;   ///< converged when ‖free residual‖ ≤ tolerance · ‖internal force‖ (all DOFs) + 1e-14
    int max_iterations = 30;   ///< per load substep
    int max_total_iterations = 0;  ///< over all substeps of one call (0: no limit); past it the solve stops (NumericalError)
    int max_halvings = 10;     ///< smallest substep 2^−max_halvings of the prescribed increment (a substep that inverts
                               ///< elements or does not converge is halved)
    /// Real time (a simulator's physics frame): when max_total_iterations is spent, or no substep of the smallest
    /// size converges, return the last accepted state (converged = false, load_fraction how far the prescribed
    /// values got) instead of throwing; the next frame starts from it.
    bool keep_going = false;
    /// Force [N] the residual is also measured against: converged when ‖free residual‖ ≤ tolerance ·
    /// max(‖internal force‖, force_scale) + 1e-14. A problem with nothing prescribed or fixed (a released clip's
    /// spring against a free patch) has ‖internal force‖ → 0 at equilibrium, so it needs this floor.
    double force_scale = 0;
    /// Chord steps: a corrector iteration whose residual fell to at most this fraction of the last one's after a
    /// full step (α = 1) solves with the last factorisation instead of a new tangent (0: never). A factorisation
    /// of the patch's tangent is most of a frame; near convergence the old one is nearly as good.
    double chord_ratio = 0;
    /// A diagnostic (bench/bench_factor.cpp): when not empty, the first factorisation of this call first writes the
    /// free tangent's upper triangle there as a symmetric Matrix Market file (through a temporary name).
    std::string dump_free_tangent;
    /// Kept between calls (make_newton_workspace): the analysis is reused while the free tangent's pattern stays.
    /// Null: analysed in every call that needs a linear solve.
    std::shared_ptr<NewtonWorkspace> workspace;
    /// Set by another thread to stop the solve before its next substep or iteration (a real-time run that ends): with
    /// keep_going the last accepted state comes back (converged = false, NewtonResult::cancelled), else
    /// aneu::Cancelled is thrown. Null: not cancellable.
    const std::atomic<bool>* cancel = nullptr;
};

struct NewtonResult {
    Eigen::VectorXd u;          ///< 3#N [mm]
    Eigen::VectorXd reaction;   ///< per prescribed DOF, in its order: the internal force there [N] (what the constraint applies)
    int iterations = 0;         ///< Newton iterations over all substeps
    int substeps = 0;           ///< substeps the prescribed increment was split into
    int shifted = 0;            ///< iterations whose tangent was not positive definite (projected element tangents used)
    double residual = 0;        ///< final ‖free residual‖ / ‖internal force‖
    double min_J = 1;           ///< smallest det F at the end
    bool converged = true;      ///< false only with NewtonOptions::keep_going
    double load_fraction = 1;   ///< of the prescribed increment reached (< 1 only when not converged)
    std::string failure;        ///< why the last attempt failed, when not converged (for logs)
    bool cancelled = false;     ///< stopped by NewtonOptions::cancel
    int factorisations = 0;     ///< numeric Cholesky factorisations (predictors, iterations, shifted retries)
    /// The analysis came from NewtonOptions::workspace (the free tangent's pattern unchanged since the last call).
    bool analysis_reused = false;
    /// Load substeps accepted without a linear solve: moving the prescribed DOFs alone left the free ones in
    /// equilibrium (a held clip whose opening moved by rounding: no predictor, no factorisation).
    int unsolved_substeps = 0;
    /// Wall-clock seconds of the call's parts: the free tangent's pattern and CHOLMOD's ordering and analysis (once,
    /// at the first linearised solve; none when the call starts converged), tangent assembly, numeric
    /// factorisation, back substitution. The rest is residuals and energies (line searches, convergence checks).
    double setup_s = 0, tangent_s = 0, factorise_s = 0, back_solve_s = 0;
    /// Of the factorisations: those that found the matrix not positive definite, and their seconds (in factorise_s).
    int failed_factorisations = 0;
    int chord_steps = 0;        ///< corrector iterations solved with an earlier factorisation (NewtonOptions::chord_ratio)
    double failed_factorise_s = 0;
};

/// Static equilibrium without body or surface loads: u = 0 on `fixed_dofs`, u = value on each prescribed
/// (DOF, value), the other DOFs free, from the state `u0` (its prescribed entries are moved to the new values
/// along a straight path, in substeps). Newton's method on the energy: CHOLMOD Cholesky of the free tangent,
/// ordered and analysed once per call or kept in NewtonOptions::workspace (a tangent that is not positive definite — buckling — is replaced by
/// the sum of the element tangents projected onto positive semidefinite ones, shifted by a multiple of its
/// diagonal if still singular),
/// backtracking line search on the energy from the largest step the body admits (ElasticBody::max_step: a contact's
/// collision detection; an inverting step is never taken), and halving of the prescribed
/// increment when a substep does not converge. A substep whose prescribed move alone leaves the free DOFs within the
/// tolerance (and passes no contact: max_step) is taken as it is, without a linear solve.
/// @throws InputError bad DOF indices; NumericalError when no substep of the allowed size converges (names the
///         residual and the smallest J reached)
NewtonResult solve_neo_hookean(const ElasticBody& solid, const Eigen::VectorXi& fixed_dofs,
                               const std::vector<std::pair<int, double>>& prescribed, const Eigen::VectorXd& u0,
                               const NewtonOptions& options = {});

}  // namespace aneu::fem
