// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Synthetic CT angiography of an intracranial aneurysm with analytic ground truth: a curved parent artery,
/// a branch, a saccular aneurysm with a neck narrower than its dome, optional bone, partial volume,
/// point-spread blur and Gaussian noise. Deterministic for a given seed.
#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "aneu/core/bundle.hpp"
#include "aneu/core/image_grid.hpp"
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

/// Parameters of `aneuprep phantom`. Lengths in mm, intensities in HU, angles in degrees.
struct PhantomParams {
    std::uint64_t seed = 1;                           ///< noise seed
    std::array<double, 3> spacing_mm{0.4, 0.4, 0.5};  ///< voxel size along the grid axes i, j, k
    std::array<double, 3> fov_mm{26.0, 20.0, 16.0};   ///< grid extent along i, j, k, centred on fov_centre
    std::array<double, 3> fov_centre_mm{0.0, 0.0, 2.0};
    std::array<double, 3> oblique_deg{0.0, 0.0, 0.0};  ///< grid rotation about x, then y, then z (LPS)
    double parent_radius_mm = 2.0;     ///< lumen radius of the parent artery (1.5–2.5)
    double parent_bend_radius_mm = 15.0;  ///< radius of curvature of the parent artery's centerline
    double branch_radius_mm = 1.5;     ///< lumen radius of the branch
    double dome_diameter_mm = 7.0;     ///< aneurysm sac diameter (4–10)
    double neck_diameter_mm = 4.0;     ///< neck diameter; must be smaller than the dome
    bool with_branch = true;
    bool with_sac = true;
    bool with_bone = false;            ///< bone-like ellipsoid beside the sac (segmentation distractor)
    double lumen_hu = 400.0;
    double tissue_hu = 40.0;
    double bone_hu = 1200.0;
    double bone_gap_mm = 1.5;          ///< gap between the sac and the bone (0 = touching)
    double psf_sigma_mm = 0.3;         ///< Gaussian point-spread function (FWHM = 2.355 sigma)
    double noise_sd_hu = 10.0;         ///< additive Gaussian noise
    int supersampling = 4;             ///< sub-samples per voxel edge for partial volume and the truth mask
};
void validate_phantom_geometry(const PhantomParams& p);

/// The options of `aneuprep phantom`, declared once.
inline const opt::Spec<PhantomParams>& phantom_spec() {
    using namespace opt;
    using P = PhantomParams;
    static const Spec<P> spec = [] {
        Spec<P> s("phantom");
        s.integer("seed", &P::seed, ge(0), "noise seed")
            .numbers<3>("spacing-mm", &P::spacing_mm, "mm", "voxel size i,j,k")
            .numbers<3>("fov-mm", &P::fov_mm, "mm", "grid extent i,j,k")
            .numbers<3>("fov-centre-mm", &P::fov_centre_mm, "mm", "grid centre x,y,z")
            .numbers<3>("oblique-deg", &P::oblique_deg, "deg", "grid rotation about x,y,z")
            .real("parent-radius-mm", &P::parent_radius_mm, "mm", closed(0.5, 5), "parent artery lumen radius")
            .real("bend-radius-mm", &P::parent_bend_radius_mm, "mm", any(), "parent artery bend radius")
            .named("parent_bend_radius_mm")
            .real("branch-radius-mm", &P::branch_radius_mm, "mm", any(), "branch lumen radius")
            .real("dome-diameter-mm", &P::dome_diameter_mm, "mm", closed(2, 20), "aneurysm dome diameter")
            .real("neck-diameter-mm", &P::neck_diameter_mm, "mm", any(), "aneurysm neck diameter (< dome)");
        auto inverted = [&s](const char* key, const char* name, bool P::*field, const char* help) {
            Option o;
            o.key = key;
            o.name = name;
            o.form = Form::FLAG;
            o.negatable = false;
            o.help = help;
            s.custom(
                o, [field, key](P& p, const std::vector<std::string>& v) {
                    p.*field = !(v.size() == 1 && parse_bool(v[0], std::string("--") + key));
                },
                [field](const P& p) { return std::string(p.*field ? "true" : "false"); });
        };
        inverted("no-branch", "with_branch", &P::with_branch, "omit the branch");
        inverted("no-sac", "with_sac", &P::with_sac, "omit the aneurysm");
        s.flag("bone", &P::with_bone, "add a bone-like structure beside the sac", false)
            .named("with_bone")
            .real("lumen-hu", &P::lumen_hu, "HU", closed(-1024, 3071), "contrast-filled lumen")
            .real("tissue-hu", &P::tissue_hu, "HU", closed(-1024, 3071), "soft tissue")
            .real("bone-hu", &P::bone_hu, "HU", closed(-1024, 3071), "bone")
            .real("bone-gap-mm", &P::bone_gap_mm, "mm", closed(0, 20), "gap between the sac and the bone (0 = touching)")
            .real("psf-sigma-mm", &P::psf_sigma_mm, "mm", closed(0, 5), "point-spread function sigma")
            .real("noise-sd-hu", &P::noise_sd_hu, "HU", closed(0, 1000), "Gaussian noise standard deviation")
            .integer("supersampling", &P::supersampling, closed(1, 16), "sub-samples per voxel edge (partial volume)")
            .rule(validate_phantom_geometry);
        return s;
    }();
    return spec;
}
/// The rules across parameters (grid size, radii, bend, neck < dome). @throws InputError
void validate_phantom_geometry(const PhantomParams& p);
/// @throws InputError naming the first invalid field and the valid range
inline void validate(const PhantomParams& p) { phantom_spec().validate(p); }

