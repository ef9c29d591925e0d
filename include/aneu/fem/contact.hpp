// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Wall-on-wall contact (issue #15, item 4): opposite parts of a body's surface — the inner walls of a neck
/// the clip flattens — touch and do not pass through each other. Vertex–triangle pairs (a vertex and a face of
/// the opposite wall facing it; neighbours excluded: a vertex within `exclude_rings` edges of a face on the
/// surface mesh is the same wall) repel by a barrier on their distance (the incremental-potential contact of
/// Li et al. 2020): d is the distance from the vertex to the closest point of the closed triangle (its
/// inside, an edge or a corner), so it is C1 as a vertex passes from one face to the next; each pair adds
///     κ d̂² b(d²/d̂²),   b(x) = −(x − 1)² ln x for x < 1, 0 beyond,
/// which is C2, zero from d = d̂ (`gap_mm`) outward and infinite at d = 0. Newton's line search never steps
/// through a face: `max_step` bounds each step by continuous collision detection (additive CCD, Li et al. 2021).
/// It decorates an ElasticBody (the neo-Hookean solid or the nonlinear patch), so the contact is solved in the
/// same Newton problem as the blades. Candidate pairs are collected when the decorator is made (within
/// `search_mm` of each other in the state it starts from, and not behind the face there: a crease of the wall or
/// the far side of a fold), which fixes the tangent's pattern for one solve; make a new one for the next step.
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include <mutex>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/fem/hyperelastic.hpp"

namespace aneu::fem {

struct ContactParams {
    double gap_mm = 0.01;        ///< d̂: the barrier acts on pairs nearer than this; touching walls end between 0 and d̂ apart
    double stiffness = 0;        ///< κ [N/mm]; 0 = the largest diagonal entry of the body's tangent at rest
    double search_mm = 0.6;      ///< candidate pairs: nearer than this in the starting state
    int exclude_rings = 2;       ///< a vertex within this many surface edges of a face's corners is its neighbour, never its pair
    double depth_mm = 0.0;       ///< min_distance: a vertex more than this behind a face is on the far side (0 = 0.25 mm)
    /// Each pair's 12 × 12 tangent projected onto a positive semidefinite one (projected Newton, as IPC does): the
    /// barrier's curvature across a face edge or corner is negative. false: the exact Hessian (tangent(u, true)
    /// projects it anyway).
    bool project_pairs = false;
    /// Vertices paired with every face whose centre lies within the face's radius + `close_search_mm` of them
    /// where the solve starts, whatever the normals or rings (but the faces round the vertex itself): a vertex
    /// that a trial solve took through a face its ordinary pairs left out (solve_without_crossings).
    std::vector<int> close_vertices;
    double close_search_mm = 0;
    /// Kept between the decorators of successive solves (make_pattern_cache); null: each merges its own pattern.
    std::shared_ptr<PatternCache> pattern_cache;
    /// Which surface each face belongs to (one entry a face of the surface the pairs are searched on; empty: all one
    /// surface). A vertex pairs only with the faces of its own surface (a vertex's surface: its faces'), close vertices
    /// included: the lumen's vertices with the lumen's faces, the outer surface's with the outer surface's. Across the
    /// wall a lumen vertex lies behind an outer face by the wall's thickness, facing it; a squeezed wall's less.
    std::vector<int> face_surface;
};

namespace detail {
struct MergedPattern;
}

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
    const Eigen::SparseMatrix<double, Eigen::RowMajor>& pattern() const override;
    void add_tangent(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const override;
    double min_jacobian(const Eigen::VectorXd& u) const override { return m_body.min_jacobian(u); }

    /// Candidate vertex–face pairs.
    std::size_t candidates() const { return m_pairs.size(); }
    /// Pairs in contact (d < gap) at u, and the smallest signed distance among the candidates (negative: the
    /// vertex is behind its face, over it, by less than depth_mm; interpenetration).
    std::size_t active(const Eigen::VectorXd& u) const;
    double min_distance(const Eigen::VectorXd& u) const;
    double stiffness() const { return m_kappa; }
    /// Whether (vertex v, face f) is one of the candidate pairs.
    bool is_pair(int v, int f) const;
    /// The largest α ≤ 1 such that no candidate vertex comes nearer to its face than a tenth of its distance at u
    /// along u + α du (additive CCD).
    double max_step(const Eigen::VectorXd& u, const Eigen::VectorXd& du) const override;

private:
    struct Pair {
        int v, f;
    };
    /// The signed distance of the pair at u: to the closest point of the face, negative when the vertex projects
    /// into the face from behind it.
    double signed_distance(const Eigen::VectorXd& u, const Pair& p) const;
    Eigen::Vector3d x(const Eigen::VectorXd& u, int node) const { return m_X.row(node).transpose() + u.segment<3>(3 * node); }
    /// The tangent's pattern (the body's and a 12 × 12 block per pair), made when first needed: a patch's has
    /// millions of entries (its dense exterior block), and a frame whose blades touch nothing needs none.
    void build_pattern() const;

    const ElasticBody& m_body;
    Eigen::MatrixX3d m_X;
    Eigen::MatrixX3i m_F;
    ContactParams m_p;
    double m_kappa = 0;
    std::vector<Pair> m_pairs;
    mutable std::once_flag m_pattern_once;
    mutable std::shared_ptr<const detail::MergedPattern> m_merged;  // the pattern, and where the body's entries lie in it
    mutable std::vector<std::array<std::int64_t, 144>> m_pair_slots;  // 12 × 12 entries of each pair
    // add_tangent into a decorator's matrix: the body's entries' places there (a buffer kept between calls).
    mutable std::mutex m_compose_mutex;
    mutable std::vector<std::int64_t> m_compose;
    /// The pairs' terms at u, added into values at where[slot] (where null: the slots themselves).
    void add_pair_tangents(const Eigen::VectorXd& u, bool project, double* values, const std::int64_t* where) const;
};

/// ContactBody's candidate vertex–face pairs (vertex, face) of the surface `faces` at the state u: a vertex and a face
/// without it, beyond `exclude_rings` edges of its corners, within `search_mm` of it, facing each other (vertex and
/// face normals more than 90° apart) and not behind it (by `behind_mm` or more: hard contact leaves a pressed vertex a
/// hair behind its face); each of `close_vertices` with every face within reach but its own. u: 3 per node of X. With
/// `face_surface`, a vertex and faces of its own surface only.
/// @throws InputError a state or face_surface that does not fit, a face naming a node outside X
std::vector<std::array<int, 2>> contact_pairs(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, const ContactParams& p,
                                              double behind_mm = 0);

/// u with the walls `faces` apart: every candidate pair's vertex (contact_pairs at u, with a vertex up to 0.05 mm behind
/// its face a pair) at least `delta_mm` in front of its face, a vertex nearer or behind moved along the face's normal
/// (a few passes: a vertex's move changes its other pairs). A state a ContactBody's barrier can start from, made where
/// another contact model left the walls: hard contact leaves them exactly touching or a hair through, where the
/// barrier is infinite, its pairs are not found (a vertex on or behind a face is not its pair), and a step from ~0
/// apart is cut to ~0. Make the ContactBody at the result. 0 < delta_mm < p.gap_mm.
Eigen::VectorXd separate_walls(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, const ContactParams& p, double delta_mm);

/// The signed distance from p to the closest point of the triangle (a, b, c) (negative when p projects into the face
/// from behind it) and, with grad, its gradient over (p, a, b, c).
double signed_vertex_face_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                   Eigen::Matrix<double, 12, 1>* grad = nullptr);

