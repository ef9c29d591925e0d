// SPDX-License-Identifier: MIT
// `surface`: lumen surface from a segmentation (sub-voxel isosurface of the smoothed CT restricted to the
// segmented lumen, cut at the end planes, windowed-sinc smoothing, remeshing) or from another tool's
// surface (open ends, or flat caps removed); then the artery/aneurysm label of every face and the end id of
// every boundary loop.
#include <algorithm>
#include <cmath>
#include <map>
#include <queue>
#include <set>

#include <Eigen/Dense>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/image_filters.hpp"
#include "aneu/pipeline/image_io.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace aneu::pipeline {

namespace {


Eigen::Vector3d centroid(const SurfaceData& s, Eigen::Index f) {
    return (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
}
double area(const SurfaceData& s, Eigen::Index f) {
    const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    return 0.5 * (b - a).cross(c - a).norm();
}

/// Face neighbours across edges.
std::vector<std::vector<int>> face_adjacency(const SurfaceData& s) {
    std::map<std::pair<int, int>, std::vector<int>> edge_faces;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
            const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
            edge_faces[{std::min(a, b), std::max(a, b)}].push_back(static_cast<int>(f));
        }
    std::vector<std::vector<int>> adj(static_cast<size_t>(s.F.rows()));
    for (const auto& [e, fs] : edge_faces) {
        (void)e;
        for (int a : fs)
            for (int b : fs)
                if (a != b) adj[static_cast<size_t>(a)].push_back(b);
    }
    return adj;
}

/// Boundary loops of the surface matched to the nearest end plane; fills loop_* of `s`.
void label_loops(SurfaceData& s, const std::vector<EndPlane>& planes) {
    const auto loops = boundary_loops(s);
    std::vector<int> off{0}, verts, ids;
    for (const auto& l : loops) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int v : l) c += s.V.row(v).transpose();
        c /= static_cast<double>(l.size());
        int best = -1;
        double bd = 1e300;
        for (const auto& p : planes) {
            const double d = (c - p.point).norm() + 10.0 * std::abs(p.normal.dot(c - p.point));
            if (d < bd) {
                bd = d;
                best = p.id;
            }
        }
        if (best < 0) throw MeshingError("surface: a boundary loop at (" + shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) + ") mm matches no end plane");
        verts.insert(verts.end(), l.begin(), l.end());
        off.push_back(static_cast<int>(verts.size()));
        ids.push_back(best);
    }
    s.loop_offsets = Eigen::Map<Eigen::VectorXi>(off.data(), static_cast<Eigen::Index>(off.size()));
    s.loop_vertices = Eigen::Map<Eigen::VectorXi>(verts.data(), static_cast<Eigen::Index>(verts.size()));
    s.loop_end_id = Eigen::Map<Eigen::VectorXi>(ids.data(), static_cast<Eigen::Index>(ids.size()));
}

/// A surface from another tool: finite coordinates in mm (scaled by `scale` first).
/// @throws InputError naming the file and what was expected (for metres, the factor to use)
void check_input_surface(SurfaceData& s, const std::string& path, double scale) {
    if (!s.V.allFinite()) {
        Eigen::Index bad = 0;
        while (s.V.row(bad).allFinite()) ++bad;
        throw InputError(path + ": vertex " + std::to_string(bad) + " has a NaN or infinite coordinate; expected finite coordinates in mm");
    }
    s.V *= scale;
    const double extent = (s.V.colwise().maxCoeff() - s.V.colwise().minCoeff()).norm();
    // A vessel segment with an aneurysm spans millimetres to a few centimetres; a file in metres spans a few
    // hundredths of a unit and one in micrometres tens of thousands.
    if (extent < 1.0) {
        const double factor = extent > 0 && extent < 0.5 ? 1000.0 : 0.0;
        throw InputError(path + ": the surface spans " + shortest(extent) + " mm, implausibly small for a vessel in mm" +
                         (factor > 0 ? "; the file looks like metres: give --input-scale 1000" : "; expected coordinates in mm"));
    }
    if (extent > 1000.0) {
        throw InputError(path + ": the surface spans " + shortest(extent) + " mm, implausibly large for a vessel in mm" +
                         (extent > 5000.0 ? "; the file looks like micrometres: give --input-scale 0.001" : "; expected coordinates in mm"));
    }
}

/// @throws InputError when a surface from another tool intersects itself (two overlapping tubes, a fold)
void check_no_overlap(const SurfaceData& s, const std::string& path) {
    std::vector<std::pair<int, int>> inter;
    try {
        inter = self_intersections(s, 1);
    } catch (const InputError& e) {
        throw InputError(path + ": " + e.what());
    }
    if (!inter.empty()) {
        const Eigen::Vector3d c = centroid(s, inter.front().first);
        throw InputError(path + ": the surface intersects itself near (" + shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) +
                         ") mm (faces " + std::to_string(inter.front().first) + " and " + std::to_string(inter.front().second) +
                         "); expected one lumen surface without overlaps");
    }
}

