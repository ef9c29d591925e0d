// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Assembly of the global stiffness matrix of a tetrahedral mesh, and the checks that it can be solved.
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::fem {

/// @throws InputError naming the region if E ≤ 0 or ν ∉ (−1, 0.5), or if there are fewer materials than regions
void validate_materials(const std::vector<Material>& materials, int n_regions);

/// Global stiffness K [N/mm] of a linear (T: #T×4) or quadratic (#T×10) tetrahedral mesh, both triangles
/// stored, DOF 3·node + axis, no boundary conditions. Element matrices are assembled in parallel (OpenMP)
/// into a precomputed sparsity pattern.
/// @param[in] V #N×3 nodes [mm]; T elements; region #T indices into materials
/// @throws InputError bad materials or indices; MeshingError an inverted or degenerate element (named)
Eigen::SparseMatrix<double, Eigen::RowMajor> assemble_stiffness(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T,
                                                                const Eigen::VectorXi& region,
                                                                const std::vector<Material>& materials,
                                                                Reporter& rep = null_reporter());

/// Refuses a mesh whose stiffness would be singular once `fixed_nodes` are held: no fixed node at all, a
/// node that belongs to no element, or a connected piece of the mesh with no fixed node.
/// @throws InputError saying which, with a node of the offending piece and its position
void check_constrained(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T, const Eigen::VectorXi& fixed_nodes);

/// A 10-node mesh from a 4-node one: one new node at the midpoint of every edge (shared between elements).
struct QuadraticMesh {
    Eigen::MatrixX3d V;   ///< the original nodes first, then the mid-edge nodes
    Eigen::MatrixXi T;    ///< #T×10 in the order of element.hpp
    Eigen::MatrixX2i edge_of_mid;  ///< corner pair of each new node (row k = node #V_linear + k)
};
QuadraticMesh quadratic_mesh(const Eigen::MatrixX3d& V, const Eigen::MatrixXi& T4);

/// The node set of a quadratic mesh that corresponds to a corner node set: a mid-edge node belongs to it
/// when both corners do and the edge lies on a boundary face whose corners all do.
Eigen::VectorXi quadratic_node_set(const QuadraticMesh& q, const Eigen::MatrixXi& T4, int n_linear_nodes,
                                   const Eigen::VectorXi& corner_set);

/// The 6-node faces (corners, then mid-edges (0,1), (1,2), (2,0)) of corner faces F3 of a quadratic mesh.
Eigen::MatrixXi quadratic_faces(const QuadraticMesh& q, int n_linear_nodes, const Eigen::MatrixX3i& F3);

/// The mid-edge nodes of a 10-node mesh (T10: #T×10, element.hpp's order), looked up by their two corners.
class MidEdgeNodes {
public:
    /// @param tets which rows of T10 to take (empty: all)
    /// @throws InputError T10 is not #T×10, or a row index is outside it
    explicit MidEdgeNodes(const Eigen::MatrixXi& T10, const std::vector<int>& tets = {});
    /// The node between corners a and b (either order); −1 where a–b is no edge of the elements taken.
    int operator()(int a, int b) const;

private:
    std::vector<std::pair<std::uint64_t, int>> m_sorted;  // (corner pair key, mid node), sorted by key
};

/// The quadratic surface as flat triangles: each corner triangle (a, b, c) of F3 split at its edges' mid-edge nodes
/// into (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca), in its orientation (rows 4f … 4f + 3 for triangle f).
/// Contact on these acts on every node of the 10-node elements' faces; on the corner triangles alone the quadratic
/// surface between the corners bulges through what it touches and away from it (bench/bench_fold.cpp: a tube
/// flattened to 0.7 × its two walls' thickness, one layer of elements, needs 2.9 × the blade force once its walls
/// touch along their mid-edge nodes too).
/// @throws InputError an edge of F3 with no mid-edge node in `mid`
Eigen::MatrixX3i quadratic_surface_triangles(const MidEdgeNodes& mid, const Eigen::MatrixX3i& F3);

/// Boundary faces of a tetrahedral mesh (faces used by exactly one tetrahedron), oriented outward,
/// as corner-node triples.
Eigen::MatrixX3i boundary_faces(const Eigen::MatrixXi& T4);

}  // namespace aneu::fem
