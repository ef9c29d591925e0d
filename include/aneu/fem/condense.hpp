// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Static condensation of the stiffness onto the simulated surface DOFs: W = (K⁻¹)_MM, the compliance
/// seen from M (equal to the inverse of the Schur complement of K onto M). Always computed in double.
#include <cstdint>
#include <memory>
#include <string>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/bundle.hpp"
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::fem {

enum class CondenseMethod {
    SPARSE,  ///< CHOLMOD supernodal LLᵀ (METIS nested dissection), Y = L⁻¹ P E_M by a sparse forward solve, W = YᵀY by per-supernode SYRK
    DENSE,   ///< the simple reference: S = K_MM − K_MI K_II⁻¹ K_IM formed densely, W = S⁻¹ by LAPACK dpotrf + dpotri
};

/// Parameters of `aneuprep condense`.
struct CondenseParams {
    CondenseMethod method = CondenseMethod::SPARSE;
    Precision precision = Precision::FLOAT32;  ///< storage precision of W (computation is double)
    int tile_size = 512;                       ///< tile edge of W (see TiledSymmetric): also the SYRK block size
    std::string ordering = "metis";            ///< fill-reducing ordering of K: metis, nesdis (CHOLMOD's), amd
    double memory_limit_gb = 0.0;              ///< refuse beyond this predicted peak; 0 = 90 % of MemAvailable
    int residual_columns = 4;                  ///< columns of W checked against independent sparse solves
};
/// The numerical options of a condensation, declared once (`aneuprep condense` includes them).
inline const opt::Spec<CondenseParams>& condense_numeric_spec() {
    using namespace opt;
    using P = CondenseParams;
    static const Spec<P> spec = [] {
        Spec<P> s("condense");
        s.choice<CondenseMethod>("method", &P::method, {{"sparse", CondenseMethod::SPARSE}, {"dense", CondenseMethod::DENSE}},
                                 "sparse (CHOLMOD + SYRK) or dense (Schur complement + LAPACK)")
            .choice<Precision>("precision", &P::precision, {{"float32", Precision::FLOAT32}, {"float64", Precision::FLOAT64}},
                               "storage precision of W (computed in double)");
        s.integer("tile-size", &P::tile_size, closed(8, 4096), "tile edge of W")
            .text("ordering", &P::ordering, {"metis", "nesdis", "amd"}, "fill-reducing ordering of K")
            .real("memory-limit-gb", &P::memory_limit_gb, "GB", ge(0), "refuse above this predicted peak (0 = 90 % of available)")
            .integer("residual-columns", &P::residual_columns, closed(0, 1000), "columns of W checked against independent sparse solves");
        return s;
    }();
    return spec;
}
/// @throws InputError naming the field
inline void validate(const CondenseParams& p) { condense_numeric_spec().validate(p); }

/// The factor of K's free block (CHOLMOD supernodal L Lᵀ with the condensation's ordering) that condense made for W, kept
/// for solves with that block: fem::Linearisation's free step and frame displacements, without factorising K again.
class CondenseFactor {
public:
    CondenseFactor();
    ~CondenseFactor();
    CondenseFactor(const CondenseFactor&) = delete;
    CondenseFactor& operator=(const CondenseFactor&) = delete;
    /// K_ff⁻¹ b, b on the free DOFs (those not fixed, in increasing order). One caller at a time (CHOLMOD's workspace).
    Eigen::VectorXd solve(const Eigen::VectorXd& b) const;
    /// K_ff⁻¹ B for the columns of B, one CHOLMOD solve
    Eigen::MatrixXd solve_columns(const Eigen::MatrixXd& B) const;
    struct Impl;
    std::unique_ptr<Impl> m;
};

/// Condenses K onto the kept DOFs.
/// @param[in] K           3#N×3#N stiffness [N/mm], both triangles (as assemble_stiffness returns); the SPARSE
///                        method reads only the upper triangle (entries j ≥ i of row i), so K stored upper-only serves too
/// @param[in] fixed_dofs  DOFs held at zero (removed from K)
/// @param[in] kept_dofs   DOFs of M (unique, not fixed)
/// @return the DOF map and W with diagnostics (method, seconds per step, flops, GFLOP/s, predicted and
///         measured memory, residual of sample columns, condition estimate of K). The rows of W follow
///         the factor's elimination order (SPARSE) or the order of kept_dofs (DENSE); dof_node/dof_axis
///         say which DOF each row is.
/// @throws InputError bad DOF sets, or a predicted peak memory beyond the limit (with the figures);
///         NumericalError K is not positive definite once the fixed DOFs are removed
/// @param[out] factor     if not null, the factor of K_ff kept for solves (SPARSE method only; null with DENSE)
CondensedData condense(const Eigen::SparseMatrix<double, Eigen::RowMajor>& K, const Eigen::VectorXi& fixed_dofs,
                       const Eigen::VectorXi& kept_dofs, const CondenseParams& p, Reporter& rep = null_reporter(),
                       std::unique_ptr<CondenseFactor>* factor = nullptr);

/// MemAvailable of /proc/meminfo [bytes] (0 if unknown).
std::uint64_t available_memory_bytes();
/// Peak resident memory of this process so far [bytes] (VmHWM).
std::uint64_t peak_memory_bytes();

}  // namespace aneu::fem
