// SPDX-License-Identifier: MIT
// The residual blood flow after a session: `aneuprep flow` (OpenFOAM, minutes) run as a child process on the
// series' last frame once the session is over, its figures read back for the report. The simulator links none of
// the offline stack (VTK, CGAL, OpenFOAM): it only starts the program.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>


#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/program.hpp"
#include "aneu/core/reporter.hpp"
#include "aneu/sim/simulator.hpp"

namespace fs = std::filesystem;

namespace aneu::sim {

ResidualFlow residual_flow(const Scene& sc) {
    ResidualFlow r;
    r.file = sc.flow;
    std::error_code ec;
    const fs::path beside = fs::read_symlink("/proc/self/exe", ec).parent_path() / "aneuprep";
    const std::string exe = !ec && fs::exists(beside) ? beside.string() : "aneuprep";
    const auto t0 = std::chrono::steady_clock::now();
    // Its progress and messages go to this terminal.
    const int code = run_program({{exe, "flow", sc.bundle, "--series", sc.series + ".h5", "-o", sc.flow}, "", "", std::nullopt, {}}).code;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (code != 0) {
        r.error = "aneuprep flow failed (exit " + std::to_string(code) + "; its message is above)";
        return r;
    }
    BundleParts parts;
    parts.image = false;
    parts.volume = false;
    parts.fem = false;
    parts.condensed_W = false;
    const Bundle b = read_bundle(sc.flow, parts);
    if (b.meta.stages.empty() || b.meta.stages.back().stage != "flow") {
        r.error = sc.flow + ": not a flow stage's output";
        return r;
    }
    for (const auto& [k, v] : b.meta.stages.back().qa) {
        if (k == "residual_sac_inflow_ratio") r.ratio = v;
        if (k == "sac_inflow_ml_s") r.sac_inflow_ml_s = v;
        if (k == "pre_clip_sac_inflow_ml_s") r.pre_clip_sac_inflow_ml_s = v;
        if (k == "sac_volume_mm3") r.sac_volume_mm3 = v;
        if (k == "ends_closed_off") r.ends_closed_off = v;
    }
    // Pictures for the assessment (VTK renders through X: only with a display).
    const std::string base = fs::path(sc.flow).replace_extension().string();
    if (std::getenv("DISPLAY") != nullptr) {
        for (const auto& [what, args] : std::vector<std::pair<std::string, std::vector<std::string>>>{
                 {base + "_streamlines.png", {"--streamlines"}}, {base + "_wss.png", {"--surface", "blood", "--color-by", "wall_shear_stress_pa"}}}) {
            std::vector<std::string> cmd = {exe, "-q", "snapshot", sc.flow, "-o", what};
            cmd.insert(cmd.end(), args.begin(), args.end());
            if (run_program({cmd, "", "", std::nullopt, {}}).code == 0) r.pictures.push_back(what);
        }
    } else {
        r.pictures_note = "no display for pictures: xvfb-run -a aneuprep snapshot " + sc.flow + " --streamlines -o " + base + "_streamlines.png";
    }
    return r;
}

}  // namespace aneu::sim
