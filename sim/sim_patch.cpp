// SPDX-License-Identifier: MIT
// The nonlinear patch under a clip (simulator_impl.hpp; Scene::wall_model = PATCH; issue #15, item 2).
//
// A held clip whose jaws close within PatchSpec::trigger_mm of the wall gets a patch: the tetrahedra within
// PatchSpec::radius_mm of its jaws' wedge become a neo-Hookean solid on the exact linear exterior
// (fem::PatchModel). From then on the clip's jaws make no prescribed displacements: each physics frame solves
// the patch with the clip's blades (fem::ClipBody, its opening θ prescribed: the applier's, or, for a clip with a
// spring, the balance of spring and tissue that the frames approach, never below what the applier holds open)
// and the inner walls' contact (fem::ContactBody) in one Newton problem, warm-started from the last frame. The
// rest of the scene stays linear; the two add (the patch's displacement of the surface on top of the linear
// solve's). With PatchSpec::Solver::COMPLIANCE a frame is instead the hard contact of blades and walls on the
// patch's compliance at a linearisation (fem::solve_compliant_clip_walls), remade every refresh_frames frames.
#include <omp.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <tuple>
#include <utility>

#include "aneu/core/error.hpp"
#include "aneu/fem/assembly.hpp"
#include "aneu/fem/contact.hpp"
#include "aneu/sim/assessment.hpp"
#include "simulator_impl.hpp"

