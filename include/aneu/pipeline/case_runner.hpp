// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A case config (configs/cases/<id>.toml) as a chain of stages with their files, planned from the stage
/// specs and run in-process: what `aneuprep run` does, what `Makefile.cases` builds (one stage per target)
/// and what `aneuprep report` shows. Library code: it prints nothing; the caller sees each step through
/// CaseEvents and gets a stage's failure back in CaseRunResult.
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/reporter.hpp"
#include "aneu/pipeline/stage_registry.hpp"

namespace aneu::pipeline {

/// One stage of a case: its name, input file (empty for the phantom) and output.
struct CaseStep {
    std::string stage;
    std::string input;
    std::string output;           ///< what the stage writes (the phantom: a directory)
    std::string provenance_file;  ///< the file whose /meta records the stage (the phantom: DIR/truth.h5)
};

/// A case: its config, id, output folder and stages in order.
struct CaseChain {
    std::string config;   ///< path of the TOML file
    std::string id;       ///< its file name without extension
    std::string out_dir;  ///< [run] out-dir, default out/cases/<id>
    std::string source;   ///< [run] source: "phantom", a CT (file or DICOM directory) or a lumen surface
    std::vector<CaseStep> steps;
    /// Options per stage from the config's sections, then from --set STAGE.KEY=VALUE (later ones win).
    std::map<std::string, std::vector<std::pair<std::string, std::vector<std::string>>>> options;
    /// The --set overrides alone, as KEY=VALUE per stage (for the command line recorded in provenance).
    std::map<std::string, std::vector<std::pair<std::string, std::string>>> sets;

    const CaseStep* find(const std::string& stage) const;
    /// The case bundle (the condense stage's output; a [flow] stage may follow it).
    const std::string& bundle() const { return find("condense") ? find("condense")->output : steps.back().output; }
};

/// The stages a case can have, in pipeline order.
const std::vector<std::string>& all_case_stages();

/// Reads `config` ([run] keys source, out-dir; one section per stage, keys = the stage's options) and
/// builds the chain. `out_dir`/`source` non-empty override the config; `sets` are STAGE.KEY=VALUE.
/// @throws InputError naming the file, section or key
CaseChain make_case_chain(const std::string& config, const std::string& out_dir = "", const std::string& source = "",
                          const std::vector<std::string>& sets = {});

/// A stage of a case with its options applied and validated.
struct StagePlan {
    std::string stage;
    std::vector<std::pair<std::string, std::string>> parameters;  ///< as its provenance records them
    std::vector<std::string> inputs;
    std::string output;
    std::string command;  ///< the equivalent aneuprep command line (recorded in provenance)
    std::shared_ptr<StageJob> job;
};
/// Every stage of the chain planned (the phantom's CT name, which segment reads, from its formats).
/// @throws InputError (UnknownOptionError for an unknown key) "stage S of case C: its options ...: <why>"
std::vector<StagePlan> plan_case(CaseChain& chain);

/// Why the stage must run ("" when its output is current): its output's provenance against the plan
/// (tool version, every parameter, the inputs' SHA-256).
std::string why_stale(const StagePlan& plan, const CaseStep& step);

struct CaseRunOptions {
    std::string config, out_dir, source;
    std::vector<std::string> sets;
    std::string stage;       ///< run only this stage (Makefile.cases)
    std::string from;        ///< rerun from this stage on
    bool force = false;      ///< rerun every stage
    bool dry_run = false;    ///< say what would run; run nothing
    std::string make_rules;  ///< write this case's make rules and parameter stamps; run nothing
};

/// What happens, as it happens (every member optional).
struct CaseEvents {
    std::function<void(const CaseChain&)> begin;                                     ///< before the first stage
    std::function<void(const CaseStep&)> current;                                    ///< output up to date
    std::function<void(const CaseStep&, const std::string& why)> would_run;          ///< dry run
    std::function<void(const CaseStep&, const std::string& why)> start;              ///< a stage starts
    std::function<void(const CaseStep&, int removed)> removed_parts;                 ///< leftovers of a killed run removed
    std::function<void(const CaseStep&, double seconds, const std::string& why)> done;
    std::function<void(const CaseStep&, double seconds, const std::string& why)> failed;  ///< before run_case returns
};

struct CaseRunResult {
    CaseChain chain;
    int ran = 0, current = 0;
    double seconds = 0;
    std::string failed_stage;  ///< "" when every stage ran or was current
    std::exception_ptr error;  ///< the failed stage's exception (its type gives the exit code)
};

/// Plans the case and runs each stage whose output is not current, in order, stopping at the first that
/// fails (returned, not thrown: the caller names the stage). Writes make rules instead when asked.
/// @throws InputError bad config, --set, --stage/--from, or stage options (before anything runs)
CaseRunResult run_case(const CaseRunOptions& o, const CaseEvents& events, Reporter& stage_reporter);

/// Removes "<output>.part-<pid>[<ext>]" leftovers (AtomicPath) of writers that no longer run. Returns how many.
int remove_stale_parts(const std::string& output);

}  // namespace aneu::pipeline
