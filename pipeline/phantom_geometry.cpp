// SPDX-License-Identifier: MIT
// Analytic anatomy of the CT phantom, its rasterisation with partial volume, and its true end planes.
// Pure Eigen + OpenMP: no ITK here (ITK 5.2 bundles an incompatible Eigen).
#include <algorithm>
#include <cmath>
#include <charconv>

#include <Eigen/Geometry>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/phantom.hpp"

namespace aneu::pipeline {

namespace {

constexpr double DEG = PI / 180.0;
/// Centerline sampling step [mm]: the chord error of a 15 mm bend is step²/(8·R) ≈ 5e-4 mm.
constexpr double POLYLINE_STEP_MM = 0.25;
/// Tilt of the parent artery's plane about x, so that no vessel lies along a grid axis.
constexpr double PARENT_PLANE_TILT_DEG = 20.0;
/// Half-angle of the parent's circular arc, and its straight extensions beyond the arc.
constexpr double PARENT_ARC_HALF_ANGLE_DEG = 75.0;
constexpr double PARENT_EXTENSION_MM = 20.0;
/// Where the branch leaves the parent (arc angle) and its length.
constexpr double BRANCH_ANGLE_DEG = -35.0;
constexpr double BRANCH_LENGTH_MM = 25.0;

Eigen::Matrix3d rotation_xyz(const std::array<double, 3>& deg) {
    const Eigen::Matrix3d rx = Eigen::AngleAxisd(deg[0] * DEG, Eigen::Vector3d::UnitX()).toRotationMatrix();
    const Eigen::Matrix3d ry = Eigen::AngleAxisd(deg[1] * DEG, Eigen::Vector3d::UnitY()).toRotationMatrix();
    const Eigen::Matrix3d rz = Eigen::AngleAxisd(deg[2] * DEG, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return rz * ry * rx;
}

double sphere_volume(double r) { return 4.0 / 3.0 * PI * r * r * r; }

/// Distance from x to a polyline.
double polyline_distance(const Eigen::MatrixX3d& P, const Eigen::Vector3d& x) {
    double best2 = std::numeric_limits<double>::infinity();
    for (Eigen::Index i = 0; i + 1 < P.rows(); ++i) {
        const Eigen::Vector3d a = P.row(i).transpose(), ab = P.row(i + 1).transpose() - a;
        const double t = std::clamp((x - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        best2 = std::min(best2, (a + t * ab - x).squaredNorm());
    }
    if (P.rows() == 1) best2 = (P.row(0).transpose() - x).squaredNorm();
    return std::sqrt(best2);
}

double box_distance(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& x) {
    return (x.cwiseMax(lo).cwiseMin(hi) - x).norm();
}

}  // namespace

double vessel_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& v : g.vessels) {
        const Eigen::Vector3d lo = v.points.colwise().minCoeff().transpose();
        const Eigen::Vector3d hi = v.points.colwise().maxCoeff().transpose();
        if (box_distance(lo, hi, x) - v.radius_mm >= best) continue;
        best = std::min(best, polyline_distance(v.points, x) - v.radius_mm);
    }
    return best;
}

double sac_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x) {
    return g.sac ? (x - g.sac->centre).norm() - g.sac->radius_mm : std::numeric_limits<double>::infinity();
}

namespace {

/// (|(x−c)/r| − 1)·min(r): 1-Lipschitz, so a lower bound of the distance to the ellipsoid's surface.
double bone_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x) {
    if (!g.bone) return std::numeric_limits<double>::infinity();
    const Eigen::Vector3d y = (x - g.bone->centre).cwiseQuotient(g.bone->radii);
    return (y.norm() - 1.0) * g.bone->radii.minCoeff();
}

Eigen::Vector3d vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

bool in_box(const ImageGrid& grid, const Eigen::Vector3d& x) {
    const auto ci = grid.continuous_index({x[0], x[1], x[2]});
    for (int d = 0; d < 3; ++d) {
        if (ci[d] < -0.5 || ci[d] > static_cast<double>(grid.size[d]) - 0.5) return false;
    }
    return true;
}

/// The point where segment a→b (a and b on different sides) crosses the box boundary, by bisection.
Eigen::Vector3d box_crossing(const ImageGrid& grid, Eigen::Vector3d a, Eigen::Vector3d b) {
    const bool a_in = in_box(grid, a);
    for (int it = 0; it < 60; ++it) {
        const Eigen::Vector3d m = 0.5 * (a + b);
        (in_box(grid, m) == a_in ? a : b) = m;
    }
    return 0.5 * (a + b);
}


}  // namespace