/// Each boundary loop of a surface from another tool must be a vessel's cut end: nearly planar (a hole in
/// the side of the wall is not).
/// @throws InputError naming the loop's place and its distance from its plane
void check_vessel_ends(const SurfaceData& s, const std::vector<std::vector<int>>& loops, const std::string& path) {
    std::map<std::pair<int, int>, int> edge_face;  // directed edge → its face
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) edge_face[{s.F(f, k), s.F(f, (k + 1) % 3)}] = static_cast<int>(f);
    for (const auto& l : loops) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
        for (int v : l) c += s.V.row(v).transpose();
        c /= static_cast<double>(l.size());
        for (size_t i = 0; i < l.size(); ++i) w += (s.V.row(l[i]).transpose() - c).cross(s.V.row(l[(i + 1) % l.size()]).transpose() - c);
        const double radius = std::sqrt(0.5 * w.norm() / PI);
        const Eigen::Vector3d nrm = w.normalized();
        double off = 0;
        for (int v : l) off = std::max(off, std::abs(nrm.dot(s.V.row(v).transpose() - c)));
        // At a vessel's cut end the wall runs across the loop's plane (face normals nearly in the plane); around
        // a hole in the side of the wall the surface lies along it (normals along the plane's normal).
        double along = 0;
        int n_faces = 0;
        for (size_t i = 0; i < l.size(); ++i) {
            const auto it = edge_face.find({l[i], l[(i + 1) % l.size()]});
            if (it == edge_face.end()) continue;
            const int f = it->second;
            const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
            const Eigen::Vector3d fn = (b - a).cross(c - a);
            if (fn.norm() > 0) {
                along += std::abs(fn.normalized().dot(nrm));
                ++n_faces;
            }
        }
        if (n_faces > 0) along /= n_faces;
        // Cut ends of other tools' surfaces are planar to a small fraction of their radius.
        if (!(off <= 0.25 * radius) || l.size() < 3 || along > 0.8) {
            throw InputError(path + ": the boundary loop at (" + shortest(c.x()) + ", " + shortest(c.y()) + ", " + shortest(c.z()) + ") mm (" +
                             std::to_string(l.size()) + " edges, equivalent radius " + shortest(radius) + " mm) is not a vessel's cut end (it strays " +
                             shortest(off) + " mm from its plane; the wall lies along it, " + shortest(along) +
                             "): a hole in the side of the surface? Close it, or cut the vessel there");
        }
    }
}

std::string vec3(const Eigen::Vector3d& x) { return "(" + shortest(x.x()) + ", " + shortest(x.y()) + ", " + shortest(x.z()) + ")"; }

/// The segmentation joins voxels across edges and corners (26-neighbourhood); marching cubes joins them across
/// faces only, so a thin vessel held to the tree by a diagonal link fell off the surface as a separate piece
/// (a real TOF-MRA lost 4 of its 9 ends that way). In every 2×2×2 cell whose lumen voxels are not
/// face-connected within it, the brightest background voxels that join them are added. Returns the count.
size_t bridge_diagonal_links(Volume<std::uint8_t>& mask, const std::vector<float>& intensity) {
    const ImageGrid& g = mask.grid;
    size_t added = 0;
    for (std::int64_t k = 0; k + 1 < g.size[2]; ++k)
        for (std::int64_t j = 0; j + 1 < g.size[1]; ++j)
            for (std::int64_t i = 0; i + 1 < g.size[0]; ++i) {
                size_t idx[8];
                int set = 0;
                for (int q = 0; q < 8; ++q) {
                    idx[q] = g.linear(i + (q & 1), j + ((q >> 1) & 1), k + ((q >> 2) & 1));
                    set += mask.data[idx[q]] ? 1 : 0;
                }
                if (set < 2 || set > 6) continue;
                // Face-connected components of the set corners (corners q, r are face neighbours when their bit
                // patterns differ in one bit).
                auto components = [&]() {
                    int comp[8], n = 0;
                    for (int q = 0; q < 8; ++q) comp[q] = -1;
                    for (int q = 0; q < 8; ++q) {
                        if (!mask.data[idx[q]] || comp[q] >= 0) continue;
                        int stack[8], top = 0;
                        stack[top++] = q;
                        comp[q] = n;
                        while (top > 0) {
                            const int u = stack[--top];
                            for (int b = 0; b < 3; ++b) {
                                const int w = u ^ (1 << b);
                                if (mask.data[idx[w]] && comp[w] < 0) {
                                    comp[w] = n;
                                    stack[top++] = w;
                                }
                            }
                        }
                        ++n;
                    }
                    return n;
                };
                for (int guard = 0; guard < 4 && components() > 1; ++guard) {
                    // The brightest background corner that is a face neighbour of the lumen in this cell.
                    int best = -1;
                    for (int q = 0; q < 8; ++q) {
                        if (mask.data[idx[q]]) continue;
                        bool touches = false;
                        for (int b = 0; b < 3; ++b) touches = touches || mask.data[idx[q ^ (1 << b)]];
                        if (touches && (best < 0 || intensity[idx[q]] > intensity[idx[static_cast<size_t>(best)]])) best = q;
                    }
                    if (best < 0) break;
                    mask.data[idx[best]] = 1;
                    ++added;
                }
            }
    return added;
}

/// The boundary loop that lies in `pl` (smallest offset from the plane plus a tenth of the distance).
int loop_of_plane(const SurfaceData& s, const std::vector<std::vector<int>>& loops, const EndPlane& pl) {
    int best = -1;
    double bd = 1e300;
    for (size_t q = 0; q < loops.size(); ++q) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int v : loops[q]) c += s.V.row(v).transpose();
        c /= static_cast<double>(loops[q].size());
        const double d = std::abs(pl.normal.dot(c - pl.point)) + 0.1 * (c - pl.point).norm();
        if (d < bd) {
            bd = d;
            best = static_cast<int>(q);
        }
    }
    return best;
}

/// Vertices reachable from `seeds` over edges without leaving the ball of `radius` about `centre`.
std::vector<char> flood_in_ball(const SurfaceData& s, const std::vector<std::vector<int>>& adj, const std::vector<int>& seeds,
                                const Eigen::Vector3d& centre, double radius) {
    std::vector<char> in(static_cast<size_t>(s.V.rows()), 0);
    std::vector<int> stack;
    for (int v : seeds) {
        in[static_cast<size_t>(v)] = 1;
        stack.push_back(v);
    }
    while (!stack.empty()) {
        const int u = stack.back();
        stack.pop_back();
        for (int w : adj[static_cast<size_t>(u)])
            if (!in[static_cast<size_t>(w)] && (s.V.row(w).transpose() - centre).norm() < radius) {
                in[static_cast<size_t>(w)] = 1;
                stack.push_back(w);
            }
    }
    return in;
}

