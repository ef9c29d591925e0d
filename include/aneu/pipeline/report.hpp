// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The QA report of a case: one self-contained HTML page (pictures embedded, opens offline) with the pictures
/// of every stage, its QA figures (Dice against the truth when the case is a phantom, thickness per region,
/// mesh quality histograms, condensation diagnostics, timings and memory) and the provenance.
#include <string>
#include <vector>

#include "aneu/core/reporter.hpp"

namespace aneu::pipeline {

/// One stage of the case as the report sees it.
struct ReportStage {
    std::string stage;            ///< phantom, segment, surface, wall, tetmesh, assemble, condense
    std::string output;           ///< what the stage wrote (a directory for the phantom)
    std::string provenance_file;  ///< the .h5 whose /meta records it
};

struct ReportInput {
    std::string case_id;
    std::string config_path;
    std::string config_text;
    std::vector<ReportStage> stages;  ///< in pipeline order; missing outputs are reported as such
    int width = 900, height = 675;    ///< picture size [px]
};

/// Writes the report to `html` atomically. Renders pictures with VTK (needs an X display: xvfb-run -a).
/// @throws InputError when no stage output exists, or no X display
void write_case_report(const ReportInput& in, const std::string& html, Reporter& rep);

}  // namespace aneu::pipeline
