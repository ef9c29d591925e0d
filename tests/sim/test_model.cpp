// SPDX-License-Identifier: MIT
// The simulator loads exactly the columns of W its working region needs.
#include <gtest/gtest.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/sim/model.hpp"
#include "sim_fixtures.hpp"
#include "test_bundles.hpp"

using namespace aneu;

TEST(SimModel, LoadsAllColumnsOrOnlyTheRegion) {
    test::TempDir d("sim");
    const Bundle b = test::tube_case(Precision::FLOAT32, 16, 8).bundle;
    write_bundle(d.file("b.h5"), b);
    const Eigen::MatrixXf W = b.condensed->W32.to_dense();
    const Eigen::Index M = W.rows();
    const sim::SimModel all = sim::load_model(d.file("b.h5"));
    ASSERT_EQ(static_cast<Eigen::Index>(all.active.size()), M);
    ASSERT_EQ(all.n_active, M);
    EXPECT_EQ(all.nodes, b.volume->nodes);
    for (Eigen::Index q = 0; q < M; ++q)
        for (Eigen::Index p = 0; p < M; ++p) ASSERT_EQ(all.Wf(p, q), W(all.file_row[p], all.active[static_cast<size_t>(q)]));

    const sim::RegionSphere region{Eigen::Vector3d(1.9, 0, 4), 2.0};
    const sim::SimModel part = sim::load_model(d.file("b.h5"), region);
    ASSERT_FALSE(part.active.empty());
    ASSERT_LT(static_cast<Eigen::Index>(part.active.size()), M);
    for (size_t q = 0; q < part.active.size(); ++q) {
        const int r = part.active[q];
        EXPECT_LE((b.volume->nodes.row(b.condensed->dof_node[r]).transpose() - region.centre).norm(), 2.0);
        // Rows permuted: the region's rows first, in file order, so the top block is W(active, active).
        EXPECT_EQ(part.file_row[static_cast<Eigen::Index>(q)], r);
        for (Eigen::Index p = 0; p < M; ++p)
            ASSERT_EQ(part.Wf(p, static_cast<Eigen::Index>(q)), W(part.file_row[p], r));
    }
    // Surface vertices outside the region have rows past n_active.
    for (Eigen::Index v = 0; v < part.surface.size(); ++v) {
        const bool inside = (part.surface.X.row(v).transpose() - region.centre).norm() <= 2.0;
        EXPECT_EQ(part.surface.row(v, 0) < part.n_active, inside);
    }
}

TEST(SimModel, RefusesBundleWithoutCondensedOrEmptyRegion) {
    test::TempDir d("sim2");
    Bundle b = test::full_bundle(Precision::FLOAT64, 40);
    write_bundle(d.file("b.h5"), b);
    EXPECT_THROW(sim::load_model(d.file("b.h5"), sim::RegionSphere{{1e3, 0, 0}, 1.0}), InputError);
    b.condensed.reset();
    write_bundle(d.file("c.h5"), b);
    try {
        sim::load_model(d.file("c.h5"));
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no /condensed group"), std::string::npos) << e.what();
    }
}

TEST(SimModel, WallThicknessIsTheDistanceToTheInnerWall) {
    // Tube wall 1.5..1.9 mm: every outer vertex is 0.4 mm from the inner surface (its nodes lie on the circle at
    // the same angles). Without an inner node set the thickness is unknown (NaN), not guessed.
    test::TempDir d("thick");
    test::TubeCase c = test::tube_case(Precision::FLOAT64, 24, 12);
    write_bundle(d.file("t.h5"), c.bundle);
    const sim::SimModel m = sim::load_model(d.file("t.h5"));
    ASSERT_EQ(m.surface.thickness.size(), m.surface.size());
    EXPECT_NEAR(m.surface.thickness.minCoeff(), 0.4, 1e-9);
    EXPECT_NEAR(m.surface.thickness.maxCoeff(), 0.4, 1e-9);
    c.bundle.volume->node_sets.erase("inner");
    write_bundle(d.file("u.h5"), c.bundle);
    const sim::SimModel n = sim::load_model(d.file("u.h5"));
    EXPECT_TRUE(n.surface.thickness.array().isNaN().all());
}
