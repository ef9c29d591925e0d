// SPDX-License-Identifier: MIT
#include <fstream>
#include <regex>

#include <gtest/gtest.h>

#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/core/version.hpp"
#include "test_bundles.hpp"

using namespace aneu;

TEST(Provenance, Sha256KnownVectors) {
    // FIPS 180-2 examples.
    EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Provenance, FileAndDirectoryHashes) {
    test::TempDir d("sha");
    std::ofstream(d.file("a.txt")) << "abc";
    EXPECT_EQ(sha256_path(d.file("a.txt")), sha256_hex("abc"));
    std::filesystem::create_directory(d.file("dir"));
    std::ofstream(d.file("dir/2.dcm")) << "two";
    std::ofstream(d.file("dir/1.dcm")) << "one";
    const std::string expected =
        sha256_hex("1.dcm " + sha256_hex("one") + "\n" + "2.dcm " + sha256_hex("two") + "\n");
    EXPECT_EQ(sha256_path(d.file("dir")), expected);
    std::ofstream(d.file("dir/1.dcm")) << "changed";
    EXPECT_NE(sha256_path(d.file("dir")), expected);
    EXPECT_THROW(sha256_path(d.file("missing")), InputError);
}

TEST(Provenance, ShellJoinQuotesWhatNeedsIt) {
    EXPECT_EQ(shell_join({"aneuprep", "phantom", "-o", "out dir", "--x=1,2", "it's"}),
              "aneuprep phantom -o 'out dir' --x=1,2 'it'\\''s'");
    EXPECT_EQ(shell_join({"a", ""}), "a ''");
}

TEST(Provenance, StageRecordHasVersionTimeAndInputHashes) {
    test::TempDir d("rec");
    std::ofstream(d.file("in.nii")) << "abc";
    const StageRecord r = make_stage_record("segment", "aneuprep segment in.nii", {{"k", "v"}}, {d.file("in.nii")});
    EXPECT_EQ(r.stage, "segment");
    EXPECT_EQ(r.tool_version, tool_version());
    EXPECT_EQ(r.git_revision, git_revision());
    EXPECT_TRUE(std::regex_match(r.created_utc, std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)"))) << r.created_utc;
    ASSERT_EQ(r.inputs.size(), 1u);
    EXPECT_EQ(r.inputs[0].sha256, sha256_hex("abc"));
}
