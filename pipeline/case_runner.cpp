// SPDX-License-Identifier: MIT
// The case runner: a case config planned stage by stage from the stage specs (no command line rebuilt and
// re-parsed), each stage's output checked against its provenance, stale stages run in-process; and the
// make rules of Makefile.cases.
#include "aneu/pipeline/case_runner.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <filesystem>

#include <CLI/CLI.hpp>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/version.hpp"

namespace aneu::pipeline {

namespace fs = std::filesystem;

const std::vector<std::string>& all_case_stages() {
    static const std::vector<std::string> s{"phantom", "segment", "surface", "wall", "tetmesh", "assemble", "condense", "flow"};
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

std::string joined(const std::vector<std::string>& v, const char* sep = ", ") {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : sep) + x;
    return s;
}

}  // namespace

CaseChain make_case_chain(const std::string& config, const std::string& out_dir, const std::string& source,
                          const std::vector<std::string>& sets) {
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
    bool has_phantom = false, has_flow = false;
    const auto& stages = all_case_stages();
    for (const auto& it : items) {
        if (it.name == "++" || it.name == "--") {  // CLI11's section markers: an empty [flow] asks for the stage too
            if (!it.parents.empty() && it.parents[0] == "flow") has_flow = true;
            continue;
        }
        if (it.parents.empty()) throw InputError("case config '" + config + "': " + it.name + ": a key outside any [section]");
        const std::string& section = it.parents[0];
        if (section == "run") {
            const std::string v = it.inputs.empty() ? std::string() : it.inputs.front();
            if (it.name == "out-dir") {
                cfg_out = v;
            } else if (it.name == "source") {
                cfg_source = v;
            } else {
                throw InputError("case config '" + config + "': [run] " + it.name + ": unknown key (expected source, out-dir)");
            }
            continue;
        }
        if (std::find(stages.begin(), stages.end(), section) == stages.end()) {
            throw InputError("case config '" + config + "': [" + section + "]: not a stage (expected run, " + joined(stages) + ")");
        }
        if (section == "phantom") has_phantom = true;
        if (section == "flow") has_flow = true;
        c.options[section].emplace_back(it.name, it.inputs);
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
        c.steps.push_back({"segment", "", file("segment.h5"), file("segment.h5")});  // input: the phantom's CT (plan_case)
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
    // The blood flow, only where the config asks for it ([flow]): the pre-clip lumen needs the surface only (a
    // session's frame, [flow] series, the case bundle: below).
    if (has_flow) c.steps.push_back({"flow", file("surface.h5"), file("flow.h5"), file("flow.h5")});

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
        const std::string key = s.substr(dot + 1, eq - dot - 1), value = s.substr(eq + 1);
        c.options[stage].emplace_back(key, std::vector<std::string>{value});
        c.sets[stage].emplace_back(key, value);
    }
    // The flow of a simulator session (series = SCENE_series.h5, a path like [run] source): the case bundle's mesh
    // carries the series' deformation to the lumen, so the stage follows condense instead of the surface.
    for (CaseStep& st : c.steps) {
        if (st.stage != "flow") continue;
        for (const auto& [k, v] : c.options["flow"])
            if (k == "series") st.input = v.empty() || v.front().empty() ? file("surface.h5") : file("case.h5");
    }
    return c;
}

namespace {

/// The stage's options applied from the chain (config section, then --set) and validated.
StagePlan plan_step(const CaseChain& chain, const CaseStep& step) {
    StagePlan plan;
    plan.stage = step.stage;
    plan.job = make_stage_job(step.stage);
    auto wrap = [&](const std::string& why) {
        return "stage " + step.stage + " of case " + chain.id + ": its options ([" + step.stage + "] in " + chain.config + ", or --set " +
               step.stage + ".KEY=VALUE): " + why;
    };
    try {
        if (auto it = chain.options.find(step.stage); it != chain.options.end()) {
            for (const auto& [key, values] : it->second) plan.job->set(key, values);
        }
        plan.job->validate();
    } catch (const UnknownOptionError& e) {
        throw UnknownOptionError(wrap(e.what()));
    } catch (const InputError& e) {
        throw InputError(wrap(e.what()));
    }
    plan.parameters = plan.job->parameters();
    if (!step.input.empty()) plan.inputs.push_back(step.input);
    if (step.stage == "flow" && !step.input.empty())  // a session's series is an input too: a new session reruns the flow
        if (auto it = chain.options.find("flow"); it != chain.options.end())
            for (const auto& [k, v] : it->second)
                if (k == "series" && !v.empty() && !v.back().empty()) plan.inputs.push_back(v.back());
    plan.output = step.output;
    std::vector<std::string> argv{"aneuprep", "--config", chain.config, step.stage};
    if (!step.input.empty()) argv.push_back(step.input);
    argv.push_back("-o");
    argv.push_back(step.output);
    if (auto it = chain.sets.find(step.stage); it != chain.sets.end()) {
        for (const auto& [k, v] : it->second) {
            argv.push_back("--" + k);
            argv.push_back(v);
        }
    }
    plan.command = shell_join(argv);
    return plan;
}

}  // namespace