/// Moves each end plane inward (against its normal) until no other part of the lumen comes within
/// `clearance` of the end's cut — the wall extends each end and closes it with an annular cap there, and
/// another vessel in that space merges the outer ends or meets the cap — and cuts the surface at the moved
/// plane. Real trees have side branches and loops right beside their cut ends. Returns the moves made.
int clear_ends(SurfaceData& s, std::vector<EndPlane>& planes, double clearance, Reporter& rep) {
    int moves = 0;
    for (auto& pl : planes) {
        for (int attempt = 0;; ++attempt) {
            const auto loops = boundary_loops(s);
            const int li = loop_of_plane(s, loops, pl);
            if (li < 0) break;
            const auto& loop = loops[static_cast<size_t>(li)];
            std::vector<std::vector<int>> adj(static_cast<size_t>(s.V.rows()));
            for (Eigen::Index f = 0; f < s.F.rows(); ++f)
                for (int k = 0; k < 3; ++k) {
                    adj[static_cast<size_t>(s.F(f, k))].push_back(s.F(f, (k + 1) % 3));
                    adj[static_cast<size_t>(s.F(f, (k + 1) % 3))].push_back(s.F(f, k));
                }
            double rmax = 0;
            for (int v : loop) rmax = std::max(rmax, (s.V.row(v).transpose() - pl.point).norm());
            const double R = std::max(rmax, 1.5 * pl.radius_mm) + clearance;
            const std::vector<char> own = flood_in_ball(s, adj, loop, pl.point, R + 2 * clearance);
            bool clean = true;
            for (Eigen::Index v = 0; v < s.V.rows() && clean; ++v) {
                if (own[static_cast<size_t>(v)]) continue;
                const Eigen::Vector3d d = s.V.row(v).transpose() - pl.point;
                const double along = pl.normal.dot(d);
                clean = !(along > -clearance && along < 2 * clearance && (d - along * pl.normal).norm() < R);
            }
            if (clean) break;
            const double step = std::max(0.25, 0.5 * pl.radius_mm);
            if (attempt >= 8) {
                rep.warn("surface: end " + std::to_string(pl.id) + " at " + vec3(pl.point) + " mm stays within " + shortest(clearance) +
                         " mm of another vessel after moving it " + shortest(attempt * step) + " mm inward");
                break;
            }
            EndPlane moved = pl;
            moved.point -= step * pl.normal;
            const std::vector<char> region = flood_in_ball(s, adj, loop, pl.point, R + step + clearance);
            s = clip_region_at_plane(s, region, moved);
            // The new end: its loop's centroid and equivalent radius.
            const auto nl = boundary_loops(s);
            const int ni = loop_of_plane(s, nl, moved);
            if (ni < 0) throw MeshingError("surface: moving end " + std::to_string(pl.id) + " inward lost its boundary loop near " + vec3(moved.point) + " mm");
            Eigen::Vector3d c = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
            const auto& l = nl[static_cast<size_t>(ni)];
            for (int v : l) c += s.V.row(v).transpose();
            c /= static_cast<double>(l.size());
            for (size_t i = 0; i < l.size(); ++i) w += (s.V.row(l[i]).transpose() - c).cross(s.V.row(l[(i + 1) % l.size()]).transpose() - c);
            pl.point = c - pl.normal.dot(c - moved.point) * pl.normal;
            pl.radius_mm = std::sqrt(0.5 * w.norm() / PI);
            ++moves;
        }
    }
    return moves;
}

/// Remesh, label (automatic or overridden), loops, QA.
void finish_lumen(LumenResult& r, SurfaceData s, const SurfaceParams& p, Reporter& rep) {
    double a_in = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) a_in += area(s, f);
    refuse_triangle_count("surface: --edge-mm", p.edge_mm, a_in);
    smooth_surface(s, p.smoothing_iterations, p.smoothing_passband);
    rep.info("surface: remeshing " + std::to_string(s.F.rows()) + " triangles to " + shortest(p.edge_mm) + " mm edges (" + p.remesher + ")");
    RemeshOutcome rm = remesh_checked(s, p.edge_mm, p.remesher, p.timeout_s);
    if (!rm.fallback_why.empty()) rep.warn("surface: remeshed with " + rm.method + " instead of " + p.remesher + " (" + rm.fallback_why + ")");
    r.qa.emplace_back("remesher_fallback", rm.fallback_why.empty() ? 0.0 : 1.0);
    SurfaceData m = std::move(rm.surface);
    // The centerline's radius becomes the maximal inscribed sphere's: the distance from each point to the
    // surface (sub-voxel; the voxel distance map only bounds it within a voxel).
    Centerline& cl = r.image.centerline;
    const NearestOnSurface mis = nearest_on_surface(m, cl.points);
    cl.radius = mis.distance;
    std::string how = "automatic";
    if (p.aneurysm_sphere) {
        const auto& q = *p.aneurysm_sphere;
        m.face_label.resize(m.F.rows());
        for (Eigen::Index f = 0; f < m.F.rows(); ++f) m.face_label[f] = (centroid(m, f) - Eigen::Vector3d(q[0], q[1], q[2])).norm() < q[3];
        how = "sphere";
    } else if (!p.aneurysm_labelmap.empty()) {
        const Volume<std::uint8_t> lm = read_image<std::uint8_t>(p.aneurysm_labelmap);
        m.face_label.resize(m.F.rows());
        for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
            const Eigen::Vector3d c = centroid(m, f);
            const auto ci = lm.grid.continuous_index({c.x(), c.y(), c.z()});
            const std::int64_t i = std::llround(ci[0]), j = std::llround(ci[1]), k = std::llround(ci[2]);
            const bool in = i >= 0 && j >= 0 && k >= 0 && i < lm.grid.size[0] && j < lm.grid.size[1] && k < lm.grid.size[2];
            m.face_label[f] = in && lm.data[lm.grid.linear(i, j, k)] != 0;
        }
        how = "labelmap";
    } else {
        SacCandidates cand;
        m.face_label = label_aneurysm(m, r.image.centerline, p.aneurysm_ratio_high, p.aneurysm_ratio_low, &cand);
        r.qa.emplace_back("sac_candidates", static_cast<double>(cand.pieces.size()));
        int tubes = 0;
        for (const auto& pc : cand.pieces) tubes += pc.tube ? 1 : 0;
        r.qa.emplace_back("sac_candidates_tubular", static_cast<double>(tubes));
        if (cand.kept < 0 && !cand.pieces.empty())
            rep.warn("surface: no aneurysm found: the " + std::to_string(cand.pieces.size()) +
                     " pieces that stand off the centerline are stretches of vessel (a vessel against another); every face is artery "
                     "(a sac there: --aneurysm-sphere or --aneurysm-labelmap)");
        if (cand.pieces.size() > 1 && cand.kept >= 0) {
            const auto mm = [](const Eigen::Vector3d& x) { return vec3((x * 100).array().round().matrix() / 100); };
            const auto r1 = [](double x, double k) { return shortest(std::round(x * k) / k); };
            const auto describe = [&](const SacCandidates::Piece& q) {
                return mm(q.centroid) + " (" + r1(q.area_mm2, 10) + " mm², ratio " + r1(q.max_ratio, 100) + ", " + r1(q.along_mm, 10) +
                       " mm along the centerline within " + r1(q.d90_mm, 100) + " mm of it" + (q.tube ? ": a stretch of vessel" : "") + ")";
            };
            std::string others;
            for (size_t i = 0; i < cand.pieces.size(); ++i)
                if (static_cast<int>(i) != cand.kept) others += " " + describe(cand.pieces[i]) + ";";
            rep.info("surface: " + std::to_string(cand.pieces.size()) + " sac candidates; kept the most prominent at " +
                     describe(cand.pieces[static_cast<size_t>(cand.kept)]) + "; artery:" + others + " (another sac: --aneurysm-sphere or --aneurysm-labelmap)");
        }
    }
    m.label_names = {"artery", "aneurysm"};
    m.face_region = m.face_label;
    m.region_names = m.label_names;
    label_loops(m, r.image.planes);
    r.lumen = std::move(m);
    for (auto& q : triangle_quality(r.lumen)) r.qa.push_back(q);
    double a_art = 0, a_sac = 0;
    for (Eigen::Index f = 0; f < r.lumen.F.rows(); ++f) (r.lumen.face_label[f] ? a_sac : a_art) += area(r.lumen, f);
    r.qa.emplace_back("area_artery_mm2", a_art);
    r.qa.emplace_back("area_aneurysm_mm2", a_sac);
    r.qa.emplace_back("boundary_loops", static_cast<double>(r.lumen.loop_end_id.size()));
    r.qa.emplace_back("aneurysm_label_from_override", how == "automatic" ? 0.0 : 1.0);
    rep.info("surface: " + std::to_string(r.lumen.F.rows()) + " triangles, aneurysm " + shortest(a_sac) + " mm² (" + how + "), artery " +
             shortest(a_art) + " mm², " + std::to_string(r.lumen.loop_end_id.size()) + " open ends");
}

}  // namespace



