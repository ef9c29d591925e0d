// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// ITK image filters used by `segment` and `surface`, behind standard types (ITK stays in
/// image_filters_itk.cpp). All are spacing- and direction-aware as ITK is.
#include <array>
#include <cstdint>
#include <vector>

#include "aneu/core/image_grid.hpp"

namespace aneu::pipeline {

using Index3 = std::array<std::int64_t, 3>;

/// Edge-preserving smoothing: ITK's gradient anisotropic diffusion (Perona–Malik). `conductance` is in
/// the image's intensity units (HU): gradients much larger than it are kept as edges.
/// The time step is the stable one for the grid (min spacing / 2^(3+1)).
Volume<float> anisotropic_diffusion(const Volume<float>& v, int iterations, double conductance_hu);

/// Voxels with lower <= value <= upper connected (26-neighbourhood, ITK "full connectivity") to any seed.
Volume<std::uint8_t> connected_threshold(const Volume<float>& v, float lower, float upper, const std::vector<Index3>& seeds);

/// Connected components of the non-zero voxels (26-neighbourhood, or 6 with `full_connectivity` false),
/// relabelled 1..n by decreasing size.
struct Components {
    Volume<std::int32_t> labels;
    std::vector<std::int64_t> sizes;  ///< voxels of component 1..n at [0..n-1]
};
Components connected_components(const Volume<std::uint8_t>& m, bool full_connectivity = true);

/// Fills cavities of a binary mask (background regions not connected to the image border).
Volume<std::uint8_t> fill_holes(const Volume<std::uint8_t>& m);

/// Exact Euclidean distance [mm] from every foreground voxel centre to the nearest background voxel centre
/// (separable squared-distance transform of Felzenszwalb & Huttenlocher, spacing-aware; distance_map.cpp);
/// 0 on background voxels. Voxels beyond the grid do not count as background. ITK's signed Maurer map
/// measures to the object's own contour voxels instead, which is not the radius this needs.
Volume<float> inside_distance_mm(const Volume<std::uint8_t>& m);

/// Bright-tube measure per voxel (Frangi's vesselness through ITK's HessianToObjectnessMeasure, object
/// dimension 1, α = β = 0.5, γ = 50 HU), the maximum over `steps` scales from `sigma_min_mm` to
/// `sigma_max_mm` (logarithmic, scale-normalised Hessians). High along vessels; low on bone plates, blobs
/// and flat tissue.
Volume<float> vesselness(const Volume<float>& v, double sigma_min_mm, double sigma_max_mm, int steps);

/// Otsu's threshold of the values of `v` where `roi` is non-zero (all voxels if `roi` is empty).
double otsu_threshold(const Volume<float>& v, const std::vector<std::uint8_t>& roi);

}  // namespace aneu::pipeline