std::vector<StagePlan> plan_case(CaseChain& chain) {
    // Every stage section is checked, also one this case's source skips (a [segment] in a surface case).
    for (const auto& [stage, opts] : chain.options) {
        if (chain.find(stage)) continue;
        CaseStep ghost{stage, "", "", ""};
        plan_step(chain, ghost);
    }
    std::vector<StagePlan> plans;
    for (auto& step : chain.steps) {
        if (step.stage == "segment" && chain.source == "phantom") {
            step.input = (fs::path(chain.find("phantom")->output) / phantom_ct_name(plans.front().parameters)).string();
        }
        plans.push_back(plan_step(chain, step));
    }
    return plans;
}

std::string why_stale(const StagePlan& plan, const CaseStep& step) {
    if (!fs::exists(step.provenance_file)) return "no output yet";
    Meta meta;
    try {
        meta = read_meta(step.provenance_file);
    } catch (const std::exception&) {
        return "output unreadable";
    }
    const StageRecord* rec = nullptr;
    for (const auto& r : meta.stages) {
        if (r.stage == plan.stage) rec = &r;
    }
    if (!rec) return "output has no provenance of this stage";
    if (rec->tool_version != tool_version()) return "made by aneuclip " + rec->tool_version;
    std::map<std::string, std::string> before(rec->parameters.begin(), rec->parameters.end());
    std::string changed;
    for (const auto& [k, v] : plan.parameters) {
        auto it = before.find(k);
        if (it == before.end() || it->second != v) {
            changed += (changed.empty() ? "" : ", ") + k + " " + (it == before.end() ? "(new)" : it->second) + " -> " + v;
        }
        if (it != before.end()) before.erase(it);
    }
    for (const auto& [k, v] : before) changed += (changed.empty() ? "" : ", ") + k + " (dropped)";
    if (!changed.empty()) return "parameters changed: " + changed;
    if (rec->inputs.size() != plan.inputs.size()) return "inputs changed";
    for (size_t i = 0; i < plan.inputs.size(); ++i) {
        if (!fs::exists(plan.inputs[i])) return "input " + plan.inputs[i] + " missing";
        if (sha256_path(plan.inputs[i]) != rec->inputs[i].sha256) return "input changed: " + plan.inputs[i];
    }
    return "";
}

namespace {

std::string params_text(const StagePlan& p) {
    std::string t = "stage " + p.stage + "\naneuclip " + tool_version() + "\n";
    for (const auto& [k, v] : p.parameters) t += k + " = " + v + "\n";
    for (const auto& in : p.inputs) t += "input " + in + "\n";
    return t;
}

/// Writes `text` to `path` atomically; leaves the file (and its time) alone when it already holds it.
void write_if_changed(const fs::path& path, const std::string& text) {
    if (fs::exists(path) && read_file(path.string()) == text) return;
    fs::create_directories(path.parent_path());
    write_text_atomically(path.string(), text);
}

/// A make-safe word (no spaces, no '$', ':' or '#').
std::string make_word(const std::string& s, const std::string& what) {
    if (s.find_first_of(" \t$:#%\n") != std::string::npos) {
        throw InputError(what + " '" + s + "': a path with spaces, '$', ':', '#' or '%' cannot be a make target");
    }
    return s;
}

/// The rules of one case for Makefile.cases, and a parameter stamp per stage (rewritten only when the
/// stage's parameters change, so make reruns exactly the stages whose parameters changed and what follows).
void write_make_rules(const CaseRunOptions& o, const CaseChain& chain, const std::vector<StagePlan>& plans) {
    const fs::path stamps = fs::path(chain.out_dir) / ".params";
    std::string r = "# Rules of case " + chain.id + ", generated by `aneuprep run " + chain.config +
                    " --make-rules` from the config; regenerated when it or aneuprep changes. Do not edit.\n";
    std::string run_args = make_word(chain.config, "case config") + " --out-dir " + make_word(chain.out_dir, "--out-dir");
    if (!o.source.empty()) run_args += " --source " + make_word(o.source, "--source");
    for (const auto& s : o.sets) run_args += " --set " + make_word(s, "--set");
    for (size_t i = 0; i < chain.steps.size(); ++i) {
        const auto& s = chain.steps[i];
        const fs::path stamp = stamps / (s.stage + ".txt");
        write_if_changed(stamp, params_text(plans[i]));
        std::string deps = make_word(stamp.string(), "stamp") + " $(PREP)";
        if (s.stage == "flow" && plans[i].inputs.size() > 1) {  // a session's flow: the case bundle and the series
            const std::string series = make_word(plans[i].inputs[1], "[flow] series");
            deps = make_word(s.input, "input") + " " + series + " " + deps;
            r += series + ":\n\t@echo '" + chain.id + ": no " + plans[i].inputs[1] +
                 ": run the scene first (aneusim run SCENE; its outputs.series)' >&2; exit 1\n";
        } else if (s.stage == "flow") {  // the lumen only: a changed wall or condensation does not rerun it
            deps = make_word(s.input, "input") + " " + deps;
        } else if (i > 0) {
            deps = chain.steps[i - 1].provenance_file + " " + deps;
        } else if (!s.input.empty()) {
            deps = make_word(s.input, "source") + " " + deps;
        }
        r += make_word(s.provenance_file, "output") + ": " + deps + "\n";
        r += "\t@$(PREP) run " + run_args + " --stage " + s.stage + " --quiet || { echo '" + chain.id + " " + s.stage +
             "' >> $(FAILED); exit 1; }\n";
    }
    r += "BUNDLES += " + chain.bundle() + "\n";
    if (const CaseStep* f = chain.find("flow")) r += "BUNDLES += " + f->provenance_file + "\n";
    write_if_changed(o.make_rules, r);
}

}  // namespace