Eigen::VectorXi label_aneurysm(const SurfaceData& s, const Centerline& c, double high, double low, SacCandidates* found) {
    const Eigen::Index nf = s.F.rows();
    // The radius of each centerline point is raised to the largest within ±2 mm of arc length on its branch
    // (about one parent radius): where a path runs off the axis — at a junction, where a branch path cuts across
    // the ostium, or where it starts off-centre at a cut end — its inscribed radius dips, and faces of plain
    // artery wall there would look far from the vessel.
    constexpr double WINDOW_MM = 2.0;
    Eigen::VectorXd rad_w = c.radius;
    for (Eigen::Index l = 0; l + 1 < c.offsets.size(); ++l) {
        const int b = c.offsets[l], e = c.offsets[l + 1];
        std::vector<double> arc(static_cast<size_t>(e - b), 0.0);
        for (int i = b + 1; i < e; ++i) arc[static_cast<size_t>(i - b)] = arc[static_cast<size_t>(i - b - 1)] + (c.points.row(i) - c.points.row(i - 1)).norm();
        for (int i = b, lo = b, hi = b; i < e; ++i) {
            while (arc[static_cast<size_t>(i - b)] - arc[static_cast<size_t>(lo - b)] > WINDOW_MM) ++lo;
            while (hi + 1 < e && arc[static_cast<size_t>(hi + 1 - b)] - arc[static_cast<size_t>(i - b)] <= WINDOW_MM) ++hi;
            rad_w[i] = c.radius.segment(lo, hi - lo + 1).maxCoeff();
        }
    }
    // Each face is judged against the vessel tube that fits it best: the smallest distance / radius over all
    // centerline segments (not only the nearest one, which near a junction may belong to the other branch).
    // Also kept per face: its distance to the nearest centerline segment, that segment's branch and the arc
    // length there (for the tube test of the candidates below).
    Eigen::VectorXd arc_at(c.points.rows());
    for (Eigen::Index l = 0; l + 1 < c.offsets.size(); ++l)
        for (int i = c.offsets[l]; i < c.offsets[l + 1]; ++i)
            arc_at[i] = i == c.offsets[l] ? 0.0 : arc_at[i - 1] + (c.points.row(i) - c.points.row(i - 1)).norm();
    Eigen::VectorXd ratio(nf), near_d(nf), near_arc(nf);
    Eigen::VectorXi near_branch(nf);
    for (Eigen::Index f = 0; f < nf; ++f) {
        const Eigen::Vector3d x = centroid(s, f);
        double best = 1e300, dmin = 1e300;
        for (Eigen::Index l = 0; l + 1 < c.offsets.size(); ++l)
            for (int i = c.offsets[l]; i + 1 < c.offsets[l + 1]; ++i) {
                const Eigen::Vector3d a = c.points.row(i).transpose(), b = c.points.row(i + 1).transpose();
                const double L2 = (b - a).squaredNorm();
                const double t = L2 > 0 ? std::clamp((x - a).dot(b - a) / L2, 0.0, 1.0) : 0.0;
                const double d = (x - (a + t * (b - a))).norm();
                const double rad = std::max((1 - t) * rad_w[i] + t * rad_w[i + 1], 1e-6);
                best = std::min(best, d / rad);
                if (d < dmin) {
                    dmin = d;
                    near_branch[f] = static_cast<int>(l);
                    near_arc[f] = arc_at[i] + t * std::sqrt(L2);
                }
            }
        ratio[f] = best;
        near_d[f] = dmin;
    }
    // Hysteresis: faces above `high` seed the sac; it grows over neighbours above `low`.
    Eigen::VectorXi label = Eigen::VectorXi::Zero(nf);
    const auto adj = face_adjacency(s);
    std::queue<int> q;
    for (Eigen::Index f = 0; f < nf; ++f)
        if (ratio[f] > high) {
            label[f] = 1;
            q.push(static_cast<int>(f));
        }
    while (!q.empty()) {
        const int f = q.front();
        q.pop();
        for (int g : adj[static_cast<size_t>(f)])
            if (!label[g] && ratio[g] > low) {
                label[g] = 1;
                q.push(g);
            }
    }
    // Holes in the sac label (a few faces below `low` surrounded by sac) are sac too: fill artery pieces
    // that touch no boundary loop and are small.
    std::vector<int> comp(static_cast<size_t>(nf), -1);
    std::vector<char> on_boundary(static_cast<size_t>(nf), 0);
    for (Eigen::Index f = 0; f < nf; ++f) on_boundary[static_cast<size_t>(f)] = adj[static_cast<size_t>(f)].size() < 3;
    for (Eigen::Index f0 = 0; f0 < nf; ++f0) {
        if (label[f0] || comp[static_cast<size_t>(f0)] >= 0) continue;
        std::vector<int> piece{static_cast<int>(f0)};
        comp[static_cast<size_t>(f0)] = 1;
        bool touches = false;
        for (size_t i = 0; i < piece.size(); ++i) {
            touches = touches || on_boundary[static_cast<size_t>(piece[i])];
            for (int g : adj[static_cast<size_t>(piece[i])])
                if (!label[g] && comp[static_cast<size_t>(g)] < 0) {
                    comp[static_cast<size_t>(g)] = 1;
                    piece.push_back(g);
                }
        }
        if (!touches)
            for (int f : piece) label[f] = 1;
    }
    // One sac: the most prominent connected piece.
    SacCandidates cand;
    std::vector<int> piece_of(static_cast<size_t>(nf), -1);
    for (Eigen::Index f0 = 0; f0 < nf; ++f0) {
        if (!label[f0] || piece_of[static_cast<size_t>(f0)] >= 0) continue;
        const int id = static_cast<int>(cand.pieces.size());
        SacCandidates::Piece pc;
        std::vector<int> piece{static_cast<int>(f0)};
        piece_of[static_cast<size_t>(f0)] = id;
        for (size_t i = 0; i < piece.size(); ++i) {
            const int f = piece[i];
            pc.area_mm2 += area(s, f);
            pc.centroid += area(s, f) * centroid(s, f);
            pc.max_ratio = std::max(pc.max_ratio, ratio[f]);
            for (int g : adj[static_cast<size_t>(f)])
                if (label[g] && piece_of[static_cast<size_t>(g)] < 0) {
                    piece_of[static_cast<size_t>(g)] = id;
                    piece.push_back(g);
                }
        }
        if (pc.area_mm2 > 0) pc.centroid /= pc.area_mm2;
        // The tube test. A sac stands off its parent vessel at least about as far as it extends along it; a
        // piece whose faces stay close to the centerline (90th percentile of their distance) along a stretch of
        // it many times that long is a stretch of vessel whose radius the centerline underestimates — where two
        // vessels touch, the path runs along the seam between them and its inscribed radius is near zero.
        // Measured on the corpus: 0.5–2.2 for the 11 real sacs, 17 (22.3 mm within 1.3 mm) for a thin vessel
        // lying against another in a CTA (topcow_066). Length along: the 0.25 mm bins of arc length the piece's faces project to,
        // per branch, so that a sac in a bend that projects to two stretches is not counted as one long one.
        {
            std::vector<double> d;
            std::set<std::pair<int, long>> bins;
            for (int f : piece) {
                d.push_back(near_d[f]);
                bins.insert({near_branch[f], std::lround(std::floor(near_arc[f] / 0.25))});
            }
            const size_t k = std::min(d.size() - 1, static_cast<size_t>(0.9 * static_cast<double>(d.size())));
            std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(k), d.end());
            pc.d90_mm = d[k];
            pc.along_mm = 0.25 * static_cast<double>(bins.size());
            pc.tube = pc.along_mm > TUBE_ALONG_PER_DISTANCE * pc.d90_mm;
        }
        cand.pieces.push_back(pc);
        const auto score = [](const SacCandidates::Piece& q) { return q.area_mm2 * (q.max_ratio - 1.0); };
        if (!pc.tube && (cand.kept < 0 || score(pc) > score(cand.pieces[static_cast<size_t>(cand.kept)]))) cand.kept = id;
    }
    for (Eigen::Index f = 0; f < nf; ++f) label[f] = label[f] && cand.kept >= 0 && piece_of[static_cast<size_t>(f)] == cand.kept ? 1 : 0;
    if (found != nullptr) *found = std::move(cand);
    return label;
}

