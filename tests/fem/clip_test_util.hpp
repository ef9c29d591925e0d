// SPDX-License-Identifier: MIT
#pragma once
// Helpers of the clip tests (test_clip.cpp, test_compliance.cpp): a block of known stiffness and the label spring.
#include <cmath>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "aneu/core/common.hpp"
#include "aneu/fem/clip.hpp"
#include "aneu/fem/hyperelastic.hpp"
#include "aneu/fem/structured_mesh.hpp"

namespace aneu::test {

/// Two block nodes at (A, ±H, 0), each tied to a fixed ground node at the same place by an isotropic spring of
/// stiffness K: a block of known stiffness between the blades of a clip hinged at the origin (axis x, opening
/// along y).
struct Block {
    static constexpr double A = 4.0, H = 0.5, K = 20.0;
    Eigen::MatrixX3d X{4, 3};
    Eigen::VectorXi fixed{6};
    std::unique_ptr<aneu::fem::LinearBody> body;
    Block() {
        X << A, H, 0, A, -H, 0, A, H, 0, A, -H, 0;
        for (int k = 0; k < 6; ++k) fixed[k] = k;
        std::vector<Eigen::Triplet<double>> t;
        for (int pair = 0; pair < 2; ++pair)
            for (int ax = 0; ax < 3; ++ax) {
                const int g = 3 * pair + ax, b = 3 * (pair + 2) + ax;
                t.emplace_back(g, g, K);
                t.emplace_back(b, b, K);
                t.emplace_back(g, b, -K);
                t.emplace_back(b, g, -K);
            }
        Eigen::SparseMatrix<double, Eigen::RowMajor> Km(12, 12);
        Km.setFromTriplets(t.begin(), t.end());
        body = std::make_unique<aneu::fem::LinearBody>(Km);
    }
};

inline aneu::fem::ClipSpring test_spring() {
    // 1.5 N at 1 mm opening a third of a 7 mm blade from its tip, 2.5 N there at 40°: the label convention.
    const double r = 7.0 * 2.0 / 3.0;
    return aneu::fem::ClipSpring::from_forces(r, aneu::fem::opening_angle(r, 1.0, 0.0), 1.5, 40 * DEG, 2.5);
}

/// A 2 × 1 × 1 mm neo-Hookean block (1 MPa, ν 0.45) between the blades of a clip hinged at the origin (axis x,
/// opening along y), 3 … 5 mm from the hinge, its far face (x = 5) held; `surface`: its faces the blades press (y = ±0.5).
struct HeldBlock {
    Eigen::MatrixX3d X;
    std::unique_ptr<aneu::fem::NeoHookeanSolid> solid;
    Eigen::VectorXi fixed;
    std::vector<int> surface;
    HeldBlock() {
        const aneu::fem::StructuredMesh m = aneu::fem::box_mesh(2.0, 1.0, 1.0, 8, 4, 4);
        X = m.V;
        X.col(0).array() += 3.0;
        X.col(1).array() -= 0.5;
        X.col(2).array() -= 0.5;
        solid = std::make_unique<aneu::fem::NeoHookeanSolid>(X, m.T, Eigen::VectorXi::Zero(m.T.rows()), std::vector<Material>{Material{"wall", 1.0, 0.45}});
        std::vector<int> fd;
        for (Eigen::Index i = 0; i < X.rows(); ++i) {
            if (X(i, 0) > 5.0 - 1e-9)
                for (int k = 0; k < 3; ++k) fd.push_back(static_cast<int>(3 * i + k));
            if (std::abs(std::abs(X(i, 1)) - 0.5) < 1e-9) surface.push_back(static_cast<int>(i));
        }
        fixed = Eigen::Map<Eigen::VectorXi>(fd.data(), static_cast<Eigen::Index>(fd.size()));
    }
};

}  // namespace aneu::test
