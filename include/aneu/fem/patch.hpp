// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A geometrically nonlinear patch inside the linear model (issue #15, item 2). The tetrahedra of the patch
/// are the neo-Hookean solid (hyperelastic.hpp: same elements, quadrature and materials as K); the rest of the
/// vessel stays linear and is condensed exactly onto the interface nodes I the patch shares with it:
///
///     S = K_II − K^patch_II − K_IE K_EE⁻¹ K_EI        (E: the DOFs of every node outside the patch, not fixed)
///
/// so the patch's energy is Ψ_patch(u) + ½ u_Iᵀ S u_I and its Newton solve (solve_neo_hookean, with contacts
/// as prescribed DOFs) sees the exterior's true linear stiffness. With a linear material in the patch the
/// result equals the linear model's to round-off; the exterior's displacement follows from u_I by one solve
/// with the factor of K_EE that the model keeps. The cost is paid when a patch is made (one factorisation
/// and 3·#I solves; bench/bench_closure.cpp measures it), not per frame.
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/bundle.hpp"
#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem {

class PatchModel final : public ElasticBody {
public:
    /// @param patch_tets indices into vol.tets (at least one)
    /// @param map_nodes  global nodes whose displacement the model should give cheaply for any patch state
    ///                   (mapped_displacement): the rows of K_EE⁻¹ K_EI for them are kept from the setup's
    ///                   interface solves (a simulator's visible surface outside the patch)
    /// @param cancel     set by another thread to stop the setup between blocks of interface solves (null: not
    ///                   cancellable)
    /// @throws InputError empty or out-of-range patch or map node, a model without the whole vessel outside it;
    ///         NumericalError K_EE not positive definite; aneu::Cancelled when cancel was set
    PatchModel(const VolumeData& vol, const FemData& fem, const std::vector<int>& patch_tets, const std::vector<int>& map_nodes = {},
               const std::atomic<bool>* cancel = nullptr);
    ~PatchModel() override;
    PatchModel(const PatchModel&) = delete;
    PatchModel& operator=(const PatchModel&) = delete;

    // ElasticBody, on the patch's DOFs (3 per patch node, in nodes() order)
    Eigen::Index dofs() const override;
    double energy(const Eigen::VectorXd& u) const override;
    Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const override;
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& u, bool project = false) const override;
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override;
    void add_tangent(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const override;
    double min_jacobian(const Eigen::VectorXd& u) const override;

    /// Global node of each patch node.
    const std::vector<int>& nodes() const;
    /// Patch index of a global node, −1 outside the patch.
    int local(int global_node) const;
    /// Whether a patch node is on the interface (shared with the linear exterior).
    bool on_interface(int local_node) const;
    Eigen::Index interface_nodes() const;
    /// The model's fixed DOFs that lie in the patch, in patch numbering.
    const Eigen::VectorXi& fixed_dofs() const;
    /// The patch's part of a full displacement (3#N → patch DOFs).
    Eigen::VectorXd restrict_to_patch(const Eigen::VectorXd& u_full) const;
    /// The whole model's displacement (3#N): the patch's, and the exterior's from the interface (linear).
    Eigen::VectorXd full_displacement(const Eigen::VectorXd& u_patch) const;
    /// Displacement (3 per node, in the order given to the constructor) of the map nodes for a patch state:
    /// a patch node's own, an exterior node's from the interface through the kept rows of −K_EE⁻¹ K_EI (a
    /// dense product, 3#map × 3#interface; no solve), zero for fixed DOFs. Equals full_displacement there.
    Eigen::VectorXd mapped_displacement(const Eigen::VectorXd& u_patch) const;
    /// Seconds to make the patch: the factorisation of K_EE and the interface solves.
    double setup_seconds() const;

private:
    struct Impl;
    std::unique_ptr<Impl> m;
};

}  // namespace aneu::fem