void validate_phantom_geometry(const PhantomParams& p) {
    auto fail = [](const std::string& m) { throw InputError("phantom: " + m); };
    for (int d = 0; d < 3; ++d) {
        if (!(p.spacing_mm[d] > 0.01 && p.spacing_mm[d] <= 5.0)) {
            fail("spacing_mm[" + std::to_string(d) + "] = " + shortest(p.spacing_mm[d]) + ": must be in (0.01, 5]");
        }
        if (!(p.fov_mm[d] >= p.spacing_mm[d] && p.fov_mm[d] <= 500.0)) {
            fail("fov_mm[" + std::to_string(d) + "] = " + shortest(p.fov_mm[d]) + ": must be in [spacing, 500]");
        }
        if (!std::isfinite(p.oblique_deg[d]) || !std::isfinite(p.fov_centre_mm[d])) {
            fail("oblique_deg and fov_centre_mm must be finite");
        }
    }
    const double voxels = (p.fov_mm[0] / p.spacing_mm[0]) * (p.fov_mm[1] / p.spacing_mm[1]) *
                          (p.fov_mm[2] / p.spacing_mm[2]);
    if (voxels > 512.0 * 512 * 512) fail("fov_mm / spacing_mm gives " + shortest(voxels) + " voxels: at most 512^3");
    if (!(p.branch_radius_mm >= 0.3 && p.branch_radius_mm <= p.parent_radius_mm)) {
        fail("branch_radius_mm = " + shortest(p.branch_radius_mm) + ": must be in [0.3, parent_radius_mm]");
    }
    if (!(p.parent_bend_radius_mm >= 2.0 * p.parent_radius_mm)) {
        fail("parent_bend_radius_mm = " + shortest(p.parent_bend_radius_mm) + ": must be >= 2 * parent_radius_mm");
    }
    if (!(p.neck_diameter_mm > 0.0 && p.neck_diameter_mm < p.dome_diameter_mm)) {
        fail("neck_diameter_mm = " + shortest(p.neck_diameter_mm) + ": must be in (0, dome_diameter_mm = " +
             shortest(p.dome_diameter_mm) + ")");
    }
}


PhantomGeometry make_phantom_geometry(const PhantomParams& p) {
    validate(p);
    PhantomGeometry g;
    const double Rc = p.parent_bend_radius_mm, rp = p.parent_radius_mm;
    const double tilt = PARENT_PLANE_TILT_DEG * DEG;
    const Eigen::Vector3d e1 = Eigen::Vector3d::UnitX();
    const Eigen::Vector3d e2(0.0, std::cos(tilt), std::sin(tilt));
    const Eigen::Vector3d e3 = e1.cross(e2);
    const Eigen::Vector3d C = -Rc * e2;  // the top of the arc (θ = 0) is the origin
    auto arc = [&](double th) -> Eigen::Vector3d { return C + Rc * (std::sin(th) * e1 + std::cos(th) * e2); };
    auto tangent = [&](double th) -> Eigen::Vector3d { return std::cos(th) * e1 - std::sin(th) * e2; };

    // Parent: straight extension, circular arc over ±75°, straight extension.
    const double th_max = PARENT_ARC_HALF_ANGLE_DEG * DEG;
    const int n_arc = static_cast<int>(std::ceil(2.0 * th_max * Rc / POLYLINE_STEP_MM));
    const int n_ext = static_cast<int>(std::ceil(PARENT_EXTENSION_MM / POLYLINE_STEP_MM));
    std::vector<Eigen::Vector3d> pts;
    for (int i = n_ext; i >= 1; --i) pts.push_back(arc(-th_max) - tangent(-th_max) * (PARENT_EXTENSION_MM * i / n_ext));
    for (int i = 0; i <= n_arc; ++i) pts.push_back(arc(-th_max + 2.0 * th_max * i / n_arc));
    for (int i = 1; i <= n_ext; ++i) pts.push_back(arc(th_max) + tangent(th_max) * (PARENT_EXTENSION_MM * i / n_ext));
    Vessel parent{"parent", Eigen::MatrixX3d(static_cast<Eigen::Index>(pts.size()), 3), rp};
    for (size_t i = 0; i < pts.size(); ++i) parent.points.row(static_cast<Eigen::Index>(i)) = pts[i].transpose();
    g.vessels.push_back(parent);
    g.part_volumes_mm3.emplace_back("parent", PI * rp * rp * (2.0 * th_max * Rc + 2.0 * PARENT_EXTENSION_MM) +
                                                  sphere_volume(rp));

    if (p.with_branch) {
        const double thb = BRANCH_ANGLE_DEG * DEG;
        const Eigen::Vector3d radial = (arc(thb) - C).normalized();
        const Eigen::Vector3d dir = (-0.25 * e1 + 0.2 * radial + e3).normalized();
        const int n = static_cast<int>(std::ceil(BRANCH_LENGTH_MM / POLYLINE_STEP_MM));
        Vessel b{"branch", Eigen::MatrixX3d(n + 1, 3), p.branch_radius_mm};
        for (int i = 0; i <= n; ++i) b.points.row(i) = (arc(thb) + dir * (BRANCH_LENGTH_MM * i / n)).transpose();
        g.vessels.push_back(b);
        const double rb = p.branch_radius_mm;
        g.part_volumes_mm3.emplace_back("branch", PI * rb * rb * BRANCH_LENGTH_MM + sphere_volume(rb));
    }
    const double Rs = 0.5 * p.dome_diameter_mm, rn = 0.5 * p.neck_diameter_mm;
    const Eigen::Vector3d sac_centre = (rp + std::sqrt(Rs * Rs - rn * rn)) * e2;
    if (p.with_sac) {
        g.sac = Sphere{sac_centre, Rs};
        g.neck = Neck{rp * e2, e2, rn};
        g.part_volumes_mm3.emplace_back("sac", sphere_volume(Rs));
    }
    if (p.with_bone) {
        Ellipsoid e;
        e.radii = Eigen::Vector3d(2.5, 2.0, 3.5);
        const Eigen::Vector3d u = Eigen::Vector3d(-6.8, 1.0, -1.5).normalized();
        const double extent = 1.0 / u.cwiseQuotient(e.radii).norm();  // ellipsoid's reach along u
        e.centre = sac_centre + (Rs + p.bone_gap_mm + extent) * u;
        g.bone = e;
    }
    return g;
}