/// A surface vertex lying behind a face of the same surface (its closest point inside the face, on the face's
/// back, less than `depth` deep) that lay in front of the face's plane in the reference shape: the surface passed
/// through itself there. (One behind the plane at rest, however deep or wherever beside the face, lies on its far
/// side: another lumen beyond the wall, squeezed nearer.)
struct SurfaceCrossing {
    int v = -1, f = -1;
    double depth_mm = 0;  ///< how far behind the face (> 0)
};
/// Every crossing of the surface `faces` (reference X, displacement u) by its own vertices, independent of any
/// candidate pairs (a ContactBody's pairs are fixed where its solve starts; this looks at all of them): vertices
/// within `exclude_rings` edges of a face's corners are its neighbours and never count; `depth` bounds how far
/// behind a face a vertex still counts as through it (beyond lies another part of the body). A uniform grid
/// keeps it near linear in the surface's size.
/// `face_depth` (one per face, each ≤ depth; null: none): a face's own bound instead. `face_surface` (one per face;
/// null or empty: one surface): a vertex counts only behind the faces of its own surface (ContactParams::face_surface).
std::vector<SurfaceCrossing> surface_crossings(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u, int exclude_rings,
                                               double depth, const Eigen::VectorXd* face_depth = nullptr, const std::vector<int>* face_surface = nullptr);

/// Per node of a body with `nodes` nodes, the surface its faces belong to (face_surface: one entry a face; −1: a node on
/// no face); empty when face_surface is. A node on faces of two surfaces takes its first face's.
/// @throws InputError a face_surface whose size is not the faces' count, a face naming a node outside the body
std::vector<int> vertex_surfaces(const Eigen::MatrixX3i& faces, const std::vector<int>& face_surface, Eigen::Index nodes);

