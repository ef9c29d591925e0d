// SPDX-License-Identifier: MIT
// `aneuprep report`: the self-contained HTML QA page of a case.
#include "aneu/core/common.hpp"
#include "aneu/pipeline/report.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"
#include "aneu/core/text.hpp"
#include "aneu/core/version.hpp"
#include "aneu/pipeline/flow.hpp"
#include "aneu/pipeline/snapshot.hpp"
#include "aneu/pipeline/surface_ops.hpp"

namespace aneu::pipeline {

namespace fs = std::filesystem;

namespace {


std::string esc(const std::string& s) {
    std::string o;
    for (char c : s) {
        switch (c) {
        case '&': o += "&amp;"; break;
        case '<': o += "&lt;"; break;
        case '>': o += "&gt;"; break;
        case '"': o += "&quot;"; break;
        default: o += c;
        }
    }
    return o;
}

std::string base64(const std::string& in) {
    static const char* T = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string o;
    o.reserve((in.size() + 2) / 3 * 4);
    size_t i = 0;
    for (; i + 2 < in.size(); i += 3) {
        const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8) |
                           static_cast<unsigned char>(in[i + 2]);
        o += T[(v >> 18) & 63], o += T[(v >> 12) & 63], o += T[(v >> 6) & 63], o += T[v & 63];
    }
    if (i < in.size()) {
        unsigned v = static_cast<unsigned char>(in[i]) << 16;
        if (i + 1 < in.size()) v |= static_cast<unsigned char>(in[i + 1]) << 8;
        o += T[(v >> 18) & 63], o += T[(v >> 12) & 63];
        o += i + 1 < in.size() ? T[(v >> 6) & 63] : '=';
        o += '=';
    }
    return o;
}

std::string num(double v) {
    if (v == std::floor(v) && std::abs(v) < 1e12) return fmt::format("{:.0f}", v);
    return fmt::format("{:.4g}", v);
}

const StageRecord* record_of(const Meta& m, const std::string& stage) {
    const StageRecord* r = nullptr;
    for (const auto& s : m.stages) {
        if (s.stage == stage) r = &s;
    }
    return r;
}

double qa_value(const NamedValues& qa, const std::string& key, double fallback = NAN) {
    for (const auto& [k, v] : qa) {
        if (k == key) return v;
    }
    return fallback;
}

/// An inline SVG histogram of `v` on [lo, hi] with `bins` bars; `mark` draws a dashed limit line.
std::string svg_histogram(const std::vector<double>& v, double lo, double hi, int bins, const std::string& xlabel,
                          double mark = NAN, const std::string& mark_label = "") {
    std::vector<int> count(static_cast<size_t>(bins), 0);
    for (double x : v) {
        const int b = std::clamp(static_cast<int>((x - lo) / (hi - lo) * bins), 0, bins - 1);
        ++count[static_cast<size_t>(b)];
    }
    const int cmax = std::max(1, *std::max_element(count.begin(), count.end()));
    const double W = 420, H = 170, L = 48, B = 30, T = 10, R = 10;
    const double pw = W - L - R, ph = H - T - B;
    std::string s = fmt::format("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" class=\"hist\">", W, H);
    for (int b = 0; b < bins; ++b) {
        const double h = ph * count[static_cast<size_t>(b)] / cmax;
        s += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"#4a7fb5\"/>", L + pw * b / bins,
                         T + ph - h, std::max(0.5, pw / bins - 1), h);
    }
    s += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#333\"/>", L, T + ph, L + pw, T + ph);
    s += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#333\"/>", L, T, L, T + ph);
    for (int k = 0; k <= 4; ++k) {
        const double x = lo + (hi - lo) * k / 4;
        s += fmt::format("<text x=\"{:.1f}\" y=\"{}\" font-size=\"10\" text-anchor=\"middle\">{}</text>", L + pw * k / 4, T + ph + 12, num(x));
    }
    s += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">{}</text>", L - 4, T + 8, cmax);
    s += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">0</text>", L - 4, T + ph);
    s += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{} (n = {})</text>", L + pw / 2, H - 3,
                     esc(xlabel), v.size());
    if (std::isfinite(mark) && mark > lo && mark < hi) {
        const double x = L + pw * (mark - lo) / (hi - lo);
        s += fmt::format("<line x1=\"{:.1f}\" y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" stroke=\"#c0392b\" stroke-dasharray=\"4,3\"/>", x, T, x, T + ph);
        s += fmt::format("<text x=\"{:.1f}\" y=\"{}\" font-size=\"10\" fill=\"#c0392b\">{}</text>", x + 3, T + 10, esc(mark_label));
    }
    return s + "</svg>";
}

