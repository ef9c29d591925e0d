// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Scene planning for any case bundle (`aneusim plan`): the neck from the labels, a straight clip that approaches
/// along the neck's long axis from the freer side and closes across it, a suction tube parked nearby (sim/plan.cpp).
#include <string>

#include <Eigen/Core>

#include "aneu/sim/model.hpp"

namespace aneu::sim {

/// The neck's frame: the sac's border on the lumen (SimLumen::neck_loops), its centre (by length), principal axes
/// (long, short: in the neck plane) and the plane's normal towards the sac, with the neck's extents along them.
struct NeckFrame {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d long_axis = Eigen::Vector3d::UnitX();
    Eigen::Vector3d short_axis = Eigen::Vector3d::UnitY();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< towards the sac
    double length_mm = 0.0;  ///< extent along the long axis
    double width_mm = 0.0;   ///< extent along the short axis
    double line_mm = 0.0;    ///< length of the neck line's border (the smoothed line the occlusion is measured on)
    double label_line_mm = 0.0;  ///< length of the label loops' mesh edges (a staircase around the border)
};
/// The neck line's border, loop by loop, at rest: the smoothed neck line's points (SimLumen::neck_line), or the
/// label loop's vertices where a loop has none.
std::vector<std::vector<Eigen::Vector3d>> neck_border(const SimLumen& lumen);
/// @throws InputError when the bundle has no neck (no "aneurysm" region on the lumen under the condensed surface)
NeckFrame neck_frame(const SimModel& m);

struct PlanOptions {
    double approach_mm = 12.0;    ///< the applier starts this far back along the long axis
    double max_opening_deg = 60.0;
    bool flow = false;            ///< outputs.flow = STEM_flow.h5: the residual sac inflow after the session (aneuprep flow)
    /// The least share of the neck's border the jaws' width must cover: a pose below it (the only clear way over
    /// the dome or the parents) is refused. A quarter: the corpus's planned poses cover 52-100 % where a clear
    /// way across the neck exists; one that covers less is beside the neck, not across it.
    double min_cover = 0.25;
    /// How far behind the blades' heel they turn (ClipModel::fulcrum_mm; 0: about the heel). The planned clip model
    /// carries it, the applier's pose is the fulcrum's, its openings are the heel-hinged clip's scaled to open the
    /// jaws as wide at the neck's far end, and the arms between the fulcrum and the heel are checked as blade.
    double fulcrum_mm = 0.0;
    /// A curved clip (ClipModel::jaw_curve_radius_mm; 0: straight): its blades bend from the heel on a circle of this
    /// radius [mm], towards the sac or away from it, whichever covers more of the neck line; the pose search, the
    /// clearance checks and the cover follow the bent blades.
    double curve_radius_mm = 0.0;
    /// Tandem clips (straight clips only): a second applier with the same clip model beside the first, its path the
    /// first's moved a jaw's width and TANDEM_GAP_MM across the blades (along axis × up), to the side where more of the
    /// neck line lies beside the first clip's jaws at rest (within the second's), or, where none does, to the parent's
    /// side, where the closing jaws squeeze the line (measured on the corpus's sidewall necks: 0.5-0.8 mm towards the
    /// parent). Both close together. The second path's approach, parent and clamped-end checks are reported in the
    /// header, not chosen for: a second clip the clamped ends forbid is not planned (said in the header).
    bool tandem = false;
    /// A pose is clear of the parent only where no lumen vertex of the parent (over 1 mm from the neck's border) lies
    /// between its open jaws across their whole width. By default only the half of the width towards the sac counts:
    /// a band that grazes the top of the parent beyond a sidewall neck pinches a sliver of its wall and is allowed.
    /// On the sample and C0001 the planned jaws close on the parent's top there (24-50 vertices in the parent's
    /// half). A pose clear across the whole width presses only the neck but covers less of its line: measured worse
    /// on both (the sample 57.9 -> 29.5 % closed, parent narrowed 40 -> 29 %; C0001 0 %; compliance.md, session 63),
    /// hence not the default.
    bool parent_whole_band = false;
};
/// How far apart the tandem clips' jaws stand (PlanOptions::tandem): their blades' facing edges [mm].
constexpr double TANDEM_GAP_MM = 0.1;

/// The planned scene as JSON text (docs/scene_format.md): `bundle_ref` is written as the scene's bundle, the
/// outputs are named after `stem` beside the scene. The clip opens to 80 % of `max_opening_deg`; its hinge stands
/// far enough before the neck that every neck point passes between the open jaws with its wall and 0.5 mm to
/// spare (at least 1 mm); the blades are the shortest of 3, 5, …, 15 mm that reach 0.5 mm past the neck.
/// A pose is clear when its open blades touch no outer-surface vertex along the approach and its jaws would not
/// close on the parent's lumen. A pose with a clamped node (SimModel::fixed_nodes: the domain's cut ends) in or
/// within half a millimetre of the space the jaws close on is never taken: the model ends there, the vessel does not.
/// @throws InputError no neck, a neck longer than the longest clip, every spanning pose closing on a clamped end,
///         or no pose that covers min_cover of the neck's border (clear, or the fewest vertices in the way when no
///         pose is clear)
std::string plan_scene(const SimModel& m, const std::string& bundle_ref, const std::string& stem, const PlanOptions& o = {});

}  // namespace aneu::sim
