// SPDX-License-Identifier: MIT
// `aneuprep run CASE`: every stage of a case whose inputs or parameters changed since its output was made
// (the output's /meta provenance tells), one line per stage; and the make rules of Makefile.cases.
#include <cerrno>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/core/text.hpp"
#include "aneu/core/version.hpp"
#include "aneu/pipeline/report.hpp"
#include "case_chain.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace fs = std::filesystem;

namespace {

struct RunOptions {
    std::string config, out_dir, source, stage, from, make_rules;
    std::vector<std::string> sets;
    bool force = false, dry_run = false, verbose = false;
};

/// A stage (or its planning) ended with a non-zero exit code; the stage has already said why.
struct StageFailed {
    int rc;
};

/// Parses `argv` into a fresh aneuprep and runs its action (in plan mode when a plan sink is set).
int invoke(const std::vector<std::string>& argv) {
    CLI::App app{"aneuclip offline pipeline", "aneuprep"};
    LoggingOptions log;
    std::function<int()> action;
    build_aneuprep(app, log, argv, action);
    std::vector<const char*> c;
    for (const auto& a : argv) c.push_back(a.c_str());
    if (const int rc = parse_aneuprep(app, static_cast<int>(c.size()), c.data()); rc >= 0) return rc;
    return action ? action() : 0;
}

StagePlan plan_of(const CaseChain& chain, const CaseStep& step) {
    std::optional<StagePlan> got;
    set_plan_sink([&](const StagePlan& p) { got = p; });
    const int rc = invoke(stage_argv(chain, step));
    set_plan_sink({});
    if (rc != 0 || !got) {
        fmt::print(stderr, "aneuprep run: error: stage {} of case {}: its options ([{}] in {}, or --set {}.KEY=VALUE) "
                           "are invalid, see above\n",
                   step.stage, chain.id, step.stage, chain.config, step.stage);
        throw StageFailed{rc != 0 ? rc : EXIT_PROCESSING};
    }
    return *got;
}

std::string phantom_ct_name(const StagePlan& phantom) {
    std::string formats;
    for (const auto& [k, v] : phantom.parameters) {
        if (k == "formats") formats = v;
    }
    for (const auto& [fmt, file] : std::vector<std::pair<std::string, std::string>>{
             {"nrrd", "ct.nrrd"}, {"mha", "ct.mha"}, {"nii", "ct.nii.gz"}, {"dicom", "dicom"}}) {
        if (formats.find(fmt) != std::string::npos) return file;
    }
    throw InputError("[phantom] formats '" + formats + "': expected at least one of nrrd, mha, nii, dicom");
}

/// The chain with every stage planned (parameters validated); the phantom's CT name comes from its plan.
std::pair<CaseChain, std::vector<StagePlan>> plan_case(const RunOptions& o) {
    CaseChain chain = make_case_chain(o.config, o.out_dir, o.source, o.sets);
    std::vector<StagePlan> plans;
    for (auto& step : chain.steps) {
        plans.push_back(plan_of(chain, step));
        if (step.stage == "phantom") {
            for (auto& s : chain.steps) {
                if (s.stage == "segment") s.input = (fs::path(step.output) / phantom_ct_name(plans.back())).string();
            }
        }
    }
    return {chain, plans};
}

/// Why the stage must run ("" when its output is current): compares the plan with the output's provenance.
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

std::string params_text(const StagePlan& p) {
    std::string t = "stage " + p.stage + "\naneuclip " + tool_version() + "\n";
    for (const auto& [k, v] : p.parameters) t += k + " = " + v + "\n";
    for (const auto& in : p.inputs) t += "input " + in + "\n";
    return t;
}

/// Writes `text` to `path` through a temporary name; leaves the file (and its time) alone when it holds it.
void write_if_changed(const fs::path& path, const std::string& text) {
    if (fs::exists(path) && read_file(path.string()) == text) return;
    fs::create_directories(path.parent_path());
    const fs::path tmp = path.string() + ".part";
    {
        std::ofstream f(tmp, std::ios::binary);
        f << text;
        if (!f) throw IoError("cannot write '" + tmp.string() + "'");
    }
    fs::rename(tmp, path);
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
void write_make_rules(const RunOptions& o, const CaseChain& chain, const std::vector<StagePlan>& plans) {
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
        if (i > 0) {
            deps = chain.steps[i - 1].provenance_file + " " + deps;
        } else if (!s.input.empty()) {
            deps = make_word(s.input, "source") + " " + deps;
        }
        r += make_word(s.provenance_file, "output") + ": " + deps + "\n";
        r += "\t@$(PREP) run " + run_args + " --stage " + s.stage + " --quiet || { echo '" + chain.id + " " + s.stage +
             "' >> $(FAILED); exit 1; }\n";
    }
    r += "BUNDLES += " + chain.bundle() + "\n";
    write_if_changed(o.make_rules, r);
}

/// Removes "<output>.part-<pid>" leftovers of writers that no longer run (a killed batch): every stage writes
/// there and renames, so these are never results, only litter. Returns how many were removed.
int remove_stale_parts(const std::string& output) {
    const fs::path out(output);
    const fs::path dir = out.parent_path().empty() ? fs::path(".") : out.parent_path();
    const std::string prefix = out.filename().string() + ".part-";
    int removed = 0;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(prefix, 0) != 0) continue;
        const std::string pid_text = name.substr(prefix.size());
        if (pid_text.empty() || pid_text.find_first_not_of("0123456789") != std::string::npos) continue;
        const long pid = std::stol(pid_text);
        if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) {
            fs::remove_all(e.path(), ec);
            if (!ec) ++removed;
        }
    }
    return removed;
}

