// SPDX-License-Identifier: MIT
#include "case_chain.hpp"

#include <algorithm>
#include <filesystem>

#include <CLI/CLI.hpp>

#include "aneu/core/error.hpp"

namespace aneu::tools {

namespace fs = std::filesystem;

const std::vector<std::string>& all_case_stages() {
    static const std::vector<std::string> s{"phantom", "segment", "surface", "wall", "tetmesh", "assemble", "condense"};
    return s;
}

const CaseStep* CaseChain::find(const std::string& stage) const {
    for (const auto& s : steps) {
        if (s.stage == stage) return &s;
    }
    return nullptr;
}

namespace {

std::string lower_ext(const std::string& path) {
    std::string e = fs::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return e;
}

}  // namespace

CaseChain make_case_chain(const std::string& config, const std::string& out_dir, const std::string& source,
                          const std::vector<std::string>& sets, const std::string& phantom_ct_name) {
    if (!fs::is_regular_file(config)) throw InputError("case config '" + config + "': no such file (expected configs/cases/<id>.toml)");
    CaseChain c;
    c.config = config;
    c.id = fs::path(config).stem().string();
    std::vector<CLI::ConfigItem> items;
    try {
        items = CLI::ConfigTOML().from_file(config);
    } catch (const std::exception& e) {
        throw InputError("case config '" + config + "': " + e.what());
    }
    std::string cfg_out, cfg_source;
    bool has_phantom = false;
    for (const auto& it : items) {
        if (!it.parents.empty() && it.parents[0] == "phantom") has_phantom = true;
        if (it.parents.size() != 1 || it.parents[0] != "run") continue;
        const std::string v = it.inputs.empty() ? std::string() : it.inputs.front();
        if (it.name == "out-dir") {
            cfg_out = v;
        } else if (it.name == "source") {
            cfg_source = v;
        } else if (it.name != "++" && it.name != "--") {  // CLI11's section markers
            throw InputError("case config '" + config + "': [run] " + it.name + ": unknown key (expected source, out-dir)");
        }
    }
    c.out_dir = !out_dir.empty() ? out_dir : !cfg_out.empty() ? cfg_out : "out/cases/" + c.id;
    c.source = !source.empty() ? source : !cfg_source.empty() ? cfg_source : has_phantom ? "phantom" : "";
    if (c.source.empty()) {
        throw InputError("case config '" + config + "': no input: set [run] source = a CT (NIfTI, NRRD, MHA, DICOM "
                         "directory) or a lumen surface (STL, VTP, OBJ, PLY), or give a [phantom] section");
    }
    const fs::path d(c.out_dir);
    auto file = [&](const char* name) { return (d / name).string(); };
    std::string lumen_surface;
    if (c.source == "phantom") {
        c.steps.push_back({"phantom", "", file("phantom"), file("phantom/truth.h5")});
        c.steps.push_back({"segment", (d / "phantom" / phantom_ct_name).string(), file("segment.h5"), file("segment.h5")});
    } else {
        if (!fs::exists(c.source)) throw InputError("case config '" + config + "': [run] source '" + c.source + "': no such file or directory");
        const std::string e = lower_ext(c.source);
        if (e == ".stl" || e == ".vtp" || e == ".vtk" || e == ".obj" || e == ".ply") {
            lumen_surface = c.source;
        } else {
            c.steps.push_back({"segment", c.source, file("segment.h5"), file("segment.h5")});
        }
    }
    const std::string surf_in = lumen_surface.empty() ? file("segment.h5") : lumen_surface;
    c.steps.push_back({"surface", surf_in, file("surface.h5"), file("surface.h5")});
    c.steps.push_back({"wall", file("surface.h5"), file("wall.h5"), file("wall.h5")});
    c.steps.push_back({"tetmesh", file("wall.h5"), file("volume.h5"), file("volume.h5")});
    c.steps.push_back({"assemble", file("volume.h5"), file("fem.h5"), file("fem.h5")});
    c.steps.push_back({"condense", file("fem.h5"), file("case.h5"), file("case.h5")});

    for (const auto& s : sets) {
        const size_t dot = s.find('.');
        const size_t eq = s.find('=');
        if (dot == std::string::npos || eq == std::string::npos || dot > eq || dot == 0 || eq == dot + 1) {
            throw InputError("--set '" + s + "': expected STAGE.KEY=VALUE, e.g. wall.aneurysm-thickness-mm=0.15");
        }
        const std::string stage = s.substr(0, dot);
        if (!c.find(stage)) {
            std::string names;
            for (const auto& st : c.steps) names += (names.empty() ? "" : ", ") + st.stage;
            throw InputError("--set '" + s + "': stage '" + stage + "' is not a stage of this case (" + names + ")");
        }
        auto& o = c.overrides[stage];
        o.push_back("--" + s.substr(dot + 1, eq - dot - 1));
        o.push_back(s.substr(eq + 1));
    }
    return c;
}

std::vector<std::string> stage_argv(const CaseChain& chain, const CaseStep& step) {
    std::vector<std::string> a{"aneuprep", "--config", chain.config, step.stage};
    if (!step.input.empty()) a.push_back(step.input);
    a.push_back("-o");
    a.push_back(step.output);
    if (auto it = chain.overrides.find(step.stage); it != chain.overrides.end()) {
        a.insert(a.end(), it->second.begin(), it->second.end());
    }
    return a;
}

}  // namespace aneu::tools