std::vector<double> triangle_min_angles(const SurfaceData& s) {
    std::vector<double> a(static_cast<size_t>(s.F.rows()));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        double m = 180;
        for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3d p = s.V.row(s.F(f, k)), q = s.V.row(s.F(f, (k + 1) % 3)), r = s.V.row(s.F(f, (k + 2) % 3));
            const Eigen::Vector3d u = q - p, w = r - p;
            m = std::min(m, std::atan2(u.cross(w).norm(), u.dot(w)) * 180 / PI);
        }
        a[static_cast<size_t>(f)] = m;
    }
    return a;
}

std::vector<double> tet_min_dihedral(const VolumeData& v) {
    static constexpr int E[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
    std::vector<double> out(static_cast<size_t>(v.tets.rows()));
    for (Eigen::Index t = 0; t < v.tets.rows(); ++t) {
        double m = 180;
        for (const auto& e : E) {  // dihedral angle along edge (e0,e1) between the faces through e2 and e3
            const Eigen::Vector3d a = v.nodes.row(v.tets(t, e[0])), b = v.nodes.row(v.tets(t, e[1]));
            const Eigen::Vector3d c = v.nodes.row(v.tets(t, e[2])), d = v.nodes.row(v.tets(t, e[3]));
            const Eigen::Vector3d ab = (b - a).normalized();
            Eigen::Vector3d pc = (c - a) - (c - a).dot(ab) * ab, pd = (d - a) - (d - a).dot(ab) * ab;
            m = std::min(m, std::atan2(pc.cross(pd).norm(), pc.dot(pd)) * 180 / PI);
        }
        out[static_cast<size_t>(t)] = m;
    }
    return out;
}

/// Dice of the segmentation's lumen against the phantom's truth (artery + aneurysm labels), voxel by voxel in
/// the physical frame (the segmentation may be a crop of the truth's grid).
double dice_against_truth(const ImageData& seg, const ImageData& truth) {
    std::vector<char> lumen_label(truth.mask_label_names.size(), 0);
    for (size_t k = 0; k < truth.mask_label_names.size(); ++k) {
        lumen_label[k] = truth.mask_label_names[k] == "artery" || truth.mask_label_names[k] == "aneurysm";
    }
    const auto& g = truth.grid;
    double both = 0, n_truth = 0, n_seg = 0;
    for (std::int64_t k = 0; k < g.size[2]; ++k) {
        for (std::int64_t j = 0; j < g.size[1]; ++j) {
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const std::uint8_t t = truth.mask[g.linear(i, j, k)];
                const bool in_t = t < lumen_label.size() && lumen_label[t];
                const auto c = seg.grid.continuous_index(g.point(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k)));
                const auto si = std::llround(c[0]), sj = std::llround(c[1]), sk = std::llround(c[2]);
                bool in_s = false;
                if (si >= 0 && sj >= 0 && sk >= 0 && si < seg.grid.size[0] && sj < seg.grid.size[1] && sk < seg.grid.size[2]) {
                    in_s = seg.mask[seg.grid.linear(si, sj, sk)] != 0;
                }
                both += in_t && in_s;
                n_truth += in_t;
                n_seg += in_s;
            }
        }
    }
    return n_truth + n_seg > 0 ? 2 * both / (n_truth + n_seg) : NAN;
}

struct Picture {
    std::string title, caption, png_bytes;
};