void touch(const std::string& path) { fs::last_write_time(path, fs::file_time_type::clock::now()); }

int run_case(const RunOptions& o) {
    const auto& names = all_case_stages();
    for (const auto* opt : {&o.stage, &o.from}) {
        if (!opt->empty() && std::find(names.begin(), names.end(), *opt) == names.end()) {
            throw InputError((opt == &o.stage ? "--stage '" : "--from '") + *opt +
                             "': expected phantom, segment, surface, wall, tetmesh, assemble or condense");
        }
    }
    auto [chain, plans] = plan_case(o);
    if (!o.make_rules.empty()) {
        write_make_rules(o, chain, plans);
        return 0;
    }
    const bool single = !o.stage.empty();
    if (single && !chain.find(o.stage)) throw InputError("--stage '" + o.stage + "': not a stage of case " + chain.id + " (its source is " + chain.source + ")");
    if (!o.from.empty() && !chain.find(o.from)) throw InputError("--from '" + o.from + "': not a stage of case " + chain.id);

    if (!o.dry_run) fs::create_directories(chain.out_dir);
    auto& log = logger();
    const auto level = log.level();
    if (!single) fmt::print("aneuprep run {} ({}) -> {}\n", chain.id, chain.config, chain.out_dir);
    const auto t0 = std::chrono::steady_clock::now();
    int ran = 0, current = 0;
    bool forced = o.force;
    std::string upstream;  // dry run: the first stage that would run (every later one follows it)
    for (size_t i = 0; i < chain.steps.size(); ++i) {
        const auto& step = chain.steps[i];
        if (step.stage == o.from) forced = true;
        if (single && step.stage != o.stage) continue;
        std::string why = forced ? std::string("forced")
                          : !upstream.empty() ? "after " + upstream
                                              : why_stale(plans[i], step);
        if (why.empty()) {
            ++current;
            if (single) {
                touch(step.provenance_file);  // make asked: the output is current, say so by its time
                fmt::print("{} {}: up to date -> {}\n", chain.id, step.stage, step.output);
            } else {
                fmt::print("  {:<9} {:<38} {}\n", step.stage, "up to date", step.output);
            }
            continue;
        }
        if (o.dry_run) {
            fmt::print("  {:<9} {:<38} {}\n", step.stage, "would run (" + why + ")", step.output);
            if (upstream.empty()) upstream = step.stage;
            continue;
        }
        if (!single) {  // one line per stage: the outcome is appended when it ends
            fmt::print("  {:<9} {} ({}) ...", step.stage, "running", why);
            std::fflush(stdout);
        }
        if (const int n = remove_stale_parts(step.output); n > 0) {
            log.info("{}: removed {} unfinished output(s) of an interrupted run", step.stage, n);
        }
        if (!o.verbose) log.set_level(spdlog::level::warn);
        const auto ts = std::chrono::steady_clock::now();
        const int rc = invoke(stage_argv(chain, step));
        log.set_level(level);
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
        if (single) {  // under make -j: one whole line when it ends
            fmt::print("{} {}: {} in {:.1f} s ({}) -> {}\n", chain.id, step.stage, rc == 0 ? "ran" : "FAILED", s, why,
                       step.output);
            if (rc != 0) return rc;
            ++ran;
            continue;
        }
        if (rc != 0) {
            fmt::print(" FAILED after {:.1f} s (exit code {})\n", s, rc);
            if (!single) fmt::print("stopped at {}: later stages not run; fix the input or parameter named above and rerun\n", step.stage);
            return rc;
        }
        ++ran;
        fmt::print(" {:.1f} s -> {}\n", s, step.output);
    }
    if (!single && !o.dry_run) {
        const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::uintmax_t size = fs::exists(chain.bundle()) ? fs::file_size(chain.bundle()) : 0;
        fmt::print("done: {} ran, {} up to date, {:.1f} s; case bundle {} ({})\n", ran, current, total, chain.bundle(),
                   human_bytes(size));
    }
    return 0;
}

}  // namespace