std::vector<std::vector<int>> detect_flat_caps(const SurfaceData& s, double tol_deg, double tol_mm) {
    const Eigen::Index nf = s.F.rows();
    Eigen::MatrixX3d n(nf, 3);
    for (Eigen::Index f = 0; f < nf; ++f) {
        const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
        n.row(f) = (b - a).cross(c - a).normalized().transpose();
    }
    const auto adj = face_adjacency(s);
    // Grown loosely (twice the tolerances, against the seed's plane), then judged strictly against the
    // plane fitted to the whole set: the caps of real CFD meshes are planar to a few degrees and hundredths
    // of a millimetre, not to round-off.
    const double cos_grow = std::cos(2 * tol_deg * PI / 180.0), cos_tol = std::cos(tol_deg * PI / 180.0);
    const double cos_crease = std::cos(30.0 * PI / 180.0);
    std::vector<int> region(static_cast<size_t>(nf), -1);
    std::vector<std::vector<int>> caps;
    for (Eigen::Index f0 = 0; f0 < nf; ++f0) {
        if (region[static_cast<size_t>(f0)] >= 0 || !n.row(f0).allFinite()) continue;
        const Eigen::Vector3d n0 = n.row(f0).transpose(), x0 = s.V.row(s.F(f0, 0)).transpose();
        std::vector<int> piece{static_cast<int>(f0)};
        region[static_cast<size_t>(f0)] = static_cast<int>(f0);
        for (size_t i = 0; i < piece.size(); ++i)
            for (int g : adj[static_cast<size_t>(piece[i])]) {
                if (region[static_cast<size_t>(g)] >= 0 || !(n.row(g).dot(n0) >= cos_grow)) continue;
                bool near = true;
                for (int k = 0; k < 3; ++k) near = near && std::abs(n0.dot(s.V.row(s.F(g, k)).transpose() - x0)) <= 2 * tol_mm;
                if (!near) continue;
                region[static_cast<size_t>(g)] = static_cast<int>(f0);
                piece.push_back(g);
            }
        if (piece.size() < 2) continue;
        // Fitted plane: area-weighted mean normal through the area-weighted centroid.
        Eigen::Vector3d nm = Eigen::Vector3d::Zero(), cm = Eigen::Vector3d::Zero();
        double a = 0;
        for (int f : piece) {
            const double af = area(s, f);
            nm += af * n.row(f).transpose();
            cm += af * centroid(s, f);
            a += af;
        }
        if (!(a > 0.05)) continue;
        nm.normalize();
        cm /= a;
        bool flat = true;
        for (int f : piece) {
            flat = flat && n.row(f).dot(nm) >= cos_tol;
            for (int k = 0; k < 3; ++k) flat = flat && std::abs(nm.dot(s.V.row(s.F(f, k)).transpose() - cm)) <= tol_mm;
        }
        if (!flat) continue;
        // A cap meets the wall at a crease along (nearly) all of its border.
        int border = 0, creased = 0;
        for (int f : piece)
            for (int g : adj[static_cast<size_t>(f)])
                if (region[static_cast<size_t>(g)] != static_cast<int>(f0)) {
                    ++border;
                    if (n.row(g).dot(nm) < cos_crease) ++creased;
                }
        if (border > 0 && creased >= 0.9 * border) caps.push_back(std::move(piece));
    }
    return caps;
}

