// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Measures of a clipping's result on the deformed vessel (sim/assessment.cpp).
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"

namespace aneu::sim {

/// How much of the aneurysm's neck is occluded.
struct NeckOcclusion {
    double length_mm = 0.0;            ///< deformed length of the neck line on the lumen (the inner wall)
    double closed_mm = 0.0;            ///< of which the opposite inner walls touch or lie within the tolerance
    double fraction = 0.0;             ///< closed_mm / length_mm (0 when there is no neck)
    double min_gap_mm = 0.0;           ///< smallest lumen gap found across the neck line (negative: interpenetration)
    double max_interpenetration_mm = 0.0;  ///< largest depth of one inner wall through the opposite one (0: none)
    /// Per neck loop, per vertex in loop order: the lumen gap there (+inf: no opposite wall within reach), so a
    /// report can say where along the neck line it stays open.
    std::vector<std::vector<double>> gap_mm;
    std::vector<std::vector<Eigen::Vector3d>> points;  ///< the neck line's points on the deformed lumen, per loop
    std::vector<std::vector<int>> faces;               ///< the lumen face each point lies on
};

/// Neck occlusion on the deformed lumen `y` (#L×3, SimLumen::deformed). The neck line is the sac's border on
/// the lumen (SimLumen::neck_loops), smoothed (smoothed_neck_line; SimLumen::neck_line when set, else smoothed
/// here). At each of its points the lumen gap is the distance across the lumen (against the deformed normal
/// interpolated there) to the nearest opposite wall — faces whose deformed normal turns more than 120° from it,
/// not those round its face's corners or their one ring — negative when that wall lies behind the point within
/// its own wall (`wall_mm` per vertex: the walls pass through each other). A segment of the line is closed when
/// the gaps at both its ends are at most `gap_tol_mm`; where no opposite wall lies within 12 mm the gap is
/// infinite. Lengths are the deformed lumen's: where a clip flattens the neck, its two folds collapse to almost
/// no length. A clip across the neck that presses the walls together closes nearly all of it; a clip beside the
/// neck closes none.
NeckOcclusion neck_occlusion(const SimLumen& lumen, const Eigen::MatrixX3d& y, double gap_tol_mm, const Eigen::VectorXd& wall_mm);

/// The lumen passing through itself anywhere, not only on the neck line: lumen vertices lying behind a lumen face (out
/// of the lumen, into that face's wall) by more than 1 µm and at most `depth_mm` and the wall's thickness there
/// (SimLumen::wall_mm, its corners' mean, where known: deeper lies beyond the wall), their projection inside the face, that
/// lay in front of its plane at rest (fem::surface_crossings); faces within `exclude_rings` edges of the vertex do not
/// count. One ring, as the compliance frames' wall search (fem::ContactBody's default is two): an over-bent fold (the lumen's surface folded back onto itself
/// within two rings, session 45's C0054) is a crossing too, while a vertex cannot lie behind a face it shares an
/// edge with unless an element between them turned inside out.
/// Where the tissue is known (`tissue`: a nonlinear patch's elements round the face), a vertex behind a face counts
/// only if it lies inside the tissue, in an element that is not its own, deeper than 1 µm (fem::nodes_inside_elements;
/// C0001's vertices up to 0.49 mm behind a face lay less than 1 µm inside an element, t = 1.232 s): behind the face
/// but in no element it lies beyond a wall squeezed thinner than the depth, or beside the wall (session 47: C0001's
/// vertices 0.1-0.5 mm behind faces past the tips). Those are reported apart (`beside_*`), not as crossings.
struct LumenCrossing {
    double depth_mm = 0.0;                         ///< the deepest (0: none)
    int vertices = 0;                              ///< lumen vertices through a face
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  ///< the deepest vertex, deformed
    double beside_mm = 0.0;                        ///< the deepest vertex behind a face but in no tissue there
    int beside_vertices = 0;                       ///< such vertices (not counted in `vertices`)
};
/// The tissue round the lumen where a nonlinear patch holds it: per lumen vertex, the patch (−1: none; a vertex on
/// the patch's interface with the linear exterior has tissue outside the patch too: −1) and whether the vertex lies in
/// one of that patch's elements that is not its own, deeper than TISSUE_ROUNDOFF_MM.
struct LumenTissue {
    std::vector<int> patch;
    std::vector<char> inside;
};
/// The measure's rules, shared with aneusim's per-frame trace of the patch's walls (ANEU_WALL_TRACE).
constexpr int LUMEN_CROSSING_RINGS = 1;
constexpr double LUMEN_CROSSING_DEPTH_MM = 0.5;
/// A patch node counts as inside another element's tissue (Assessment::patch_nodes_in_other_tissue) deeper than this.
constexpr double TISSUE_ROUNDOFF_MM = 1e-3;
LumenCrossing lumen_crossing(const SimLumen& lumen, const Eigen::MatrixX3d& y, int exclude_rings = LUMEN_CROSSING_RINGS,
                             double depth_mm = LUMEN_CROSSING_DEPTH_MM, const LumenTissue* tissue = nullptr);

/// Where the lumen is about to meet itself: the lumen vertices (and the corners of the faces they meet) within
/// `approach_mm` in front of an opposite lumen face, or up to fem::WALL_THROUGH_MM behind it having lain in front of its
/// plane at rest (fem::contact_pairs on the faces turned into the lumen, LUMEN_CROSSING_RINGS left out), that lay more
/// than `apart_mm` from the face at rest (the distance to its closest point): walls the motion brought together, not
/// the lumen's own narrow places. With `outside` (one entry a lumen vertex), only the pairs with the vertex or a corner
/// of the face outside (aneusim: not a node of the nonlinear patch, or on its interface with the linear exterior).
/// Each vertex once, ascending.
/// @throws InputError positions or `outside` of another size than the lumen
std::vector<int> lumen_meeting(const SimLumen& lumen, const Eigen::MatrixX3d& y, double approach_mm, double apart_mm,
                               const std::vector<char>* outside = nullptr);

/// The lumen's edge length round each face at rest: the mean, over the faces sharing a vertex with it, of their
/// shortest edge (on a mesh of edge h, about h; across a stretched mesh, its fine direction: the resolution across
/// a fold, which sets the channel a flattened fold keeps on the mesh: bench/bench_fold.cpp, patch_sim_notes.md).
Eigen::VectorXd lumen_edges_mm(const SimLumen& lumen);

/// Whether the clip seals the sac off the parent, and if not, through how wide a channel blood still gets in.
struct NeckChannel {
    /// The widest channel of the deformed lumen joining the sac to the parent [mm]: the largest d such that the
    /// lumen's faces of width ≥ d connect a sac face to a parent face (both at least `clear_mm` from the neck
    /// line at rest), the width of a face being the diameter of the largest ball inside the lumen that touches
    /// the wall at its centroid. At most `cap_mm` (a lumen that wide is open); NaN without a neck.
    double width_mm = std::numeric_limits<double>::quiet_NaN();
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  ///< the channel's narrowest place (a face centroid, deformed)
    int face = -1;                                 ///< the face there (−1: none)
    int faces_measured = 0;                        ///< faces whose width was measured (the rest count as `cap_mm`)
    std::vector<double> face_width_mm;             ///< per lumen face: its width (`cap_mm` where not measured)
    /// Per lumen face: the widest channel joining it to the parent's faces (widest_reach; 0 on a piece of lumen
    /// without them). Blood reaches a face through a channel that wide: at most the tolerance, it is cut off.
    std::vector<double> reach_mm;
};

/// The fraction of the neck line (by deformed length, over the points `occ` measured on `lumen`) cut off
/// from the parent: segments whose ends lie on faces that the parent's lumen reaches only through channels at most
/// `gap_tol_mm` wide (NeckChannel::reach_mm) — their walls touch, or they lie on the sac's side of walls that touch.
/// A clip across the neck cuts off all of it; one on the sac's side above it seals the sac but leaves the neck line
/// reached (a neck remnant); one on the parent's side below it cuts it off with the sac. −1 without a reach.
double neck_cut_off_fraction(const NeckOcclusion& occ, const NeckChannel& channel, double gap_tol_mm);

/// A clip's jaws as a box for neck_in_jaws: hinge, unit axis (towards the tips) and up (the opening direction), length
/// and width [mm]; a point counts as within them up to margin_mm beyond their width and max_up_mm from their mid-plane
/// along up (infinite: at any height).
struct JawsBox {
    Eigen::Vector3d hinge, axis, up;
    double length_mm = 0, width_mm = 0;
    double margin_mm = 0, max_up_mm = std::numeric_limits<double>::infinity();
    double curve_radius_mm = 0, curve_from_mm = 0;  ///< curved blades (fem::ClipBlades): along and across their centre line
    double face_from_mm = 0;  ///< where the faces begin along the axis (fem::ClipBlades::face_from_mm): a point before it is not in the jaws
};
/// Where a neck line (closed loops of points) lies against clips' jaws: the fraction of its length (segment by
/// segment, at their midpoints) within some clip's jaws (face_from_mm ≤ along the axis ≤ length, within half the width plus the
/// margin of the mid-plane across it, within max_up_mm of it along up), and the farthest beside that width that a
/// midpoint along the jaws' length lies (0: none). NaN both without jaws or a line.
std::pair<double, double> neck_in_jaws(const std::vector<std::vector<Eigen::Vector3d>>& loops, const std::vector<JawsBox>& jaws);

/// The lumen's width at a point of face `face` (barycentric `w`) of the deformed lumen `y`: the diameter of the
/// largest ball inside the lumen that touches the wall there (the maximal inscribed sphere of VMTK's centrelines,
/// here tangent at a wall point: its centre lies along the inward normal interpolated there), at most `cap_mm`.
/// Across a slit it is the slit's gap, at a fold the fold's inner diameter, in a round tube its diameter. The
/// faces round the point's face (its two rings) constrain it by their vertices only: the ball does not rest on
/// the facets' kinks beside the point.
double lumen_width(const SimLumen& lumen, const Eigen::MatrixX3d& y, int face, const Eigen::Vector3d& w, double cap_mm);

/// The widest channel across a triangle surface between two sets of its faces: the largest d such that faces of
/// `width` ≥ d, joined across shared edges, connect a face of `a_side` to one of `b_side` (a maximin path, by
/// union–find over the faces widest first). Returns d and the face where the channel is narrowest; (0, −1) when the
/// two sides lie on different pieces of the surface. The neck's channel (neck_channel) and the flattened tube's
/// (bench/bench_fold.cpp).
std::pair<double, int> widest_channel(const Eigen::MatrixX3i& F, const std::vector<double>& width, const std::vector<char>& a_side,
                                      const std::vector<char>& b_side);

/// Per face of a triangle surface: the widest channel joining it to a face of `from` — the largest d such that
/// faces of `width` ≥ d, joined across shared edges, connect the two (its own width at most; a maximin path, by a
/// widest-first search from `from`); 0 for faces on pieces of the surface without a face of `from`.
std::vector<double> widest_reach(const Eigen::MatrixX3i& F, const std::vector<double>& width, const std::vector<char>& from);

/// The channel through the neck (NeckChannel) on the deformed lumen `y`; `sac_region` is the aneurysm's index in
/// SimLumen::face_region. Faces farther than `measure_mm` from the neck line at rest are taken as `cap_mm` wide.
/// Unlike neck_occlusion, it does not ask where the seal lies: walls squeezed beside the jaws that leave the neck's
/// border open can still seal the sac, and a border closed everywhere can leave a channel round a fold.
NeckChannel neck_channel(const SimLumen& lumen, const Eigen::MatrixX3d& y, int sac_region, double cap_mm = 2.0, double clear_mm = 1.0,
                         double measure_mm = 6.0);

/// Whether the parent artery stays open under the clip: the narrowest place its blood passes between the parent's ends,
/// deformed against at rest. A clip set too far towards the parent seals the neck by narrowing the parent (a stenosis).
struct ParentChannel {
    int ends = 0;        ///< pieces of the parent's lumen at least `end_mm` from the neck line at rest (its inflow and outflows)
    /// Of the pairs of ends, the one narrowed most: the widest channel between them (the diameter of the largest ball that
    /// passes, as NeckChannel's) at rest and deformed, and 1 − deformed / rest (0: as wide as at rest; 1: closed).
    /// Negative where that passage widened. NaN with fewer than two ends.
    double rest_mm = std::numeric_limits<double>::quiet_NaN();
    double width_mm = std::numeric_limits<double>::quiet_NaN();
    double narrowing = std::numeric_limits<double>::quiet_NaN();
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  ///< that channel's narrowest place, deformed (a face centroid)
};
/// The parent's channel (ParentChannel) on the deformed lumen `y`: the parent's faces (those not in `sac_region`) at
/// least `end_mm` from the neck line at rest, grouped into pieces joined across edges, are its ends; faces nearer the
/// neck line are measured (lumen_width at their centroid, at most `cap_mm`), farther ones count as `cap_mm`; the sac's
/// faces count as 0 (the parent's blood is not routed through the aneurysm). Without a neck, nothing is measured.
ParentChannel parent_channel(const SimLumen& lumen, const Eigen::MatrixX3d& y, int sac_region, double cap_mm = 8.0, double end_mm = 6.0);

/// Writes the deformed lumen `y` (SimLumen::X's rows) as a Wavefront OBJ with the neck line's points and gaps, the faces'
/// widths and the channel after it as comments: what bench/render_channel.py draws (`ANEU_LUMEN_OBJ`, aneu_bench_compliance).
/// False where the file cannot be written.
bool write_lumen_obj(const std::string& path, const SimLumen& lumen, const Eigen::MatrixX3d& y, const NeckOcclusion& occ, const NeckChannel& channel);

}  // namespace aneu::sim
