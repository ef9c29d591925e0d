// SPDX-License-Identifier: MIT
// `aneuprep run CASE` and `aneuprep report CASE`: the command line of the case runner (pipeline::run_case,
// which plans and runs the stages in-process) — one line per stage on stdout, a failed stage's error named
// by the stage, exit codes by the top-level handler.
#include <filesystem>
#include <memory>

#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/core/text.hpp"
#include "aneu/pipeline/case_runner.hpp"
#include "aneu/pipeline/report.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace fs = std::filesystem;

namespace {

struct RunOptions {
    pipeline::CaseRunOptions run;
    bool verbose = false;
};

int run_case_cli(const RunOptions& ro) {
    const auto& o = ro.run;
    const bool single = !o.stage.empty();
    auto& log = logger();
    const auto level = log.level();
    std::string id;
    pipeline::CaseEvents ev;
    ev.begin = [&](const pipeline::CaseChain& c) {
        id = c.id;
        if (!single) fmt::print("aneuprep run {} ({}) -> {}\n", c.id, c.config, c.out_dir);
    };
    ev.current = [&](const pipeline::CaseStep& s) {
        if (single) {
            fmt::print("{} {}: up to date -> {}\n", id, s.stage, s.output);
        } else {
            fmt::print("  {:<9} {:<38} {}\n", s.stage, "up to date", s.output);
        }
    };
    ev.would_run = [&](const pipeline::CaseStep& s, const std::string& why) {
        fmt::print("  {:<9} {:<38} {}\n", s.stage, "would run (" + why + ")", s.output);
    };
    ev.start = [&](const pipeline::CaseStep& s, const std::string& why) {
        if (!single) {  // one line per stage: the outcome is appended when it ends
            fmt::print("  {:<9} {} ({}) ...", s.stage, "running", why);
            std::fflush(stdout);
        }
        if (!ro.verbose) log.set_level(spdlog::level::warn);
    };
    ev.removed_parts = [&](const pipeline::CaseStep& s, int n) {
        log.info("{}: removed {} unfinished output(s) of an interrupted run", s.stage, n);
    };
    ev.done = [&](const pipeline::CaseStep& s, double sec, const std::string& why) {
        log.set_level(level);
        if (single) {  // under make -j: one whole line when it ends
            fmt::print("{} {}: ran in {:.1f} s ({}) -> {}\n", id, s.stage, sec, why, s.output);
        } else {
            fmt::print(" {:.1f} s -> {}\n", sec, s.output);
        }
    };
    ev.failed = [&](const pipeline::CaseStep& s, double sec, const std::string& why) {
        log.set_level(level);
        if (single) {
            fmt::print("{} {}: FAILED in {:.1f} s ({}) -> {}\n", id, s.stage, sec, why, s.output);
        } else {
            fmt::print(" FAILED after {:.1f} s\n", sec);
        }
        std::fflush(stdout);
    };
    Reporter rep = make_log_reporter();
    const auto res = pipeline::run_case(o, ev, rep);
    if (res.error) {
        // The stage's own error line, named by the stage (as when the stage runs alone).
        const int rc = run_guarded("aneuprep " + res.failed_stage, [&] { std::rethrow_exception(res.error); });
        if (!single) fmt::print("stopped at {}: later stages not run; fix the input or parameter named above and rerun\n", res.failed_stage);
        return rc;
    }
    if (!single && !o.dry_run && o.make_rules.empty()) {
        const std::string& b = res.chain.bundle();
        const std::uintmax_t size = fs::exists(b) ? fs::file_size(b) : 0;
        fmt::print("done: {} ran, {} up to date, {:.1f} s; case bundle {} ({})\n", res.ran, res.current, res.seconds, b, human_bytes(size));
    }
    return 0;
}

}  // namespace

void add_run_command(CLI::App& app, std::function<int()>& action) {
    auto ro = std::make_shared<RunOptions>();
    auto* o = &ro->run;
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
    c->add_flag("--verbose", ro->verbose, "show the stages' own log lines");
    c->add_option("--make-rules", o->make_rules, "write this case's make rules (for Makefile.cases) and parameter stamps; run nothing");
    c->callback([ro, &action] {
        action = [ro] {
            int rc = 0;
            const int g = run_guarded("aneuprep run", [&] { rc = run_case_cli(*ro); });
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
                const pipeline::CaseChain chain = pipeline::make_case_chain(o->config, o->out_dir, o->source);
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