LumenResult lumen_from_segmentation(const ImageData& seg, const SurfaceParams& p, Reporter& rep) {
    validate(p);
    if (seg.intensity.size() != seg.grid.voxel_count()) {
        throw InputError("surface: the input's /image has no smoothed intensity (run `aneuprep segment` first, or give a surface mesh)");
    }
    if (seg.planes.empty()) throw InputError("surface: the input's /image has no end planes");
    LumenResult r;
    r.image = seg;
    const ImageGrid& g = seg.grid;
    const double level = p.iso_hu != 0 ? p.iso_hu : seg.threshold_hu;
    // The field: the smoothed CT near the segmented lumen (two voxels around it), well below the level
    // elsewhere, so other bright structures (bone, other vessels) give no surface; deep inside the lumen at
    // least the level, so that a filled hole gives none either.
    Volume<std::uint8_t> mask{g, seg.mask};
    const auto dist_out = [&] {
        Volume<std::uint8_t> inv{g, std::vector<std::uint8_t>(seg.mask.size())};
        for (size_t l = 0; l < inv.data.size(); ++l) inv.data[l] = seg.mask[l] == 0;
        return inside_distance_mm(inv);  // distance of background voxels to the lumen
    }();
    const Volume<float> dist_in = inside_distance_mm(mask);
    const size_t bridged = bridge_diagonal_links(mask, seg.intensity);
    r.qa.emplace_back("diagonal_links_bridged", static_cast<double>(bridged));
    const double smax = std::max({g.spacing[0], g.spacing[1], g.spacing[2]});
    Volume<float> field{g, seg.intensity};
    const float low = static_cast<float>(level - 100.0);
    for (size_t l = 0; l < field.data.size(); ++l) {
        if (!seg.mask[l] && dist_out.data[l] > 2.01 * smax) field.data[l] = std::min(field.data[l], low);
        if (seg.mask[l] && dist_in.data[l] > 1.99 * smax) field.data[l] = std::max(field.data[l], static_cast<float>(level + 1.0));
        // Every lumen voxel inside the surface and every other voxel outside, so the surface has the mask's
        // topology (values move by at most 1 HU across the level: the sub-voxel position is kept).
        if (mask.data[l]) field.data[l] = std::max(field.data[l], static_cast<float>(level + 1.0));
        if (!mask.data[l]) field.data[l] = std::min(field.data[l], static_cast<float>(level - 1.0));
    }
    SurfaceData iso = isosurface(field, level, true, true);
    r.qa.emplace_back("iso_level_hu", level);
    r.qa.emplace_back("isosurface_triangles", static_cast<double>(iso.F.rows()));
    // Each plane removes only the vessel stub it cuts (a disc of 1.5 radii + 1 mm): in a dense tree, a wider disc
    // also cut the neighbouring vessels that pass beyond the plane, and the largest piece lost whole branches.
    SurfaceData cut = clip_at_planes(iso, seg.planes, 3.0, 1.0);
    r.qa.emplace_back("clipped_triangles", static_cast<double>(cut.F.rows()));
    std::vector<std::vector<int>> loops;
    try {
        loops = boundary_loops(cut);
        const int moved = clear_ends(cut, r.image.planes, p.end_clearance_mm, rep);
        r.qa.emplace_back("end_planes_moved", static_cast<double>(moved));
        if (moved > 0) loops = boundary_loops(cut);
    } catch (const InputError& e) {  // the stage's own isosurface, not the input, is at fault
        throw MeshingError(std::string("surface: check 'cut isosurface is a manifold' failed: ") + e.what());
    }
    if (loops.size() < 2) {  // nothing left to remesh: smoothing and remeshing an empty or closed piece crashed VTK
        throw MeshingError("surface: check 'the cut lumen has open ends' failed: the isosurface cut at the segmentation's " + std::to_string(seg.planes.size()) +
                           " end planes has " + std::to_string(cut.F.rows()) + " triangles and " + std::to_string(loops.size()) +
                           " open end(s), a vessel needs 2 (do the planes cross the segmented vessel? see `aneuprep inspect` of the segment file)");
    }
    if (loops.size() != seg.planes.size()) {
        rep.warn("surface: the cut surface has " + std::to_string(loops.size()) + " open ends for " + std::to_string(seg.planes.size()) +
                 " end planes (a plane may not cut its vessel cleanly)");
    }
    finish_lumen(r, std::move(cut), p, rep);
    return r;
}

