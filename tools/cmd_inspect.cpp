// SPDX-License-Identifier: MIT
// `aneuprep inspect FILE [--json]`: what a stage file or case bundle holds.
#include <memory>

#include <nlohmann/json.hpp>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/file_summary.hpp"
#include "aneu/pipeline/flow.hpp"
#include "aneu/pipeline/snapshot.hpp"
#include "aneu/core/text.hpp"
#include "cli_common.hpp"
#include "commands.hpp"

namespace aneu::tools {

namespace {

std::string shape_text(const std::vector<std::uint64_t>& s) {
    std::string o = "[";
    for (size_t i = 0; i < s.size(); ++i) o += (i ? "," : "") + std::to_string(s[i]);
    return o + "]";
}

std::uint64_t dim(const FileSummary& s, const std::string& path, size_t d) {
    const H5Entry* e = s.find(path);
    return e && e->shape.size() > d ? e->shape[d] : 0;
}

std::string attr(const FileSummary& s, const std::string& path, const std::string& name) {
    const H5Entry* e = s.find(path);
    if (!e) return "";
    for (const auto& [k, v] : e->attributes) {
        if (k == name) return v;
    }
    return "";
}

/// One line per known group, with the counts a user looks for first.
std::vector<std::pair<std::string, std::string>> contents(const FileSummary& s) {
    std::vector<std::pair<std::string, std::string>> out;
    if (s.find("/image")) {
        out.emplace_back("/image", fmt::format("mask {}x{}x{} voxels (i,j,k); centerline {} points in {} polylines; {} end planes",
                                               dim(s, "/image/mask", 2), dim(s, "/image/mask", 1), dim(s, "/image/mask", 0),
                                               dim(s, "/image/centerline/points", 0),
                                               dim(s, "/image/centerline/offsets", 0) ? dim(s, "/image/centerline/offsets", 0) - 1 : 0,
                                               dim(s, "/image/planes/id", 0)));
    }
    for (const auto& e : s.entries) {
        if (!e.is_group || e.path.rfind("/surface/", 0) != 0 || e.path.find('/', 9) != std::string::npos) continue;
        out.emplace_back(e.path, fmt::format("{} vertices, {} triangles, {} boundary loops", dim(s, e.path + "/vertices", 0),
                                             dim(s, e.path + "/triangles", 0), dim(s, e.path + "/loops/end_id", 0)));
    }
    if (s.find("/volume")) {
        std::string sets;
        for (const auto& e : s.entries) {
            if (e.path.rfind("/volume/node_sets/", 0) == 0) {
                sets += fmt::format("{}{}={}", sets.empty() ? "" : ", ", e.path.substr(18), e.shape.empty() ? 0 : e.shape[0]);
            }
        }
        const auto cols = dim(s, "/volume/tets", 1);
        out.emplace_back("/volume", fmt::format("{} nodes, {} tets ({}); node sets: {}", dim(s, "/volume/nodes", 0),
                                                dim(s, "/volume/tets", 0), cols == 10 ? "quadratic" : "linear",
                                                sets.empty() ? "none" : sets));
    }
    auto attrs_line = [&](const std::string& group) {
        std::string line;
        if (const H5Entry* e = s.find(group)) {
            for (const auto& [k, v] : e->attributes) line += fmt::format("{}{}={}", line.empty() ? "" : ", ", k, v);
        }
        return line;
    };
    if (s.find("/volume/quality")) out.emplace_back("  quality", attrs_line("/volume/quality"));
    if (s.find("/fem")) {
        out.emplace_back("/fem", fmt::format("K {} DOFs, {} stored nonzeros ({}), element order {}, {} fixed DOFs",
                                             attr(s, "/fem/K", "n"), dim(s, "/fem/K/data", 0), attr(s, "/fem/K", "storage"),
                                             attr(s, "/fem", "element_order"), dim(s, "/fem/fixed_dofs", 0)));
    }
    if (const H5Entry* w = s.find("/condensed/W_tiles")) {
        out.emplace_back("/condensed", fmt::format("W {} kept DOFs, {} in tiles of {} ({} on disk), method {}",
                                                   attr(s, "/condensed", "n"), attr(s, "/condensed", "precision"),
                                                   attr(s, "/condensed", "tile_size"), human_bytes(w->stored_bytes),
                                                   attr(s, "/condensed", "method")));
    }
    if (s.find("/condensed/diagnostics")) out.emplace_back("  diagnostics", attrs_line("/condensed/diagnostics"));
    if (s.find("/flow")) out.emplace_back("/flow", fmt::format("{} fluid cells: velocity, pressure, volume", dim(s, "/flow/cell_centre", 0)));
    return out;
}

void print_text(const FileSummary& s) {
    fmt::print("{}  ({})\n", s.path, human_bytes(s.file_bytes));
    fmt::print("  aneuclip bundle, schema v{}, case '{}', units {}\n", s.meta.schema_version, s.meta.case_id, s.meta.units);
    fmt::print("\ncontents\n");
    for (const auto& [k, v] : contents(s)) fmt::print("  {:<16} {}\n", k, v);
    fmt::print("\ndatasets\n");
    fmt::print("  {:<34} {:<18} {:<8} {:<6} {:>10}  {}\n", "path", "shape", "type", "units", "stored", "layout");
    for (const auto& e : s.entries) {
        if (e.is_group) continue;
        fmt::print("  {:<34} {:<18} {:<8} {:<6} {:>10}  {}\n", e.path, shape_text(e.shape), e.dtype,
                   e.units.empty() ? "-" : e.units, human_bytes(e.stored_bytes), e.filters);
    }
    fmt::print("\nprovenance\n");
    for (size_t i = 0; i < s.meta.stages.size(); ++i) {
        const auto& st = s.meta.stages[i];
        fmt::print("  [{}] {}  {}  aneuclip {} ({})  {:.2f} s\n", i, st.stage, st.created_utc, st.tool_version,
                   st.git_revision, st.wall_time_s);
        fmt::print("      command     {}\n", st.command_line);
        std::string params;
        for (const auto& [k, v] : st.parameters) params += fmt::format("{}{}={}", params.empty() ? "" : " ", k, v);
        fmt::print("      parameters  {}\n", params);
        if (!st.qa.empty()) {
            std::string qa;
            for (const auto& [k, v] : st.qa) qa += fmt::format("{}{}={}", qa.empty() ? "" : " ", k, shortest(v));
            fmt::print("      qa          {}\n", qa);
        }
        if (st.inputs.empty()) fmt::print("      inputs      (none)\n");
        for (const auto& in : st.inputs) fmt::print("      input       {}  sha256 {}\n", in.path, in.sha256);
    }
}

nlohmann::json to_json(const FileSummary& s) {
    nlohmann::json j;
    j["file"] = s.path;
    j["file_bytes"] = s.file_bytes;
    j["schema_version"] = s.meta.schema_version;
    j["case_id"] = s.meta.case_id;
    j["units"] = s.meta.units;
    for (const auto& [k, v] : contents(s)) j["contents"][k] = v;
    j["entries"] = nlohmann::json::array();
    for (const auto& e : s.entries) {
        nlohmann::json x{{"path", e.path}, {"kind", e.is_group ? "group" : "dataset"}};
        if (!e.is_group) {
            x["shape"] = e.shape;
            x["dtype"] = e.dtype;
            x["units"] = e.units;
            x["stored_bytes"] = e.stored_bytes;
            x["layout"] = e.filters;
        }
        for (const auto& [k, v] : e.attributes) x["attributes"][k] = v;
        j["entries"].push_back(x);
    }
    j["provenance"] = nlohmann::json::array();
    for (const auto& st : s.meta.stages) {
        nlohmann::json p{{"stage", st.stage},          {"tool_version", st.tool_version},
                         {"git_revision", st.git_revision}, {"created_utc", st.created_utc},
                         {"command_line", st.command_line}, {"wall_time_s", st.wall_time_s}};
        p["parameters"] = nlohmann::json::object();
        for (const auto& [k, v] : st.parameters) p["parameters"][k] = v;
        p["qa"] = nlohmann::json::object();
        for (const auto& [k, v] : st.qa) p["qa"][k] = v;
        p["inputs"] = nlohmann::json::array();
        for (const auto& in : st.inputs) p["inputs"].push_back({{"path", in.path}, {"sha256", in.sha256}});
        j["provenance"].push_back(p);
    }
    return j;
}

}  // namespace

void add_snapshot_command(CLI::App& app, std::function<int()>& action) {
    struct Opts {
        std::string file, surface = "wall", color_by = "label", png;
        bool streamlines = false;
        int seeds = 150;
    };
    auto o = std::make_shared<Opts>();
    auto* c = app.add_subcommand("snapshot", "render a surface of a stage file to PNG (needs X: use xvfb-run -a)");
    c->add_option("file", o->file, "stage file (.h5)")->required();
    c->add_option("--surface", o->surface, "which /surface/<name>")->capture_default_str();
    c->add_option("--color-by", o->color_by, "label, region, or a face field of the surface (e.g. wall_shear_stress_pa of the flow stage's blood surface)")
        ->capture_default_str();
    c->add_option("-o,--output", o->png, "PNG file")->required();
    auto* sl = c->add_flag("--streamlines", o->streamlines,
                           "a flow stage's file: streamlines from the inlet coloured by speed, in the blood surface (translucent; --surface blood unless given)");
    c->add_option("--seeds", o->seeds, "--streamlines: how many, spread over the inlet")->capture_default_str()->check(CLI::Range(1, 5000))->needs(sl);
    c->callback([o, c, &action] {
        if (o->streamlines && c->count("--surface") == 0) o->surface = "blood";
        action = [o] {
            return run_guarded("aneuprep snapshot", [&] {
                BundleParts parts;
                parts.volume = parts.fem = parts.condensed_W = parts.image = false;
                const Bundle b = read_bundle(o->file, parts);
                if (o->streamlines) {
                    if (!b.flow || b.meta.stages.empty() || b.meta.stages.back().stage != "flow")
                        throw InputError(o->file + ": no /flow (--streamlines needs a file of the flow stage)");
                    const auto bs = b.surfaces.find(o->surface);
                    if (bs == b.surfaces.end()) throw InputError(o->file + ": no /surface/" + o->surface);
                    double inlet = -1;
                    for (const auto& [k, v] : b.meta.stages.back().qa)
                        if (k == "inlet_end") inlet = v;
                    const auto lines = pipeline::trace_streamlines(*b.flow, bs->second, "end_" + std::to_string(static_cast<int>(inlet)), o->seeds);
                    pipeline::SnapshotScene sc;
                    sc.layers.push_back({bs->second, pipeline::ColorBy::LABEL, 0.25, false, ""});
                    for (const auto& l : lines) {
                        sc.lines.push_back(l.points);
                        sc.line_values.push_back(l.speed_cm_s);
                    }
                    sc.line_title = "speed [cm/s]";
                    sc.title = "streamlines from the inlet (" + std::to_string(lines.size()) + ")";
                    pipeline::snapshot_scene(sc, o->png, 1000, 800);
                    return;
                }
                const auto it = b.surfaces.find(o->surface);
                if (it == b.surfaces.end()) throw InputError(o->file + ": no /surface/" + o->surface);
                const SurfaceData& sf = it->second;
                if (o->color_by == "label" || o->color_by == "region") {
                    pipeline::snapshot_surface(sf, o->color_by == "region" ? pipeline::ColorBy::REGION : pipeline::ColorBy::LABEL, o->png);
                } else {
                    if (!sf.face_fields.count(o->color_by)) {
                        std::string names = "label, region";
                        for (const auto& [n, m] : sf.face_fields) names += ", " + n;
                        throw InputError("--color-by '" + o->color_by + "': expected one of " + names + " (/surface/" + o->surface + " of " + o->file + ")");
                    }
                    pipeline::snapshot_surface(sf, pipeline::ColorBy::FIELD, o->png, 1000, 800, o->color_by);
                }
            });
        };
    });
}

void add_inspect_command(CLI::App& app, std::function<int()>& action) {
    struct Opts {
        std::string file;
        bool json = false;
    };
    auto o = std::make_shared<Opts>();
    auto* c = app.add_subcommand("inspect", "print what a stage file or case bundle holds");
    c->add_option("file", o->file, "stage file or case bundle (.h5)")->required();
    c->add_flag("--json", o->json, "machine-readable JSON on stdout");
    c->callback([o, &action] {
        action = [o] {
            return run_guarded("aneuprep inspect", [&] {
                const FileSummary s = summarize_bundle(o->file);
                if (o->json) {
                    fmt::print("{}\n", to_json(s).dump(2));
                } else {
                    print_text(s);
                }
            });
        };
    });
}

}  // namespace aneu::tools
