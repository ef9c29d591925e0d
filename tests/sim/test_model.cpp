// SPDX-License-Identifier: MIT
// The simulator loads exactly the columns of W its working region needs.
#include <gtest/gtest.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/sim/model.hpp"
#include "test_bundles.hpp"

using namespace aneu;

TEST(SimModel, LoadsAllColumnsOrOnlyTheRegion) {
    test::TempDir d("sim");
    Bundle b = test::full_bundle(Precision::FLOAT32, 150, 32);
    write_bundle(d.file("b.h5"), b);
    const Eigen::MatrixXf W = b.condensed->W32.to_dense();
    const sim::SimModel all = sim::load_model(d.file("b.h5"));
    ASSERT_EQ(all.active.size(), 150u);
    EXPECT_EQ(all.Wf, W);
    EXPECT_EQ(all.nodes, b.volume->nodes);

    const sim::RegionSphere region{b.volume->nodes.row(5).transpose(), 6.0};
    const sim::SimModel part = sim::load_model(d.file("b.h5"), region);
    ASSERT_FALSE(part.active.empty());
    ASSERT_LT(part.active.size(), 150u);
    for (size_t q = 0; q < part.active.size(); ++q) {
        const int r = part.active[q];
        EXPECT_LE((b.volume->nodes.row(b.condensed->dof_node[r]).transpose() - region.centre).norm(), 6.0);
        EXPECT_EQ(part.Wf.col(static_cast<Eigen::Index>(q)), W.col(r));
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
