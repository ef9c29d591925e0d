// SPDX-License-Identifier: MIT
#pragma once
// A case config (configs/cases/<id>.toml) as a chain of stages with their files: what `aneuprep run`
// runs, what `Makefile.cases` builds and what `aneuprep report` shows.
#include <map>
#include <string>
#include <vector>

namespace aneu::tools {

/// One stage of a case: its subcommand, input file (empty for the phantom) and output.
struct CaseStep {
    std::string stage;
    std::string input;
    std::string output;           ///< what the stage's -o names (the phantom: a directory)
    std::string provenance_file;  ///< the file whose /meta records the stage (the phantom: DIR/truth.h5)
};

/// A case: its config, id, output folder and stages in order.
struct CaseChain {
    std::string config;   ///< path of the TOML file
    std::string id;       ///< its file name without extension
    std::string out_dir;  ///< [run] out-dir, default out/cases/<id>
    std::string source;   ///< [run] source: "phantom", a CT (file or DICOM directory) or a lumen surface
    std::vector<CaseStep> steps;
    /// Command-line overrides per stage: `--set wall.blend-mm=1.5` gives {"wall": {"--blend-mm", "1.5"}}.
    std::map<std::string, std::vector<std::string>> overrides;

    const CaseStep* find(const std::string& stage) const;
    /// The bundle (output of the last stage).
    const std::string& bundle() const { return steps.back().output; }
};

/// Every stage in pipeline order.
const std::vector<std::string>& all_case_stages();

/// Reads the [run] section of `config` (keys `source`, `out-dir`; other keys are an InputError naming
/// them) and builds the chain. `out_dir`/`source` non-empty override the config. `phantom_ct` names the
/// phantom's CT file inside its directory (from its formats). @throws InputError
CaseChain make_case_chain(const std::string& config, const std::string& out_dir, const std::string& source,
                          const std::vector<std::string>& sets, const std::string& phantom_ct_name = "ct.nrrd");

/// The argv of stage `step` of the chain: aneuprep --config CONFIG STAGE [INPUT] -o OUTPUT [overrides].
std::vector<std::string> stage_argv(const CaseChain& chain, const CaseStep& step);

}  // namespace aneu::tools