class Page {
public:
    std::string body;
    int pictures = 0;
    void h2(const std::string& t, const std::string& id) { body += "<h2 id=\"" + id + "\">" + esc(t) + "</h2>\n"; }
    void p(const std::string& t) { body += "<p>" + t + "</p>\n"; }
    void table(const std::vector<std::string>& head, const std::vector<std::vector<std::string>>& rows) {
        body += "<table><tr>";
        for (const auto& h : head) body += "<th>" + esc(h) + "</th>";
        body += "</tr>\n";
        for (const auto& r : rows) {
            body += "<tr>";
            for (const auto& c : r) body += "<td>" + c + "</td>";
            body += "</tr>\n";
        }
        body += "</table>\n";
    }
    void picture(const Picture& pic) {
        body += "<figure><img alt=\"" + esc(pic.title) + "\" src=\"data:image/png;base64," + base64(pic.png_bytes) +
                "\"><figcaption><b>" + esc(pic.title) + "</b> " + esc(pic.caption) + "</figcaption></figure>\n";
        ++pictures;
    }
};

}  // namespace

void write_case_report(const ReportInput& in, const std::string& html, Reporter& rep) {
    require_snapshot_display();
    const fs::path out(html);
    if (!out.parent_path().empty() && !fs::is_directory(out.parent_path())) {
        throw InputError(html + ": cannot create, parent directory '" + out.parent_path().string() + "' does not exist");
    }
    // Read what exists: every stage file without W.
    std::map<std::string, Bundle> files;
    BundleParts parts;
    parts.condensed_W = false;
    for (const auto& s : in.stages) {
        if (fs::exists(s.provenance_file)) files[s.stage] = read_bundle(s.provenance_file, parts);
    }
    if (files.empty()) throw InputError("case " + in.case_id + ": no stage output exists yet (run `aneuprep run " + in.config_path + "` first)");

    const fs::path tmpdir = fs::temp_directory_path() / ("aneuclip-report-" + std::to_string(::getpid()));
    fs::create_directories(tmpdir);
    struct Cleanup {
        fs::path p;
        ~Cleanup() {
            std::error_code ec;
            fs::remove_all(p, ec);
        }
    } cleanup{tmpdir};
    auto render = [&](const SnapshotScene& sc) {
        const fs::path png = tmpdir / "p.png";
        snapshot_scene(sc, png.string(), in.width, in.height);
        return read_file(png.string());
    };

    Page pg;
    // --- summary
    std::vector<std::vector<std::string>> rows;
    double total_time = 0;
    for (const auto& s : in.stages) {
        auto it = files.find(s.stage);
        if (it == files.end()) {
            rows.push_back({esc(s.stage), "<span class=\"bad\">missing</span>", "", "", "", esc(s.output)});
            continue;
        }
        const StageRecord* r = record_of(it->second.meta, s.stage);
        std::uintmax_t size = 0;
        if (fs::is_directory(s.output)) {
            for (const auto& e : fs::recursive_directory_iterator(s.output)) size += e.is_regular_file() ? e.file_size() : 0;
        } else {
            size = fs::file_size(s.output);
        }
        total_time += r ? r->wall_time_s : 0;
        rows.push_back({esc(s.stage), "<span class=\"ok\">done</span>", r ? esc(r->created_utc) : "?",
                        r ? fmt::format("{:.1f}", r->wall_time_s) : "?", human_bytes(size), esc(s.output)});
    }
    pg.h2("Stages", "stages");
    pg.table({"stage", "state", "made (UTC)", "time [s]", "size", "file"}, rows);
    pg.p(fmt::format("Sum of the stages' wall times: {:.1f} s.", total_time));

    // --- QA figures
    pg.h2("QA figures", "qa");
    std::vector<std::vector<std::string>> key;
    if (files.count("phantom") && files.count("segment") && files["phantom"].image && files["segment"].image) {
        const double d = dice_against_truth(*files["segment"].image, *files["phantom"].image);
        key.push_back({"segment", "Dice of the lumen against the phantom's truth", fmt::format("{:.4f}", d), d >= 0.95 ? "&ge; 0.95" : "<span class=\"bad\">&lt; 0.95</span>"});
    }
    if (files.count("surface")) {
        const auto& qa = record_of(files["surface"].meta, "surface")->qa;
        key.push_back({"surface", "edge length mean [mm]", num(qa_value(qa, "edge_mean_mm")), ""});
        key.push_back({"surface", "minimum triangle angle [deg]", num(qa_value(qa, "min_angle_deg")), qa_value(qa, "min_angle_deg") >= 15 ? "&ge; 15" : "<span class=\"bad\">&lt; 15</span>"});
        key.push_back({"surface", "aneurysm area [mm²]", num(qa_value(qa, "area_aneurysm_mm2")), ""});
    }
    if (files.count("wall")) {
        const auto& qa = record_of(files["wall"].meta, "wall")->qa;
        for (const auto& [k, v] : qa) {
            if (k.rfind("thickness_", 0) == 0) key.push_back({"wall", esc(k), num(v), ""});
        }
    }
    if (files.count("tetmesh") && files["tetmesh"].volume) {
        const auto& v = *files["tetmesh"].volume;
        key.push_back({"tetmesh", "nodes / tetrahedra", fmt::format("{} / {}", v.nodes.rows(), v.tets.rows()), ""});
        for (const auto& [k, val] : v.quality) key.push_back({"tetmesh", esc(k), num(val), ""});
    }
    if (files.count("condense") && files["condense"].condensed) {
        const auto& c = *files["condense"].condensed;
        const double bytes = c.precision == Precision::FLOAT32 ? 4.0 : 8.0;
        key.push_back({"condense", "kept DOFs (W is #M×#M)", std::to_string(c.size()), ""});
        key.push_back({"condense", "W storage (upper triangle)", fmt::format("{} ({})", human_bytes(static_cast<std::uint64_t>(bytes * static_cast<double>(c.size()) * static_cast<double>(c.size() + 1) / 2)),
                                                                           c.precision == Precision::FLOAT32 ? "float32" : "float64"), ""});
        key.push_back({"condense", "method", esc(c.method), ""});
        for (const auto& [k, v] : c.diagnostics) {
            key.push_back({"condense", esc(k), k.find("bytes") != std::string::npos ? human_bytes(static_cast<std::uint64_t>(v)) : num(v), ""});
        }
    }
    if (files.count("flow") && record_of(files["flow"].meta, "flow")) {
        const auto& qa = record_of(files["flow"].meta, "flow")->qa;
        const bool session = !std::isnan(qa_value(qa, "frame"));
        const std::pair<const char*, const char*> shown[] = {
            {"inflow_ml_s", "inflow [mL/s]"},
            {"cells", "fluid cells"},
            {"mass_imbalance", "mass imbalance (inflow − outflows) / inflow"},
            {"pressure_drop_pa", "pressure drop, inlet to outlets [Pa]"},
            {"wss_mean_pa", "wall shear stress, area mean [Pa]"},
            {"sac_inflow_ml_s", "sac inflow through the neck [mL/s]"},
            {"sac_inflow_fraction", "sac inflow / inflow"},
            {"sac_mean_speed_cm_s", "mean speed in the sac [cm/s]"},
            {"pre_clip_sac_inflow_ml_s", "pre-clip sac inflow [mL/s]"},
            {"residual_sac_inflow_ratio", "residual sac inflow / pre-clip"},
            {"ends_closed_off", "vessel ends closed off"}};
        for (const auto& [k, label] : shown) {
            const double v = qa_value(qa, k);
            if (std::isnan(v)) continue;
            std::string accept;
            if (std::string(k) == "mass_imbalance") accept = v <= 0.005 ? "&le; 0.5 %" : "<span class=\"bad\">&gt; 0.5 %</span>";
            if (std::string(k) == "residual_sac_inflow_ratio") accept = v < 0.05 ? "closed (&lt; 5 %)" : "<span class=\"bad\">open (&ge; 5 %)</span>";
            key.push_back({session ? "flow (session)" : "flow", label, num(v), accept});
        }
    }
    pg.table({"stage", "figure", "value", "acceptance"}, key);

    // --- pictures
    pg.h2("Pictures", "pictures");
    if (files.count("segment") && files["segment"].image) {
        const ImageData& im = *files["segment"].image;
        const SnapshotScene sc = segment_scene(im, "segment");
        pg.picture({"segment", fmt::format("lumen mask (voxel surface), centerline with radius, {} end planes with their outward normals; threshold {} HU.",
                                           im.planes.size(), num(im.threshold_hu)), render(sc)});
    }
    if (files.count("surface") && files["surface"].surfaces.count("lumen")) {
        const SnapshotScene sc = surface_scene(files["surface"].surfaces["lumen"],
                                               files["surface"].image ? files["surface"].image->planes : std::vector<EndPlane>{}, "surface");
        pg.picture({"surface", "lumen surface after cutting, smoothing and remeshing, faces labelled artery/aneurysm.", render(sc)});
    }
    if (files.count("wall") && files["wall"].surfaces.count("wall")) {
        const SurfaceData& w = files["wall"].surfaces["wall"];
        const SnapshotScene sc = wall_thickness_scene(w, "wall thickness");
        pg.picture({"wall", "outer wall surface and end caps coloured by the measured thickness [mm].", render(sc)});
        SnapshotScene sl;
        sl.layers.push_back({w, ColorBy::LABEL, 1.0, true, ""});
        sl.title = "wall labels";
        pg.picture({"wall", "closed wall surface by label: inner, outer and one annular cap per vessel end.", render(sl)});
    }
    if (files.count("tetmesh") && files["tetmesh"].surfaces.count("wall")) {
        SnapshotScene sc;
        sc.layers.push_back({files["tetmesh"].surfaces["wall"], ColorBy::REGION, 1.0, true, ""});
        sc.title = "tetmesh regions";
        pg.picture({"tetmesh", "boundary of the tetrahedral mesh coloured by material region (artery/aneurysm).", render(sc)});
    }

    if (files.count("flow") && files["flow"].surfaces.count("blood")) {
        const Bundle& fb = files["flow"];
        const SurfaceData& blood = fb.surfaces.at("blood");
        if (blood.face_fields.count("wall_shear_stress_pa")) {
            SnapshotScene sc;
            sc.layers.push_back({blood, ColorBy::FIELD, 1.0, false, "wall_shear_stress_pa"});
            sc.title = "wall shear stress [Pa]";
            pg.picture({"flow", "wall shear stress of the steady blood flow on the blood domain's wall (colour bar to its 98th percentile).", render(sc)});
        }
        if (fb.flow) {
            const double inlet = qa_value(record_of(fb.meta, "flow")->qa, "inlet_end");
            const auto lines = trace_streamlines(*fb.flow, blood, "end_" + std::to_string(static_cast<int>(inlet)));
            SnapshotScene sc;
            sc.layers.push_back({blood, ColorBy::LABEL, 0.25, false, ""});
            for (const auto& l : lines) {
                sc.lines.push_back(l.points);
                sc.line_values.push_back(l.speed_cm_s);
            }
            sc.line_title = "speed [cm/s]";
            sc.title = "streamlines";
            pg.picture({"flow", fmt::format("{} streamlines from the inlet, coloured by speed, in the blood domain (translucent).", lines.size()), render(sc)});
        }
    }

    // --- histograms
    pg.h2("Mesh quality", "quality");
    std::string hist;
    if (files.count("surface") && files["surface"].surfaces.count("lumen")) {
        hist += svg_histogram(triangle_min_angles(files["surface"].surfaces["lumen"]), 0, 60, 30, "lumen: smallest triangle angle [deg]", 15, "15°");
    }
    if (files.count("wall") && files["wall"].surfaces.count("wall")) {
        const SurfaceData& w = files["wall"].surfaces["wall"];
        hist += svg_histogram(triangle_min_angles(w), 0, 60, 30, "wall: smallest triangle angle [deg]", 15, "15°");
        if (w.vertex_thickness.size() == w.V.rows()) {
            std::vector<std::vector<double>> by_region(w.region_names.size());
            std::vector<int> vregion(static_cast<size_t>(w.V.rows()), -1);
            for (Eigen::Index f = 0; f < w.F.rows(); ++f) {
                if (w.face_region.size() != w.F.rows() || w.face_label[f] == 0) continue;  // outer and caps
                for (int k = 0; k < 3; ++k) vregion[static_cast<size_t>(w.F(f, k))] = w.face_region[f];
            }
            double tmax = 0;
            for (Eigen::Index i = 0; i < w.V.rows(); ++i) {
                const int r = vregion[static_cast<size_t>(i)];
                if (r >= 0 && static_cast<size_t>(r) < by_region.size()) by_region[static_cast<size_t>(r)].push_back(w.vertex_thickness[i]);
                tmax = std::max(tmax, w.vertex_thickness[i]);
            }
            for (size_t r = 0; r < by_region.size(); ++r) {
                if (!by_region[r].empty()) hist += svg_histogram(by_region[r], 0, std::max(0.1, 1.2 * tmax), 30, "wall thickness, " + w.region_names[r] + " [mm]");
            }
        }
    }
    if (files.count("tetmesh") && files["tetmesh"].volume) {
        hist += svg_histogram(tet_min_dihedral(*files["tetmesh"].volume), 0, 70.53, 35, "tetrahedra: smallest dihedral angle [deg]");
    }
    pg.body += "<div class=\"hists\">" + hist + "</div>\n";

    // --- provenance
    pg.h2("Provenance", "provenance");
    for (const auto& s : in.stages) {
        auto it = files.find(s.stage);
        if (it == files.end()) continue;
        const StageRecord* r = record_of(it->second.meta, s.stage);
        if (!r) continue;
        std::string params, inputs;
        for (const auto& [k, v] : r->parameters) params += esc(k) + " = " + esc(v) + "<br>";
        for (const auto& f : r->inputs) inputs += esc(f.path) + " <code>" + esc(f.sha256.substr(0, 16)) + "…</code><br>";
        pg.body += "<details><summary>" + esc(s.stage) + " — " + esc(r->created_utc) + ", aneuclip " + esc(r->tool_version) + " (" +
                   esc(r->git_revision) + ")</summary>";
        pg.body += "<p><code>" + esc(r->command_line) + "</code></p>";
        pg.table({"parameters", "inputs (SHA-256)"}, {{params, inputs.empty() ? "none" : inputs}});
        pg.body += "</details>\n";
    }
    pg.h2("Case config", "config");
    pg.body += "<pre>" + esc(in.config_text) + "</pre>\n";

    std::string page = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>aneuclip case " + esc(in.case_id) + "</title>\n";
    page += "<style>body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}table{border-collapse:collapse;margin:.5em 0}"
            "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top;font-size:13px}th{background:#eef}"
            "figure{display:inline-block;margin:.5em;width:440px;vertical-align:top}figure img{width:440px;border:1px solid #ddd}"
            "figcaption{font-size:12px}.ok{color:#1e7b34}.bad{color:#c0392b;font-weight:bold}.hists svg{margin:.3em;border:1px solid #eee}"
            "code{font-size:12px}pre{background:#f6f6f6;padding:.5em;font-size:12px}</style></head><body>\n";
    page += "<h1>aneuclip case " + esc(in.case_id) + "</h1>\n<p>Config <code>" + esc(in.config_path) + "</code>; report made " +
            esc(utc_now_iso8601()) + " by aneuclip " + esc(tool_version()) + " (" + esc(git_revision()) + "). " +
            "<span id=\"picture-check\" data-ok=\"unknown\">pictures not checked (scripts off)</span></p>\n";
    page += pg.body;
    page += "<script>window.addEventListener('load',function(){var im=document.images,ok=0;for(var i=0;i<im.length;++i)"
            "if(im[i].complete&&im[i].naturalWidth>0)++ok;var s=document.getElementById('picture-check');"
            "s.textContent=ok+' of '+im.length+' pictures shown';s.setAttribute('data-ok',ok==im.length&&im.length>0?'yes':'no');});</script>\n";
    page += "</body></html>\n";

    write_text_atomically(out.string(), page);
    rep.info(fmt::format("report: {} pictures, {} -> {}", pg.pictures, human_bytes(page.size()), html));
}

}  // namespace aneu::pipeline
