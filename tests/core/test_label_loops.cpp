// SPDX-License-Identifier: MIT
// The neck line on a labelled surface: the sac's border, without the loops round labelling noise.
#include <algorithm>

#include <gtest/gtest.h>

#include "aneu/core/label_loops.hpp"

using namespace aneu;

namespace {
// A flat 16 × 16 grid of unit squares (two triangles each) in z = 0; face labels 0 (artery) and 1 (sac).
struct Grid {
    static constexpr int N = 16;
    Eigen::MatrixX3d V;
    Eigen::MatrixX3i F;
    Eigen::VectorXi label;
    Grid() {
        V.resize((N + 1) * (N + 1), 3);
        for (int j = 0; j <= N; ++j)
            for (int i = 0; i <= N; ++i) V.row(j * (N + 1) + i) << i, j, 0;
        F.resize(2 * N * N, 3);
        for (int j = 0; j < N; ++j)
            for (int i = 0; i < N; ++i) {
                const int a = j * (N + 1) + i, b = a + 1, c = a + N + 2, d = a + N + 1;
                F.row(2 * (j * N + i)) << a, b, c;
                F.row(2 * (j * N + i) + 1) << a, c, d;
            }
        label = Eigen::VectorXi::Zero(F.rows());
    }
    void set_square(int i0, int j0, int i1, int j1, int value) {  // the squares i0 ≤ i < i1, j0 ≤ j < j1
        for (int j = j0; j < j1; ++j)
            for (int i = i0; i < i1; ++i) label[2 * (j * N + i)] = label[2 * (j * N + i) + 1] = value;
    }
    double length(const std::vector<int>& loop) const {
        double l = 0;
        for (size_t k = 0; k < loop.size(); ++k) l += (V.row(loop[(k + 1) % loop.size()]) - V.row(loop[k])).norm();
        return l;
    }
};
}  // namespace

TEST(NeckLoops, IslandsAndHolesOfTheLabelAreNotNeckLine) {
    Grid g;
    g.set_square(4, 4, 10, 10, 1);   // the sac: 6 × 6, its border 24 long
    g.set_square(6, 6, 8, 8, 0);     // a hole in it (2 × 2: border 8)
    g.label[2 * (5 * Grid::N + 8)] = 0;  // one triangle of noise inside the sac (border 2 + √2)
    g.set_square(12, 12, 14, 13, 1); // a sac island out in the artery (2 × 1: border 6)
    const auto all = label_border_loops(g.F, g.label, 1);
    ASSERT_EQ(all.size(), 4u);
    const auto neck = neck_border_loops(g.F, g.V, g.label, 1);
    ASSERT_EQ(neck.size(), 1u);
    EXPECT_DOUBLE_EQ(g.length(neck[0]), 24.0);
    for (int v : neck[0]) {
        const double x = g.V(v, 0), y = g.V(v, 1);
        EXPECT_TRUE(x == 4 || x == 10 || y == 4 || y == 10) << x << " " << y;
    }
}

TEST(NeckLoops, TheParentReachesTheSurfacesEdgeAHoleDoesNot) {
    // The unlabelled side of the neck is the piece that reaches the surface's own boundary (the parent vessel runs
    // on past the working region), even where a hole in the sac is larger than it.
    Grid g;
    g.set_square(1, 1, 15, 15, 1);   // the sac: 14 × 14, its outer border 56 long; the parent: the 1-wide ring (60)
    g.set_square(3, 3, 13, 13, 0);   // a hole of 10 × 10 = 100 squares
    ASSERT_EQ(label_border_loops(g.F, g.label, 1).size(), 2u);
    const auto neck = neck_border_loops(g.F, g.V, g.label, 1);
    ASSERT_EQ(neck.size(), 1u);
    EXPECT_DOUBLE_EQ(g.length(neck[0]), 56.0);
}