LumenResult lumen_from_mesh(const std::string& path, const SurfaceParams& p, Reporter& rep) {
    validate(p);
    LumenResult r;
    SurfaceData s = read_mesh_file(path, p.weld_mm / p.input_scale);
    check_input_surface(s, path, p.input_scale);
    std::vector<std::vector<int>> loops;
    try {
        loops = boundary_loops(s);
    } catch (const InputError& e) {
        throw InputError(path + ": " + e.what());
    }
    check_no_overlap(s, path);
    r.qa.emplace_back("input_triangles", static_cast<double>(s.F.rows()));
    r.qa.emplace_back("input_open_ends", static_cast<double>(loops.size()));
    if (loops.empty()) {
        const auto caps = detect_flat_caps(s, p.cap_tolerance_deg, p.cap_tolerance_mm);
        if (!caps.empty()) {
            std::vector<char> keep(static_cast<size_t>(s.F.rows()), 1);
            for (const auto& c : caps)
                for (int f : c) keep[static_cast<size_t>(f)] = 0;
            s = sub_surface(s, keep);
            loops = boundary_loops(s);
            r.qa.emplace_back("input_caps_removed", static_cast<double>(caps.size()));
            rep.info("surface: removed " + std::to_string(caps.size()) + " flat end caps from " + path);
        } else {
            // Rounded ends (a segmentation's closed surface): cut where each vessel is tubular again. Voxels of
            // half the target edge, at most MAX_ROUNDED_END_VOXELS in the box.
            constexpr double MAX_ROUNDED_END_VOXELS = 8e6;
            const Eigen::Vector3d box = (s.V.colwise().maxCoeff() - s.V.colwise().minCoeff()).transpose();
            const double h = std::max(0.5 * p.edge_mm, std::cbrt((box.x() + 1) * (box.y() + 1) * (box.z() + 1) / MAX_ROUNDED_END_VOXELS));
            const RoundedEnds ends = find_rounded_ends(s, h);
            if (ends.planes.size() < 2) {
                throw InputError(path + ": the surface is closed and has no flat end cap to remove (none planar within --cap-tolerance-deg " +
                                 shortest(p.cap_tolerance_deg) + " and --cap-tolerance-mm " + shortest(p.cap_tolerance_mm) + ") and " +
                                 std::to_string(ends.planes.size()) + " rounded end(s) where a vessel becomes tubular; a lumen surface needs open ends, flat caps or 2 rounded vessel ends");
            }
            // Each plane cuts off only its own tip (a disc alone would also cut a neighbouring vessel that passes
            // beyond the plane).
            SurfaceData cut = clip_at_planes(s, ends.planes, 3.0, 1.0, ends.tips);
            std::vector<std::vector<int>> cut_loops;
            try {
                cut_loops = boundary_loops(cut);
            } catch (const InputError& e) {
                throw MeshingError(std::string("surface: check 'rounded ends cut to a manifold' failed: ") + e.what());
            }
            if (cut_loops.size() != ends.planes.size()) {
                throw MeshingError("surface: check 'one open end per rounded end cut' failed: " + std::to_string(cut_loops.size()) + " open ends for " +
                                   std::to_string(ends.planes.size()) + " cuts of " + path);
            }
            s = std::move(cut);
            loops = std::move(cut_loops);
            r.qa.emplace_back("input_rounded_ends_cut", static_cast<double>(ends.planes.size()));
            r.qa.emplace_back("input_rounded_tips_kept", static_cast<double>(ends.kept_tips.size()));
            const auto r2 = [](const Eigen::Vector3d& x) { return vec3((x * 100).array().round().matrix() / 100); };
            std::string where;
            for (const auto& e : ends.planes) where += " " + r2(e.point) + " r " + shortest(std::round(e.radius_mm * 100) / 100) + " mm;";
            std::string kept;
            for (const auto& t : ends.kept_tips) kept += " " + r2(t);
            rep.info("surface: cut " + std::to_string(ends.planes.size()) + " rounded ends of " + path + " where the vessel is tubular:" + where +
                     " kept whole (not tubular near the tip, e.g. the sac):" + (kept.empty() ? " none" : kept));
        }
    }
    if (loops.size() < 2) throw InputError(path + ": the surface has " + std::to_string(loops.size()) + " open end(s); a vessel needs at least 2");
    check_vessel_ends(s, loops, path);
    // Orient outward: the capped surface must enclose a positive volume.
    {
        SurfaceData capped = s;
        cap_loops(capped, loops, std::vector<int>(loops.size(), 0));
        if (enclosed_volume(capped) < 0) {
            s.F.col(1).swap(s.F.col(2));
            loops = boundary_loops(s);
        }
    }
    // End planes from the loops: centroid, outward normal (against the loop's vector area in face order),
    // radius of the circle of equal area.
    std::vector<EndPlane> planes;
    double rmin = 1e300;
    for (size_t q = 0; q < loops.size(); ++q) {
        const auto& l = loops[q];
        Eigen::Vector3d c = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
        for (int v : l) c += s.V.row(v).transpose();
        c /= static_cast<double>(l.size());
        for (size_t i = 0; i < l.size(); ++i) w += (s.V.row(l[i]).transpose() - c).cross(s.V.row(l[(i + 1) % l.size()]).transpose() - c);
        EndPlane e;
        e.id = static_cast<int>(q);
        e.point = c;
        e.normal = -w.normalized();
        e.radius_mm = std::sqrt(0.5 * w.norm() / PI);
        rmin = std::min(rmin, e.radius_mm);
        planes.push_back(e);
    }
    // Project each loop into its plane (flat caps give planar loops; open ends of other tools may not be).
    for (size_t q = 0; q < loops.size(); ++q)
        for (int v : loops[q]) {
            const Eigen::Vector3d x = s.V.row(v).transpose();
            s.V.row(v) = (x - planes[q].normal.dot(x - planes[q].point) * planes[q].normal).transpose();
        }
    const int moved = clear_ends(s, planes, p.end_clearance_mm, rep);
    r.qa.emplace_back("end_planes_moved", static_cast<double>(moved));
    if (moved > 0) {
        std::vector<std::vector<int>> reordered;  // loops in the order of their planes
        const auto nl = boundary_loops(s);
        for (const auto& pl : planes) reordered.push_back(nl[static_cast<size_t>(loop_of_plane(s, nl, pl))]);
        loops = reordered;
        rmin = 1e300;
        for (const auto& pl : planes) rmin = std::min(rmin, pl.radius_mm);
    }
    // Centerline: voxelise the capped surface, minimal paths between the ends.
    SurfaceData capped = s;
    cap_loops(capped, loops, std::vector<int>(loops.size(), 0));
    // Voxels of a quarter of the smallest end's radius, but at most MAX_CENTERLINE_VOXELS in the box: a real
    // tree with a 0.4 mm side-branch stub in a 44×59×34 mm box took 90 M voxels (2 GB, 12 s) at rmin/4; the
    // centerline only labels faces and its radius is re-measured on the surface afterwards.
    constexpr double MAX_CENTERLINE_VOXELS = 8e6;
    const Eigen::Vector3d box = (capped.V.colwise().maxCoeff() - capped.V.colwise().minCoeff()).transpose();
    const double h_box = std::cbrt((box.x() + 1) * (box.y() + 1) * (box.z() + 1) / MAX_CENTERLINE_VOXELS);
    const double h = std::max(std::min(0.5 * p.edge_mm, rmin / 4.0), h_box);
    Volume<std::uint8_t> mask = voxelize(capped, h, 2 * h);
    const Volume<float> dist = inside_distance_mm(mask);
    std::vector<std::vector<size_t>> ends(planes.size());
    for (std::int64_t k = 0; k < mask.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < mask.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < mask.grid.size[0]; ++i) {
                const size_t l = mask.grid.linear(i, j, k);
                if (!mask.data[l]) continue;
                const auto x3 = mask.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                const Eigen::Vector3d x(x3[0], x3[1], x3[2]);
                // An end is the voxels by the cap near its axis: the cap bounds the distance of every voxel in that
                // thin slab alike, so one anywhere across the end would do as the path's start — off the axis, it
                // gave the first millimetres of centerline a radius far too small.
                for (size_t q = 0; q < planes.size(); ++q) {
                    const Eigen::Vector3d r = x - planes[q].point;
                    const double along = planes[q].normal.dot(r);
                    if (std::abs(along) < 1.5 * h && (r - along * planes[q].normal).norm() < std::max(1.5 * h, 0.25 * planes[q].radius_mm)) {
                        ends[q].push_back(l);
                    }
                }
            }
    for (size_t q = 0; q < ends.size(); ++q)
        if (ends[q].empty()) throw InputError(path + ": open end " + std::to_string(q) + " encloses no voxel (is it a real vessel end?)");
    // The largest end first (the root of the minimal paths), ids kept.
    std::vector<size_t> order(planes.size());
    for (size_t q = 0; q < order.size(); ++q) order[q] = q;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return planes[a].radius_mm > planes[b].radius_mm; });
    std::vector<std::vector<size_t>> ends_sorted;
    for (size_t q : order) ends_sorted.push_back(ends[q]);
    CenterlineResult cl = centerline_from_ends(mask, dist, {}, ends_sorted, 0.0);
    // The paths start and stop at the voxels nearest the planes: continue each end branch to its plane's
    // point, so that faces at the cut ends measure their distance to the centerline, not to its tip.
    {
        Centerline& c = cl.centerline;
        std::vector<Eigen::Vector3d> pts;
        std::vector<double> rad;
        std::vector<int> off{0};
        for (Eigen::Index b = 0; b + 1 < c.offsets.size(); ++b) {
            if (b == 0) {
                pts.push_back(planes[order[0]].point);
                rad.push_back(planes[order[0]].radius_mm);
            }
            for (int i = c.offsets[b]; i < c.offsets[b + 1]; ++i) {
                pts.push_back(c.points.row(i).transpose());
                rad.push_back(c.radius[i]);
            }
            pts.push_back(planes[order[static_cast<size_t>(b + 1)]].point);  // branch b ends at end b + 1
            rad.push_back(planes[order[static_cast<size_t>(b + 1)]].radius_mm);
            off.push_back(static_cast<int>(pts.size()));
        }
        c.points.resize(static_cast<Eigen::Index>(pts.size()), 3);
        c.radius.resize(static_cast<Eigen::Index>(pts.size()));
        for (size_t i = 0; i < pts.size(); ++i) {
            c.points.row(static_cast<Eigen::Index>(i)) = pts[i].transpose();
            c.radius[static_cast<Eigen::Index>(i)] = rad[i];
        }
        c.offsets = Eigen::Map<Eigen::VectorXi>(off.data(), static_cast<Eigen::Index>(off.size()));
    }
    r.image.grid = mask.grid;
    r.image.mask = mask.data;
    r.image.mask_label_names = {"background", "lumen"};
    r.image.centerline = cl.centerline;
    r.image.planes = planes;
    r.qa.emplace_back("voxelisation_spacing_mm", h);
    finish_lumen(r, std::move(s), p, rep);
    return r;
}

}  // namespace aneu::pipeline
