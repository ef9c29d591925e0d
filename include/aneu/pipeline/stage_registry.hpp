// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Every stage of aneuprep with its option spec: what the command line (tools/) and the case runner
/// (pipeline::run_case) both build on, so a stage and its options are declared once.
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/options.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

/// A stage's name, what it does, its input.
struct StageInfo {
    std::string name;
    std::string help;
    bool has_input = true;
    std::string input_help;   ///< what the positional input is
    std::string output_help;  ///< what -o names
};

/// One run of a stage: its parameters set from text (command line, config, --set), validated, listed for
/// provenance, then run.
class StageJob {
public:
    virtual ~StageJob() = default;
    virtual const StageInfo& info() const = 0;
    virtual std::vector<opt::Option> options() const = 0;
    /// @throws UnknownOptionError no such option; InputError the value does not parse
    virtual void set(const std::string& key, const std::vector<std::string>& values) = 0;
    /// @throws InputError naming the option
    virtual void validate() const = 0;
    /// Provenance parameters, defaults included.
    virtual std::vector<std::pair<std::string, std::string>> parameters() const = 0;
    /// Validates and runs: reads `input` ("" without one), writes `output` atomically.
    virtual void run(const std::string& input, const std::string& output, StageRecord record, Reporter& rep) const = 0;
};

/// The stages in pipeline order (phantom … condense), then tubewall (a test and example source).
const std::vector<StageInfo>& stage_infos();
/// A job of stage `name` with default parameters. @throws InputError unknown stage (naming the known ones)
std::unique_ptr<StageJob> make_stage_job(const std::string& name);

/// The CT file name the phantom stage writes first among its formats (what segment reads in a case).
/// @throws InputError no CT format among them
std::string phantom_ct_name(const std::vector<std::pair<std::string, std::string>>& phantom_parameters);

}  // namespace aneu::pipeline