/// A vessel: a polyline centerline swept by a ball of constant radius (a capsule chain).
struct Vessel {
    std::string name;
    Eigen::MatrixX3d points;  ///< dense polyline [mm], physical frame
    double radius_mm = 0;
};
struct Sphere {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    double radius_mm = 0;
};
/// The ideal neck: the circle where the sac meets the parent artery's wall.
struct Neck {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< from the parent into the sac
    double radius_mm = 0;
};
struct Ellipsoid {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d radii = Eigen::Vector3d::Ones();
};

/// Analytic description of the phantom's anatomy in the physical frame.
struct PhantomGeometry {
    std::vector<Vessel> vessels;  ///< [0] parent, [1] branch if any
    std::optional<Sphere> sac;
    std::optional<Neck> neck;
    std::optional<Ellipsoid> bone;
    /// Analytic lumen volumes of the parts [mm³] (each part alone, uncut, without overlaps):
    /// ("parent", π r² L + 4/3 π r³), ("branch", ...), ("sac", 4/3 π R³).
    std::vector<std::pair<std::string, double>> part_volumes_mm3;
};

/// Label values of the truth mask.
enum TruthLabel : std::uint8_t { BACKGROUND = 0, ARTERY = 1, ANEURYSM = 2, BONE = 3 };

/// The geometry the parameters describe.
PhantomGeometry make_phantom_geometry(const PhantomParams& p);
/// The image grid of the parameters (centred on fov_centre_mm, rotated by oblique_deg).
ImageGrid make_phantom_grid(const PhantomParams& p);

/// Signed distance bound to the lumen (negative inside; 1-Lipschitz, exact for capsules and spheres).
double lumen_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x);

/// Partial-volume rasterisation of the geometry on a grid.
struct Rasterized {
    Volume<std::uint8_t> labels;       ///< TruthLabel per voxel (lumen fraction ≥ 0.5 → lumen)
    std::vector<float> lumen_fraction;  ///< [0,1] per voxel
    std::vector<float> bone_fraction;   ///< [0,1] per voxel
};
/// @param[in] supersampling  sub-samples per voxel edge, used only for voxels the surface can cross
Rasterized rasterize(const PhantomGeometry& g, const ImageGrid& grid, int supersampling);

/// CT intensities [HU] of a rasterised phantom: tissue + partial-volume lumen and bone, blurred by the
/// PSF, plus seeded noise (what write_phantom writes).
Volume<std::int16_t> synthesize_ct(const PhantomParams& p, const Rasterized& r);

/// Signed distance to the sac sphere and to the vessel capsules separately (negative inside).
double sac_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x);
double vessel_sdf(const PhantomGeometry& g, const Eigen::Vector3d& x);

/// Where the vessel centerlines leave the grid's box: one plane per end, outward normal along the
/// centerline tangent, ids in order of the vessels.
std::vector<EndPlane> true_end_planes(const PhantomGeometry& g, const ImageGrid& grid);
/// The centerlines clipped to the grid's box, with radius per point.
Centerline true_centerline(const PhantomGeometry& g, const ImageGrid& grid);

/// Output formats of the CT volume.
struct PhantomOutputs {
    bool nifti = true, nrrd = true, mha = true, dicom = true;
};

/// Generates the phantom into directory `out_dir` (created; replaced atomically if it exists):
/// ct.nii.gz, ct.nrrd, ct.mha, dicom/ (as selected), truth_labels.nrrd, truth.json and truth.h5
/// (a bundle whose /image holds the truth label mask, the true centerline and end planes).
/// @param[in] stage  provenance record of the run (parameters, command line); completed here
void write_phantom(const PhantomParams& p, const PhantomOutputs& outputs, const std::string& out_dir,
                   StageRecord stage, Reporter& rep = null_reporter());

}  // namespace aneu::pipeline
