// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Wall-on-wall contact (issue #15, item 4): opposite parts of a body's surface — the inner walls of a neck
/// the clip flattens — touch and do not pass through each other. Vertex–triangle pairs, one-sided (a vertex
/// is pushed back only from the front of a face, along the face's deformed normal), neighbours excluded
/// (a vertex within `exclude_rings` edges of a face on the surface mesh is the same wall), a penalty
/// ½ κ (gap − d)² when the vertex comes nearer than `gap_mm` to the face. It decorates an ElasticBody (the
/// neo-Hookean solid or the nonlinear patch), so the contact is solved in the same Newton problem as the
/// blades' prescribed displacements. Candidate pairs are collected when the decorator is made (within
/// `search_mm` of each other in the state it starts from, and not already behind the face there: a crease of
/// the wall or the far side of a fold), which fixes the tangent's pattern for one solve; make a new one for the
/// next load step.
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem {

struct ContactParams {
    double gap_mm = 0.01;        ///< a vertex is held at about this distance in front of a face
    double stiffness = 0;        ///< κ [N/mm] per pair; 0 = 100 × the largest diagonal entry of the body's tangent at rest
    double search_mm = 0.6;      ///< candidate pairs: nearer than this in the starting state
    int exclude_rings = 2;       ///< a vertex within this many surface edges of a face's corners is its neighbour, never its pair
    double depth_mm = 0.0;       ///< a vertex more than this behind a face is on the far side, not in contact (0 = 0.25 mm)
};

class ContactBody final : public ElasticBody {
public:
    /// @param X      reference positions of the body's nodes
    /// @param faces  surface triangles that can touch (node indices), normals towards where the opposite wall is
    /// @param u0     the state the solve starts from (candidate pairs are found in it: a vertex and a face facing each
    ///               other, the vertex normal and the face normal more than 90° apart)
    ContactBody(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0,
                const ContactParams& p = {});
    Eigen::Index dofs() const override { return m_body.dofs(); }
    double energy(const Eigen::VectorXd& u) const override;
    Eigen::VectorXd internal_force(const Eigen::VectorXd& u) const override;
    Eigen::SparseMatrix<double, Eigen::RowMajor> tangent(const Eigen::VectorXd& u, bool project = false) const override;
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override { return m_pattern; }
    double min_jacobian(const Eigen::VectorXd& u) const override { return m_body.min_jacobian(u); }

    /// Candidate vertex–face pairs.
    std::size_t candidates() const { return m_pairs.size(); }
    /// Pairs in contact (d < gap) at u, and the smallest signed distance among the candidates in front of
    /// their face (negative: interpenetration).
    std::size_t active(const Eigen::VectorXd& u) const;
    double min_distance(const Eigen::VectorXd& u) const;
    double stiffness() const { return m_kappa; }

private:
    struct Pair {
        int v, f;
    };
    /// Distance of the pair at u: d, barycentrics and the face normal; false when the vertex does not project
    /// onto the face or lies beyond `depth` behind it.
    bool measure(const Eigen::VectorXd& u, const Pair& p, double& d, Eigen::Vector3d& b, Eigen::Vector3d& n) const;
    /// The same without the gap and depth limits: whether the vertex projects onto the face, and d.
    bool project(const Eigen::VectorXd& u, const Pair& p, double& d, Eigen::Vector3d& b, Eigen::Vector3d& n) const;
    Eigen::Vector3d x(const Eigen::VectorXd& u, int node) const { return m_X.row(node).transpose() + u.segment<3>(3 * node); }

    const ElasticBody& m_body;
    Eigen::MatrixX3d m_X;
    Eigen::MatrixX3i m_F;
    ContactParams m_p;
    double m_kappa = 0;
    std::vector<Pair> m_pairs;
    Eigen::SparseMatrix<double, Eigen::RowMajor> m_pattern;
    std::vector<std::int64_t> m_body_to_pattern;
    std::vector<std::array<std::int64_t, 144>> m_pair_slots;  // 12 × 12 entries of each pair
};

}  // namespace aneu::fem