namespace aneu::sim {

namespace {

// A refresh's candidates are those of the wedge the blades sweep closing from this much more than their opening
// (the spring or the forceps may open them a little before the next refresh) ...
constexpr double RESELECT_MARGIN_RAD = 2.0 * DEG;
// ... and a hinge that moves this far from where they were selected makes the frames due for another (the selection
// keeps nodes within 0.1 mm of the wedge).
constexpr double RESELECT_HINGE_MM = 0.05;
// A frame beyond its linearisation's linear range is solved again on one made where it got to, at most this many
// times (each a refresh: ~7-10 s on the sample, 10-15 s on the real cases). Three were enough for the sample's frames
// (session 45); a remade patch's first frame, which starts from the linear exterior's map of the nodes the new patch
// took over, and frames where the wall buckles need more (session 49: the tube's remade frame 2.27 -> 2.33 -> 1.83 ->
// 0.36 -> 0.23 wall thicknesses; C0054's buckling frame 1.68 -> 1.18 -> 0.54 -> 0.72 with three). (Tried, before the
// re-solves kept the frame's start: each linearised at most the linear range further along, a trust region. On the
// tube with sliding jaws the remade frame's attempts then crept 2.30 -> 1.56 -> 0.89 -> 0.73 -> 0.81 -> 0.85, full
// steps stayed at 0.60: every re-solve turned the gripped tissue with the blades again.) The number is the scene's
// (PatchSpec::range_resolves, 8).
// A frame whose re-solves all end beyond the range may be solved again in two halves of its opening's change, each as
// a frame of its own (linearised where it starts, re-solved as above), and a half that ends beyond it in halves again,
// at most PatchSpec::range_splits times (0 by default). It helps where a frame's reach is its step's (the tube with no
// re-solves: every frame within the range); on C0001's fold (session 51, t = 1.200 s) the last quarter step of
// 0.06 deg still ended 0.54 wall thicknesses out (the whole 0.24 deg step: 0.32) and the frame took 584 s (93 s), and
// on C0024's remade patch 0.37 as before: there the re-solves do not converge at the state itself, whatever the step.
// Such a frame may instead be solved as a Newton frame (PatchSpec::range_newton iterations, 0 by default): the
// nonlinear patch with the barriers, which has no linear range, from where the frame started (its walls and pressed
// nodes first set NEWTON_LIFT_MM apart), and the frames go on from its state, linearised there.
// A spring clip's balance takes its secant dR/dθ over steps of at least this much (in degrees at the heel: scaled by
// ClipModel::turn_per_heel_turn for a clip turning about a fulcrum behind it).
constexpr double SECANT_MIN_DEG = 0.01;
// A compliance frame solved as a Newton frame (PatchSpec::range_newton) starts from the compliance frames' state, whose
// walls touch exactly: the barrier (d̂ = 0.01 mm) cannot start there (infinite at 0 apart; C0001's fold frame, session 52:
// "the predictor runs into a contact" at once). Its inner walls' vertices are first set this far apart and its pressed
// nodes this far off the blades (half d̂).
constexpr double NEWTON_LIFT_MM = 0.005;
// ... and one that has reached the frame's whole opening but not the tolerance when its iterations run out is taken if
// its residual (the free DOFs' force over the whole force, fem::NewtonResult::residual) is at most this: its state is
// the barriers' (the walls apart, no element inverted: the line search keeps the energy finite), and what is left of
// the imbalance is the next frame's free step (it is linearised at that state). The Newton solver's own frames leave
// an unconverged iterate for the next frame in the same way.
constexpr double NEWTON_FRAME_LOOSE = 1e-2;

/// How many of the nodes (at X) lie inside a blade's solid, or within `gap` in front of its face, at opening θ.
int nodes_in_blades(const fem::ClipBlades& b, double theta, const Eigen::MatrixX3d& X, const std::vector<int>& nodes, double gap) {
    int n = 0;
    for (int s : {1, -1}) {
        Eigen::Vector3d t, nn, w;
        b.frame(s, theta, t, nn, w);
        for (int a : nodes) {
            const Eigen::Vector3d rel = X.row(a).transpose() - b.hinge;
            const double r = rel.dot(t), across = rel.dot(w), p = 0.5 * b.closed_gap_mm + rel.dot(nn);
            if (r >= b.face_from_mm && r <= b.length_mm && std::abs(across) <= 0.5 * b.width_mm && p < gap && p > -b.thickness_mm) ++n;
        }
    }
    return n;
}

/// The largest displacement of a patch's surface vertices (`cand_vertex`, at patch nodes `cand`) between patch states u
/// and ref, over the wall's thickness there (the linear model's measure, Scene::linear_limit): the ratio, and the
/// displacement, thickness and rest place of the vertex where it is largest (0 and unset where none has a thickness).
struct Reach {
    double ratio = 0, mm = 0, thickness_mm = 0;
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  // the vertex's rest position
    Eigen::Index vertex = -1;
};
Reach surface_reach(const SimSurface& sf, const std::vector<int>& cand_vertex, const std::vector<int>& cand, const Eigen::VectorXd& u,
                    const Eigen::VectorXd& ref) {
    Reach r;
    for (size_t k = 0; k < cand_vertex.size(); ++k) {
        const Eigen::Index v = cand_vertex[k];
        const double th = sf.thickness.size() ? sf.thickness[v] : std::nan("");
        if (!(std::isfinite(th) && th > 0)) continue;
        const Eigen::Index d0 = 3 * static_cast<Eigen::Index>(cand[k]);
        const double d = (u.segment<3>(d0) - ref.segment<3>(d0)).norm();
        if (d / th <= r.ratio) continue;
        r = {d / th, d, th, sf.X.row(v).transpose(), v};
    }
    return r;
}

/// Passes a frame on a borrowed W may take before the next linearisation makes its own W (each pass a back
/// substitution; the tube's frames on a W up to 3 frames old took 3-16).
constexpr int BORROW_SLOW_PASSES = 8;

/// After a linearisation whose tangent was not positive definite, the next this many project its element tangents
/// from the start, and the one after them tries the tangent itself again. A buckled patch stays buckled: the failed
/// attempt is a whole factorisation (CHOLMOD fails at the top separator, after nearly all its work), and it failed on
/// 148 of C0024's 208 linearisations and 90 of the sample's 146, every one from the first that failed to the run's end
/// but for a few early runs of 2-3 (session 57's planned runs; C0024's patch 6 of a projected linearisation's 13 s).
/// Where the tangent would have been positive definite again within those, the frames take the projected one, as
/// they take it wherever the tangent is not.
constexpr int PROJECTED_RUN = 3;

/// A frame's re-solves for the linear range stop where an attempt went more than this many times as far from its
/// linearisation as the frame's nearest attempt: Newton's steps that have left the neighbourhood of an equilibrium by
/// that much do not come back to it, and each costs a linearisation at a state ever further off (the sample's 2 mm
/// jaws at t = 1.252 s, session 62: 0.88 -> 1.34 -> 37.3 -> 33.8 -> 28.1 wall thicknesses, an element inverted at the
/// states reached, the candidates 3,930 -> 7,062, a minute a re-solve). The frame then ends with its nearest attempt,
/// as after its last re-solve. (Nor is one re-solved from beyond RANGE_ABSURD, below.)
constexpr double RANGE_HOPELESS = 4.0;

/// A compliance frame that still ends this many wall thicknesses from its linearisation after its re-solves (the
/// nearest attempt kept) is not taken: the tangent it was solved on (buckled, its element tangents projected) put the
/// tissue millimetres away in one frame. It counts as a frame that did not converge: the patch stays where the frame
/// started, and a second in a row goes back to the last converged state with a smaller step of the opening (the
/// sample's 2 mm jaws at t = 1.260 s, session 63: 36.2 wall thicknesses, 4.8 mm, in the first attempt).
constexpr double RANGE_ABSURD = 10.0;

/// The linearisation of a compliance patch at state u, or where u has an element inverted (frames on a linearisation
/// can take the patch where the nonlinear model cannot follow), at the state nearest u on the way back to `valid` (the
/// last linearisation's, which has none) that has none: u_valid + β (u − u_valid), β halved from 1/2 at most 10 times.
/// `back` gets β (1: u itself). Throws what the Linearisation throws where no such state is found or another fault.
/// With `borrow`, on `cand`, borrowing its W (fem::Linearisation's borrowing constructor: the added candidates' columns
/// made on the tangent that W was made on). `project_first`: the element tangents projected without the tangent
/// tried first (fem::Linearisation's project_first; see PROJECTED_RUN).
std::unique_ptr<fem::Linearisation> linearise_patch(const fem::PatchModel& pm, const Eigen::MatrixX3d& X, const Eigen::VectorXd& u,
                                                    const Eigen::VectorXd* valid, const std::vector<int>& cand, double& back,
                                                    const fem::Linearisation* borrow = nullptr, bool project_first = false) {
    back = 1;
    auto make = [&](const Eigen::VectorXd& at) {
        return borrow ? std::make_unique<fem::Linearisation>(pm, X, pm.fixed_dofs(), at, cand, *borrow, project_first)
                      : std::make_unique<fem::Linearisation>(pm, X, pm.fixed_dofs(), at, cand, project_first);
    };
    if (valid && valid->size() == u.size() && !(pm.min_jacobian(u) > 0)) {
        // (Before: the sample refreshed every frame had 42 of its 67 refreshes refused, an element inverted at the
        // state reached, and the frames stayed on the last one; the real-time mode's, once refused, never recovered.)
        for (double b = 0.5; b > 1e-3; b *= 0.5) {
            const Eigen::VectorXd ub = *valid + b * (u - *valid);
            if (pm.min_jacobian(ub) > 0) {
                back = b;
                return make(ub);
            }
        }
    }
    return make(u);
}

}  // namespace

bool Simulator::Impl::patch_holds_instrument(size_t i) const {
    const int c = ins[i].clip;
    return c >= 0 && static_cast<size_t>(c) < patch_of_clip.size() && patch_of_clip[static_cast<size_t>(c)] >= 0;
}

void Simulator::Impl::set_patch_part(Eigen::Index v, const Eigen::Vector3d& value) {
    d.row(v) += (value - d_patch.row(v).transpose()).transpose();
    d_patch.row(v) = value.transpose();
}

void Simulator::Impl::drop_patch(int index) {
    PatchRun& P = patches[static_cast<size_t>(index)];
    for (size_t k = 0; k < P.cand_vertex.size(); ++k) set_patch_part(P.cand_vertex[k], Eigen::Vector3d::Zero());
    for (int v : P.map_vertex) set_patch_part(v, Eigen::Vector3d::Zero());
    patch_of_clip[static_cast<size_t>(P.clip)] = -1;
    for (const PatchRun::Member& m : P.more) patch_of_clip[static_cast<size_t>(m.clip)] = -1;
    P.more.clear();
    P.alive = false;
    P.pm.reset();
}

void Simulator::Impl::leave_patch(int clip) {
    const int index = patch_of_clip[static_cast<size_t>(clip)];
    if (index < 0) return;
    PatchRun& P = patches[static_cast<size_t>(index)];
    if (P.more.empty()) {
        drop_patch(index);
        return;
    }
    patch_of_clip[static_cast<size_t>(clip)] = -1;
    // (The compliance frames' rows are numbered by clip, fem::compliant_row_kind: the next frame finds its clips changed
    // and begins its rows again, solve_patches. Not here: in threaded mode a frame may be using them.)
    const auto it = std::find_if(P.more.begin(), P.more.end(), [&](const PatchRun::Member& m) { return m.clip == clip; });
    if (it != P.more.end()) {
        P.more.erase(it);
        return;
    }
    // The first clip: the next takes its place (its opening the patch's θ, its balance the course's).
    const PatchRun::Member m = P.more.front();
    P.more.erase(P.more.begin());
    const Eigen::Index nb = P.pm->dofs();
    P.clip = m.clip;
    P.v[nb] = m.theta;
    if (P.v_ok.size() == P.v.size()) P.v_ok[nb] = m.theta_ok;
    P.course.theta_bal = m.course.theta_bal;
    P.course.prev_theta = m.course.prev_theta;
    P.course.prev_R = m.course.prev_R;
    P.course.tissue_k = m.course.tissue_k;
    P.course.loads_ok = m.course.loads_ok;
    P.contacts = m.contacts;
    P.grips.clear();
    P.grips_ok.clear();
    P.gripped = P.gripped_ok = false;
    P.hinge_prev = blades_of(clips[static_cast<size_t>(m.clip)], scene.clip_models.at(clips[static_cast<size_t>(m.clip)].model)).hinge;
}

// Patches for held clips whose jaws come near the wall, and remade ones for jaws that left theirs.
void Simulator::Impl::make_patches(Frame& fr) {
    if (scene.wall_model != WallModel::PATCH) return;
    const SimSurface& sf = model.surface;
    std::vector<int> cand;
    for (size_t i = 0; i < ins.size(); ++i) {
        // The clip as the frame began (the haptic thread may release it meanwhile: build_patch checks again).
        const int cid = fr.jaws[i].clip;
        if (cid < 0 || !fr.jaws[i].on) continue;
        const fem::ClipBlades& b = fr.jaws[i].blades;
        const double theta = fr.jaws[i].theta;
        int have = -1;
        std::shared_ptr<const fem::PatchModel> have_pm;  // (the haptic thread drops a fallen clip's patch under the lock)
        {
            std::unique_lock<std::mutex> lk;
            if (fr.mx) lk = std::unique_lock<std::mutex>(*fr.mx);
            have = patch_of_clip[static_cast<size_t>(cid)];
            if (have >= 0) have_pm = patches[static_cast<size_t>(have)].pm;
        }
        if (have >= 0 && !have_pm) continue;
        // A first patch when the jaws close on the wall (while they only come near, open, the linear model's
        // contacts are small and the jaws may still move far: a patch made then would have to follow them).
        if (have < 0 && !(theta < fr.jaws[i].theta_prev - 1e-9)) continue;
        // The surface near the jaws: within trigger_mm (a first patch), or within half the patch radius (a patch
        // that must still cover it).
        const double reach = have < 0 ? scene.patch.trigger_mm : 0.5 * scene.patch.radius_mm;
        Aabb box;
        box.lo = box.hi = b.hinge;
        for (int s : {1, -1}) {
            Eigen::Vector3d t, n, w;
            b.frame(s, theta, t, n, w);
            for (double a : {-0.5, 0.5}) {
                const Eigen::Vector3d tip = b.hinge + b.length_mm * t + a * b.width_mm * w;
                const Eigen::Vector3d heel = b.hinge + a * b.width_mm * w;
                for (const Eigen::Vector3d& p : {tip, heel}) {
                    box.lo = box.lo.cwiseMin(p);
                    box.hi = box.hi.cwiseMax(p);
                }
            }
        }
        grid.query(box.grown(reach + b.thickness_mm), cand);
        bool near = false;
        int uncovered = -1;
        for (int v : cand) {
            const Eigen::Vector3d p = x_grid.row(v).transpose();
            if (!b.near_wedge(theta, p, reach)) continue;
            near = true;
            if (have >= 0 && uncovered < 0 && have_pm->local(sf.node[v]) < 0) uncovered = v;
        }
        std::string why;
        if (uncovered >= 0) {
            // Why (for the log): the jaws moved to it, or it moved to them.
            const Eigen::Vector3d x0 = sf.X.row(uncovered).transpose();
            char w[200];
            std::snprintf(w, sizeof w, "; surface vertex %d, %.3f mm from rest, lay within %.2f mm of the jaws outside the patch (at rest: %s)", uncovered,
                          (x_grid.row(uncovered).transpose() - x0).norm(), reach, b.near_wedge(theta, x0, reach) ? "within" : "not within");
            why = w;
        }
        if ((have < 0 && near) || uncovered >= 0) {
            build_patch(i, fr.jaws[i], fr.mx, why);
            continue;
        }
        // Grown where the lumen meets itself beside the patch (PatchSpec::grow), once a frame for each patch (by its
        // first clip).
        if (have < 0 || !scene.patch.grow || sf.lumen.F.rows() == 0) continue;
        std::vector<Eigen::Vector3d> spots;
        {
            std::unique_lock<std::mutex> lk;
            if (fr.mx) lk = std::unique_lock<std::mutex>(*fr.mx);
            const PatchRun& P = patches[static_cast<size_t>(have)];
            if (!P.alive || P.pm != have_pm || P.clip != cid) continue;
            const SimLumen& lumen = sf.lumen;
            std::vector<char> outside(static_cast<size_t>(lumen.X.rows()), 1);
            for (Eigen::Index l = 0; l < lumen.X.rows(); ++l) {
                const int a = have_pm->local(lumen.node[l]);
                outside[static_cast<size_t>(l)] = a < 0 || have_pm->on_interface(a) ? 1 : 0;
            }
            const Eigen::MatrixX3d y = lumen_now(sf.X + d);
            const std::vector<int> meet = lumen_meeting(lumen, y, fem::COMPLIANT_WALL_APPROACH_MM, PATCH_GROW_APART_MM, &outside);
            // (Those the patch grew for already and still lie outside, at its radius: not again.)
            for (int l : meet) {
                const Eigen::Vector3d x0 = lumen.X.row(l).transpose();
                bool had = false;
                for (const Eigen::Vector3d& g : P.grown) had = had || (g - x0).norm() < 1e-9;
                if (!had) spots.push_back(x0);
            }
        }
        if (spots.empty()) continue;
        Eigen::Vector3d lo = spots[0], hi = spots[0];
        for (const Eigen::Vector3d& p : spots) {
            lo = lo.cwiseMin(p);
            hi = hi.cwiseMax(p);
        }
        char w[300];
        std::snprintf(w, sizeof w, "; grown where the lumen meets itself beside it: %zu lumen vertices within %.2f mm of the opposite wall (or through it), between (%.2f, %.2f, %.2f) and (%.2f, %.2f, %.2f) at rest",
                      spots.size(), fem::COMPLIANT_WALL_APPROACH_MM, lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z());
        build_patch(i, fr.jaws[i], fr.mx, w, -1, spots);
    }
}

// Made without the lock (the factorisation and interface solves take seconds); what the other threads read is
// changed under it. In threaded mode the haptic thread may release the clip meanwhile (it is then deposited on
// what the linear model holds, or falls away and drops the old patch): the new patch is then not used.
void Simulator::Impl::build_patch(size_t instrument, const Jaws& jaws, std::mutex* mx, const std::string& why, int join,
                                  const std::vector<Eigen::Vector3d>& grow) {
    const Stopwatch sw;
    const SimSurface& sf = model.surface;
    const VolumeData& vol = *model.volume;
    const FemData& fem = *model.fem;
    const int clip = jaws.clip;
    const fem::ClipBlades& blades = jaws.blades;
    const double theta = jaws.theta;
    int old = -1;
    std::shared_ptr<const fem::PatchModel> old_pm;  // kept alive while it is read below, without the lock
    // The wedges the patch covers: this clip's jaws, and a remade (or joined) patch's other clips' where they are now
    // (their poses taken under the lock; the first clip's opening the patch's θ, the others' their own).
    std::vector<std::pair<fem::ClipBlades, double>> wedges;
    std::vector<int> members;  // the old patch's clips as they were (still so when the patch is taken: below)
    std::vector<Eigen::Vector3d> grown;  // where it grew (PatchRun::grown): the old patch's, then `grow`
    auto clips_of = [](const PatchRun& O) {
        std::vector<int> c{O.clip};
        for (const PatchRun::Member& m : O.more) c.push_back(m.clip);
        return c;
    };
    {
        std::unique_lock<std::mutex> lk;
        if (mx) lk = std::unique_lock<std::mutex>(*mx);
        old = join >= 0 ? join : patch_of_clip[static_cast<size_t>(clip)];
        if (old >= 0) {
            const PatchRun& O = patches[static_cast<size_t>(old)];
            old_pm = O.pm;
            members = clips_of(O);
            auto add = [&](int c, double th) {
                const Clip& k = clips[static_cast<size_t>(c)];
                if (c != clip && !k.model.empty()) wedges.emplace_back(blades_of(k, scene.clip_models.at(k.model)), th);
            };
            if (old_pm) {
                add(O.clip, O.v[old_pm->dofs()]);
                for (const PatchRun::Member& m : O.more) add(m.clip, m.theta);
                grown = O.grown;
            }
        }
    }
    if (old >= 0 && !old_pm) return;  // dropped: its clip fell away
    wedges.emplace_back(blades, theta);
    grown.insert(grown.end(), grow.begin(), grow.end());
    const double r2 = scene.patch.radius_mm * scene.patch.radius_mm;
    auto near_any = [&](const Eigen::Vector3d& p) {
        for (const auto& [b, th] : wedges)
            if (b.near_wedge(th, p, scene.patch.radius_mm)) return true;
        for (const Eigen::Vector3d& g : grown)
            if ((p - g).squaredNorm() <= r2) return true;
        return false;
    };
    // The tetrahedra with a corner within radius_mm of the wedge, at rest or where it is now: the surface's vertices
    // where they are displaced to, the old patch's nodes where it holds them. (At rest alone, a remade patch missed
    // tissue the closing jaws had drawn in from beyond the radius, and the next frame's check found it uncovered
    // within half the radius: the sample's patch was remade every second frame as it closed.)
    std::vector<Eigen::Vector3d> now;
    std::vector<char> moved;
    if (old >= 0 || d.rows() == S) {
        now.resize(static_cast<size_t>(vol.nodes.rows()));
        moved.assign(now.size(), 0);
        if (d.rows() == S)
            for (Eigen::Index v = 0; v < S; ++v) {
                const auto n = static_cast<size_t>(sf.node[v]);
                now[n] = vol.nodes.row(sf.node[v]).transpose() + d.row(v).transpose();
                moved[n] = 1;
            }
        if (old >= 0) {
            const PatchRun& O = patches[static_cast<size_t>(old)];
            for (size_t a = 0; a < old_pm->nodes().size(); ++a) {
                const auto n = static_cast<size_t>(old_pm->nodes()[a]);
                now[n] = O.X.row(static_cast<Eigen::Index>(a)).transpose() + O.v.segment<3>(3 * static_cast<Eigen::Index>(a));
                moved[n] = 1;
            }
        }
    }
    std::vector<int> tets;
    for (Eigen::Index t = 0; t < vol.tets.rows(); ++t)
        for (int k = 0; k < 4; ++k) {
            const int n = vol.tets(t, k);
            if (near_any(vol.nodes.row(n).transpose()) || (!moved.empty() && moved[static_cast<size_t>(n)] && near_any(now[static_cast<size_t>(n)]))) {
                tets.push_back(static_cast<int>(t));
                break;
            }
        }
    if (tets.empty()) return;
    // A compliance patch's new clip whose tissue another clip's patch already holds (tandem clips on one neck) joins
    // that patch: it is remade over both clips' jaws and its frames solve with both (fem::CompliantClip). (Two patches
    // over the same tissue would each solve with its own clip's blades and write their displacements to the nodes they
    // share.) The Newton frames take one clip: there the second patch is made, and warned below.
    if (old < 0 && scene.patch.solver == PatchSpec::Solver::COMPLIANCE) {
        int with = -1;
        {
            std::unique_lock<std::mutex> lk;
            if (mx) lk = std::unique_lock<std::mutex>(*mx);
            for (size_t h = 0; h < patches.size() && with < 0; ++h) {
                const PatchRun& H = patches[h];
                if (!H.alive || !H.pm) continue;
                for (int t : tets) {
                    for (Eigen::Index k = 0; k < vol.tets.cols() && with < 0; ++k)
                        if (H.pm->local(vol.tets(t, k)) >= 0) with = static_cast<int>(h);
                    if (with >= 0) break;
                }
            }
        }
        if (with >= 0) {
            build_patch(instrument, jaws, mx, why, with);
            return;
        }
    }
    // The visible surface the patch moves: in-region vertices (their displacement from the interface).
    std::vector<int> map_vertex, map_nodes;
    for (Eigen::Index v = 0; v < S; ++v)
        if (in_region[static_cast<size_t>(v)]) {
            map_vertex.push_back(static_cast<int>(v));
            map_nodes.push_back(sf.node[v]);
        }
    PatchRun P;
    P.clip = clip;
    P.grown = grown;
    try {
        P.pm = std::make_shared<fem::PatchModel>(vol, fem, tets, map_nodes, &cancel_frames);
    } catch (const Cancelled&) {
        return;  // the run is ending
    }
    const fem::PatchModel& pm = *P.pm;
    P.tets = static_cast<int>(tets.size());
    P.elements.resize(static_cast<Eigen::Index>(tets.size()), vol.tets.cols());
    for (size_t e = 0; e < tets.size(); ++e)
        for (Eigen::Index k = 0; k < vol.tets.cols(); ++k) P.elements(static_cast<Eigen::Index>(e), k) = pm.local(vol.tets(tets[e], k));
    P.map_vertex = std::move(map_vertex);
    const auto np = static_cast<Eigen::Index>(pm.nodes().size());
    P.X.resize(np, 3);
    for (Eigen::Index a = 0; a < np; ++a) P.X.row(a) = vol.nodes.row(pm.nodes()[static_cast<size_t>(a)]);
    std::vector<char> is_cand_vertex(static_cast<size_t>(S), 0);
    for (Eigen::Index v = 0; v < S; ++v) {
        const int a = pm.local(sf.node[v]);
        if (a >= 0 && in_region[static_cast<size_t>(v)]) {
            P.cand.push_back(a);
            P.cand_vertex.push_back(static_cast<int>(v));
            is_cand_vertex[static_cast<size_t>(v)] = 1;
        }
    }
    // With 10-node elements the contacts act on the quadratic surface, mid-edge nodes included: on the corners alone
    // the surface between them bulges through a blade or the opposite wall (bench/bench_fold.cpp). The blades' candidates
    // get the mid-edge nodes of the simulated surface's edges between candidate vertices (after the vertices: the
    // first cand_vertex.size() candidates are the surface's own), the inner walls' contact the lumen's triangles split
    // at their mid-edge nodes.
    const bool quadratic = vol.tets.cols() == 10;
    P.quadratic = quadratic;
    std::optional<fem::MidEdgeNodes> mid;
    if (quadratic) {
        mid.emplace(vol.tets);  // all elements: a lumen edge between patch nodes may be an edge of elements outside it
        std::vector<char> added(static_cast<size_t>(np), 0);
        for (Eigen::Index f = 0; f < sf.F.rows(); ++f)
            for (int k = 0; k < 3; ++k) {
                const int va = sf.F(f, k), vb = sf.F(f, (k + 1) % 3);
                if (!is_cand_vertex[static_cast<size_t>(va)] || !is_cand_vertex[static_cast<size_t>(vb)]) continue;
                const int m = (*mid)(sf.node[va], sf.node[vb]);
                const int a = m < 0 ? -1 : pm.local(m);
                if (a < 0 || added[static_cast<size_t>(a)]) continue;
                added[static_cast<size_t>(a)] = 1;
                P.cand.push_back(a);
            }
    }
    // A surface's triangles in the patch (their three corners patch nodes), in patch numbering, split at their mid-edge
    // nodes with 10-node elements (a split triangle with a mid-edge node outside the patch is left out with its three
    // siblings); `flip`: turned over.
    const int per = quadratic ? 4 : 1;
    auto patch_triangles = [&](const Eigen::MatrixX3i& F, const Eigen::VectorXi& node, bool flip) {
        std::vector<int> on;
        for (Eigen::Index f = 0; f < F.rows(); ++f)
            if (pm.local(node[F(f, 0)]) >= 0 && pm.local(node[F(f, 1)]) >= 0 && pm.local(node[F(f, 2)]) >= 0) on.push_back(static_cast<int>(f));
        Eigen::MatrixX3i walls(static_cast<Eigen::Index>(on.size()), 3);
        for (size_t k = 0; k < on.size(); ++k)
            walls.row(static_cast<Eigen::Index>(k)) << node[F(on[k], 0)], node[F(on[k], flip ? 2 : 1)], node[F(on[k], flip ? 1 : 2)];
        if (quadratic) walls = fem::quadratic_surface_triangles(*mid, walls);
        std::vector<Eigen::Vector3i> tri;
        for (Eigen::Index f = 0; f < walls.rows(); f += per) {
            bool inside = true;
            for (int r = 0; r < per; ++r)
                for (int k = 0; k < 3; ++k) inside = inside && pm.local(walls(f + r, k)) >= 0;
            if (!inside) continue;
            for (int r = 0; r < per; ++r) tri.emplace_back(pm.local(walls(f + r, 0)), pm.local(walls(f + r, 1)), pm.local(walls(f + r, 2)));
        }
        Eigen::MatrixX3i out(static_cast<Eigen::Index>(tri.size()), 3);
        for (size_t f = 0; f < tri.size(); ++f) out.row(static_cast<Eigen::Index>(f)) = tri[f].transpose();
        return out;
    };
    // The lumen's, turned into the lumen (towards the opposite wall).
    P.inner = patch_triangles(sf.lumen.F, sf.lumen.node, true);
    // The outer surface's, as they are (counter-clockwise from outside: normals out of the wall): where the outer
    // surface, squeezed along the jaws, folds onto itself (session 48: C0001's folded 0.11 mm into its own wall), the
    // frames' wall contact keeps it apart (compliant_setup's outer faces).
    P.outer = patch_triangles(sf.F, sf.node, false);
    P.v = Eigen::VectorXd::Zero(pm.dofs() + 1);
    P.v[pm.dofs()] = theta;
    // The handover from the linear model: the patch starts at rest, where tissue the linear model pushed aside with
    // the jaws (open, coming round the vessel, or already closing) lies inside a blade. A blade would then push such
    // nodes out through its back, or hold them with forces of tens of N. So a first patch's blades start at the
    // smallest opening (from θ up, in 0.25° steps) that holds no node inside them; the frames then close them to the
    // applier's opening (the clip's θ is prescribed each frame; a frame that cannot reach it carries on from where
    // it got).
    int inside = 0;
    bool cleared = true;
    if (old < 0) {
        const double top = std::max(theta, jaws.max_opening_deg * DEG);
        inside = nodes_in_blades(blades, theta, P.X, P.cand, 0.01);
        cleared = inside == 0;
        for (double th = theta; !cleared && th <= top; th += 0.25 * DEG)
            if (nodes_in_blades(blades, th, P.X, P.cand, 0.01) == 0) {
                P.v[pm.dofs()] = th;
                cleared = true;
            }
    }
    P.hinge_prev = blades.hinge;
    P.stats.clip = clip;
    P.stats.builds = 1;
    P.stats.min_wall_distance_mm = std::numeric_limits<double>::infinity();
    std::unique_lock<std::mutex> lock;
    if (mx) lock = std::unique_lock<std::mutex>(*mx);
    // Still the instrument's held clip, with the patch it had when the build began?
    const Clip& now_clip = clips[static_cast<size_t>(clip)];
    if (ins[instrument].clip != clip || now_clip.state != Clip::State::HELD || now_clip.model.empty() ||
        patch_of_clip[static_cast<size_t>(clip)] != (join >= 0 ? -1 : old) ||
        (old >= 0 && (patches[static_cast<size_t>(old)].pm != old_pm || clips_of(patches[static_cast<size_t>(old)]) != members))) {
        char b[200];
        std::snprintf(b, sizeof b, "clip %d was released while its nonlinear patch was being %s (%.2f s): the patch is not used", clip,
                      join >= 0 ? "joined" : old >= 0 ? "remade" : "made", sw.seconds());
        warn(b);
        return;
    }
    if (old >= 0) {
        // Remade: the state carries over exactly (the old patch's whole displacement, restricted to the new one).
        PatchRun& O = patches[static_cast<size_t>(old)];
        P.clip = O.clip;
        P.more = O.more;
        if (O.clip != clip) P.hinge_prev = O.hinge_prev;  // (remade for a further clip: the first's hinge at its last solve)
        const auto carry = [&](const Eigen::VectorXd& ov) {
            Eigen::VectorXd nv(pm.dofs() + 1);
            nv.head(pm.dofs()) = pm.restrict_to_patch(O.pm->full_displacement(ov.head(O.pm->dofs())));
            nv[pm.dofs()] = ov[O.pm->dofs()];
            return nv;
        };
        P.v = carry(O.v);
        P.kappa_wall = O.kappa_wall;
        P.kappa_blade = O.kappa_blade;
        // The grips carry over to the new patch's numbering (a node that is no longer a candidate lets go).
        std::vector<int> is_cand(static_cast<size_t>(np), 0);
        for (int a : P.cand) is_cand[static_cast<size_t>(a)] = 1;
        const auto carry_grips = [&](const std::vector<fem::BladeGrip>& from, std::vector<fem::BladeGrip>& to) {
            for (fem::BladeGrip g : from) {
                const int a = pm.local(O.pm->nodes()[static_cast<size_t>(g.node)]);
                if (a < 0 || !is_cand[static_cast<size_t>(a)]) continue;
                g.node = a;
                to.push_back(g);
            }
        };
        carry_grips(O.grips, P.grips);
        P.gripped = O.gripped;
        // And the last converged state: a patch remade after an unconverged frame still goes back to it. (Without
        // this the sample's patch, remade at the frame after one that did not converge, took that frame's iterate
        // for its start and went back to it.)
        if (O.v_ok.size() == O.v.size()) {
            P.v_ok = carry(O.v_ok);
            carry_grips(O.grips_ok, P.grips_ok);
            P.gripped_ok = O.gripped_ok;
        }
        // So does the course: the restart's bookkeeping and the spring's balance estimate with its secant (before,
        // a remade patch began the approach again from where it stood: a held clip stood still for that frame).
        P.course = O.course;
        P.stats = O.stats;
        ++P.stats.builds;
        P.iterations_sum = O.iterations_sum;
        P.solve_ms_sum = O.solve_ms_sum;
        P.contacts = O.contacts;
        if (join >= 0) {
            // The joining clip: its blades start, as a first patch's do, at the smallest opening from θ up that holds
            // none of the patch's nodes inside them where the patch now holds them (the linear model's contacts pushed
            // the tissue it closed on before the patch took it over).
            PatchRun::Member m;
            m.clip = clip;
            m.theta = theta;
            const Eigen::MatrixX3d x = P.positions();
            inside = nodes_in_blades(blades, theta, x, P.cand, 0.01);
            cleared = inside == 0;
            const double top = std::max(theta, jaws.max_opening_deg * DEG);
            for (double th = theta; !cleared && th <= top; th += 0.25 * DEG)
                if (nodes_in_blades(blades, th, x, P.cand, 0.01) == 0) {
                    m.theta = th;
                    cleared = true;
                }
            m.theta_ok = m.theta;
            P.more.push_back(m);
            P.stats.more_clips.push_back(clip);
            patch_of_clip[static_cast<size_t>(clip)] = old;
        }
        for (int v : O.map_vertex) set_patch_part(v, Eigen::Vector3d::Zero());
        O.pm.reset();
        patches[static_cast<size_t>(old)] = std::move(P);
    } else {
        // Another clip's patch over the same tissue (tandem clips on one neck): the two are not coupled, each solves
        // with its own blades and writes its displacement to the nodes they share. The compliance frames can take
        // several clips in one problem (fem::CompliantClip); a patch owning several clips is not built yet (notes:
        // compliance.md, session 54). Said when the patch is made, for each clip whose patch it overlaps.
        for (const PatchRun& O : patches) {
            if (!O.alive || !O.pm || O.clip == clip) continue;
            size_t shared = 0;
            for (int n : P.pm->nodes()) shared += O.pm->local(n) >= 0 ? 1 : 0;
            if (shared == 0) continue;
            char b[400];
            std::snprintf(b, sizeof b,
                          "clip %d's nonlinear patch shares %zu nodes with clip %d's: two clips on the same tissue are not coupled in the patch model "
                          "(each patch solves with its own clip's blades only); place the clips further apart or use model.wall = \"linear\"",
                          clip, shared, O.clip);
            warn(b);
        }
        patch_of_clip[static_cast<size_t>(clip)] = static_cast<int>(patches.size());
        patches.push_back(std::move(P));
    }
    PatchRun& N = patches[static_cast<size_t>(patch_of_clip[static_cast<size_t>(clip)])];
    const double theta_start = join >= 0 ? N.more.back().theta : N.v[N.pm->dofs()];
    N.stats.nodes = static_cast<int>(np);
    N.stats.interface_nodes = static_cast<int>(N.pm->interface_nodes());
    N.stats.tets = N.tets;
    N.stats.setup_s = N.pm->setup_seconds();
    N.t_map = -1;
    char b[300];
    if (join >= 0)
        std::snprintf(b, sizeof b, "clip %d joins clip %d's nonlinear patch at t=%.3f s (tandem clips: one patch, solved with every clip's blades): remade over %zu clips' jaws: %d tetrahedra, %lld nodes (%lld on the interface), made in %.2f s",
                      clip, N.clip, t_phys, N.more.size() + 1, N.tets, static_cast<long long>(np), static_cast<long long>(N.pm->interface_nodes()), sw.seconds());
    else
        std::snprintf(b, sizeof b, "clip %d: nonlinear patch %s at t=%.3f s: %d tetrahedra, %lld nodes (%lld on the interface), made in %.2f s", clip,
                      old >= 0 ? "remade" : "made", t_phys, N.tets, static_cast<long long>(np), static_cast<long long>(N.pm->interface_nodes()),
                      sw.seconds());
    warn(b + why);
    if (inside > 0 && cleared) {
        std::snprintf(b, sizeof b, "clip %d: %d surface nodes the linear model had pushed lay inside the blades at %.2f deg: the patch's blades start at %.2f deg and close from there",
                      clip, inside, theta / DEG, theta_start / DEG);
        warn(b);
    } else if (inside > 0) {
        std::snprintf(b, sizeof b, "clip %d: %d surface nodes the linear model had pushed lie inside the blades at every opening up to the clip's largest: the patch starts with them there",
                      clip, inside);
        warn(b);
    }
}

// Each patch's Newton solve with its clip, then the surface's displacement from it.
void Simulator::Impl::solve_patches(Frame& fr) {
    const SimSurface& sf = model.surface;
    // Refresh threads that are done (threaded mode): joined (a done one has only to return).
    for (auto it = refresh_jobs.begin(); it != refresh_jobs.end();)
        if (it->first->done.load(std::memory_order_acquire)) {
            it->second.join();
            it = refresh_jobs.erase(it);
        } else {
            ++it;
        }
    if (patches.empty()) return;
    patch_force.assign(ins.size(), Eigen::Vector3d::Zero());
    for (PatchRun& P : patches) {
        if (!P.alive) continue;
        Clip& c = clips[static_cast<size_t>(P.clip)];
        const ClipModel& cm = scene.clip_models.at(c.model);
        // The solve runs without the lock in threaded mode: it keeps the model alive if the clip falls away meanwhile.
        const std::shared_ptr<const fem::PatchModel> hold = P.pm;
        const fem::PatchModel& pm = *hold;
        const Eigen::Index nb = pm.dofs();
        const fem::ClipBlades blades = blades_of(c, cm);
        const bool held = c.state == Clip::State::HELD;
        const double theta_applier = std::clamp(c.forceps_deg, 0.0, cm.max_opening_deg) * DEG;
        // The opening this frame holds. Without a spring: the applier's (held) or the clip's own (deposited). With
        // one: the balance the frames approach (below), but never below what the applier holds open.
        if (P.course.theta_bal < 0) P.course.theta_bal = P.v[nb];
        const double theta_wanted = !cm.spring ? (held ? theta_applier : c.opening_deg * DEG)
                                               : std::max(held ? theta_applier : 0.0, P.course.theta_bal);
        // After a restart (below) the opening moves at most theta_step a frame towards it. In the threaded real-time
        // mode at most REALTIME_STEP_DEG as well: there the applier moves on while a patch frame solves, so the next
        // frame would take the whole way at once, and a frame's cost grows steeply with that (the sample's first
        // real-time frame after its patch was made, 60 -> 40 deg in one frame: 557 s, 388 s of it the tangent's
        // pattern and analysis, 47 s a factorisation, none of it interruptible). The patch then lags the applier
        // and catches up frame by frame. (The deterministic timeline moves the applier by a frame's worth only.)
        constexpr double REALTIME_STEP_DEG = 1.0;
        const double step_max = fr.mx ? std::min(P.course.theta_step, REALTIME_STEP_DEG * DEG * cm.turn_per_heel_turn()) : P.course.theta_step;
        const double theta_kept = P.v[nb] + std::clamp(theta_wanted - P.v[nb], -step_max, step_max);
        if (P.v_ok.size() != P.v.size()) {  // a new patch: its start is its last converged state
            P.v_ok = P.v;
            P.grips_ok = P.grips;
            P.gripped_ok = P.gripped;
        }
        const fem::ClipSpring spring = cm.spring ? *cm.spring : fem::ClipSpring{1e-3, 0.0};
        // The patch's further clips (tandem clips; compliance frames only): each holds its own opening this frame, found
        // as the first clip's (the applier's, or its spring's balance, never below what the applier holds open), by
        // the frame's step bound. Copied under the lock: the haptic thread may release one meanwhile (leave_patch),
        // and what the frame finds is written back to the clips still in the patch after it.
        struct MemberFrame {
            int clip = -1;
            fem::ClipBlades blades;
            fem::ClipSpring spring{1e-3, 0.0};
            bool held = false, has_spring = false;
            double theta_from = 0, theta_ok = 0, theta_kept = 0;
            double turn = 1;                     // ClipModel::turn_per_heel_turn
            PatchRun::Course course;             // its balance, updated by the frame
            fem::BladeLoads loads;               // the frame's loads on its blades
        };
        std::vector<MemberFrame> mf;
        for (PatchRun::Member& m : P.more) {
            const Clip& cj = clips[static_cast<size_t>(m.clip)];
            const ClipModel& cmj = scene.clip_models.at(cj.model);
            MemberFrame g;
            g.clip = m.clip;
            g.blades = blades_of(cj, cmj);
            g.has_spring = cmj.spring.has_value();
            if (cmj.spring) g.spring = *cmj.spring;
            g.held = cj.state == Clip::State::HELD;
            g.theta_from = m.theta;
            g.theta_ok = m.theta_ok;
            g.turn = cmj.turn_per_heel_turn();
            if (m.course.theta_bal < 0) m.course.theta_bal = m.theta;
            g.course = m.course;
            const double applier = std::clamp(cj.forceps_deg, 0.0, cmj.max_opening_deg) * DEG;
            const double wanted = !cmj.spring ? (g.held ? applier : cj.opening_deg * DEG) : std::max(g.held ? applier : 0.0, m.course.theta_bal);
            const double smax = fr.mx ? std::min(P.course.theta_step, REALTIME_STEP_DEG * DEG * g.turn) : P.course.theta_step;
            g.theta_kept = m.theta + std::clamp(wanted - m.theta, -smax, smax);
            mf.push_back(std::move(g));
        }
        std::vector<int> frame_clips{P.clip};  // the clips the frame solves with, first to last
        for (const MemberFrame& g : mf) frame_clips.push_back(g.clip);
        if (fr.mx) fr.lock.unlock();
        const Stopwatch sw;
        const Eigen::VectorXd v0 = P.v;
        fem::ClipContactParams bp;
        bp.stiffness = P.kappa_blade;
        bp.friction = scene.patch.blade_friction;
        bp.pattern_cache = P.clip_patterns;
        const int merges_before = fem::pattern_cache_counts(*P.wall_patterns).first + fem::pattern_cache_counts(*P.clip_patterns).first;
        fem::NewtonOptions o;
        o.tolerance = scene.patch.tolerance;
        // Chord steps are an experiment, not a scene option: on the tube they save a third of a frame, but with
        // 8 Newton iterations a frame and sliding jaws the restarts then leave nodes behind the blades (notes).
        if (const char* c = std::getenv("ANEU_CHORD_RATIO")) o.chord_ratio = std::atof(c);
        // The first patch tangent factorised in this process, for bench/bench_factor.cpp (orderings, the floor).
        static std::atomic<bool> tangent_dumped{false};
        if (const char* d = std::getenv("ANEU_DUMP_TANGENT"); d && !tangent_dumped) o.dump_free_tangent = d;
        o.max_iterations = o.max_total_iterations = scene.patch.newton_per_frame;
        o.max_halvings = 3;
        o.keep_going = true;
        o.force_scale = 1e-3;  // N: a released clip's free problem has no reaction to measure the residual by
        o.workspace = P.newton;
        o.cancel = &cancel_frames;
        // θ is prescribed in every frame's solve (a free θ against a stiff, buckling, pressed-together wall makes
        // Newton crawl); the solve's reaction on it is R = τ(θ) − M(θ), the spring's torque less the tissue's
        // moment. A spring clip's balance R = 0 is approached over the frames by secant steps on R (at most 1° a
        // frame), as the applier lets it close or once it is released.
        double t_wall = 0, t_clip = 0;
        int its = 0;  // Newton iterations over the frame's solves
        int factorisations = 0, reused = 0, unsolved = 0;  // analyses reused, substeps without a linear solve
        double t_setup = 0, t_tangent = 0, t_factor = 0, t_back = 0;  // over the frame's solves (NewtonResult)
        int failed = 0, chords = 0;  // factorisations that found the tangent not positive definite; chord steps
        double t_failed = 0;
        bool at_rest = false;
        fem::BladeLoads loads;
        std::vector<fem::BladeGrip> grips;
        double wall_min = std::numeric_limits<double>::infinity();
        int touching = 0;
        // Where a Newton frame starts: v0, or (lift_mm > 0: a compliance frame's state, its walls exactly touching, its
        // nodes exactly on the blades) v0 with the inner walls' vertices lift_mm apart and the pressed nodes lift_mm off
        // the blades (fem::separate_walls, fem::ClipBody::separated), for the barriers to start from.
        double lift_mm = 0;
        Eigen::VectorXd v_from = v0;  // (the walls already apart, newton_frame)
        double newton_deepened_mm = 0;  // how much deeper the deepest vertex behind a face is at a Newton frame's end than at its start
        // One solve of the frame with the blades on `body` (the patch, or the patch with its inner walls' contact).
        auto solve_with = [&](const fem::ElasticBody& body, const fem::ContactBody* wall) {
            t_wall = sw.seconds();
            Eigen::VectorXd v_start = v_from;
            if (lift_mm > 0) {
                const fem::ClipBody at(body, P.X, P.cand, v_start, blades, spring, bp, nullptr);
                v_start = at.separated(v_start, lift_mm);
            }
            // The grips of the last solve (in the blades' frame, so the clip's rigid motion carries them).
            const fem::ClipBody cb(body, P.X, P.cand, v_start, blades, spring, bp, P.gripped ? &P.grips : nullptr);
            t_clip = sw.seconds();
            P.kappa_blade = cb.stiffness();
            const std::vector<std::pair<int, double>> held_at{{static_cast<int>(cb.theta_dof()), theta_kept}};
            // A patch at rest whose blades, at the new opening, touch nothing stays at rest: no solve (the jaws
            // closing through the air before they reach the wall).
            fem::NewtonResult res;
            Eigen::VectorXd moved = v_start;
            moved[cb.theta_dof()] = theta_kept;
            const fem::BladeLoads free_loads = cb.loads(moved);
            at_rest = v_start.head(nb).isZero(0.0) && free_loads.contacts[0] + free_loads.contacts[1] == 0;
            if (at_rest) {
                res.u = moved;
                res.reaction = Eigen::VectorXd::Constant(1, spring.torque(theta_kept));
                res.converged = true;
            } else {
                res = fem::solve_neo_hookean(cb, pm.fixed_dofs(), held_at, v_start, o);
            }
            if (res.factorisations > 0 && !o.dump_free_tangent.empty()) {
                tangent_dumped = true;
                o.dump_free_tangent.clear();
            }
            its += res.iterations;
            factorisations += res.factorisations;
            reused += res.analysis_reused ? 1 : 0;
            unsolved += res.unsolved_substeps;
            t_setup += res.setup_s;
            t_tangent += res.tangent_s;
            t_factor += res.factorise_s;
            failed += res.failed_factorisations;
            chords += res.chord_steps;
            t_failed += res.failed_factorise_s;
            t_back += res.back_solve_s;
            loads = at_rest ? free_loads : cb.loads(res.u);
            grips = cb.grips(res.u);
            if (wall) {
                wall_min = wall->min_distance(res.u.head(nb));
                touching = static_cast<int>(wall->active(res.u.head(nb)));
            }
            return res;
        };
        // The Newton frame: the neo-Hookean patch with the blades' and (with wall_contact) the inner walls' barriers, from
        // where the frame starts (v0) to the opening theta_kept, at most o.max_iterations iterations. The NEWTON solver's
        // every frame; a COMPLIANCE frame still beyond its linear range after its re-solves (PatchSpec::range_newton).
        auto newton_frame = [&]() {
            v_from = v0;
            newton_deepened_mm = 0;
            if (!scene.patch.wall_contact || P.inner.rows() == 0) return solve_with(pm, nullptr);
            fem::ContactParams cp;
            cp.stiffness = P.kappa_wall;
            cp.pattern_cache = P.wall_patterns;
            // Pairs are found where the frame starts: far enough for what the jaws can close in this frame (the
            // walls between them close by up to the jaws' own motion). A vertex the solve still takes through a
            // face its pairs left out is caught after it, and the frame solved again with it paired with every
            // face near its path (fem::solve_without_crossings).
            const double jaw_motion = std::abs(theta_kept - v0[nb]) * blades.length_mm + (blades.hinge - P.hinge_prev).norm();
            cp.search_mm = std::max(cp.search_mm, 0.2 + 2.0 * jaw_motion);
            // Vertices an earlier frame found going through a face its ordinary pairs left out stay paired with
            // every face within this frame's reach: else each frame would take them through again and repeat its
            // solve (the sample's 13 mm clip held at 1.89°: two solves in every held frame, 27 s each).
            cp.close_vertices = P.close_vertices;
            if (lift_mm > 0) v_from.head(nb) = fem::separate_walls(P.X, P.inner, v0.head(nb), cp, lift_mm);
            const fem::CrossingFreeSolve cs = fem::solve_without_crossings(pm, P.X, P.inner, v_from, cp, [&](const fem::ContactBody& wall) {
                P.kappa_wall = wall.stiffness();
                return solve_with(wall, &wall);
            });
            fem::NewtonResult r = cs.result;
            newton_deepened_mm = cs.deepest_mm - cs.deepest_start_mm;
            P.close_vertices = cs.close_vertices;
            P.stats.wall_resolves += cs.rounds;
            // Whatever is through a face at the end counts as interpenetration (a vertex behind a face where the
            // frame started has no pair to push it out).
            if (cs.deepest_mm > 0) wall_min = std::min(wall_min, -cs.deepest_mm);
            if (std::getenv("ANEU_PATCH_TRACE"))
                for (const fem::SurfaceCrossing& q : cs.left)
                    std::fprintf(stderr, "patch crossing left: node %d %.4f mm behind face %d (%d %d %d)\n", q.v, q.depth_mm, q.f, P.inner(q.f, 0), P.inner(q.f, 1),
                                 P.inner(q.f, 2));
            if (cs.rounds > 0 && std::getenv("ANEU_PATCH_TRACE"))
                std::fprintf(stderr, "patch t=%.4f: solved %d more time(s) with vertices that went through unpaired faces paired (%zu pairs)\n", fr.t, cs.rounds,
                             cs.pairs);
            return r;
        };
        // PatchSpec::Solver::COMPLIANCE: the frame on the patch's linearisation (made at its first frame, again every
        // refresh_frames frames at the state reached): the blades' contact (with friction) and the inner walls' (one
        // row a vertex, on the quadratic surface with 10-node elements) hard, as a complementarity problem on the
        // compliance of the nodes they can touch (fem::solve_compliant_clip_walls). The opening is held at theta_kept, as
        // in the Newton frames: a spring clip's balance is approached by the same secant steps on R = τ − M. (With θ an
        // unknown of the frame, at the balance (the compliance frames' released clip), the sample's held clip, pushed open
        // past the applier, swung 3.2 -> 5.8 -> 4.6 -> 5.5 deg in successive frames and its walls went 4-5 mm through each
        // other: each frame's blades linearised where the last one left them.)
        const bool compliance = scene.patch.solver == PatchSpec::Solver::COMPLIANCE;
        // The compliance frame's parts [s], for the trace: a linearisation made in it, the rows, the Delassus matrix,
        // the LCP, the wall pairs' search and crossing checks, the patch's displacement from the forces.
        double c_lin = 0, c_rows = 0, c_delassus = 0, c_lcp = 0, c_search = 0, c_disp = 0;
        // The compliance frame's largest reach from its linearisation, over the wall's thickness, and where.
        Reach lag;
        std::vector<double> c_profile, c_across;  // the blades' normal force per mm from the hinge, per 0.1 mm across (PatchEnd)
        int c_repeats = 0, c_nrows = 0, c_pivots = 0, c_sweeps = 0;
        auto compliant_frame = [&]() {
            fem::NewtonResult res;
            res.u = v0;
            std::shared_ptr<PatchRun::Compliant>& C = P.compliant;
            const Eigen::VectorXd u0 = v0.head(nb);
            // The nodes the blades can reach as they close from opening th (within 0.1 mm of their wedge), and the inner
            // walls they flatten (faces whose corners lie within 0.3 mm of it) or that are about to meet anywhere in the
            // patch (within 0.3 mm of each other), the faces' corners candidates too (fem::compliant_setup, as
            // aneu_bench_compliance's frames), the patch's nodes standing at X + u.
            // (Tandem clips: near any clip's wedge, each at its own opening `th_more`.)
            auto setup_at = [&](const Eigen::VectorXd& u, double th, const std::vector<double>& th_more) {
                Eigen::MatrixX3d x = P.X;
                for (Eigen::Index a = 0; a < x.rows(); ++a) x.row(a) += u.segment<3>(3 * a).transpose();
                // (ANEU_NO_OUTER_CONTACT: without the outer surface's faces, to measure what they cost; not a scene option.)
                static const bool outer = !std::getenv("ANEU_NO_OUTER_CONTACT");
                const Eigen::MatrixX3i inner = scene.patch.wall_contact ? P.inner : Eigen::MatrixX3i();
                const Eigen::MatrixX3i outer_faces = scene.patch.wall_contact && outer ? P.outer : Eigen::MatrixX3i();
                if (mf.empty()) return fem::compliant_setup(blades, th, x, P.cand, inner, fem::COMPLIANT_WALL_APPROACH_MM, outer_faces, &P.X);
                std::vector<fem::CompliantClip> all{fem::CompliantClip{blades, th, th, spring}};
                for (size_t j = 0; j < mf.size(); ++j) all.push_back(fem::CompliantClip{mf[j].blades, th_more[j], th_more[j], mf[j].spring});
                return fem::compliant_setup(all, x, P.cand, inner, fem::COMPLIANT_WALL_APPROACH_MM, outer_faces, &P.X);
            };
            std::vector<double> more_from, more_kept;
            std::vector<Eigen::Vector3d> more_hinges;
            for (const MemberFrame& g : mf) {
                more_from.push_back(g.theta_from);
                more_kept.push_back(g.theta_kept);
                more_hinges.push_back(g.blades.hinge);
            }
            // The candidates the frames act on from here, selected at opening th with the hinge there (the further
            // clips' at th_more with theirs).
            auto adopt = [&](fem::CompliantSetup&& cs, double th, const Eigen::Vector3d& hinge, const std::vector<double>& th_more,
                             const std::vector<Eigen::Vector3d>& hinges_more) {
                C->cand = std::move(cs.candidates);
                C->faces = std::move(cs.faces);
                C->search.params.face_surface = std::move(cs.face_surface);
                C->approach_faces = cs.approach_faces;
                C->Xc.resize(static_cast<Eigen::Index>(C->cand.size()), 3);
                for (size_t k = 0; k < C->cand.size(); ++k) C->Xc.row(static_cast<Eigen::Index>(k)) = P.X.row(C->cand[k]);
                C->theta_sel = th;
                C->hinge_sel = hinge;
                C->more_theta_sel = th_more;
                C->more_hinge_sel = hinges_more;
            };
            // Frames made for other clips than this frame's (a further clip left the patch, or the first handed it on:
            // leave_patch) go on on their linearisation and candidates (those of every clip there was: the clips left
            // among them), but without their last rows, which are numbered by clip: the next frame starts where the
            // patch stands, its rows cold. (Made anew instead, linearised at the state reached, the tube's clip left
            // alone, on frames linearised once at rest, gripped 0.006 N instead of 1.12 N: the free state of a
            // linearisation there lies elsewhere than the frames' own.) The further clips' selection is due again.
            bool start_at_state = false;
            if (C && C->clips != frame_clips) {
                C->last = fem::CompliantFrame{};
                C->warm = false;
                C->clips = frame_clips;
                C->more_theta_sel.clear();
                C->more_hinge_sel.clear();
                start_at_state = true;
            }
            if (C && C->from_state) {  // the patch went back (a frame not taken, a restart): its rows stay warm
                start_at_state = true;
                C->from_state = false;
            }
            if (!C) {
                // A remade patch's first frames (its state carried, off rest) start where it stands too, for the same
                // reason: from the new linearisation's free state the gripped tissue starts sprung back through the
                // blades. (Session 55, the tube's jaws sliding out of their patch twice: its remade frames needed 4
                // re-solves for the linear range, 2.27 -> 2.33 -> 1.83 -> 0.36 -> 0.23 wall thicknesses, 10 in the
                // run; started where the patch stands, at most 1 a frame, 7 in the run, reach 0.217 x against 0.232.)
                if (!u0.isZero(0.0)) start_at_state = true;
                C = std::make_shared<PatchRun::Compliant>();
                C->clips = frame_clips;
                adopt(setup_at(u0, v0[nb], more_from), v0[nb], blades.hinge, more_from, more_hinges);
            }
            // A refresh selects the candidates again, for the jaws as they are (the wedge they sweep closing from a
            // little more than this opening), and the inner walls' faces where the walls now are: the first selection
            // is for the jaws as they first closed on the wall (the sample's: 2,391 candidates at 60 deg, 1,821 at the
            // end; its walls on the neck line 0.0011 mm through each other, 0.0685 mm with the first selection kept).
            std::vector<double> more_sel;
            for (size_t j = 0; j < mf.size(); ++j) more_sel.push_back(std::max(more_from[j], more_kept[j]) + RESELECT_MARGIN_RAD);
            auto select = [&](const Eigen::VectorXd& u) {
                const double th = std::max(v0[nb], theta_kept) + RESELECT_MARGIN_RAD;
                return std::make_pair(setup_at(u, th, more_sel), th);
            };
            // The frames' state carried over to a refresh's candidates, which the frames then act on.
            auto take_setup = [&](fem::CompliantSetup&& cs, double th, const Eigen::Vector3d& hinge, const std::vector<double>& th_more,
                                  const std::vector<Eigen::Vector3d>& hinges_more, const Eigen::VectorXd& at) {
                fem::carry_compliant_frames(C->cand, C->faces, cs.candidates, cs.faces, at, C->last, C->search);
                adopt(std::move(cs), th, hinge, th_more, hinges_more);
            };
            // A refresh made on the second core (threaded mode) that is done: the frames go on with it from here.
            if (C->pending && C->pending->done.load(std::memory_order_acquire)) {
                Refresh& q = *C->pending;
                // The frames have gone on meanwhile: a linearisation the patch's surface has since left by more than the
                // linear range (Scene::linear_limit wall thicknesses, as the frames' reach is measured) would take the
                // frames back to its state in one step (the tube closing: an element inverted in the first frame on a
                // refresh 0.36 s old, and every refresh after it refused). It is dropped, and one begun from here.
                const double moved = q.lin ? surface_reach(sf, P.cand_vertex, P.cand, u0, q.lin->u0()).ratio : 0.0;
                const bool stale = q.lin && scene.linear_limit > 0 && moved > scene.linear_limit;
                if (stale) {
                    ++P.stats.refreshes_stale;
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: the linearisation at t=%.4f made on another thread (%.2f s) dropped: the surface has moved %.2f wall thicknesses since\n",
                                     fr.t, q.t, q.seconds, moved);
                } else if (q.lin) {
                    take_setup(std::move(q.setup), q.theta_sel, q.hinge_sel, q.more_theta_sel, q.more_hinge_sel, u0);
                    C->lin = std::move(q.lin);
                    C->note_projection(PROJECTED_RUN);
                    C->borrowed = 0;
                    C->own_w_flops = C->lin->w_flops;
                    C->own_factor_flops = C->lin->factor_flops;
                    ++P.stats.linearisations;
                    P.stats.last_candidates = static_cast<int>(C->cand.size());
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: the linearisation at t=%.4f made on another thread (%.2f s: tangent %.2f s, factorised %.2f s%s, compliance %.2f s; free step %.4g; %.4g of the way to that state) taken\n",
                                     fr.t, q.t, q.seconds, C->lin->tangent_s, C->lin->factorise_s, C->lin->projected_first ? " (projected from the start)" : C->lin->projected ? " (projected)" : "", C->lin->compliance_s,
                                     C->lin->free_step, q.back);
                } else {
                    ++P.stats.linearisations_failed;
                    if (std::getenv("ANEU_PATCH_TRACE")) std::fprintf(stderr, "patch t=%.4f: the linearisation at t=%.4f refused: %s\n", fr.t, q.t, q.failed.c_str());
                }
                P.stats.linearise_s += q.seconds;
                if (!stale) C->since = 0;  // (a dropped one: another is begun from here at once)
                C->pending.reset();
            }
            // (Refreshed frames are also due for one when the jaws open past the wedge their candidates were selected
            // for, or the hinge moves: the candidates may miss what the blades now reach.)
            const bool reselect = scene.patch.refresh_frames > 0;
            bool left_wedge = reselect && (theta_kept > C->theta_sel || (blades.hinge - C->hinge_sel).norm() > RESELECT_HINGE_MM);
            if (reselect && C->more_theta_sel.size() != mf.size()) left_wedge = true;
            for (size_t j = 0; reselect && j < mf.size() && j < C->more_theta_sel.size(); ++j)
                if (more_kept[j] > C->more_theta_sel[j] || (more_hinges[j] - C->more_hinge_sel[j]).norm() > RESELECT_HINGE_MM) left_wedge = true;
            const bool due = reselect && (C->since >= scene.patch.refresh_frames || left_wedge);
            if (C->lin && due && fr.mx && !C->pending) {
                // Threaded (real-time) mode: the refresh is made on another thread (the second core) from this frame's
                // state, and the frames go on with the linearisation they have until it is done (the sample's refresh
                // takes 10-13 s: inline, every refresh held the physics thread that long). The deterministic mode makes
                // it inline, at the frame it is due, so its logs stay the same from run to run.
                auto q = std::make_shared<Refresh>();
                q->t = fr.t;
                std::tie(q->setup, q->theta_sel) = select(u0);
                q->hinge_sel = blades.hinge;
                q->more_theta_sel = more_sel;
                q->more_hinge_sel = more_hinges;
                C->pending = q;
                refresh_jobs.emplace_back(q, std::thread([q, hold, X = P.X, u0, valid = Eigen::VectorXd(C->lin->u0()), cand = q->setup.candidates,
                                                          pf = C->project_next > 0] {
                    omp_set_num_threads(1);  // the tangent's assembly beside the physics thread, not across its core
                    const Stopwatch lw;
                    try {
                        q->lin = linearise_patch(*hold, X, u0, &valid, cand, q->back, nullptr, pf);
                    } catch (const std::exception& e) {  // NumericalError: an element inverted at that state
                        q->lin.reset();
                        q->failed = e.what();
                    }
                    q->seconds = lw.seconds();
                    q->done.store(true, std::memory_order_release);
                }));
            }
            // A linearisation made here, inline, at the patch's state `at`: the first, a refresh due, or one for a frame
            // that went beyond the linear range of the last (below).
            // With PatchSpec::compliance_reuse it borrows the last one's W where the candidates it selects are all among
            // W's, unless `own` (a frame whose passes on a borrowed W did not converge).
            auto refresh_at = [&](const Eigen::VectorXd& at, bool own = false) {
                const Stopwatch lw;
                bool made = true;
                try {
                    double back = 1;
                    bool borrow = false;
                    if (C->lin && reselect) {
                        auto [cs, th] = select(at);
                        // Borrowing takes the new selection: W's blocks between the candidates it shares with the
                        // last W are that W's, the added ones' columns made on the tangent it was made on
                        // (fem::Linearisation's borrowing constructor on other candidates), where at most a quarter of
                        // the selection is new. (Session 56 borrowed only where the new selection lay within W's
                        // candidates: C0024's planned clip then borrowed 7 of 176 times. Keeping the old selection
                        // instead missed the outer surface about to meet itself: its tissue ended 0.19 mm inside
                        // itself, against 0.012 mm.) While borrowing pays: a borrowed W saves making W, and a frame
                        // that does not converge on it costs another factorisation (and W). So the run borrows while its
                        // fallbacks' factorisations cost no more than the Ws its converged borrowings (two more, to
                        // start) saved, the two weighed by the last own linearisation's floating-point operations (not
                        // seconds: the run stays deterministic), W's at half weight, its SYRK running at ~2x the
                        // factorisation's rate. (C0024: W 147 against 174 GFLOP, 44 against 29 GFLOP/s, and 18 of
                        // 43 borrowing frames fell back, slower than making W each time; C0001's tandem: W 703 against
                        // 99 GFLOP, 4 of 66 fell back.)
                        const double ok = P.stats.linearisations_borrowed - P.stats.borrow_fallbacks;
                        const bool pays = P.stats.borrow_fallbacks * C->own_factor_flops <= (ok + 2) * 0.5 * C->own_w_flops;
                        if (!own && C->borrowed < scene.patch.compliance_reuse && C->lin->candidates() == C->cand && pays) {
                            std::vector<char> in_w(static_cast<size_t>(P.X.rows()), 0);
                            for (int c : C->cand) in_w[static_cast<size_t>(c)] = 1;
                            const auto added = std::count_if(cs.candidates.begin(), cs.candidates.end(), [&](int c) { return !in_w[static_cast<size_t>(c)]; });
                            borrow = 4 * static_cast<size_t>(added) <= cs.candidates.size();
                        }
                        const bool pf = C->project_next > 0;
                        std::unique_ptr<fem::Linearisation> lin = borrow ? linearise_patch(pm, P.X, at, &C->lin->u0(), cs.candidates, back, C->lin.get(), pf)
                                                                         : linearise_patch(pm, P.X, at, &C->lin->u0(), cs.candidates, back, nullptr, pf);
                        take_setup(std::move(cs), th, blades.hinge, more_sel, more_hinges, at);
                        C->lin = std::move(lin);
                        if (borrow) {
                            ++C->borrowed;
                            ++P.stats.linearisations_borrowed;
                        }
                    } else {
                        C->lin = linearise_patch(pm, P.X, at, C->lin ? &C->lin->u0() : nullptr, C->cand, back, nullptr, C->project_next > 0);
                    }
                    C->note_projection(PROJECTED_RUN);
                    if (!borrow) {
                        C->borrowed = 0;
                        C->own_w_flops = C->lin->w_flops;
                        C->own_factor_flops = C->lin->factor_flops;
                    }
                    ++P.stats.linearisations;
                    if (P.stats.first_candidates == 0) P.stats.first_candidates = static_cast<int>(C->cand.size());
                    P.stats.last_candidates = static_cast<int>(C->cand.size());
                    if (back < 1 && std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: an element is inverted at the state reached: linearised %.4g of the way there from the last linearisation\n", fr.t, back);
                    if (borrow && std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: linearised on %zu candidates, borrowing the compliance of the last made (%d in a row; %d candidates added, their columns %.2f s): tangent %.2f s, factorised %.2f s%s; free step %.4g of Newton's\n",
                                     fr.t, C->cand.size(), C->borrowed, C->lin->added_candidates, C->lin->compliance_s, C->lin->tangent_s, C->lin->factorise_s,
                                     C->lin->projected_first ? " (element tangents projected from the start)" : C->lin->projected ? " (not positive definite: again with the element tangents projected)" : "", C->lin->free_step);
                    else if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: linearised on %zu candidates (%lld wall faces, %zu where walls are about to meet away from the jaws, %lld of them the outer surface's): tangent %.2f s, factorised %.2f s%s, compliance %.2f s; free step %.4g of Newton's"
                                     " (%.0f free DOFs, %.0f kept, nnz(L) %.3g, factor %.3g GFLOP, W %.3g GFLOP at %.1f GFLOP/s)\n",
                                     fr.t, C->cand.size(), static_cast<long long>(C->faces.rows()), C->approach_faces,
                                     static_cast<long long>(std::count(C->search.params.face_surface.begin(), C->search.params.face_surface.end(), 1)), C->lin->tangent_s, C->lin->factorise_s,
                                     C->lin->projected_first ? " (element tangents projected from the start)" : C->lin->projected ? " (not positive definite: again with the element tangents projected)" : "", C->lin->compliance_s,
                                     C->lin->free_step, C->lin->free_dofs, C->lin->kept_dofs, C->lin->nnz_L, C->lin->factor_flops / 1e9,
                                     C->lin->w_flops / 1e9, C->lin->w_gflops_per_s);
                } catch (const NumericalError&) {
                    // An element the frames took past inversion: this state cannot be linearised. The frames go on
                    // with the last linearisation (a first one that fails ends the run).
                    if (!C->lin) throw;
                    ++P.stats.linearisations_failed;
                    made = false;
                }
                P.stats.linearise_s += lw.seconds();
                c_lin += lw.seconds();
                C->since = 0;
                return made;
            };
            if (!C->lin || (due && !fr.mx)) refresh_at(u0);
            fem::CompliantOptions co;
            co.blade_friction = scene.patch.blade_friction;
            co.friction_cell_mm = scene.patch.friction_cell_mm;
            co.wall_one_face = true;
            int repeats = 0;
            fem::CompliantFrame f;
            // The walls' distance a frame ended at: its rows' and, whatever its rows, anything through a face (as the
            // Newton frames' crossings count below: a vertex behind a face where the frame started has no row to push
            // it out).
            auto walls_at = [](const fem::CompliantFrame& g) {
                return g.wall_crossed_mm > 0 ? std::min(g.wall_min_distance_mm, -g.wall_crossed_mm) : g.wall_min_distance_mm;
            };
            // A frame that takes the patch's surface beyond the linear range of its linearisation (Scene::linear_limit
            // wall thicknesses: its forces there are off by more than 10 %) is solved again on a linearisation at the
            // state it reached, warm from its own rows, up to PatchSpec::range_resolves times: Newton's steps on the
            // frame, each a refresh. Inline (deterministic) mode only; the threaded mode's refreshes come from the other
            // core. Damped where they diverge: an attempt that went further from its linearisation than the one before
            // it did is linearised again halfway there, and the frame ends with the attempt nearest its own
            // linearisation (session 45: C0054's re-solves round its fold went 1.55 -> 3.10 and 0.91 -> 0.99 wall
            // thicknesses, the tangent there indefinite; the sample's went 0.40 -> 0.37 -> 0.31, one warning).
            struct Attempt {
                PatchRun::Compliant state;  // the frames' state after it (its linearisation, candidates, wall search)
                fem::CompliantFrame f;
                Eigen::VectorXd u;
                Reach lag;
                int number = 0;
            };
            enum class Span { WITHIN, BEYOND, FAILED };
            // One span of the frame: the opening from th_from to th_to, the patch starting at v_from (where the last
            // frame, or the span before, ended: the first solve is warm from it, its re-solves start there). Leaves the
            // span's end in f, res.u.head(nb) and lag.
            // The further clips in a span of the first's opening th_from -> th_to: each over the same part of its own
            // change this frame (a span split in halves splits theirs too).
            auto more_at = [&](double th_from, double th_to) {
                std::vector<fem::CompliantClip> out;
                const double whole = theta_kept - v0[nb];
                const bool moves = std::abs(whole) > 1e-12;
                const double a = moves ? (th_from - v0[nb]) / whole : 0.0, b = moves ? (th_to - v0[nb]) / whole : 1.0;
                for (const MemberFrame& g : mf)
                    out.push_back(fem::CompliantClip{g.blades, g.theta_from + b * (g.theta_kept - g.theta_from), g.theta_from + a * (g.theta_kept - g.theta_from), g.spring});
                return out;
            };
            auto span = [&](double th_from, double th_to, const Eigen::VectorXd& v_from) {
                const std::vector<fem::CompliantClip> more = more_at(th_from, th_to);
                const std::vector<fem::CompliantClip>* more_p = more.empty() ? nullptr : &more;
                std::optional<Attempt> best;
                double last_ratio = -1;
                for (int range_again = 0;; ++range_again) {
                    const fem::CompliantFrame* warm = C->warm ? &C->last : nullptr;
                    // A re-solve is warm from the attempt before it, and starts where the span started: the patch at
                    // v_from, on this linearisation's candidates (the first solve starts where the last ended, warm's end).
                    Eigen::VectorXd start;
                    if (range_again > 0 || start_at_state) {
                        start.resize(3 * static_cast<Eigen::Index>(C->cand.size()));
                        for (size_t k = 0; k < C->cand.size(); ++k)
                            start.segment<3>(3 * static_cast<Eigen::Index>(k)) = v_from.segment<3>(3 * static_cast<Eigen::Index>(C->cand[k]));
                    }
                    const Eigen::VectorXd* start_at = range_again > 0 || start_at_state ? &start : nullptr;
                    int again = 0;  // this solve's repeats for crossings (summed over the frame's solves)
                    try {
                        f = C->faces.rows() > 0 ? fem::solve_compliant_clip_walls(*C->lin, C->Xc, C->faces, C->search, blades, spring, th_to, th_from, warm, co, &again, start_at, more_p)
                                                : fem::solve_compliant_clip(*C->lin, blades, spring, th_to, th_from, warm, co, nullptr, start_at, more_p);
                        repeats += again;
                    } catch (const NumericalError& e) {
                        // The active rows' factorisation failed: the frame is not solved (an unconverged frame: the patch
                        // stays where it was; a second in a row restarts from the last converged one with a smaller step).
                        res.converged = false;
                        res.failure = e.what();
                        return Span::FAILED;
                    }
                    c_rows = f.rows_s;
                    c_delassus = f.delassus_s;
                    c_lcp = f.lcp_s;
                    c_search = f.search_s;
                    c_repeats = repeats;
                    c_nrows = static_cast<int>(f.constraint.size());
                    c_pivots = f.pivots;
                    c_sweeps = f.sweeps;
                    // Passes on a borrowed W that ended further than borrow_accept_mm from this tangent's frame: solved again, as it started,
                    // on a linearisation at the same state with its own W (not counted as a re-solve for the range).
                    if (C->lin->borrowed() && f.compliance_mismatch_mm > co.borrow_accept_mm) {
                        ++P.stats.borrow_fallbacks;
                        if (std::getenv("ANEU_PATCH_TRACE"))
                            std::fprintf(stderr, "patch t=%.4f: the frame's passes on the borrowed compliance ended %.3g mm from the tangent's (%d passes): solved again on a linearisation with its own\n",
                                         fr.t, f.compliance_mismatch_mm, f.passes);
                        const Eigen::VectorXd at = C->lin->u0();
                        if (refresh_at(at, true)) {
                            --range_again;
                            continue;
                        }
                    }
                    // Passes that converged slowly (W has drifted from the tangents): the next linearisation makes its own.
                    if (C->lin->borrowed() && f.passes > BORROW_SLOW_PASSES) C->borrowed = scene.patch.compliance_reuse;
                    const Stopwatch dw;
                    res.u.head(nb) = C->lin->displacement(f.candidate_forces);
                    c_disp = dw.seconds();
                    // How far the frame took the surface from the linearisation's state, over the wall's thickness (folded
                    // into the patch's figures, and warned, under the lock below).
                    lag = surface_reach(sf, P.cand_vertex, P.cand, res.u, C->lin->u0());
                    const bool over = reselect && !fr.mx && scene.linear_limit > 0 && lag.ratio > scene.linear_limit;
                    if (over && (!best || lag.ratio < best->lag.ratio)) best = Attempt{*C, f, res.u.head(nb), lag, range_again};
                    // No re-solve from an attempt gone over RANGE_HOPELESS times as far as the nearest, or over
                    // RANGE_ABSURD wall thicknesses (its state's linearisation would be at elements nearly inverted).
                    const bool off_nearest = over && best && best->number != range_again && lag.ratio > RANGE_HOPELESS * best->lag.ratio;
                    const bool hopeless = off_nearest || (over && lag.ratio > RANGE_ABSURD);
                    if (hopeless) {
                        ++P.stats.range_hopeless;
                        if (std::getenv("ANEU_PATCH_TRACE"))
                            std::fprintf(stderr, "patch t=%.4f: the frame's attempt %d went %.2f wall thicknesses from its linearisation, over %s (attempt %d, %.2f): no more re-solves\n",
                                         fr.t, range_again, lag.ratio, off_nearest ? "4 times its nearest" : "10 wall thicknesses; its nearest", best->number, best->lag.ratio);
                    }
                    if (over && !hopeless && range_again < scene.patch.range_resolves) {
                        const double was = lag.ratio;
                        const bool diverging = last_ratio >= 0 && was > last_ratio;
                        last_ratio = was;
                        // How far towards the attempt the next linearisation lies: all the way (a Newton step); halfway
                        // where the attempts diverge.
                        const double step = diverging ? 0.5 : 1.0;
                        const Eigen::VectorXd at = step < 1 ? Eigen::VectorXd(C->lin->u0() + step * (res.u.head(nb) - C->lin->u0())) : Eigen::VectorXd(res.u.head(nb));
                        C->last = f;  // the re-solve's warm start, carried to the new linearisation's candidates
                        C->warm = true;
                        if (refresh_at(at)) {
                            ++P.stats.range_refreshes;
                            P.stats.max_frame_resolves = std::max(P.stats.max_frame_resolves, range_again + 1);
                            if (std::getenv("ANEU_PATCH_TRACE"))
                                std::fprintf(stderr, "patch t=%.4f: the frame reached %.2f wall thicknesses from its linearisation (vertex %ld, %.4f mm): solved again on one made %.3g of the way there%s\n",
                                             fr.t, was, static_cast<long>(lag.vertex), lag.mm, step, diverging ? " (further than the attempt before)" : "");
                            continue;
                        }
                    }
                    // Ended beyond the range after re-solves: the attempt nearest its linearisation, if not this one.
                    if (over && best && best->number != range_again) {
                        if (std::getenv("ANEU_PATCH_TRACE"))
                            std::fprintf(stderr, "patch t=%.4f: the frame's attempt %d (%.2f wall thicknesses from its linearisation) kept, not the last (%.2f)\n", fr.t,
                                         best->number, best->lag.ratio, lag.ratio);
                        *C = std::move(best->state);
                        f = std::move(best->f);
                        res.u.head(nb) = best->u;
                        lag = best->lag;
                        ++P.stats.range_earlier_kept;
                    }
                    return over ? Span::BEYOND : Span::WITHIN;
                }
            };
            // The frame's reach: the largest of the spans it was solved in.
            Reach frame_lag;
            frame_lag.ratio = -1;
            std::function<Span(double, double, const Eigen::VectorXd&, int)> solve_split = [&](double th_from, double th_to, const Eigen::VectorXd& v_from,
                                                                                                int depth) {
                // The frames' state where the span starts, to solve it again from there in halves (only where it may be:
                // inline, with a split left; the linearisation is shared, the rest is small).
                std::optional<PatchRun::Compliant> saved;
                if (reselect && !fr.mx && scene.linear_limit > 0 && depth < scene.patch.range_splits && std::abs(th_to - th_from) > 1e-9) saved = *C;
                const Span got = span(th_from, th_to, v_from);
                if (got != Span::BEYOND || !saved) {
                    if (got != Span::FAILED && lag.ratio > frame_lag.ratio) frame_lag = lag;
                    return got;
                }
                // Beyond the range after every re-solve: the span again in two halves, each from where it starts.
                *C = std::move(*saved);
                ++P.stats.range_splits;
                P.stats.max_frame_splits = std::max(P.stats.max_frame_splits, depth + 1);
                const double mid = 0.5 * (th_from + th_to);
                if (std::getenv("ANEU_PATCH_TRACE"))
                    std::fprintf(stderr, "patch t=%.4f: the frame's span %.4f -> %.4f deg ended %.2f wall thicknesses from its linearisation after its re-solves: solved again in two halves\n",
                                 fr.t, th_from / DEG, th_to / DEG, lag.ratio);
                const Span first = solve_split(th_from, mid, v_from, depth + 1);
                if (first == Span::FAILED) return first;
                C->last = f;
                C->warm = true;
                Eigen::VectorXd v_mid = v_from;
                v_mid.head(nb) = res.u.head(nb);
                v_mid[nb] = mid;
                refresh_at(Eigen::VectorXd(v_mid.head(nb)));  // (refused: the half goes on with the last one)
                const Span second = solve_split(mid, th_to, v_mid, depth + 1);
                return second == Span::WITHIN && first == Span::BEYOND ? Span::BEYOND : second;
            };
            const Span got = solve_split(v0[nb], theta_kept, v0, 0);
            // A frame not taken: the blades' loads and the walls stay what the last frame reported (C->last, the warm
            // start, may be a re-solve's attempt of this frame or of one not taken: the re-solves carry it to their
            // linearisations' candidates).
            auto keep_last_frame = [&] {
                loads = P.course.loads_shown;
                for (MemberFrame& g : mf) g.loads = g.course.loads_shown;
                wall_min = P.course.wall_min_shown;
                touching = P.course.touching_shown;
            };
            // Not taken, the patch where the frame started (a frame over RANGE_ABSURD or PatchSpec::walls_reject_mm).
            auto reject_frame = [&](std::string why) {
                C->from_state = true;
                res.u = v0;
                res.converged = false;
                res.failure = std::move(why);
                res.iterations = f.passes;
                keep_last_frame();
                lag = Reach{};
                return res;
            };
            if (got == Span::FAILED) {
                keep_last_frame();
                return res;
            }
            lag = frame_lag;
            // Still beyond the range after its re-solves (and halvings): with PatchSpec::range_newton the frame is solved
            // as a Newton frame (the nonlinear patch has no linear range), from where it started, and the frames go on
            // from the state it reached, linearised there. Where it does not converge within those iterations the
            // compliance frame's nearest attempt stands (and is warned, as without it).
            // (Tandem clips: the Newton frames take one clip; their frames stay the compliance frame's.)
            // The frame solved as a Newton frame instead, with at most `iterations` iterations, from where it started
            // (its walls and pressed nodes first lifted NEWTON_LIFT_MM apart); converged, the frames go on from its
            // state, linearised there. `why` is what the trace says of the compliance frame.
            bool newton_tried = false;  // (a frame's Newton solve is tried once: range_newton's or walls_newton's)
            auto as_newton_frame = [&](int iterations, const std::string& why) -> std::optional<fem::NewtonResult> {
                newton_tried = true;
                const Stopwatch nw;
                const int frame_halvings = o.max_halvings;  // (the frame's own budget, given back after)
                o.max_iterations = o.max_total_iterations = iterations;
                o.max_halvings = 6;
                lift_mm = NEWTON_LIFT_MM;
                fem::NewtonResult nr = newton_frame();
                lift_mm = 0;
                o.max_iterations = o.max_total_iterations = scene.patch.newton_per_frame;
                o.max_halvings = frame_halvings;
                // Its barriers hold the walls apart where they are apart at its start; a vertex already behind a face
                // there has no pair to push it out and may go deeper (fem::CrossingFreeSolve::deepest_start_mm). (The
                // sample's 2 mm jaws' −0.247 mm from t = 1.260 s is not this: that vertex was as deep at the frame's
                // start; bench/results/study/compliance.md, session 66.)
                // A Newton frame that takes the deepest such vertex further than PatchSpec::walls_reject_mm is not
                // taken, as a compliance frame would not be.
                if (scene.patch.walls_reject_mm > 0 && newton_deepened_mm > scene.patch.walls_reject_mm) {
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: %s; as a Newton frame it took a vertex behind a face %.4f mm deeper than at its start (walls %.4f mm): not taken (over %g mm)\n",
                                     fr.t, why.c_str(), newton_deepened_mm, wall_min, scene.patch.walls_reject_mm);
                    nr.converged = false;
                    nr.load_fraction = 0;  // (not taken where it stands either)
                    nr.failure = "a vertex behind a face taken deeper";
                }
                const bool loose = !nr.converged && !nr.cancelled && nr.load_fraction >= 1 && nr.residual <= NEWTON_FRAME_LOOSE &&
                                   nr.u.size() == v0.size();
                if (loose) {
                    ++P.stats.newton_frames_loose;
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: the Newton frame's %d iterations ran out at residual %.2e (%s): taken there (at most %g)\n", fr.t,
                                     nr.iterations, nr.residual, nr.failure.c_str(), NEWTON_FRAME_LOOSE);
                    nr.converged = true;
                }
                if (nr.converged && !cancel_frames) {
                    // The frames' next start: Newton's state on the candidates (the LCP cold: no rows carried).
                    fem::CompliantFrame at;
                    at.theta = nr.u[nb];
                    at.loads = loads;
                    at.wall_min_distance_mm = wall_min;
                    at.wall_contacts = touching;
                    at.candidate_u.resize(3 * static_cast<Eigen::Index>(C->cand.size()));
                    for (size_t k = 0; k < C->cand.size(); ++k)
                        at.candidate_u.segment<3>(3 * static_cast<Eigen::Index>(k)) = nr.u.segment<3>(3 * static_cast<Eigen::Index>(C->cand[k]));
                    C->last = std::move(at);
                    C->warm = true;
                    const bool relinearised = refresh_at(Eigen::VectorXd(nr.u.head(nb)));
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: %s: solved as a Newton frame instead (%d iterations, residual %.2e, %.2f s; walls %.4f mm, opening %.4f -> %.4f deg)%s\n",
                                     fr.t, why.c_str(), nr.iterations, nr.residual, nw.seconds(), wall_min, v0[nb] * 180 / M_PI, nr.u[nb] * 180 / M_PI,
                                     relinearised ? ", the frames linearised at its state" : "; its state could not be linearised: the frames go on with the last linearisation");
                    lag = Reach{};  // (a Newton frame is the nonlinear patch's own: no linearisation to be away from)
                    return nr;
                }
                if (std::getenv("ANEU_PATCH_TRACE"))
                    std::fprintf(stderr, "patch t=%.4f: %s; as a Newton frame it did not converge in %d iterations (%s; %.3g of the opening's change reached, residual %.2e, %d substeps, %d iterations with the tangent projected, %.2f s): the compliance frame kept\n",
                                 fr.t, why.c_str(), nr.iterations, nr.failure.c_str(), nr.load_fraction, nr.residual, nr.substeps, nr.shifted, nw.seconds());
                grips.clear();  // (the compliance frame's loads and walls: below)
                return std::nullopt;
            };
            // Still beyond the range after its re-solves (and halvings): with PatchSpec::range_newton the frame is solved
            // as a Newton frame (the nonlinear patch has no linear range). Where it does not converge within those
            // iterations the compliance frame's nearest attempt stands (and is warned, as without it).
            // (Tandem clips: the Newton frames take one clip; their frames stay the compliance frame's.)
            if (got == Span::BEYOND && scene.patch.range_newton > 0 && mf.empty()) {
                char why[160];
                std::snprintf(why, sizeof why, "the frame ended %.2f wall thicknesses from its linearisation after its re-solves", lag.ratio);
                if (std::optional<fem::NewtonResult> nr = as_newton_frame(scene.patch.range_newton, why)) {
                    ++P.stats.range_newton_frames;
                    return *nr;
                }
                ++P.stats.range_newton_failed;
            }
            if (reselect && !fr.mx && scene.linear_limit > 0 && lag.ratio > RANGE_ABSURD) {
                ++P.stats.range_absurd;
                if (std::getenv("ANEU_PATCH_TRACE"))
                    std::fprintf(stderr, "patch t=%.4f: the frame ended %.2f wall thicknesses from its linearisation (vertex %ld, %.4f mm) after its re-solves: not taken (over %g), the patch stays where the frame started\n",
                                 fr.t, lag.ratio, static_cast<long>(lag.vertex), lag.mm, RANGE_ABSURD);
                return reject_frame("the frame went " + std::to_string(lag.ratio) + " wall thicknesses from its linearisation");
            }
            // Nor is a compliance frame taken that ends with the patch's walls more than PatchSpec::walls_reject_mm
            // [0.1 mm] through each other (its rows' distance, or anything through a face: walls_at). The acceptance
            // bound of issue #15 is 0.02 mm, and a frame 5 times past it is not a contact that was solved but a
            // linearisation that went wrong: the sample's 2 mm jaws at t = 1.252 s (session 63) kept an attempt 0.88
            // wall thicknesses from its linearisation with the walls 0.296 mm through each other, the next frame 0.403
            // mm, and every frame after it went on from there. Counted as a frame that did not converge, as
            // RANGE_ABSURD's. (Replayed on the stored traces of sessions 60-63: the planned 1 mm runs' frames end at
            // most 0.0099 mm through on the sample and C0001's 2.5 mm patch; C0024's held run (session 62) 0.0952 mm at
            // t = 1.372 s, kept; it would reject C0024's unheld run's last two frames (0.186, 0.184 mm) and five of
            // C0001's session-60 grown patch, 0.24-0.81 mm.)
            // With PatchSpec::walls_shorten N, such a frame is first shortened: the patch moved a half, a quarter, ... (at
            // most 2^-N) of the way from where the frame started to where it ended, its opening's change and its blades'
            // loads with it (from the last frame's to its end's: on one linearisation the state is affine in the forces),
            // and the longest that leaves the walls within the limit is taken: a damped step, the rest of the way left
            // to the frames after, each linearised where the last stopped, with the pairs the
            // walls now near each other make (the frames' state was out of balance, not the contact unsolvable: the
            // sample's 2 mm jaws at t = 1.252 s, held at 5.430 deg, a frame with no change of the opening went 0.88 wall
            // thicknesses). One clip's frames only (a tandem's are not taken, as before).
            const double walls = walls_at(f);
            const bool walls_past = scene.patch.walls_reject_mm > 0 && walls < -scene.patch.walls_reject_mm;
            // With PatchSpec::walls_newton N such a frame (one clip's) is first solved as a Newton frame, with at most N
            // iterations: the barriers' steps are bounded by collision detection, so the walls cannot pass through each
            // other, and its step is the neo-Hookean patch's, not the projected tangent's (the sample's 2 mm jaws from
            // t = 1.252 s: every compliance frame's whole step 1.1-1.3 mm through, session 65). Not converged, the
            // frame is shortened or not taken, as without it. (Not again where range_newton's Newton solve of this
            // frame has just failed: it would be the same solve.)
            if (walls_past && scene.patch.walls_newton > 0 && mf.empty() && !newton_tried) {
                char why[200];
                std::snprintf(why, sizeof why, "the frame ended with the walls %.4f mm through each other (%.2f wall thicknesses from its linearisation)", -walls,
                              lag.ratio);
                if (std::optional<fem::NewtonResult> nr = as_newton_frame(scene.patch.walls_newton, why)) {
                    ++P.stats.walls_newton_frames;
                    return *nr;
                }
                ++P.stats.walls_newton_failed;
            }
            bool shortened = false;
            if (walls_past && scene.patch.walls_shorten > 0 && mf.empty() && C->faces.rows() > 0 &&
                f.candidate_u.size() == 3 * static_cast<Eigen::Index>(C->cand.size())) {
                const Eigen::Index nk = static_cast<Eigen::Index>(C->cand.size());
                Eigen::VectorXd sc(3 * nk);
                for (Eigen::Index k = 0; k < nk; ++k) sc.segment<3>(3 * k) = v0.segment<3>(3 * static_cast<Eigen::Index>(C->cand[static_cast<size_t>(k)]));
                // What a step may do: take no pair further than the limit behind its face's plane, nor any vertex
                // through a face (fem::surface_crossings) deeper than it; a pair or a crossing already past the
                // limit where the frame started, no further than the limit beyond where it was. (A pair the
                // frame's crossings paired closely may start far behind its face's plane: the sample's 2 mm jaws
                // at t = 1.252 s, 0.22 mm, with nothing through a face deeper than 0.005 mm; measured from its
                // plane it would refuse every step. Measured from where they started, all pairs would let the
                // walls creep through a limit a frame: the tube's, to the 0.0012 mm of no limit.) The whole step
                // first: one that only keeps such a pair where it was is taken as it is.
                for (int h = 0; h <= scene.patch.walls_shorten; ++h) {
                    const double a = std::ldexp(1.0, -h);
                    const Eigen::VectorXd ua = sc + a * (f.candidate_u - sc);
                    const fem::CompliantWallsAt wa = fem::compliant_walls_at(*C->lin, C->Xc, C->faces, C->search, ua, sc, co, scene.patch.walls_reject_mm);
                    const double wd = std::min(wa.deepened_mm, -wa.deepened_crossed_mm);
                    if (!(wd >= -scene.patch.walls_reject_mm)) {
                        if (std::getenv("ANEU_PATCH_TRACE"))
                            std::fprintf(stderr, "patch t=%.4f: the frame shortened to %.4g of its step: the walls %.4f mm through, %.4f mm through a face (past the limit at the start: further than there; "
                                         "their pairs' closest %.4f, deepest through a face %.4f)\n",
                                         fr.t, a, -wa.deepened_mm, wa.deepened_crossed_mm, wa.min_distance_mm, wa.crossed_mm);
                        continue;
                    }
                    if (h == 0) {
                        if (std::getenv("ANEU_PATCH_TRACE"))
                            std::fprintf(stderr, "patch t=%.4f: the frame's walls %.4f mm through, %.4f mm through a face (past the limit at its start: further than there): taken whole\n", fr.t,
                                         -wa.deepened_mm, wa.deepened_crossed_mm);
                        ++P.stats.walls_within_start;
                        shortened = true;
                        break;
                    }
                    ++P.stats.walls_shortened;
                    if (std::getenv("ANEU_PATCH_TRACE"))
                        std::fprintf(stderr, "patch t=%.4f: the frame ended with the walls %.4f mm through each other (%.2f wall thicknesses from its linearisation): shortened to %.4g of its step, the walls %.4f mm (patch energy %.6g -> %.6g N mm; the whole step's %.6g)\n",
                                     fr.t, -walls, lag.ratio, a, wd, pm.energy(v0.head(nb)), pm.energy(Eigen::VectorXd(v0.head(nb) + a * (res.u.head(nb) - v0.head(nb)))),
                                     pm.energy(res.u.head(nb)));
                    res.u.head(nb) = v0.head(nb) + a * (res.u.head(nb) - v0.head(nb));
                    // Its loads between those where it started (the last frame's, which held the patch there) and
                    // its end's: on one linearisation the state is affine in the forces. (Its rows' forces stay the
                    // end's, the next frame's warm start.)
                    f.candidate_u = ua;
                    const fem::BladeLoads& l0 = P.course.loads_shown;
                    const double th0 = v0[nb];
                    f.theta = th0 + a * (f.theta - th0);
                    f.loads.opening_rad = f.theta;
                    for (size_t b = 0; b < 2; ++b) {
                        f.loads.force_n[b] = l0.force_n[b] + a * (f.loads.force_n[b] - l0.force_n[b]);
                        f.loads.moment_nmm[b] = l0.moment_nmm[b] + a * (f.loads.moment_nmm[b] - l0.moment_nmm[b]);
                        f.loads.friction_n[b] = l0.friction_n[b] + a * (f.loads.friction_n[b] - l0.friction_n[b]);
                    }
                    f.loads.net_force = l0.net_force + a * (f.loads.net_force - l0.net_force);
                    f.wall_min_distance_mm = wa.min_distance_mm;
                    f.wall_crossed_mm = wa.crossed_mm;
                    lag = surface_reach(sf, P.cand_vertex, P.cand, res.u, C->lin->u0());
                    C->from_state = true;
                    shortened = true;
                    break;
                }
            }
            if (walls_past && !shortened) {
                ++P.stats.walls_absurd;
                if (std::getenv("ANEU_PATCH_TRACE"))
                    std::fprintf(stderr, "patch t=%.4f: the frame ended with the walls %.4f mm through each other (%.2f wall thicknesses from its linearisation): not taken (over %g mm), the patch stays where the frame started\n",
                                 fr.t, -walls, lag.ratio, scene.patch.walls_reject_mm);
                return reject_frame("the frame took the walls " + std::to_string(-walls) + " mm through each other");
            }
            c_profile.assign(static_cast<size_t>(std::ceil(blades.length_mm)), 0.0);
            c_across.assign(static_cast<size_t>(std::ceil(10 * blades.width_mm - 1e-9)) + 2, 0.0);
            const Eigen::Vector3d w_dir = blades.axis.cross(blades.up);
            for (size_t i = 0; i < f.constraint.size() && i < f.lambda.size(); ++i) {
                const auto [k, s] = f.constraint[i];
                const fem::CompliantRowKind kind = fem::compliant_row_kind(s);
                if (!kind.blade || kind.clip != 0 || !(f.lambda[i] > 0)) continue;
                const Eigen::Vector3d x = C->Xc.row(k).transpose() + f.candidate_u.segment<3>(3 * static_cast<Eigen::Index>(k));
                const double r = (x - blades.hinge).dot(blades.axis), a = (x - blades.hinge).dot(w_dir) + 0.5 * blades.width_mm + 0.1;
                const auto bin = static_cast<size_t>(std::clamp(std::floor(r), 0.0, static_cast<double>(c_profile.size() - 1)));
                c_profile[bin] += 0.5 * f.lambda[i];
                const auto abin = static_cast<size_t>(std::clamp(std::floor(10 * a), 0.0, static_cast<double>(c_across.size() - 1)));
                c_across[abin] += 0.5 * f.lambda[i];
            }
            res.u[nb] = f.theta;
            res.reaction = Eigen::VectorXd::Constant(1, f.loads.spring_torque_nmm - 0.5 * (f.loads.moment_nmm[0] + f.loads.moment_nmm[1]));
            res.iterations = f.passes;
            res.converged = f.complementarity_mm <= 1e-3;
            if (!res.converged) res.failure = "complementarity " + std::to_string(f.complementarity_mm) + " mm left";
            loads = f.loads;
            for (size_t j = 0; j < mf.size() && j < f.more_loads.size(); ++j) mf[j].loads = f.more_loads[j];
            wall_min = walls_at(f);
            touching = f.wall_contacts;
            P.stats.wall_resolves += repeats;
            its += f.passes;
            // Only frames that press something count towards the refresh: one in the air leaves the patch where it was.
            int pressing = f.loads.contacts[0] + f.loads.contacts[1] + f.wall_contacts;
            for (const fem::BladeLoads& l : f.more_loads) pressing += l.contacts[0] + l.contacts[1];
            if (pressing > 0) ++C->since;
            C->last = std::move(f);
            C->warm = true;
            return res;
        };
        fem::NewtonResult r = compliance ? compliant_frame() : newton_frame();
        if (cancel_frames) {  // the run ended during the solve: nothing of the frame is kept, its course included
            if (fr.mx) fr.lock.lock();
            continue;
        }
        // A frame that does not converge leaves its last iterate for the next frame to go on from (most do: the
        // next frame, with the same opening, converges in a few iterations). A second in a row got no nearer from
        // there: the patch goes back to the last converged frame's state, grips and loads, and the opening moves
        // from there by at most half the change that first failed (at least 0.01°), doubled again by each converged
        // frame.
        // (Without it, the sample's held clip, reopened 0.5° by its spring's balance step, stayed on an
        // unconverged iterate: 40 iterations and a residual of 0.07–0.11 N in every frame from t = 1.29 s on.)
        Assessment::PatchEnd& st = P.stats;
        bool restarted = false;
        if (r.converged) {
            P.course.failed_in_row = 0;
            if (std::isfinite(P.course.theta_step) && (P.course.theta_step *= 2) > 1.0) P.course.theta_step = std::numeric_limits<double>::infinity();
            P.v_ok = r.u;
            P.grips_ok = grips;
            P.gripped_ok = true;
            P.course.loads_ok = loads;
            P.course.wall_min_ok = wall_min;
            P.course.touching_ok = touching;
            for (MemberFrame& g : mf) {
                g.theta_ok = g.theta_kept;
                g.course.loads_ok = g.loads;
            }
        } else if (++P.course.failed_in_row == 1) {
            P.course.theta_failed = theta_kept;
        } else {
            P.course.theta_step = std::max(0.5 * std::min(P.course.theta_step, std::abs(P.course.theta_failed - P.v_ok[nb])), 0.01 * DEG);
            P.course.failed_in_row = 0;
            ++st.restarts;
            restarted = true;
            if (std::getenv("ANEU_PATCH_TRACE"))
                std::fprintf(stderr, "patch t=%.4f: second unconverged frame in a row: back to the last converged state (%.3f deg), the opening now moves %.3f deg a frame at most\n",
                             fr.t, P.v_ok[nb] / DEG, P.course.theta_step / DEG);
            r.u = P.v_ok;
            grips = P.grips_ok;
            loads = P.course.loads_ok;
            wall_min = P.course.wall_min_ok;
            touching = P.course.touching_ok;
            for (MemberFrame& g : mf) {  // the further clips back to theirs
                g.theta_kept = g.theta_ok;
                g.loads = g.course.loads_ok;
            }
            if (P.compliant) P.compliant->from_state = true;
        }
        P.course.loads_shown = loads;
        P.course.wall_min_shown = wall_min;
        P.course.touching_shown = touching;
        for (MemberFrame& g : mf) g.course.loads_shown = g.loads;
        // A frame whose solve did not converge leaves the balance's estimate as it was (its reaction is not the
        // tissue's; a held clip goes on following the applier).
        // One spring clip's balance step from this frame's opening th and reaction R = τ − M (`turn`: its
        // ClipModel::turn_per_heel_turn, `clip`: for the trace, −1 the first): the next opening its frames approach.
        auto balance = [&](PatchRun::Course& q, double R, double th, const fem::ClipSpring& sp, double turn, bool held_q, bool pressed, int clip) {
            // The secant over the last step that moved the opening by at least SECANT_MIN_DEG (at the heel's turn): with
            // the patch relinearised the tissue's moment also changes at a fixed opening, and over a step of a
            // thousandth of a degree that change is the secant. (Taken over every step, the sample's held clip with its
            // fulcrum 8 mm back stalled on a steep secant, then, on a wrong-signed one clamped to the spring's k, stepped
            // the full cap closed every fourth frame and back: 2.65-3.2 deg, a 3.23 N blade peak over a 2.4 N hold.)
            // A secant below the spring's own k (R grows with θ: the spring alone gives at least that) keeps the last
            // estimate.
            double k = std::max(q.tissue_k, sp.k_nmm_per_rad);
            const double min_step = SECANT_MIN_DEG * DEG * turn;
            if (q.prev_theta < 0 || std::abs(th - q.prev_theta) >= min_step) {
                if (q.prev_theta >= 0) {
                    const double secant = (R - q.prev_R) / (th - q.prev_theta);
                    if (secant > sp.k_nmm_per_rad) k = secant;
                }
                q.tissue_k = k;
                q.prev_theta = th;
                q.prev_R = R;
            }
            // (Held, the applier bounds it from below anyway.)
            q.theta_bal = fem::next_spring_opening(th, R, k, held_q, pressed);
            // On the compliance frames, with the blades pressing, at most 125°/s (0.5° a frame at 250 Hz): a refresh
            // changes the tissue's moment at the same opening, and the secant step on that jump overshoots (the sample's
            // clip refreshed every 10 frames went 3.47 -> 1.73 deg in one frame, a 6.4 N grip and walls 0.31 mm through
            // each other, then back to 3.1 deg).
            // The cap is the blade's travel at its middle that 125°/s gives a clip turning at its heel; a clip whose
            // fulcrum lies behind the heel (ClipModel::fulcrum_mm) turns proportionally less (20 mm behind a 13 mm
            // blade's heel, 0.5° a frame would be 0.23 mm of travel at the blade's middle instead of 0.06 mm). So is
            // the real-time mode's step above.
            if (compliance && pressed) {
                const double cap = 125.0 * DEG / scene.physics_hz * turn;
                q.theta_bal = std::clamp(q.theta_bal, th - cap, th + cap);
            }
            if (std::getenv("ANEU_PATCH_TRACE")) {
                if (clip < 0)
                    std::fprintf(stderr, "balance t=%.4f theta %.4f deg R %.4g N mm k %.4g N mm/rad next %.4f deg\n", fr.t, th / DEG, R, k, q.theta_bal / DEG);
                else
                    std::fprintf(stderr, "balance t=%.4f clip %d theta %.4f deg R %.4g N mm k %.4g N mm/rad next %.4f deg\n", fr.t, clip, th / DEG, R, k, q.theta_bal / DEG);
            }
        };
        if (cm.spring && r.reaction.size() && r.converged)
            balance(P.course, r.reaction[0], r.u[nb], spring, cm.turn_per_heel_turn(), held, loads.contacts[0] + loads.contacts[1] > 0, -1);
        // The further clips' balances, each on its own R = τ − M from its blades' loads.
        for (MemberFrame& g : mf)
            if (g.has_spring && r.converged)
                balance(g.course, g.loads.spring_torque_nmm - 0.5 * (g.loads.moment_nmm[0] + g.loads.moment_nmm[1]), g.theta_kept, g.spring, g.turn, g.held,
                        g.loads.contacts[0] + g.loads.contacts[1] > 0, g.clip);
        const double t_solve = sw.seconds();
        const Eigen::Vector3d net = loads.net_force;  // the tissue's on the blades
        const double ms = 1e3 * sw.seconds();
        const int merges = fem::pattern_cache_counts(*P.wall_patterns).first + fem::pattern_cache_counts(*P.clip_patterns).first - merges_before;
        if (std::getenv("ANEU_PATCH_TRACE") && compliance)
            std::fprintf(stderr, "patch t=%.4f theta %.3f->%.3f deg (%s) its %d %s blade %.4f/%.4f N contacts %d/%d friction %.4f/%.4f N sliding %d/%d wall %.4f mm %d pairs %.1f ms (compliance: linearise %.1f, rows %.1f, delassus %.1f, lcp %.1f, search %.1f, displacement %.1f; repeats %d, rows %d, sweeps %d, pivots %d)\n",
                         fr.t, v0[nb] / DEG, r.u[nb] / DEG, held ? "held" : "deposited", its, r.converged ? "ok" : "NOT converged", loads.force_n[0], loads.force_n[1],
                         loads.contacts[0], loads.contacts[1], loads.friction_n[0], loads.friction_n[1], loads.sliding[0], loads.sliding[1], wall_min, touching, ms,
                         1e3 * c_lin, 1e3 * c_rows, 1e3 * c_delassus, 1e3 * c_lcp, 1e3 * c_search, 1e3 * c_disp, c_repeats, c_nrows, c_sweeps, c_pivots);
        else if (std::getenv("ANEU_PATCH_TRACE"))
            std::fprintf(stderr, "patch t=%.4f theta %.3f->%.3f deg (%s) its %d %s s=%.3g res %.2e blade %.4f/%.4f N contacts %d/%d friction %.4f/%.4f N sliding %d/%d wall %.4f mm %d pairs %.1f ms (wall %.1f clip %.1f newton %.1f: setup %.1f%s%s, tangent %.1f, %d factorisations %.1f (%d not positive definite: %.1f), %d chord steps, back %.1f%s)\n",
                         fr.t, v0[nb] / DEG, r.u[nb] / DEG, held ? "held" : "deposited", its, r.converged ? "ok" : "NOT converged", r.load_fraction,
                         r.residual, loads.force_n[0], loads.force_n[1], loads.contacts[0], loads.contacts[1], loads.friction_n[0], loads.friction_n[1],
                         loads.sliding[0], loads.sliding[1], wall_min, touching, ms, 1e3 * t_wall,
                         1e3 * (t_clip - t_wall), 1e3 * (t_solve - t_clip), 1e3 * t_setup, reused ? " (analysis reused)" : "", merges ? (" (patterns merged: " + std::to_string(merges) + ")").c_str() : "", 1e3 * t_tangent, factorisations, 1e3 * t_factor, failed, 1e3 * t_failed, chords, 1e3 * t_back,
                         unsolved ? ", in equilibrium without a solve" : "");
        if (std::getenv("ANEU_PATCH_TRACE") && !r.converged) std::fprintf(stderr, "patch t=%.4f not converged: %s\n", fr.t, r.failure.c_str());
        // The surface outside the patch (at region_hz) is computed here, before the lock: the haptic thread waits on it.
        const bool remap = P.t_map < 0 || fr.t - P.t_map >= 1.0 / scene.region_hz - 1e-9;
        const Eigen::VectorXd mapped = remap ? pm.mapped_displacement(r.u.head(nb)) : Eigen::VectorXd();
        if (fr.mx) {
            fr.lock.lock();
            // Released meanwhile and fallen away (the haptic thread dropped the patch): the frame goes with it.
            if (!P.alive || P.pm != hold) continue;
            // Or the first clip fell away and handed the patch on (leave_patch): the frame was for the clips before.
            if (P.clip != frame_clips[0]) continue;
        }
        Clip& cl = clips[static_cast<size_t>(P.clip)];  // (the haptic thread may have added clips: c may have moved)
        P.v = r.u;
        // ANEU_WALL_TRACE: the patch's inner walls through each other after the frame, whatever the frames' rows (one ring
        // left out, 0.5 mm deep, as sim::lumen_crossing but without its wall-thickness bound): how many vertices, the
        // deepest, whether it and the face's corners are the frames' candidates, where in the jaws' frame (session 45:
        // C0054's walls crossed over 13 frames at a fold).
        // With the patch's elements: the deepest crossing whose vertex lies in the tissue (not its own) where the
        // vertex and the face's corners are off the patch's interface (sim::lumen_crossing's rule), and how many lie
        // behind a face but in no tissue.
        if (std::getenv("ANEU_WALL_TRACE") && P.inner.rows() > 0) {
            const std::vector<fem::SurfaceCrossing> cr = fem::surface_crossings(P.X, P.inner, r.u.head(3 * P.X.rows()), LUMEN_CROSSING_RINGS, LUMEN_CROSSING_DEPTH_MM);
            const auto deep = std::max_element(cr.begin(), cr.end(), [](const auto& a, const auto& b) { return a.depth_mm < b.depth_mm; });
            if (deep != cr.end() && deep->depth_mm > 0.01) {
                const PatchRun::TissueOverlap ov = P.tissue_overlap();  // P.v is this frame's
                double tissue_mm = 0;
                int aside = 0;
                for (size_t i = 0; i < cr.size(); ++i) {
                    bool known = !pm.on_interface(cr[i].v);
                    for (int k = 0; k < 3; ++k) known = known && !pm.on_interface(P.inner(cr[i].f, k));
                    if (known && !ov.inside[static_cast<size_t>(cr[i].v)])
                        ++aside;
                    else
                        tissue_mm = std::max(tissue_mm, cr[i].depth_mm);
                }
                std::fprintf(stderr, "walls crossed in tissue t=%.4f: deepest %.4f mm; %d of %zu crossings in no tissue of the patch; %ld patch nodes in an element not their own, %.4f mm deep\n",
                             fr.t, tissue_mm, aside, cr.size(), static_cast<long>(ov.nodes), ov.deepest_mm);
                const Eigen::Vector3d rel = P.X.row(deep->v).transpose() + r.u.segment<3>(3 * deep->v) - blades.hinge;
                const std::shared_ptr<PatchRun::Compliant>& C = P.compliant;
                auto cand = [&](int a) { return C && std::find(C->cand.begin(), C->cand.end(), a) != C->cand.end() ? 1 : 0; };
                std::fprintf(stderr, "walls crossed t=%.4f: %zu vertex-face crossings, deepest %.4f mm node %d (candidate %d) behind face %d (candidate corners %d%d%d) at r %.3f across %.3f up %.3f mm\n",
                             fr.t, cr.size(), deep->depth_mm, deep->v, cand(deep->v), deep->f, cand(P.inner(deep->f, 0)), cand(P.inner(deep->f, 1)),
                             cand(P.inner(deep->f, 2)), rel.dot(blades.axis), rel.dot(blades.axis.cross(blades.up)), rel.dot(blades.up));
            }
        }
        P.grips = std::move(grips);
        P.gripped = restarted ? P.gripped_ok : true;
        P.hinge_prev = blades.hinge;
        const double theta = r.u[nb];
        cl.opening_deg = theta / DEG;
        if (held && cm.spring) cl.spring_deg = P.course.theta_bal / DEG;
        cl.grip_force_n = 0.5 * (loads.force_n[0] + loads.force_n[1]);
        cl.friction_n = 0.5 * (loads.friction_n[0] + loads.friction_n[1]);
        cl.tissue_moment_nmm = 0.5 * (loads.moment_nmm[0] + loads.moment_nmm[1]);
        cl.label_force_n = cl.tissue_moment_nmm / cm.label_arm_mm();
        cl.spring_torque_nmm = cm.spring ? loads.spring_torque_nmm : 0.0;
        P.force = net;
        P.contacts = loads.contacts[0] + loads.contacts[1];
        cl.net_force = -net;  // on the vessel
        if (held && cl.holder >= 0) patch_force[static_cast<size_t>(cl.holder)] += net;
        a.peak_vessel_force_n = std::max(a.peak_vessel_force_n, cl.grip_force_n);
        ++st.frames;
        if (!r.converged) ++st.unconverged_frames;
        st.max_iterations = std::max(st.max_iterations, its);
        P.iterations_sum += its;
        P.solve_ms_sum += ms;
        st.mean_iterations = P.iterations_sum / static_cast<double>(st.frames);
        st.mean_solve_ms = P.solve_ms_sum / static_cast<double>(st.frames);
        st.max_solve_ms = std::max(st.max_solve_ms, ms);
        st.peak_blade_force_n = std::max(st.peak_blade_force_n, cl.grip_force_n);
        st.peak_label_force_n = std::max(st.peak_label_force_n, cl.label_force_n);
        a.peak_clip_label_force_n = std::max(a.peak_clip_label_force_n, cl.label_force_n);
        // The further clips, those still in the patch (the haptic thread may have let one go meanwhile).
        for (MemberFrame& g : mf) {
            const auto m = std::find_if(P.more.begin(), P.more.end(), [&](const PatchRun::Member& x) { return x.clip == g.clip; });
            if (m == P.more.end()) continue;
            Clip& cj = clips[static_cast<size_t>(g.clip)];
            const ClipModel& cmj = scene.clip_models.at(cj.model);
            m->theta = g.theta_kept;
            m->theta_ok = g.theta_ok;
            m->course = g.course;
            m->contacts = g.loads.contacts[0] + g.loads.contacts[1];
            const bool held_j = cj.state == Clip::State::HELD;
            cj.opening_deg = g.theta_kept / DEG;
            if (held_j && cmj.spring) cj.spring_deg = g.course.theta_bal / DEG;
            cj.grip_force_n = 0.5 * (g.loads.force_n[0] + g.loads.force_n[1]);
            cj.friction_n = 0.5 * (g.loads.friction_n[0] + g.loads.friction_n[1]);
            cj.tissue_moment_nmm = 0.5 * (g.loads.moment_nmm[0] + g.loads.moment_nmm[1]);
            cj.label_force_n = cj.tissue_moment_nmm / cmj.label_arm_mm();
            cj.spring_torque_nmm = cmj.spring ? g.loads.spring_torque_nmm : 0.0;
            cj.net_force = -g.loads.net_force;
            if (held_j && cj.holder >= 0) patch_force[static_cast<size_t>(cj.holder)] += g.loads.net_force;
            a.peak_vessel_force_n = std::max(a.peak_vessel_force_n, cj.grip_force_n);
            st.peak_blade_force_n = std::max(st.peak_blade_force_n, cj.grip_force_n);
            st.peak_label_force_n = std::max(st.peak_label_force_n, cj.label_force_n);
            a.peak_clip_label_force_n = std::max(a.peak_clip_label_force_n, cj.label_force_n);
            if (std::getenv("ANEU_PATCH_TRACE"))
                std::fprintf(stderr, "patch t=%.4f clip %d theta %.3f->%.3f deg (%s) blade %.4f/%.4f N contacts %d/%d friction %.4f/%.4f N\n", fr.t, g.clip,
                             g.theta_from / DEG, g.theta_kept / DEG, held_j ? "held" : "deposited", g.loads.force_n[0], g.loads.force_n[1], g.loads.contacts[0],
                             g.loads.contacts[1], g.loads.friction_n[0], g.loads.friction_n[1]);
        }
        if (compliance && !restarted) {
            st.end_lag_to_thickness = lag.ratio;
            if (!c_profile.empty()) {
                st.blade_profile_n = c_profile;
                st.blade_profile_across_n = c_across;
            }
        }
        if (!restarted && lag.ratio > st.max_lag_to_thickness) {  // (a restart went back to an earlier state)
            st.max_lag_to_thickness = lag.ratio;
            st.max_lag_mm = lag.mm;
            st.max_lag_thickness_mm = lag.thickness_mm;
            st.max_lag_t = fr.t;
            st.max_lag_at = lag.at;
        }
        // The frames are the linear model about their linearisation's state, whose forces the study found too large by
        // more than 10 % past Scene::linear_limit (0.3) wall thicknesses (bench/results/study; compliance.md: the sample's
        // frames linearised at rest +48 % at 16 deg, +198 % at 8 deg against the nonlinear solve). Warned once a patch.
        if (!restarted && scene.linear_limit > 0 && lag.ratio > scene.linear_limit && P.compliant && !P.compliant->warned_lag) {
            P.compliant->warned_lag = true;
            char b[640];
            std::snprintf(b, sizeof b,
                          "beyond the compliance frames' range at t=%.3f s: the patch's surface at (%.2f, %.2f, %.2f) is %.3g mm from the state its "
                          "frames are linearised at, %.2g times the wall's thickness (%.3g mm); past %.2g times a linearisation's forces there are "
                          "too large by more than 10 %% (contact.linear_limit); model.refresh_frames relinearises as the patch deforms",
                          fr.t, lag.at.x(), lag.at.y(), lag.at.z(), lag.mm, lag.ratio, lag.thickness_mm, scene.linear_limit);
            warn(b);
        }
        st.min_wall_distance_mm = std::min(st.min_wall_distance_mm, wall_min);
        st.wall_pairs_touching = touching;
        fr.fs.solve_s += 1e-3 * ms;
        // The surface: the patch's own vertices every frame, the rest of the region from the interface at region_hz.
        for (size_t k = 0; k < P.cand_vertex.size(); ++k) set_patch_part(P.cand_vertex[k], P.v.segment<3>(3 * P.cand[k]));
        if (remap) {
            P.t_map = fr.t;
            for (size_t k = 0; k < P.map_vertex.size(); ++k) set_patch_part(P.map_vertex[k], mapped.segment<3>(3 * static_cast<Eigen::Index>(k)));
        }
    }
}

}  // namespace aneu::sim