ImageGrid make_phantom_grid(const PhantomParams& p) {
    validate(p);
    ImageGrid grid;
    const Eigen::Matrix3d D = rotation_xyz(p.oblique_deg);
    Eigen::Vector3d half;
    for (int d = 0; d < 3; ++d) {
        grid.size[d] = std::max<std::int64_t>(1, std::llround(p.fov_mm[d] / p.spacing_mm[d]));
        grid.spacing[d] = p.spacing_mm[d];
        half[d] = 0.5 * static_cast<double>(grid.size[d] - 1) * p.spacing_mm[d];
    }
    const Eigen::Vector3d origin = vec(p.fov_centre_mm) - D * half;
    for (int r = 0; r < 3; ++r) {
        grid.origin[r] = origin[r];
        for (int c = 0; c < 3; ++c) grid.direction[3 * r + c] = D(r, c);
    }
    return grid;
}

double lumen_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x) {
    return std::min(vessel_sdf(g, x), sac_sdf(g, x));
}

Rasterized rasterize(const PhantomGeometry& g, const ImageGrid& grid, int supersampling) {
    if (supersampling < 1) throw InputError("rasterize: supersampling = " + std::to_string(supersampling) + ": must be >= 1");
    Rasterized r;
    r.labels.grid = grid;
    const size_t n = grid.voxel_count();
    r.labels.data.assign(n, BACKGROUND);
    r.lumen_fraction.assign(n, 0.f);
    r.bone_fraction.assign(n, 0.f);
    const double half_diag =
        0.5 * std::sqrt(grid.spacing[0] * grid.spacing[0] + grid.spacing[1] * grid.spacing[1] +
                        grid.spacing[2] * grid.spacing[2]);
    const int S = supersampling;
    const double inv = 1.0 / (S * S * S);
    auto pt = [&](double i, double j, double k) {
        const auto a = grid.point(i, j, k);
        return Eigen::Vector3d(a[0], a[1], a[2]);
    };
    // A voxel whose centre is farther than half its diagonal from the surface is entirely in or out
    // (the sdf is 1-Lipschitz); only the others are sub-sampled.
    auto fraction = [&](auto&& sdf, double centre_value, std::int64_t i, std::int64_t j, std::int64_t k) {
        if (centre_value <= -half_diag) return 1.0;
        if (centre_value >= half_diag) return 0.0;
        int inside = 0;
        for (int a = 0; a < S; ++a)
            for (int b = 0; b < S; ++b)
                for (int c = 0; c < S; ++c) {
                    const double di = (a + 0.5) / S - 0.5, dj = (b + 0.5) / S - 0.5, dk = (c + 0.5) / S - 0.5;
                    inside += sdf(pt(i + di, j + dj, k + dk)) < 0.0;
                }
        return inside * inv;
    };
    auto lumen = [&](const Eigen::Vector3d& x) { return lumen_sdf(g, x); };
    auto bone = [&](const Eigen::Vector3d& x) { return bone_sdf(g, x); };
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t k = 0; k < grid.size[2]; ++k) {
        for (std::int64_t j = 0; j < grid.size[1]; ++j) {
            for (std::int64_t i = 0; i < grid.size[0]; ++i) {
                const Eigen::Vector3d x = pt(double(i), double(j), double(k));
                const size_t idx = grid.linear(i, j, k);
                const double fv = vessel_sdf(g, x), fs = sac_sdf(g, x);
                const double lf = fraction(lumen, std::min(fv, fs), i, j, k);
                const double bf = g.bone ? fraction(bone, bone_sdf(g, x), i, j, k) : 0.0;
                r.lumen_fraction[idx] = static_cast<float>(lf);
                r.bone_fraction[idx] = static_cast<float>(std::min(bf, 1.0 - lf));
                if (lf >= 0.5) {
                    // The sac's lumen is the part of the sphere outside every vessel.
                    r.labels.data[idx] = (fv > 0.0 && fs < fv) ? ANEURYSM : ARTERY;
                } else if (bf >= 0.5) {
                    r.labels.data[idx] = BONE;
                }
            }
        }
    }
    return r;
}

