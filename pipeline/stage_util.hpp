// SPDX-License-Identifier: MIT
#pragma once
// Internal to pipeline/: the common end of every file-level stage.
#include <chrono>
#include <string>

#include "aneu/core/common.hpp"
#include "aneu/core/bundle.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/reporter.hpp"
#include "aneu/core/text.hpp"

namespace aneu::pipeline {


/// Records the stage (with its wall time) in /meta and writes the bundle atomically.
inline void finish(Bundle& b, StageRecord& stage, const Stopwatch& t0, const std::string& out, Reporter& rep) {
    stage.wall_time_s = t0.seconds();
    b.meta.stages.push_back(stage);
    write_bundle(out, b, {}, rep);
    rep.info(stage.stage + ": wrote " + out + " in " + shortest(t0.seconds()) + " s");
}

/// File name without directory and extensions ("cases/a.seg.h5" -> "a").
inline std::string stem(const std::string& path) {
    std::string s = path.substr(path.find_last_of('/') + 1);
    return s.substr(0, s.find('.'));
}

/// The case id a stage output carries: its file's stem, unless that is the name `aneuprep run` gives a stage's
/// output in a case folder (out/cases/<id>/segment.h5 …), where the folder names the case.
inline std::string case_id_of(const std::string& path) {
    const std::string s = stem(path);
    for (const char* canonical : {"segment", "surface", "wall", "volume", "fem", "case"})
        if (s == canonical) {
            const auto slash = path.find_last_of('/');
            if (slash == std::string::npos || slash == 0) return s;
            const std::string dir = path.substr(0, slash);
            const std::string parent = dir.substr(dir.find_last_of('/') + 1);
            return parent.empty() || parent == "." || parent == ".." ? s : parent;
        }
    return s;
}

}  // namespace aneu::pipeline
