// SPDX-License-Identifier: MIT
// Geometry stages against phantoms of known truth: segmentation Dice, end planes, lumen surface distance
// to the analytic surface, mesh quality, aneurysm labelling, wall thickness and checks, oblique frames,
// surfaces from other tools, bad inputs.
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/image_filters.hpp"
#include "aneu/pipeline/image_io.hpp"
#include "aneu/pipeline/phantom.hpp"
#include "aneu/pipeline/surface_checks.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "aneu/pipeline/tetmesh.hpp"

namespace fs = std::filesystem;
using namespace aneu;
using namespace aneu::pipeline;

namespace {

constexpr double PI = 3.14159265358979323846;

// Acceptance figures of the geometry issue.
constexpr double DICE_DEFAULT = 0.95, DICE_NOISY_BONE = 0.90;
constexpr double SURFACE_MEAN_MM = 0.10, SURFACE_P95_MM = 0.25;
constexpr double EDGE_REL_TOL = 0.15, MIN_ANGLE_DEG = 15.0, FRACTION_BELOW_25 = 0.01;
constexpr double SAC_FOUND = 0.90, ARTERY_MISLABELLED = 0.05;
constexpr double PLANE_ANGLE_DEG = 10.0;
constexpr double THICK_ARTERY_TOL = 0.10, THICK_SAC_TOL = 0.15;

struct Case {
    PhantomParams params;
    PhantomGeometry geom;
    Volume<float> ct;
    Volume<std::uint8_t> truth;
};

Case make_case(const PhantomParams& p) {
    Case c;
    c.params = p;
    c.geom = make_phantom_geometry(p);
    const Rasterized r = rasterize(c.geom, make_phantom_grid(p), p.supersampling);
    const Volume<std::int16_t> ct = synthesize_ct(p, r);
    c.ct.grid = ct.grid;
    c.ct.data.assign(ct.data.begin(), ct.data.end());
    c.truth = r.labels;
    return c;
}

double value(const NamedValues& qa, const std::string& k) {
    for (const auto& [n, v] : qa)
        if (n == k) return v;
    ADD_FAILURE() << "no QA figure " << k;
    return std::nan("");
}

/// Dice of the lumen mask (on a sub-grid of the truth's, same geometry) against truth labels artery|aneurysm.
double dice(const ImageData& im, const Volume<std::uint8_t>& truth) {
    size_t a = 0, b = 0, ab = 0;
    // The segmentation grid is the truth grid or a crop of it: map by physical position.
    for (std::int64_t k = 0; k < truth.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < truth.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < truth.grid.size[0]; ++i) {
                const auto x = truth.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                const auto ci = im.grid.continuous_index(x);
                const std::int64_t ii = std::llround(ci[0]), jj = std::llround(ci[1]), kk = std::llround(ci[2]);
                const bool in = ii >= 0 && jj >= 0 && kk >= 0 && ii < im.grid.size[0] && jj < im.grid.size[1] && kk < im.grid.size[2];
                const bool s = in && im.mask[im.grid.linear(ii, jj, kk)] != 0;
                const auto t = truth.data[truth.grid.linear(i, j, k)];
                const bool tr = t == ARTERY || t == ANEURYSM;
                a += s;
                b += tr;
                ab += s && tr;
            }
    return 2.0 * static_cast<double>(ab) / static_cast<double>(a + b);
}

/// Distances of the vertices to the analytic lumen surface: mean and 95th percentile, ignoring vertices
/// on the cut ends (the analytic capsules continue past the planes).
std::pair<double, double> surface_error(const SurfaceData& s, const PhantomGeometry& g) {
    std::vector<char> on_loop(static_cast<size_t>(s.V.rows()), 0);
    for (Eigen::Index i = 0; i < s.loop_vertices.size(); ++i) on_loop[static_cast<size_t>(s.loop_vertices[i])] = 1;
    std::vector<double> d;
    for (Eigen::Index v = 0; v < s.V.rows(); ++v)
        if (!on_loop[static_cast<size_t>(v)]) d.push_back(std::abs(lumen_sdf(g, s.V.row(v).transpose())));
    std::sort(d.begin(), d.end());
    double mean = 0;
    for (double x : d) mean += x;
    return {mean / static_cast<double>(d.size()), d[static_cast<size_t>(0.95 * static_cast<double>(d.size() - 1))]};
}

Eigen::Vector3d centroid(const SurfaceData& s, Eigen::Index f) {
    return (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
}
double area(const SurfaceData& s, Eigen::Index f) {
    const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    return 0.5 * (b - a).cross(c - a).norm();
}

/// Fraction of the true sac area labelled aneurysm, and of the true artery area labelled aneurysm. A face
/// belongs to the sac when it lies nearer the sac sphere than the vessel capsules.
std::pair<double, double> labelling(const SurfaceData& s, const PhantomGeometry& g) {
    double sac = 0, sac_ok = 0, art = 0, art_bad = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        const Eigen::Vector3d x = centroid(s, f);
        const bool true_sac = std::abs(sac_sdf(g, x)) < std::abs(vessel_sdf(g, x));
        const double a = area(s, f);
        const bool lab = s.face_label[f] == 1;
        if (true_sac) {
            sac += a;
            sac_ok += lab ? a : 0;
        } else {
            art += a;
            art_bad += lab ? a : 0;
        }
    }
    return {sac_ok / sac, art_bad / art};
}

/// Unit tangent of the nearest vessel centerline at x.
Eigen::Vector3d true_tangent(const PhantomGeometry& g, const Eigen::Vector3d& x, double* dist) {
    double best = 1e300;
    Eigen::Vector3d t = Eigen::Vector3d::UnitX();
    for (const auto& v : g.vessels)
        for (Eigen::Index i = 0; i + 1 < v.points.rows(); ++i) {
            const Eigen::Vector3d a = v.points.row(i).transpose(), b = v.points.row(i + 1).transpose();
            const double s = std::clamp((x - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
            const double d = (x - (a + s * (b - a))).norm();
            if (d < best) {
                best = d;
                t = (b - a).normalized();
            }
        }
    *dist = best;
    return t;
}

void expect_planes_found(const Case& c, const std::vector<EndPlane>& planes) {
    const auto truth = true_end_planes(c.geom, c.truth.grid);
    ASSERT_EQ(planes.size(), truth.size());
    for (const auto& t : truth) {
        const auto it = std::min_element(planes.begin(), planes.end(),
                                         [&](const EndPlane& a, const EndPlane& b) { return (a.point - t.point).norm() < (b.point - t.point).norm(); });
        double d = 0;
        const Eigen::Vector3d tan = true_tangent(c.geom, it->point, &d);
        const double angle = std::acos(std::min(1.0, std::abs(tan.dot(it->normal)))) * 180 / PI;
        EXPECT_LT(angle, PLANE_ANGLE_DEG) << "end " << t.id;
        EXPECT_GT(it->normal.dot(t.normal), 0.5) << "end " << t.id << ": normal must point out of the ROI";
        EXPECT_LT(d, 0.3 * t.radius_mm) << "end " << t.id << ": plane point off the true centerline";
        EXPECT_LT((it->point - t.point).norm(), 4.0 * t.radius_mm + 2.0) << "end " << t.id;
        EXPECT_NEAR(it->radius_mm, t.radius_mm, 0.25 * t.radius_mm) << "end " << t.id;
    }
}

/// The lumen-surface acceptance figures. `min_angle` and `artery_mislabelled` are the acceptance values
/// except where a caller passes the measured shortfall of a known open item (see the callers).
void expect_surface_standard(const SurfaceData& s, const PhantomGeometry& g, double edge, const std::string& what,
                             double min_angle = MIN_ANGLE_DEG, double artery_mislabelled = ARTERY_MISLABELLED) {
    const auto [mean, p95] = surface_error(s, g);
    EXPECT_LE(mean, SURFACE_MEAN_MM) << what;
    EXPECT_LE(p95, SURFACE_P95_MM) << what;
    const NamedValues q = triangle_quality(s);
    EXPECT_NEAR(value(q, "edge_mean_mm"), edge, EDGE_REL_TOL * edge) << what;
    EXPECT_GE(value(q, "min_angle_deg"), min_angle) << what;
    EXPECT_LT(value(q, "fraction_min_angle_below_25deg"), FRACTION_BELOW_25) << what;
    const auto [sac_found, art_bad] = labelling(s, g);
    EXPECT_GE(sac_found, SAC_FOUND) << what;
    EXPECT_LE(art_bad, artery_mislabelled) << what;
    std::printf("%s: distance mean %.4f p95 %.4f mm; edge mean %.3f; min angle %.1f; <25deg %.4f; sac found %.3f; artery mislabelled %.4f\n",
                what.c_str(), mean, p95, value(q, "edge_mean_mm"), value(q, "min_angle_deg"), value(q, "fraction_min_angle_below_25deg"), sac_found,
                art_bad);
}

/// The default phantom, segmented and surfaced once for all tests of this file.
struct Default {
    Case c = make_case(PhantomParams{});
    Segmentation seg = segment_volume(c.ct, SegmentParams{});
};
const Default& default_case() {
    static const Default d;
    return d;
}
const LumenResult& default_lumen(const std::string& remesher) {
    static std::map<std::string, LumenResult> cache;
    auto it = cache.find(remesher);
    if (it == cache.end()) {
        SurfaceParams p;
        p.remesher = remesher;
        it = cache.emplace(remesher, lumen_from_segmentation(default_case().seg.image, p)).first;
    }
    return it->second;
}

}  // namespace

TEST(Segment, DefaultPhantomDiceAndEnds) {
    const auto& d = default_case();
    const double dc = dice(d.seg.image, d.c.truth);
    std::printf("default phantom: Dice %.4f, threshold %.1f HU\n", dc, value(d.seg.qa, "threshold_hu"));
    EXPECT_GE(dc, DICE_DEFAULT);
    expect_planes_found(d.c, d.seg.image.planes);
    // The centerline is a tree: the parent from end 0 to end 1 and the branch.
    EXPECT_EQ(d.seg.image.centerline.offsets.size(), 3);
}

TEST(Segment, NoisyPhantomWithBone) {
    PhantomParams p;
    p.with_bone = true;
    p.noise_sd_hu = 30.0;
    p.seed = 7;
    const Case c = make_case(p);
    const Segmentation s = segment_volume(c.ct, SegmentParams{});
    const double dc = dice(s.image, c.truth);
    std::printf("noisy phantom with bone: Dice %.4f, threshold %.1f HU\n", dc, value(s.qa, "threshold_hu"));
    EXPECT_GE(dc, DICE_NOISY_BONE);
    expect_planes_found(c, s.image.planes);
}

TEST(Segment, GivenThresholdSeedRoiAndPlanes) {
    const auto& d = default_case();
    SegmentParams p;
    p.threshold_hu = 220.0;
    p.seeds_mm = {{d.c.geom.vessels[0].points(d.c.geom.vessels[0].points.rows() / 2, 0), d.c.geom.vessels[0].points(d.c.geom.vessels[0].points.rows() / 2, 1),
                   d.c.geom.vessels[0].points(d.c.geom.vessels[0].points.rows() / 2, 2)}};
    p.roi_mm = std::array<double, 6>{-11, -10, -6, 11, 10, 9};
    const Segmentation s = segment_volume(d.c.ct, p);
    EXPECT_EQ(value(s.qa, "threshold_hu"), 220.0);
    EXPECT_LT(s.image.grid.voxel_count(), d.c.ct.grid.voxel_count());
    // Inside the ROI the mask agrees with the truth.
    EXPECT_GE(dice(s.image, [&] {
                  Volume<std::uint8_t> t = d.c.truth;  // truth restricted to the ROI box
                  for (std::int64_t k = 0; k < t.grid.size[2]; ++k)
                      for (std::int64_t j = 0; j < t.grid.size[1]; ++j)
                          for (std::int64_t i = 0; i < t.grid.size[0]; ++i) {
                              const auto x = t.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                              const bool in = x[0] >= -11 && x[0] <= 11 && x[1] >= -10 && x[1] <= 10 && x[2] >= -6 && x[2] <= 9;
                              if (!in) t.data[t.grid.linear(i, j, k)] = 0;
                          }
                  return t;
              }()),
              DICE_DEFAULT);
    // Given planes replace the detected ones.
    SegmentParams q;
    EndPlane e;
    e.id = 0;
    e.point = Eigen::Vector3d(1, 2, 3);
    e.normal = Eigen::Vector3d(0, 0, 1);
    e.radius_mm = 2;
    q.planes = {e};
    const Segmentation s2 = segment_volume(d.c.ct, q);
    ASSERT_EQ(s2.image.planes.size(), 1u);
    EXPECT_EQ(s2.image.planes[0].point, e.point);
}

TEST(Surface, NetgenMeetsTheStandard) {
    const auto& d = default_case();
    const LumenResult& r = default_lumen("netgen");
    expect_surface_standard(r.lumen, d.c.geom, 0.4, "netgen");
    EXPECT_EQ(r.lumen.loop_end_id.size(), 3);
}

TEST(Surface, CgalMeetsTheStandard) {
    const auto& d = default_case();
    const LumenResult& r = default_lumen("cgal");
    expect_surface_standard(r.lumen, d.c.geom, 0.4, "cgal");
    EXPECT_EQ(r.lumen.loop_end_id.size(), 3);
    // Every boundary loop lies in its end plane.
    for (Eigen::Index l = 0; l < r.lumen.loop_end_id.size(); ++l) {
        const auto& pl = r.image.planes[static_cast<size_t>(r.lumen.loop_end_id[l])];
        for (int i = r.lumen.loop_offsets[l]; i < r.lumen.loop_offsets[l + 1]; ++i)
            EXPECT_NEAR(pl.normal.dot(r.lumen.V.row(r.lumen.loop_vertices[i]).transpose() - pl.point), 0.0, 1e-6);
    }
}

TEST(Surface, OverridesOfTheAneurysmLabel) {
    const auto& d = default_case();
    SurfaceParams p;
    p.remesher = "cgal";
    const auto& sac = *d.c.geom.sac;
    p.aneurysm_sphere = std::array<double, 4>{sac.centre.x(), sac.centre.y(), sac.centre.z(), sac.radius_mm + 0.3};
    const LumenResult r = lumen_from_segmentation(d.seg.image, p);
    for (Eigen::Index f = 0; f < r.lumen.F.rows(); ++f)
        EXPECT_EQ(r.lumen.face_label[f], (centroid(r.lumen, f) - sac.centre).norm() < sac.radius_mm + 0.3 ? 1 : 0);
}

TEST(Surface, ObliqueAnisotropicPhantomInPhysicalFrame) {
    PhantomParams p;
    p.oblique_deg = {10.0, -15.0, 20.0};
    p.spacing_mm = {0.35, 0.45, 0.5};
    p.fov_mm = {30.0, 26.0, 22.0};
    const Case c = make_case(p);
    const Segmentation s = segment_volume(c.ct, SegmentParams{});
    EXPECT_GE(dice(s.image, c.truth), DICE_DEFAULT);
    expect_planes_found(c, s.image.planes);
    // Both remeshers. Short cut-end segments used to leave a 14.6° (CGAL) and a 1.3° (Netgen) triangle here;
    // such boundary edges are now collapsed.
    for (const char* remesher : {"cgal", "netgen"}) {
        SurfaceParams sp;
        sp.remesher = remesher;
        const LumenResult r = lumen_from_segmentation(s.image, sp);
        expect_surface_standard(r.lumen, c.geom, 0.4, std::string("oblique-") + remesher);
    }
}

TEST(Surface, AutomaticLabelOfASmallSacBesideTheBifurcation) {
    // configs/cases/oblique_bone.toml: a 5.5 mm sac, bone, noise 25 HU, a rotated 0.35×0.45×0.6 mm grid. The branch
    // path cuts across the ostium there, off both axes; with the radius taken at the nearest centerline point
    // alone, 6.2 % of the artery at the bifurcation was labelled aneurysm.
    PhantomParams p;
    p.seed = 2;
    p.spacing_mm = {0.35, 0.45, 0.6};
    p.fov_mm = {32.0, 24.0, 22.0};
    p.fov_centre_mm = {-2.0, 0.0, 1.0};
    p.oblique_deg = {12.0, -8.0, 20.0};
    p.dome_diameter_mm = 5.5;
    p.neck_diameter_mm = 3.2;
    p.with_bone = true;
    p.noise_sd_hu = 25.0;
    const Case c = make_case(p);
    const Segmentation s = segment_volume(c.ct, SegmentParams{});
    SurfaceParams sp;
    sp.remesher = "cgal";
    const LumenResult r = lumen_from_segmentation(s.image, sp);
    const auto [sac_found, art_bad] = labelling(r.lumen, c.geom);
    EXPECT_GE(sac_found, SAC_FOUND);
    EXPECT_LE(art_bad, ARTERY_MISLABELLED);
    std::printf("oblique-bone: sac found %.3f; artery mislabelled %.4f\n", sac_found, art_bad);
}

TEST(Surface, StlFromAnotherToolOpenAndCapped) {
    const auto& d = default_case();
    const LumenResult& ref = default_lumen("cgal");
    const fs::path dir = fs::temp_directory_path() / ("aneu_stl_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    // Open ends.
    write_mesh_file((dir / "open.stl").string(), ref.lumen);
    SurfaceParams p;
    p.remesher = "cgal";
    const LumenResult open = lumen_from_mesh((dir / "open.stl").string(), p);
    expect_surface_standard(open.lumen, d.c.geom, 0.4, "stl-open");
    EXPECT_EQ(open.lumen.loop_end_id.size(), 3);
    // Flat caps, detected and removed.
    SurfaceData capped = ref.lumen;
    cap_loops(capped, boundary_loops(capped), {0, 0, 0});
    write_mesh_file((dir / "capped.stl").string(), capped);
    const LumenResult cap = lumen_from_mesh((dir / "capped.stl").string(), p);
    EXPECT_EQ(value(cap.qa, "input_caps_removed"), 3.0);
    expect_surface_standard(cap.lumen, d.c.geom, 0.4, "stl-capped");
    // And its wall, to the wall standard (as Wall.ClosedThicknessAndBlend on the segmentation route).
    WallParams wp;
    wp.grid_spacing_mm = 0.06;
    const WallResult w = make_wall(cap.lumen, cap.image.planes, wp);
    EXPECT_NO_THROW(check_closed_surface(w.wall, "wall"));
    EXPECT_TRUE(self_intersections(w.wall, 1).empty());
    EXPECT_NEAR(value(w.qa, "thickness_artery_median_mm"), 0.4, THICK_ARTERY_TOL * 0.4);
    EXPECT_NEAR(value(w.qa, "thickness_aneurysm_median_mm"), 0.4 / 3, THICK_SAC_TOL * 0.4 / 3);
    EXPECT_LE(value(w.qa, "thickness_gradient_max"), value(w.qa, "thickness_gradient_blend_allows"));
    EXPECT_EQ(w.wall.label_names.size(), 5u);
    std::printf("stl-capped wall: median thickness artery %.4f, aneurysm %.4f; gradient max %.3f (blend allows %.3f)\n",
                value(w.qa, "thickness_artery_median_mm"), value(w.qa, "thickness_aneurysm_median_mm"), value(w.qa, "thickness_gradient_max"),
                value(w.qa, "thickness_gradient_blend_allows"));
    fs::remove_all(dir);
}

// An exporter that writes each triangle's corners with its own rounding (here up to ±3 µm): the copies of a
// vertex are not coincident, so the default weld (1e-6 of the diagonal, 0.03 µm here) leaves every triangle
// loose and the surface is refused; --weld-mm 0.01 merges them back into the original surface.
TEST(SurfaceInput, WeldToleranceMergesCoarselyRoundedCopies) {
    const LumenResult& ref = default_lumen("cgal");
    const fs::path dir = fs::temp_directory_path() / ("aneu_weld_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const std::string stl = (dir / "rounded_copies.stl").string();
    {
        std::FILE* f = std::fopen(stl.c_str(), "w");
        ASSERT_NE(f, nullptr);
        std::fprintf(f, "solid jitter\n");
        std::uint64_t state = 12345;
        auto jitter = [&state] {  // deterministic, uniform in [-3, 3] µm
            state = state * 6364136223846793005ULL + 1442695040888963407ULL;
            return (static_cast<double>(state >> 11) / 9007199254740992.0 - 0.5) * 0.006;
        };
        for (Eigen::Index t = 0; t < ref.lumen.F.rows(); ++t) {
            std::fprintf(f, " facet normal 0 0 0\n  outer loop\n");
            for (int k = 0; k < 3; ++k) {
                const Eigen::RowVector3d v = ref.lumen.V.row(ref.lumen.F(t, k));
                std::fprintf(f, "   vertex %.9f %.9f %.9f\n", v.x() + jitter(), v.y() + jitter(), v.z() + jitter());
            }
            std::fprintf(f, "  endloop\n endfacet\n");
        }
        std::fprintf(f, "endsolid jitter\n");
        std::fclose(f);
    }
    SurfaceParams p;
    p.remesher = "cgal";
    EXPECT_THROW((void)lumen_from_mesh(stl, p), InputError);
    p.weld_mm = 0.01;
    const SurfaceData welded = read_mesh_file(stl, p.weld_mm);
    EXPECT_EQ(welded.V.rows(), ref.lumen.V.rows());
    EXPECT_EQ(welded.F.rows(), ref.lumen.F.rows());
    const LumenResult r = lumen_from_mesh(stl, p);
    EXPECT_EQ(value(r.qa, "input_open_ends"), 3.0);
    EXPECT_EQ(r.lumen.loop_end_id.size(), 3u);
    fs::remove_all(dir);
}

TEST(Wall, ClosedThicknessAndBlend) {
    const LumenResult& r = default_lumen("cgal");
    WallParams p;
    p.grid_spacing_mm = 0.06;
    const WallResult w = make_wall(r.lumen, r.image.planes, p);
    EXPECT_NO_THROW(check_closed_surface(w.wall, "wall"));
    EXPECT_TRUE(self_intersections(w.wall, 1).empty());
    const double ta = value(w.qa, "thickness_artery_median_mm"), ts = value(w.qa, "thickness_aneurysm_median_mm");
    std::printf("wall: median thickness artery %.4f (target 0.4), aneurysm %.4f (target %.4f); gradient max %.3f (blend allows %.3f)\n", ta, ts,
                0.4 / 3, value(w.qa, "thickness_gradient_max"), value(w.qa, "thickness_gradient_blend_allows"));
    EXPECT_NEAR(ta, 0.4, THICK_ARTERY_TOL * 0.4);
    EXPECT_NEAR(ts, 0.4 / 3, THICK_SAC_TOL * 0.4 / 3);
    EXPECT_LE(value(w.qa, "thickness_gradient_max"), value(w.qa, "thickness_gradient_blend_allows"));
    // Nowhere thinner than half the thinnest target: an outer face that passes close to a lumen vertex without
    // crossing is refined too (a real TOF-MRA had 0.007 mm where 0.133 was meant, and flat tetrahedra through it).
    int inner_label = -1;
    for (size_t k = 0; k < w.wall.label_names.size(); ++k)
        if (w.wall.label_names[k] == "inner") inner_label = static_cast<int>(k);
    ASSERT_GE(inner_label, 0);
    ASSERT_EQ(w.wall.vertex_thickness.size(), w.wall.V.rows());
    double thinnest = 1e9;
    for (Eigen::Index f = 0; f < w.wall.F.rows(); ++f)
        if (w.wall.face_label[f] == inner_label)
            for (int k = 0; k < 3; ++k) thinnest = std::min(thinnest, w.wall.vertex_thickness[w.wall.F(f, k)]);
    EXPECT_GE(thinnest, 0.5 * 0.4 / 3);
    // Labels: inner, outer, one cap per end.
    EXPECT_EQ(w.wall.label_names.size(), 5u);
}

// A segmentation whose mask gives no surface between its end planes (a TopCoW CTA's mask once did): a clear stage
// failure, not a crash in the smoothing of an empty surface.
TEST(GeometryErrors, NoLumenBetweenTheEndPlanesIsAStageFailure) {
    ImageData img = default_case().seg.image;
    std::fill(img.mask.begin(), img.mask.end(), std::uint8_t{0});
    for (std::int64_t k = 5; k < 8; ++k)  // a closed blob in a corner, away from every end plane
        for (std::int64_t j = 5; j < 8; ++j)
            for (std::int64_t i = 5; i < 8; ++i) img.mask[img.grid.linear(i, j, k)] = 1;
    try {
        (void)lumen_from_segmentation(img, SurfaceParams{});
        ADD_FAILURE() << "an empty lumen was accepted";
    } catch (const MeshingError& e) {
        EXPECT_NE(std::string(e.what()).find("check 'the cut lumen has open ends' failed"), std::string::npos) << e.what();
    }
}

TEST(GeometryErrors, BadInputsAreInputErrors) {
    const auto& d = default_case();
    EXPECT_THROW(segment("/nonexistent/ct.nii.gz", SegmentParams{}), InputError);
    SegmentParams roi;
    roi.roi_mm = std::array<double, 6>{100, 100, 100, 110, 110, 110};
    EXPECT_THROW(segment_volume(d.c.ct, roi), InputError);
    SegmentParams seed;
    seed.seeds_mm = {{0.0, 8.0, -4.0}};  // tissue
    EXPECT_THROW(segment_volume(d.c.ct, seed), InputError);
    SegmentParams thr;
    thr.threshold_hu = 5000.0;
    EXPECT_THROW(segment_volume(d.c.ct, thr), InputError);
    // A closed surface without flat caps (a sphere), and a non-manifold one.
    const fs::path dir = fs::temp_directory_path() / ("aneu_bad_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    SurfaceData sphere;
    {
        PhantomParams p;
        Volume<float> v = make_case(p).ct;
        for (std::int64_t k = 0; k < v.grid.size[2]; ++k)
            for (std::int64_t j = 0; j < v.grid.size[1]; ++j)
                for (std::int64_t i = 0; i < v.grid.size[0]; ++i) {
                    const auto x = v.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                    v.data[v.grid.linear(i, j, k)] = static_cast<float>(3.0 - std::sqrt(x[0] * x[0] + x[1] * x[1] + (x[2] - 2) * (x[2] - 2)));
                }
        sphere = isosurface(v, 0.0, true);
    }
    write_mesh_file((dir / "sphere.stl").string(), sphere);
    try {
        (void)lumen_from_mesh((dir / "sphere.stl").string(), SurfaceParams{});
        ADD_FAILURE() << "a closed surface without caps was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no flat end cap"), std::string::npos) << e.what();
    }
    SurfaceData nm;
    nm.V.resize(5, 3);
    nm.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1;
    nm.F.resize(3, 3);
    nm.F << 0, 1, 2, 1, 0, 3, 0, 1, 4;  // edge 0-1 in three faces
    nm.face_label = Eigen::VectorXi::Zero(3);
    write_mesh_file((dir / "nonmanifold.stl").string(), nm);
    try {
        (void)lumen_from_mesh((dir / "nonmanifold.stl").string(), SurfaceParams{});
        ADD_FAILURE() << "a non-manifold surface was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("manifold"), std::string::npos) << e.what();
    }
    fs::remove_all(dir);
}

namespace {
// A volume of 0.2 mm voxels over [-4.9, ...] × [-4.9, ...] × [-13.9, ...] whose value is an implicit field (> 0 inside).
Volume<float> implicit_volume(std::array<std::int64_t, 3> size, double x0, const std::function<double(const Eigen::Vector3d&)>& field) {
    Volume<float> v;
    v.grid.size = size;
    v.grid.spacing = {0.2, 0.2, 0.2};
    v.grid.origin = {x0, -4.9, -13.9};
    v.data.resize(v.grid.voxel_count());
    for (std::int64_t k = 0; k < v.grid.size[2]; ++k)
        for (std::int64_t j = 0; j < v.grid.size[1]; ++j)
            for (std::int64_t i = 0; i < v.grid.size[0]; ++i) {
                const auto x = v.grid.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
                v.data[v.grid.linear(i, j, k)] = static_cast<float>(field(Eigen::Vector3d(x[0], x[1], x[2])));
            }
    return v;
}
// A tube of radius R along z, with hemispherical ends at ±L (beyond the box when L is large).
double tube_field(const Eigen::Vector3d& p, double R, double L) { return R - (p - Eigen::Vector3d(0, 0, std::clamp(p.z(), -L, L))).norm(); }
}  // namespace

// A segmentation's closed surface: a tube of radius 1.5 mm along z with rounded (hemispherical) blind ends at
// z = ±11.5 and a sidewall sac of radius 2.5 mm. The ends are cut where the tube is tubular again (|z| ≤ 10),
// perpendicular to the axis, and the sac is kept whole and labelled.
TEST(SurfaceInput, RoundedEndsAreCutWhereTheVesselIsTubular) {
    const double R = 1.5, L = 10.0, Rs = 2.5;
    const Eigen::Vector3d sac(0, 3.4, 1.0);
    const Volume<float> v = implicit_volume({50, 60, 140}, -4.9, [&](const Eigen::Vector3d& p) { return std::max(tube_field(p, R, L), Rs - (p - sac).norm()); });
    const SurfaceData closed = isosurface(v, 0.0, true);
    const RoundedEnds ends = find_rounded_ends(closed, 0.2);
    ASSERT_EQ(ends.planes.size(), 2u);
    for (const auto& e : ends.planes) {
        EXPECT_GT(std::abs(e.normal.z()), std::cos(5.0 * 3.14159265358979 / 180)) << e.normal.transpose();
        EXPECT_GT(e.normal.z() * e.point.z(), 0.0) << "normals point towards the tips";
        EXPECT_LE(std::abs(e.point.z()), L) << "cut inside the tubular part";
        EXPECT_GE(std::abs(e.point.z()), L - 2.0 * R) << "cut near the rounded end";
        EXPECT_NEAR(std::hypot(e.point.x(), e.point.y()), 0.0, 0.2);
        EXPECT_NEAR(e.radius_mm, R, 0.15 * R);
    }
    ASSERT_GE(ends.kept_tips.size(), 1u);  // the sac's dome
    bool dome = false;
    for (const auto& t : ends.kept_tips) dome = dome || (t - sac).norm() < Rs + 0.3;
    EXPECT_TRUE(dome);
    // Through the surface stage: two open ends, the sac labelled.
    const fs::path dir = fs::temp_directory_path() / ("aneu_rounded_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    write_mesh_file((dir / "rounded.stl").string(), closed);
    const LumenResult r = lumen_from_mesh((dir / "rounded.stl").string(), SurfaceParams{});
    EXPECT_EQ(r.lumen.loop_end_id.size(), 2);
    EXPECT_EQ(value(r.qa, "input_rounded_ends_cut"), 2.0);
    double sac_area = 0, sac_far = 0;
    for (Eigen::Index f = 0; f < r.lumen.F.rows(); ++f) {
        if (r.lumen.face_label[f] != 1) continue;
        const Eigen::Vector3d c = (r.lumen.V.row(r.lumen.F(f, 0)) + r.lumen.V.row(r.lumen.F(f, 1)) + r.lumen.V.row(r.lumen.F(f, 2))).transpose() / 3.0;
        sac_area += 1;
        sac_far = std::max(sac_far, (c - sac).norm());
    }
    EXPECT_GT(sac_area, 0.0) << "the sac is labelled";
    EXPECT_LT(sac_far, Rs + 0.5) << "only the sac is labelled";
    fs::remove_all(dir);
}

// One sac: a tube (radius 1.5 mm) with a sidewall sac (radius 2.5 mm) and, 6 mm away on the other side, a bump of
// radius 1.2 mm whose far side is 1.73 radii from the axis — above the ratio that seeds a sac. Both are candidates;
// the sac is kept and the bump becomes artery.
TEST(SurfaceInput, TheMostProminentSacCandidateIsKept) {
    const double R = 1.5, L = 30.0, Rs = 2.5, Rb = 1.2;  // the tube leaves the box: two open ends
    const Eigen::Vector3d sac(0, 3.4, 1.0), bump(0, -1.4, -5.0);
    const Volume<float> v = implicit_volume({50, 60, 140}, -4.9, [&](const Eigen::Vector3d& p) {
        return std::max({tube_field(p, R, L), Rs - (p - sac).norm(), Rb - (p - bump).norm()});
    });
    const fs::path dir = fs::temp_directory_path() / ("aneu_one_sac_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    write_mesh_file((dir / "two.stl").string(), isosurface(v, 0.0, true));
    SurfaceParams sp;
    sp.remesher = "cgal";
    const LumenResult r = lumen_from_mesh((dir / "two.stl").string(), sp);
    fs::remove_all(dir);
    EXPECT_EQ(value(r.qa, "sac_candidates"), 2.0);
    double near_sac = 0, near_bump = 0;
    for (Eigen::Index f = 0; f < r.lumen.F.rows(); ++f) {
        if (r.lumen.face_label[f] != 1) continue;
        const Eigen::Vector3d c = (r.lumen.V.row(r.lumen.F(f, 0)) + r.lumen.V.row(r.lumen.F(f, 1)) + r.lumen.V.row(r.lumen.F(f, 2))).transpose() / 3.0;
        ((c - sac).norm() < Rs + 0.5 ? near_sac : near_bump) += 1;
    }
    EXPECT_GT(near_sac, 100.0) << "the sac is labelled";
    EXPECT_EQ(near_bump, 0.0) << "the bump is artery";
}

// Where two vessels touch, the centerline of a real CTA ran along the seam between them and its inscribed radius
// there was near zero (0.01–0.3 mm in a 0.8 mm vessel): the far side of the vessel stood off it by 5–10 radii and a
// 55 mm² stretch of vessel was labelled sac. Here: a tube of radius 1.5 mm with a sidewall sac, and a centerline
// whose radius is 0.3 mm (a fifth of the truth) over 12 mm of the tube. The stretch stands off that radius like a
// sac, but it lies within d90 ≈ R of the centerline along several times that: a tube, never the sac. The sac is
// kept; without the sac nothing is labelled.
TEST(SurfaceInput, AStretchOfVesselWithAnUnderestimatedRadiusIsNotTheSac) {
    const double R = 1.5, L = 30.0, Rs = 2.5;
    const Eigen::Vector3d sac(0, 3.4, 6.0);
    Centerline c;
    const int n = 131;  // z from -13 to 13, every 0.2 mm
    c.points.resize(n, 3);
    c.radius.resize(n);
    for (int i = 0; i < n; ++i) {
        const double z = -13.0 + 0.2 * i;
        c.points.row(i) << 0, 0, z;
        c.radius[i] = z > -13.5 && z < -1.5 ? 0.3 : R;
    }
    c.offsets.resize(2);
    c.offsets << 0, n;
    for (const bool with_sac : {true, false}) {
        const Volume<float> v = implicit_volume({50, 60, 140}, -4.9, [&](const Eigen::Vector3d& p) {
            return with_sac ? std::max(tube_field(p, R, L), Rs - (p - sac).norm()) : tube_field(p, R, L);
        });
        const SurfaceData s = isosurface(v, 0.0, true);
        SacCandidates cand;
        const Eigen::VectorXi label = label_aneurysm(s, c, 1.6, 1.4, &cand);
        int tubes = 0;
        for (const auto& pc : cand.pieces) {
            tubes += pc.tube ? 1 : 0;
            if (pc.tube) {
                EXPECT_NEAR(pc.d90_mm, R, 0.2) << "the stretch lies about one true radius from the centerline";
                EXPECT_GT(pc.along_mm, 8.0) << "and along most of the stretch whose windowed radius is too small";
            }
        }
        EXPECT_EQ(tubes, 1) << (with_sac ? "with" : "without") << " the sac";
        double on_sac = 0, on_stretch = 0;
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            if (label[f] != 1) continue;
            const Eigen::Vector3d x = (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
            ((x - sac).norm() < Rs + 0.5 ? on_sac : on_stretch) += 1;
        }
        EXPECT_EQ(on_stretch, 0.0) << "no face of the stretch is sac";
        if (with_sac) {
            ASSERT_EQ(cand.pieces.size(), 2u);
            ASSERT_GE(cand.kept, 0);
            EXPECT_FALSE(cand.pieces[static_cast<size_t>(cand.kept)].tube);
            EXPECT_LT(cand.pieces[static_cast<size_t>(cand.kept)].along_mm, 2.5 * cand.pieces[static_cast<size_t>(cand.kept)].d90_mm);
            EXPECT_GT(on_sac, 100.0) << "the sac is labelled";
        } else {
            EXPECT_EQ(cand.pieces.size(), 1u);
            EXPECT_EQ(cand.kept, -1) << "no sac when every candidate is a tube";
        }
    }
}

// A sharp thin tip with the sac's thin wall: a tube of radius 1.5 mm with a needle (a cone from 0.45 mm radius at
// the tube's wall to a point 2.4 mm out, a TOF-MRA's faded branch) labelled sac, so its wall is a third of the
// artery's. The outer surface remeshed at the lumen's 0.4 mm edge cuts across the tip's offset (0.13 mm round a
// point) and splitting its triangles does not converge; the wall stage remeshes a finer zone there. The wall is
// closed, free of self-intersections, and the zone is reported.
TEST(Wall, ASharpThinWalledTipGetsAFinerZone) {
    const double R = 1.5, L = 10.0, x0 = 1.2, x1 = 4.4, r0 = 0.45;
    const Volume<float> v = implicit_volume({50, 40, 140}, -3.9, [&](const Eigen::Vector3d& p) {
        const double along = std::clamp((p.x() - x0) / (x1 - x0), 0.0, 1.0);
        const double cone = p.x() < x0 || p.x() > x1 ? -1.0 : r0 * (1 - along) - std::hypot(p.y(), p.z() - 1.0);
        return std::max(tube_field(p, R, L), cone);
    });
    const fs::path dir = fs::temp_directory_path() / ("aneu_tip_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    write_mesh_file((dir / "tip.stl").string(), isosurface(v, 0.0, true));
    SurfaceParams sp;
    sp.remesher = "cgal";
    sp.aneurysm_sphere = std::array<double, 4>{3.2, 0.0, 1.0, 1.6};
    const LumenResult r = lumen_from_mesh((dir / "tip.stl").string(), sp);
    fs::remove_all(dir);
    ASSERT_GT(r.lumen.face_label.maxCoeff(), 0);
    const WallResult w = make_wall(r.lumen, r.image.planes, WallParams{});
    std::printf("tip: lumen edge %.3f mm; outer faces refined %g, fine zone %g faces at %g mm; sac median %.4f\n", value(r.qa, "edge_mean_mm"),
                value(w.qa, "outer_faces_refined"), value(w.qa, "outer_fine_zone_faces"), value(w.qa, "outer_fine_zone_edge_mm"),
                value(w.qa, "thickness_aneurysm_median_mm"));
    EXPECT_NO_THROW(check_closed_surface(w.wall, "wall"));
    EXPECT_TRUE(self_intersections(w.wall, 1).empty());
    EXPECT_GT(value(w.qa, "outer_fine_zone_faces"), 0.0);
    EXPECT_NEAR(value(w.qa, "thickness_artery_median_mm"), 0.4, THICK_ARTERY_TOL * 0.4);
}

TEST(ImageFilters, InsideDistanceOfACylinder) {
    Volume<std::uint8_t> m;
    m.grid.size = {40, 40, 20};
    m.grid.spacing = {0.4, 0.4, 0.5};
    m.data.assign(m.grid.voxel_count(), 0);
    for (std::int64_t k = 0; k < 20; ++k)
        for (std::int64_t j = 0; j < 40; ++j)
            for (std::int64_t i = 0; i < 40; ++i) {
                const double x = static_cast<double>(i - 20) * 0.4, y = static_cast<double>(j - 20) * 0.4;
                if (x * x + y * y < 4.0 - 1e-9) m.data[m.grid.linear(i, j, k)] = 1;
            }
    const Volume<float> d = inside_distance_mm(m);
    // Nearest background voxel centre of the axis voxel: (±2.0, 0) mm.
    EXPECT_NEAR(d.data[m.grid.linear(20, 20, 10)], 2.0, 1e-5);
    EXPECT_EQ(d.data[m.grid.linear(0, 0, 10)], 0.0f);
}

// Bone brighter than the contrast, at several distances from the sac (touching included): the automatic
// threshold comes from the vessels (vesselness), not from a histogram split the bone would pull up.
TEST(Segment, BoneBrighterThanLumenAtSeveralPlacements) {
    for (double gap : {1.5, 0.8, 0.3, 0.0}) {
        PhantomParams p;
        p.with_bone = true;
        p.bone_gap_mm = gap;
        p.bone_hu = 1400.0;
        p.lumen_hu = 350.0;
        p.noise_sd_hu = 15.0;
        p.seed = 11;
        const Case c = make_case(p);
        const Segmentation s = segment_volume(c.ct, SegmentParams{});
        const double dc = dice(s.image, c.truth);
        std::printf("bone %.1f mm from the sac (1400 HU, lumen 350 HU): Dice %.4f, threshold %.1f HU, upper %.1f HU\n", gap, dc,
                    value(s.qa, "threshold_hu"), value(s.qa, "auto_upper_hu"));
        EXPECT_GE(dc, 0.95) << "bone gap " << gap << " mm";
        EXPECT_LT(value(s.qa, "threshold_hu"), p.lumen_hu) << "bone gap " << gap << " mm";
    }
}

TEST(SurfaceOps, ShortInteriorEdgesAreCollapsedAndTheBoundaryStays) {
    // A flat 10 × 10 grid of unit squares (two triangles each) with two vertices pulled next to a neighbour: an
    // interior one 0.05 from the next interior vertex, and one 0.05 inside the boundary from a boundary vertex.
    SurfaceData s;
    const int n = 11;
    s.V.resize(n * n, 3);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) s.V.row(j * n + i) << i, j, 0;
    s.F.resize(2 * 10 * 10, 3);
    int f = 0;
    for (int j = 0; j < 10; ++j)
        for (int i = 0; i < 10; ++i) {
            const int a = j * n + i;
            s.F.row(f++) << a, a + 1, a + n + 1;
            s.F.row(f++) << a, a + n + 1, a + n;
        }
    s.face_label = Eigen::VectorXi::Zero(s.F.rows());
    s.label_names = {"surface"};
    s.V.row(5 * n + 5) << 5.95, 5, 0;   // next to (6, 5)
    s.V.row(1 * n + 3) << 3, 0.05, 0;   // next to the boundary vertex (3, 0)
    const auto loops_before = boundary_loops(s);
    ASSERT_EQ(loops_before.size(), 1u);
    std::vector<Eigen::Vector3d> rim;
    for (int v : loops_before[0]) rim.push_back(s.V.row(v).transpose());
    EXPECT_EQ(collapse_short_interior_edges(s), 2);
    double area = 0, shortest_edge = 1e9;
    for (Eigen::Index g = 0; g < s.F.rows(); ++g) {
        const Eigen::Vector3d A = s.V.row(s.F(g, 0)), B = s.V.row(s.F(g, 1)), C = s.V.row(s.F(g, 2));
        const Eigen::Vector3d nrm = (B - A).cross(C - A);
        EXPECT_GT(nrm.z(), 0) << "face " << g << " flipped";
        area += 0.5 * nrm.norm();
        for (int k = 0; k < 3; ++k) shortest_edge = std::min(shortest_edge, (s.V.row(s.F(g, k)) - s.V.row(s.F(g, (k + 1) % 3))).norm());
    }
    EXPECT_NEAR(area, 100.0, 1e-9);  // flat: collapsing changes no area
    EXPECT_GT(shortest_edge, 0.25);
    EXPECT_EQ(s.V.rows(), n * n - 2);
    const auto loops = boundary_loops(s);  // the rim: same vertices, same places
    ASSERT_EQ(loops.size(), 1u);
    ASSERT_EQ(loops[0].size(), rim.size());
    for (const auto& x : rim) {
        double d = 1e9;
        for (int v : loops[0]) d = std::min(d, (s.V.row(v).transpose() - x).norm());
        EXPECT_EQ(d, 0.0);
    }
}