std::vector<EndPlane> true_end_planes(const PhantomGeometry& g, const ImageGrid& grid) {
    std::vector<EndPlane> planes;
    for (const auto& v : g.vessels) {
        for (Eigen::Index i = 0; i + 1 < v.points.rows(); ++i) {
            const Eigen::Vector3d a = v.points.row(i).transpose(), b = v.points.row(i + 1).transpose();
            const bool ia = in_box(grid, a), ib = in_box(grid, b);
            if (ia == ib) continue;
            const Eigen::Vector3d t = (b - a).normalized();
            EndPlane e;
            e.id = static_cast<int>(planes.size());
            e.point = box_crossing(grid, a, b);
            e.normal = ia ? t : Eigen::Vector3d(-t);  // leaving: along travel; entering: against it
            e.radius_mm = v.radius_mm;
            planes.push_back(e);
        }
    }
    return planes;
}

Centerline true_centerline(const PhantomGeometry& g, const ImageGrid& grid) {
    std::vector<Eigen::Vector3d> pts;
    std::vector<double> rad;
    std::vector<int> offsets{0};
    for (const auto& v : g.vessels) {
        bool open = false;
        for (Eigen::Index i = 0; i < v.points.rows(); ++i) {
            const Eigen::Vector3d x = v.points.row(i).transpose();
            const bool in = in_box(grid, x);
            if (in && !open && i > 0) {  // entering: start with the crossing point
                pts.push_back(box_crossing(grid, v.points.row(i - 1).transpose(), x));
                rad.push_back(v.radius_mm);
            }
            if (in) {
                pts.push_back(x);
                rad.push_back(v.radius_mm);
                open = true;
            } else if (open) {  // leaving: end with the crossing point
                pts.push_back(box_crossing(grid, v.points.row(i - 1).transpose(), x));
                rad.push_back(v.radius_mm);
                offsets.push_back(static_cast<int>(pts.size()));
                open = false;
            }
        }
        if (open) offsets.push_back(static_cast<int>(pts.size()));
    }
    Centerline c;
    c.points.resize(static_cast<Eigen::Index>(pts.size()), 3);
    c.radius.resize(static_cast<Eigen::Index>(pts.size()));
    for (size_t i = 0; i < pts.size(); ++i) {
        c.points.row(static_cast<Eigen::Index>(i)) = pts[i].transpose();
        c.radius[static_cast<Eigen::Index>(i)] = rad[i];
    }
    c.offsets = Eigen::Map<Eigen::VectorXi>(offsets.data(), static_cast<Eigen::Index>(offsets.size()));
    return c;
}

}  // namespace aneu::pipeline
