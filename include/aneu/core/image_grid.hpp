// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A regular 3-D grid in the scanner's physical (LPS) frame, and a volume of voxels on it.
/// Standard types only, so that ITK translation units (which cannot include system Eigen) can use it.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace aneu {

/// Geometry of a voxel grid as ITK reports it. Physical point of index (i,j,k):
/// p = origin + D · diag(spacing) · (i,j,k), with D = direction (row-major 3×3, column c = axis c).
struct ImageGrid {
    std::array<std::int64_t, 3> size{0, 0, 0};       ///< voxels along i, j, k
    std::array<double, 3> origin{0, 0, 0};           ///< physical position of voxel (0,0,0) centre [mm]
    std::array<double, 3> spacing{1, 1, 1};          ///< voxel size along i, j, k [mm]
    std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major; columns are axes

    std::size_t voxel_count() const {
        return static_cast<std::size_t>(size[0]) * static_cast<std::size_t>(size[1]) *
               static_cast<std::size_t>(size[2]);
    }
    /// Linear index of (i,j,k), i fastest.
    std::size_t linear(std::int64_t i, std::int64_t j, std::int64_t k) const {
        return static_cast<std::size_t>(i + size[0] * (j + size[1] * k));
    }
    /// Physical point of a (possibly fractional) continuous index.
    std::array<double, 3> point(double i, double j, double k) const {
        const double a = i * spacing[0], b = j * spacing[1], c = k * spacing[2];
        return {origin[0] + direction[0] * a + direction[1] * b + direction[2] * c,
                origin[1] + direction[3] * a + direction[4] * b + direction[5] * c,
                origin[2] + direction[6] * a + direction[7] * b + direction[8] * c};
    }
    /// Continuous index of a physical point (inverse of point(); D is orthonormal).
    std::array<double, 3> continuous_index(const std::array<double, 3>& p) const {
        const double d0 = p[0] - origin[0], d1 = p[1] - origin[1], d2 = p[2] - origin[2];
        return {(direction[0] * d0 + direction[3] * d1 + direction[6] * d2) / spacing[0],
                (direction[1] * d0 + direction[4] * d1 + direction[7] * d2) / spacing[1],
                (direction[2] * d0 + direction[5] * d1 + direction[8] * d2) / spacing[2]};
    }
    double voxel_volume() const { return spacing[0] * spacing[1] * spacing[2]; }
};

/// Voxels on a grid, i fastest (the memory order of ITK, VTK and NRRD).
template <class T>
struct Volume {
    ImageGrid grid;
    std::vector<T> data;
};

}  // namespace aneu