/// Per query node, an element of `elements` whose tissue holds it although the node is not one of its nodes (−1:
/// none): where a surface vertex that lies behind a face of its own surface really is inside the wall behind that face,
/// as against beside it or beyond a wall squeezed thinner than it was (session 47: C0001's vertices 0.1-0.5 mm behind
/// lumen faces past the clip's tips). `x`: the nodes' positions as they are; `elements`: rows of 4 node indices, or of
/// 10 (element.hpp's order), each then split at its mid-edge nodes into its eight straight tetrahedra (four at the
/// corners, four round the mid-edge diagonal 4-9), so that a curved element is followed to its mid-edge nodes. Inside
/// means in front of each of a tetrahedron's faces, or on one it shares with another tetrahedron (the tissue goes on
/// across it). A uniform grid over the tetrahedra's boxes keeps it near linear in the mesh's size.
/// `depth` (null: not wanted): per query node inside, an estimate of how deep: over the elements holding it, for a
/// node on the mesh's boundary the least distance to an element's own faces on the boundary (where the tissue ends) or
/// shared with one of the node's own elements (back into its own tissue), and to the edges and corners it shares with
/// those (where it meets the node's own tissue), or, for an element with no such face, and for a
/// node inside the mesh (its elements tangled: it came through no surface), to all its own faces (a lower bound); 0
/// for a node in no element. (Not the exact distance to the tissue's boundary: a
/// boundary face of an element that does not hold the node may lie nearer.) The element returned is the one giving it.
/// @throws InputError a node index out of range, elements with neither 4 nor 10 columns
std::vector<int> nodes_inside_elements(const Eigen::MatrixX3d& x, const Eigen::MatrixXi& elements, const std::vector<int>& query,
                                       std::vector<double>* depth = nullptr);

/// After a solve from u0 to u1 left the given (vertex, face) crossings: each crossing vertex and its one ring become
/// close vertices of cp (paired with every face within reach whatever the normals or rings), the reach being twice
/// how far the vertex and the face moved plus the search distance. The repeat of solve_without_crossings and of the
/// compliant wall frames.
void pair_crossings_closely(ContactParams& cp, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0, const Eigen::VectorXd& u1,
                            const std::vector<std::pair<int, int>>& crossings);

/// Whether pairing `crossings` (vertex, face) closely would give a solve anything new: some crossing's vertex is not
/// yet one of `close_vertices` (sorted), or is not paired with the face it went through (`pairs`: (vertex, face),
/// any order). A crossing of a face the vertex is closely paired with had its pair already, and its row was left out
/// on purpose (the vertex started behind the face's plane: a crease); solved again, the frame comes out the same.
bool crossings_need_pairs(const std::vector<std::pair<int, int>>& crossings, const std::vector<std::array<int, 2>>& pairs,
                          const std::vector<int>& close_vertices);

/// A solve with wall contact that no vertex passes through. `solve` is run with a ContactBody made at `u0` (the
/// body's DOFs; the solve's own state may append more, e.g. a clip's opening). Where its end state has a vertex
/// behind a face it was not behind at u0 (surface_crossings, `depth`), the vertex went through a face its pairs
/// left out (beyond the frame start's search, or an opposite face the normals or rings excluded, round the edge
/// of the face it was paired with): the solve is run again from u0 with each such vertex, and its one ring,
/// paired with every face within reach of where it went (ContactParams::close_vertices), up to `max_rounds`
/// more times. `left`: the crossings of the last round (empty: none).
struct CrossingFreeSolve {
    NewtonResult result;
    int rounds = 0;                      ///< solves run again
    std::vector<SurfaceCrossing> left;   ///< crossings after the last one that were not there at u0
    double deepest_mm = 0;               ///< the deepest vertex behind a face at the end, at u0's too (0: none)
    double deepest_start_mm = 0;         ///< the deepest vertex behind a face at u0 (0: none)
    std::size_t pairs = 0;               ///< candidate pairs of the last solve
    /// The close vertices (ContactParams::close_vertices) the last solve paired with every face near them: the
    /// given ones and the crossings' rings. A caller solving step after step passes them on to the next step: a
    /// vertex the barrier holds off a face its ordinary pairs leave out would otherwise go through it again there,
    /// and cost a repeat every step.
    std::vector<int> close_vertices;
};
CrossingFreeSolve solve_without_crossings(const ElasticBody& body, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& faces, const Eigen::VectorXd& u0,
                                          ContactParams cp, const std::function<NewtonResult(const ContactBody&)>& solve, double depth = 0.25,
                                          int max_rounds = 3);

}  // namespace aneu::fem