int remove_stale_parts(const std::string& output) {
    const fs::path out(output);
    const fs::path dir = out.parent_path().empty() ? fs::path(".") : out.parent_path();
    const std::string prefix = out.filename().string() + ".part-";
    int removed = 0;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(prefix, 0) != 0) continue;
        std::string pid_text = name.substr(prefix.size());  // "<pid>" or "<pid><ext>" (AtomicPath)
        const std::string ext = out.extension().string();
        if (!ext.empty() && pid_text.size() > ext.size() && pid_text.compare(pid_text.size() - ext.size(), ext.size(), ext) == 0) {
            pid_text.resize(pid_text.size() - ext.size());
        }
        if (pid_text.empty() || pid_text.find_first_not_of("0123456789") != std::string::npos) continue;
        const long pid = std::stol(pid_text);
        if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) {
            fs::remove_all(e.path(), ec);
            if (!ec) ++removed;
        }
    }
    return removed;
}

CaseRunResult run_case(const CaseRunOptions& o, const CaseEvents& ev, Reporter& stage_reporter) {
    const auto& names = all_case_stages();
    for (const auto* opt : {&o.stage, &o.from}) {
        if (!opt->empty() && std::find(names.begin(), names.end(), *opt) == names.end()) {
            throw InputError((opt == &o.stage ? "--stage '" : "--from '") + *opt +
                             "': expected phantom, segment, surface, wall, tetmesh, assemble, condense or flow");
        }
    }
    CaseRunResult res;
    res.chain = make_case_chain(o.config, o.out_dir, o.source, o.sets);
    auto& chain = res.chain;
    const auto plans = plan_case(chain);
    if (!o.make_rules.empty()) {
        write_make_rules(o, chain, plans);
        return res;
    }
    const bool single = !o.stage.empty();
    if (single && !chain.find(o.stage)) throw InputError("--stage '" + o.stage + "': not a stage of case " + chain.id + " (its source is " + chain.source + ")");
    if (!o.from.empty() && !chain.find(o.from)) throw InputError("--from '" + o.from + "': not a stage of case " + chain.id);

    if (!o.dry_run) fs::create_directories(chain.out_dir);
    if (ev.begin) ev.begin(chain);
    const Stopwatch total;
    bool forced = o.force;
    std::string upstream;  // dry run: the first stage that would run (every later one follows it)
    for (size_t i = 0; i < chain.steps.size(); ++i) {
        const auto& step = chain.steps[i];
        if (step.stage == o.from) forced = true;
        if (single && step.stage != o.stage) continue;
        const std::string why = forced ? std::string("forced") : !upstream.empty() ? "after " + upstream : why_stale(plans[i], step);
        if (why.empty()) {
            ++res.current;
            if (single) fs::last_write_time(step.provenance_file, fs::file_time_type::clock::now());  // make asked: say so by its time
            if (ev.current) ev.current(step);
            continue;
        }
        if (o.dry_run) {
            if (ev.would_run) ev.would_run(step, why);
            if (upstream.empty()) upstream = step.stage;
            continue;
        }
        if (ev.start) ev.start(step, why);
        if (const int n = remove_stale_parts(step.output); n > 0 && ev.removed_parts) ev.removed_parts(step, n);
        const Stopwatch ts;
        try {
            const auto& p = plans[i];
            p.job->run(step.input, step.output, make_stage_record(step.stage, p.command, p.parameters, p.inputs), stage_reporter);
        } catch (const std::exception&) {
            res.failed_stage = step.stage;
            res.error = std::current_exception();
            if (ev.failed) ev.failed(step, ts.seconds(), why);
            res.seconds = total.seconds();
            return res;
        }
        ++res.ran;
        if (ev.done) ev.done(step, ts.seconds(), why);
    }
    res.seconds = total.seconds();
    return res;
}

}  // namespace aneu::pipeline