void add_run_command(CLI::App& app, std::function<int()>& action) {
    auto o = std::make_shared<RunOptions>();
    auto* c = app.add_subcommand("run", "run every stage of a case whose inputs or parameters changed (provenance in /meta)");
    c->add_option("case", o->config, "case config, configs/cases/<id>.toml")->required();
    c->add_option("--out-dir", o->out_dir, "output folder [default: [run] out-dir of the config, or out/cases/<id>]");
    c->add_option("--source", o->source,
                  "input: 'phantom', a CT (NIfTI, NRRD, MHA, DICOM directory) or a lumen surface (STL, VTP, OBJ, PLY) "
                  "[default: [run] source, or phantom when the config has a [phantom] section]");
    c->add_option("--set", o->sets, "override a stage option: STAGE.KEY=VALUE, e.g. wall.blend-mm=1.5 (repeatable)");
    c->add_option("--stage", o->stage, "run this stage only (if it is not current); used by Makefile.cases");
    c->add_option("--from", o->from, "rerun this stage and every later one even if current");
    c->add_flag("--force", o->force, "rerun every stage");
    c->add_flag("-n,--dry-run", o->dry_run, "say which stages would run and why; run nothing");
    c->add_flag("--verbose", o->verbose, "show the stages' own log lines");
    c->add_option("--make-rules", o->make_rules, "write this case's make rules (for Makefile.cases) and parameter stamps; run nothing");
    c->callback([o, &action] {
        action = [o] {
            int rc = 0;
            const int g = run_guarded("aneuprep run", [&] {
                try {
                    rc = run_case(*o);
                } catch (const StageFailed& f) {
                    rc = f.rc;
                }
            });
            return g != 0 ? g : rc;
        };
    });
}

void add_report_command(CLI::App& app, std::function<int()>& action) {
    struct Opts {
        std::string config, out_dir, source, html;
    };
    auto o = std::make_shared<Opts>();
    auto* c = app.add_subcommand("report", "QA report of a case: one self-contained HTML page (needs X: xvfb-run -a)");
    c->add_option("case", o->config, "case config, configs/cases/<id>.toml")->required();
    c->add_option("--out-dir", o->out_dir, "the case's output folder [default: as aneuprep run]");
    c->add_option("--source", o->source, "as aneuprep run --source");
    c->add_option("-o,--output", o->html, "HTML file [default: <out-dir>/report.html]");
    c->callback([o, &action] {
        action = [o] {
            return run_guarded("aneuprep report", [&] {
                const CaseChain chain = make_case_chain(o->config, o->out_dir, o->source, {});
                pipeline::ReportInput in;
                in.case_id = chain.id;
                in.config_path = chain.config;
                in.config_text = read_file(chain.config);
                for (const auto& s : chain.steps) in.stages.push_back({s.stage, s.output, s.provenance_file});
                const std::string html = o->html.empty() ? (fs::path(chain.out_dir) / "report.html").string() : o->html;
                Reporter rep = make_log_reporter();
                pipeline::write_case_report(in, html, rep);
                fmt::print("{}\n", html);
            });
        };
    });
}

}  // namespace aneu::tools
