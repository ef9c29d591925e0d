// SPDX-License-Identifier: MIT
// The stage specs (issue #16): every option of every stage appears in its provenance and in aneuprep's
// --help, keys and names are unique, and a case config, --set and the spec's default agree.
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/case_runner.hpp"
#include "aneu/pipeline/stage_registry.hpp"
#include "commands.hpp"

using namespace aneu;
namespace fs = std::filesystem;

namespace {
/// `flag` appears in the help as a whole option name (not as the start of a longer one).
bool names_option(const std::string& help, const std::string& flag) {
    for (size_t at = help.find(flag); at != std::string::npos; at = help.find(flag, at + 1)) {
        const size_t end = at + flag.size();
        if (end == help.size() || !(std::isalnum(static_cast<unsigned char>(help[end])) || help[end] == '-')) return true;
    }
    return false;
}
}  // namespace

TEST(StageSpecs, EveryOptionIsInProvenanceAndHelp) {
    CLI::App app{"aneuprep", "aneuprep"};
    std::function<int()> action;
    tools::add_stage_commands(app, {"aneuprep"}, action);
    int checked = 0;
    for (const auto& info : pipeline::stage_infos()) {
        SCOPED_TRACE(info.name);
        const auto job = pipeline::make_stage_job(info.name);
        const auto params = job->parameters();
        std::map<std::string, std::string> by_name(params.begin(), params.end());
        EXPECT_EQ(by_name.size(), params.size()) << "a provenance name is used twice";
        std::set<std::string> keys;
        const std::string help = app.get_subcommand(info.name)->help();
        size_t in_provenance = 0;
        for (const auto& o : job->options()) {
            EXPECT_TRUE(keys.insert(o.key).second) << "--" << o.key << " declared twice";
            EXPECT_TRUE(names_option(help, "--" + o.key)) << "--" << o.key << " missing from --help";
            EXPECT_FALSE(o.help.empty()) << "--" << o.key << " has no help text";
            if (!o.provenance) continue;
            ++in_provenance;
            ASSERT_EQ(by_name.count(o.name), 1u) << "--" << o.key << " (" << o.name << ") missing from provenance";
            EXPECT_EQ(by_name[o.name], o.default_text) << o.name;
            ++checked;
        }
        EXPECT_EQ(in_provenance, params.size()) << "a provenance parameter without an option";
    }
    EXPECT_GT(checked, 60);  // 8 stages
}

namespace {

struct TempDir {
    fs::path p = fs::temp_directory_path() / ("aneu_opts_" + std::to_string(::getpid()));
    TempDir() { fs::create_directories(p); }
    ~TempDir() { fs::remove_all(p); }
};

std::map<std::string, std::string> plan_params(pipeline::CaseChain chain, const std::string& stage) {
    const auto plans = pipeline::plan_case(chain);
    for (const auto& p : plans) {
        if (p.stage == stage) return {p.parameters.begin(), p.parameters.end()};
    }
    ADD_FAILURE() << "no stage " << stage;
    return {};
}

}  // namespace

TEST(StageSpecs, ConfigAndSetAgreeAndUnknownKeysFail) {
    TempDir d;
    const std::string surf = (d.p / "lumen.stl").string();
    std::ofstream(surf) << "solid x\nendsolid x\n";
    const std::string cfg = (d.p / "c.toml").string();
    std::ofstream(cfg) << "[run]\nsource = \"" << surf << "\"\n[wall]\nblend-mm = 1.5\nremesher = \"netgen\"\n"
                       << "[condense]\nregion-sphere = [1, 2, 3, 4]\nprecision = \"float64\"\n[segment]\nseed = [\"1,2,3\", \"4,5,6\"]\nfill-holes = false\n";
    const auto from_config = pipeline::make_case_chain(cfg);
    const auto wall = plan_params(from_config, "wall");
    EXPECT_EQ(wall.at("blend_mm"), "1.5");
    EXPECT_EQ(wall.at("remesher"), "netgen");
    EXPECT_EQ(wall.at("artery_thickness_mm"), "0.4");  // the default, recorded
    const auto cond = plan_params(from_config, "condense");
    EXPECT_EQ(cond.at("region_sphere_mm"), "1,2,3,4");
    EXPECT_EQ(cond.at("precision"), "float64");

    // The same through --set on a config without those sections.
    const std::string bare = (d.p / "bare.toml").string();
    std::ofstream(bare) << "[run]\nsource = \"" << surf << "\"\n";
    const auto from_set = pipeline::make_case_chain(bare, "", "", {"wall.blend-mm=1.5", "wall.remesher=netgen", "condense.region-sphere=1,2,3,4",
                                                                  "condense.precision=float64"});
    EXPECT_EQ(plan_params(from_set, "wall"), wall);
    EXPECT_EQ(plan_params(from_set, "condense"), cond);

    // A [segment] section of a surface case is still checked: its seeds and flag parse.
    auto job = pipeline::make_stage_job("segment");
    job->set("seed", {"1,2,3", "4,5,6"});
    job->set("fill-holes", {"false"});
    std::map<std::string, std::string> seg;
    for (const auto& [k, v] : job->parameters()) seg[k] = v;
    EXPECT_EQ(seg.at("seeds_mm"), "1,2,3;4,5,6");
    EXPECT_EQ(seg.at("fill_holes"), "false");

    // Errors name the stage, the case and the key; an unknown key is an UnknownOptionError (exit 109).
    const auto bad = pipeline::make_case_chain(bare, "", "", {"wall.blend=1"});
    try {
        auto c = bad;
        (void)pipeline::plan_case(c);
        ADD_FAILURE() << "an unknown key was accepted";
    } catch (const UnknownOptionError& e) {
        EXPECT_NE(std::string(e.what()).find("stage wall of case bare: its options"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("no option --blend"), std::string::npos) << e.what();
    }
    const auto out_of_range = pipeline::make_case_chain(bare, "", "", {"wall.blend-mm=-1"});
    try {
        auto c = out_of_range;
        (void)pipeline::plan_case(c);
        ADD_FAILURE() << "a negative blend was accepted";
    } catch (const UnknownOptionError&) {
        ADD_FAILURE() << "a bad value is not an unknown key";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("wall: --blend-mm must be > 0 mm (got -1)"), std::string::npos) << e.what();
    }
    const auto not_number = pipeline::make_case_chain(bare, "", "", {"surface.edge-mm=fine"});
    try {
        auto c = not_number;
        (void)pipeline::plan_case(c);
        ADD_FAILURE() << "a word for a number was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("--edge-mm 'fine': expected a number"), std::string::npos) << e.what();
    }
    const std::string typo = (d.p / "typo.toml").string();
    std::ofstream(typo) << "[run]\nsource = \"" << surf << "\"\n[wal]\nblend-mm = 1\n";
    EXPECT_THROW((void)pipeline::make_case_chain(typo), InputError);
}
