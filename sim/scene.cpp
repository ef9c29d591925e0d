// SPDX-License-Identifier: MIT
#include "aneu/sim/scene.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"

namespace aneu::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Reads a JSON object's keys, refusing unknown ones (a typo must not silently fall back to a default).
class Obj {
public:
    Obj(const json& j, std::string where, std::string file) : m_j(j), m_where(std::move(where)), m_file(std::move(file)) {
        if (!j.is_object()) fail("expected an object");
    }
    ~Obj() = default;
    void done() const {
        for (const auto& [k, v] : m_j.items())
            if (!m_seen.count(k)) fail("unknown key \"" + k + "\"");
    }
    [[noreturn]] void fail(const std::string& what) const { throw InputError(m_file + ": " + m_where + ": " + what); }
    bool has(const std::string& k) const { return m_j.contains(k); }
    const json& at(const std::string& k) {
        m_seen.insert(k);
        if (!m_j.contains(k)) fail("missing key \"" + k + "\"");
        return m_j.at(k);
    }
    double num(const std::string& k, double def, double lo = -1e300, double hi = 1e300, bool required = false) {
        m_seen.insert(k);
        if (!m_j.contains(k)) {
            if (required) fail("missing key \"" + k + "\"");
            return def;
        }
        const json& v = m_j.at(k);
        if (!v.is_number()) fail("\"" + k + "\" must be a number");
        const double x = v.get<double>();
        if (!std::isfinite(x) || x < lo || x > hi) {
            fail("\"" + k + "\" = " + v.dump() + ", expected a value in [" + fmt(lo) + ", " + fmt(hi) + "]");
        }
        return x;
    }
    bool flag(const std::string& k, bool def) {
        m_seen.insert(k);
        if (!m_j.contains(k)) return def;
        if (!m_j.at(k).is_boolean()) fail("\"" + k + "\" must be true or false");
        return m_j.at(k).get<bool>();
    }
    std::string str(const std::string& k, const std::string& def, bool required = false) {
        m_seen.insert(k);
        if (!m_j.contains(k)) {
            if (required) fail("missing key \"" + k + "\"");
            return def;
        }
        if (!m_j.at(k).is_string()) fail("\"" + k + "\" must be a string");
        return m_j.at(k).get<std::string>();
    }
    Eigen::Vector3d vec3(const std::string& k, const Eigen::Vector3d& def, bool required = false, bool unit = false) {
        m_seen.insert(k);
        if (!m_j.contains(k)) {
            if (required) fail("missing key \"" + k + "\"");
            return def;
        }
        const json& v = m_j.at(k);
        if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() || !v[2].is_number())
            fail("\"" + k + "\" must be an array of 3 numbers");
        Eigen::Vector3d x(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
        if (!x.allFinite()) fail("\"" + k + "\" is not finite");
        if (unit) {
            if (x.norm() < 1e-12) fail("\"" + k + "\" is a zero direction");
            x.normalize();
        }
        return x;
    }
    /// A string key that must be one of `names`; returns its index (the default's when absent).
    size_t choice(const std::string& k, const std::vector<std::string>& names, size_t def = 0) {
        const std::string v = str(k, names[def]);
        const auto it = std::find(names.begin(), names.end(), v);
        if (it != names.end()) return static_cast<size_t>(it - names.begin());
        std::string list;
        for (size_t i = 0; i < names.size(); ++i) list += (i ? (i + 1 == names.size() ? " or " : ", ") : "") + names[i];
        fail("\"" + k + "\" = \"" + v + "\", expected " + list);
    }
    const std::string& where() const { return m_where; }
    const std::string& file() const { return m_file; }

private:
    static std::string fmt(double x) {
        std::ostringstream s;
        s << x;
        return s.str();
    }
    const json& m_j;
    std::string m_where, m_file;
    std::set<std::string> m_seen;
};

std::string resolve(const std::string& base_dir, const std::string& p) {
    if (p.empty() || fs::path(p).is_absolute()) return p;
    return (fs::path(base_dir) / p).lexically_normal().string();
}

Pose orthonormal(Pose p) {
    p.axis.normalize();
    p.up = (p.up - p.up.dot(p.axis) * p.axis);
    if (p.up.norm() < 1e-9) p.up = p.axis.unitOrthogonal();
    p.up.normalize();
    return p;
}

/// The keys of a clip model (scene's clip_models entry or a clip file) onto `c` (its values are the defaults).
void read_clip_keys(Obj& o, ClipModel& c, const std::string& dir) {
    c.jaw_length_mm = o.num("jaw_length_mm", c.jaw_length_mm, 0.1, 100);
    c.jaw_width_mm = o.num("jaw_width_mm", c.jaw_width_mm, 0.05, 20);
    c.jaw_thickness_mm = o.num("jaw_thickness_mm", c.jaw_thickness_mm, 0.05, 20);
    c.closed_gap_mm = o.num("closed_gap_mm", c.closed_gap_mm, 0, 20);
    c.max_opening_deg = o.num("max_opening_deg", c.max_opening_deg, 0, 120);
    c.fulcrum_mm = o.num("fulcrum_mm", c.fulcrum_mm, 0, 100);
    c.arms_press = o.flag("arms_press", c.arms_press);
    if (c.reach_mm() > 100) o.fail("\"fulcrum_mm\" + \"jaw_length_mm\" = " + std::to_string(c.reach_mm()) + ", expected at most 100 mm");
    const std::string mesh = o.str("jaw_mesh", "");
    if (!mesh.empty()) {
        c.mesh_file = resolve(dir, mesh);
        c.jaw_mesh = read_trimesh(c.mesh_file);
    }
    c.jaw_curve_radius_mm = o.num("jaw_curve_radius_mm", c.jaw_curve_radius_mm, -1000, 1000);
    if (c.jaw_curve_radius_mm != 0) {
        if (c.jaw_mesh) o.fail("\"jaw_curve_radius_mm\" with a jaw_mesh: expected 0 (a mesh jaw has its own shape)");
        const fem::ClipBlades b = c.blades(Pose{});
        try {
            b.check_curve();
        } catch (const InputError& e) {
            o.fail(std::string("jaw_curve_radius_mm: ") + e.what());
        }
    }
    if (c.jaw_mesh && c.fulcrum_mm > 0) o.fail("\"fulcrum_mm\" = " + std::to_string(c.fulcrum_mm) + " with a jaw_mesh: expected 0 (a mesh jaw is drawn from its own hinge)");
    if (o.has("spring")) {
        Obj sp(o.at("spring"), o.where() + ".spring", o.file());
        c.label_force_n = sp.num("label_force_n", 0, 1e-3, 100, true);
        c.open_force_n = sp.num("open_force_n", 0, 1e-3, 100, true);
        c.spring_placeholder = sp.flag("placeholder", false);
        c.spring_source = sp.str("source", "");
        sp.done();
    }
    if (c.label_force_n > 0) {  // (again, when a scene overrides a clip file's blade)
        // ISO 9713: the label force is measured at 1 mm opening a third of the blade from its tip (from the fulcrum:
        // fulcrum_mm + 2/3 of the blade).
        const double r = c.label_arm_mm();
        try {
            c.spring = fem::ClipSpring::from_forces(r, fem::opening_angle(r, 1.0, c.closed_gap_mm), c.label_force_n,
                                                   c.max_opening_deg * DEG, c.open_force_n);
        } catch (const InputError& e) {
            o.fail(std::string("spring: ") + e.what());
        }
    }
}

}  // namespace

ClipModel read_clip_file(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(path + ": cannot open the clip file");
    json j;
    try {
        j = json::parse(in, nullptr, true, true);
    } catch (const json::parse_error& e) {
        throw InputError(path + ": not valid JSON: " + e.what());
    }
    Obj o(j, "clip", path);
    ClipModel c;
    c.name = o.str("name", fs::path(path).stem().string());
    o.str("kind", "");
    read_clip_keys(o, c, fs::path(path).parent_path().string());
    o.done();
    c.file = path;
    return c;
}

namespace {

}  // namespace

Scene read_scene(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(path + (std::filesystem::exists(path) ? ": cannot open the scene file" : ": no such scene file"));
    json j;
    try {
        j = json::parse(in, nullptr, true, /*ignore_comments=*/true);
    } catch (const json::parse_error& e) {
        throw InputError(path + ": not valid JSON: " + e.what());
    }
    Scene s;
    s.path = path;
    const std::string dir = fs::path(path).parent_path().string();
    Obj top(j, "scene", path);
    s.bundle = resolve(dir, top.str("bundle", "", true));
    if (top.has("working_region")) {
        Obj r(top.at("working_region"), "working_region", path);
        RegionSphere rs;
        rs.centre = r.vec3("centre", Eigen::Vector3d::Zero(), true);
        rs.radius_mm = r.num("radius_mm", 0, 1e-6, 1e6, true);
        s.region = rs;
        r.done();
    }
    switch (top.choice("precision", {"bundle", "float32", "float64"})) {
        case 1: s.working_precision = Precision::FLOAT32; break;
        case 2: s.working_precision = Precision::FLOAT64; break;
        default: break;
    }
    if (top.has("clip_models")) {
        const json& cm = top.at("clip_models");
        if (!cm.is_object()) top.fail("\"clip_models\" must be an object of named models");
        for (const auto& [name, v] : cm.items()) {
            Obj o(v, "clip_models." + name, path);
            ClipModel c;
            if (o.has("file")) {
                // A clip file, optionally with keys of its own overriding it.
                c = read_clip_file(resolve(dir, o.str("file", "", true)));
            }
            c.name = name;
            read_clip_keys(o, c, dir);
            o.done();
            s.clip_models[name] = c;
        }
    }
    if (top.has("contact")) {
        Obj o(top.at("contact"), "contact", path);
        s.displacement_fraction = o.num("displacement_fraction", s.displacement_fraction, 0.01, 1.0);
        s.neighbour_weight = o.num("neighbour_weight", s.neighbour_weight, 0, 1);
        s.release_tolerance_mm = o.num("release_tolerance_mm", s.release_tolerance_mm, 0, 10);
        s.relax_time_s = o.num("relax_time_s", s.relax_time_s, 1e-4, 100);
        s.update_margin_mm = o.num("update_margin_mm", s.update_margin_mm, 0, 1e3);
        s.linear_limit = o.num("linear_limit", s.linear_limit, 0, 1e3);
        s.jaw_push = o.choice("jaw_push", {"shape", "node_normal"}) == 0 ? JawPush::SHAPE : JawPush::NODE_NORMAL;
        s.clip_method = o.choice("deposited_clips", {"exact", "two-solve"}) == 0 ? GroupMethod::EXACT : GroupMethod::TWO_SOLVE;
        o.done();
    }
    if (top.has("model")) {
        Obj o(top.at("model"), "model", path);
        s.wall_model = o.choice("wall", {"linear", "patch"}) == 0 ? WallModel::LINEAR : WallModel::PATCH;
        s.patch.radius_mm = o.num("patch_radius_mm", s.patch.radius_mm, 0.1, 50);
        s.patch.trigger_mm = o.num("trigger_mm", s.patch.trigger_mm, 0, 20);
        s.patch.grow = o.flag("patch_grow", s.patch.grow);
        s.patch.newton_per_frame = static_cast<int>(o.num("newton_per_frame", s.patch.newton_per_frame, 1, 1000));
        s.patch.tolerance = o.num("tolerance", s.patch.tolerance, 1e-14, 1e-1);
        s.patch.wall_contact = o.flag("wall_contact", s.patch.wall_contact);
        s.patch.blade_friction = o.num("blade_friction", s.patch.blade_friction, 0, 5);
        s.patch.solver = o.choice("patch_solver", {"newton", "compliance"}) == 0 ? PatchSpec::Solver::NEWTON : PatchSpec::Solver::COMPLIANCE;
        s.patch.refresh_frames = static_cast<int>(o.num("refresh_frames", s.patch.refresh_frames, 0, 1e6));
        s.patch.range_resolves = static_cast<int>(o.num("range_resolves", s.patch.range_resolves, 0, 100));
        s.patch.range_splits = static_cast<int>(o.num("range_splits", s.patch.range_splits, 0, 6));
        s.patch.range_newton = static_cast<int>(o.num("range_newton", s.patch.range_newton, 0, 1000));
        s.patch.walls_reject_mm = o.num("walls_reject_mm", s.patch.walls_reject_mm, 0, 10);
        s.patch.walls_shorten = static_cast<int>(o.num("walls_shorten", s.patch.walls_shorten, 0, 20));
        s.patch.walls_newton = static_cast<int>(o.num("walls_newton", s.patch.walls_newton, 0, 1000));
        s.patch.friction_cell_mm = o.num("friction_cell_mm", s.patch.friction_cell_mm, 0, 10);
        s.patch.compliance_reuse = static_cast<int>(o.num("compliance_reuse", s.patch.compliance_reuse, 0, 1e6));
        o.done();
    }
    if (top.has("haptic")) {
        Obj o(top.at("haptic"), "haptic", path);
        s.plane_stiffness_n_per_mm = o.num("plane_stiffness_n_per_mm", s.plane_stiffness_n_per_mm, 0, 1e4);
        s.friction_n_s_per_mm = o.num("friction_n_s_per_mm", s.friction_n_s_per_mm, 0, 1e3);
        s.obstacle_stiffness_n_per_mm = o.num("obstacle_stiffness_n_per_mm", s.obstacle_stiffness_n_per_mm, 0, 1e4);
        s.friction_depth_mm = o.num("friction_depth_mm", s.friction_depth_mm, 1e-6, 10);
        s.approach_margin_mm = o.num("approach_margin_mm", s.approach_margin_mm, 0, 20);
        o.done();
    }
    if (top.has("rates_hz")) {
        Obj o(top.at("rates_hz"), "rates_hz", path);
        s.haptic_hz = o.num("haptic", s.haptic_hz, 1, 1e5);
        s.physics_hz = o.num("physics", s.physics_hz, 1, s.haptic_hz);
        s.log_hz = o.num("log", s.log_hz, 0.01, s.haptic_hz);
        s.series_hz = o.num("series", s.series_hz, 0, s.haptic_hz);
        s.region_hz = o.num("region", s.region_hz, 0.01, s.haptic_hz);
        o.done();
    }
    if (top.has("assessment")) {
        Obj o(top.at("assessment"), "assessment", path);
        s.force_threshold_n = o.num("force_threshold_n", s.force_threshold_n, 0, 1e4);
        s.velocity_threshold_mm_s = o.num("velocity_threshold_mm_s", s.velocity_threshold_mm_s, 0, 1e6);
        s.neck_tolerance_mm = o.num("neck_tolerance_mm", s.neck_tolerance_mm, 0, 10);
        s.neck_gap_mm = o.num("neck_gap_mm", s.neck_gap_mm, 0, 5);
        o.done();
    }
    if (top.has("outputs")) {
        Obj o(top.at("outputs"), "outputs", path);
        s.log = resolve(dir, o.str("log", ""));
        s.haptic_log = resolve(dir, o.str("haptic_log", ""));
        s.series = resolve(dir, o.str("series", ""));
        s.report = resolve(dir, o.str("report", ""));
        s.flow = resolve(dir, o.str("flow", ""));
        if (!s.flow.empty() && s.series.empty()) o.fail("\"flow\" needs \"series\": the residual flow is computed on the series' last frame");
        o.done();
    }
    s.duration_s = top.num("duration_s", 0.0, 0.0, 1e6);
    s.live_input = top.flag("live_input", false);
    if (top.has("obstacles")) {
        const json& arr = top.at("obstacles");
        if (!arr.is_array()) top.fail("\"obstacles\" must be an array");
        for (size_t i = 0; i < arr.size(); ++i) {
            Obj o(arr[i], "obstacles[" + std::to_string(i) + "]", path);
            ObstacleSpec ob;
            ob.name = o.str("name", "obstacle" + std::to_string(i));
            ob.mesh_file = resolve(dir, o.str("mesh", "", true));
            ob.mesh = read_trimesh(ob.mesh_file);
            o.done();
            s.obstacles.push_back(std::move(ob));
        }
    }
    const json& arr = top.at("instruments");
    if (!arr.is_array() || arr.empty()) top.fail("\"instruments\" must be a non-empty array");
    std::set<std::string> names;
    for (size_t i = 0; i < arr.size(); ++i) {
        Obj o(arr[i], "instruments[" + std::to_string(i) + "]", path);
        InstrumentSpec ins;
        ins.name = o.str("name", "", true);
        if (!names.insert(ins.name).second) o.fail("instrument name \"" + ins.name + "\" used twice");
        if (!o.has("kind")) o.fail("missing key \"kind\"");
        ins.kind = o.choice("kind", {"clip_applier", "suction"}) == 0 ? InstrumentSpec::Kind::CLIP_APPLIER
                                                                       : InstrumentSpec::Kind::SUCTION;
        ins.radius_mm = o.num("radius_mm", ins.radius_mm, 0.05, 20);
        ins.length_mm = o.num("length_mm", ins.length_mm, 0.1, 500);
        if (o.has("keyframes")) {
            const json& ks = o.at("keyframes");
            if (!ks.is_array()) o.fail("\"keyframes\" must be an array");
            Keyframe prev;
            for (size_t k = 0; k < ks.size(); ++k) {
                Obj ko(ks[k], o.where() + ".keyframes[" + std::to_string(k) + "]", path);
                Keyframe kf;
                kf.t = ko.num("t", 0, 0, 1e6, true);
                if (k > 0 && kf.t <= prev.t) ko.fail("\"t\" = " + std::to_string(kf.t) + " must be after the previous keyframe's");
                const Pose p0 = k > 0 ? prev.pose : Pose{};
                kf.pose.position = ko.vec3("position", p0.position, k == 0);
                kf.pose.axis = ko.vec3("axis", p0.axis, k == 0, true);
                kf.pose.up = ko.vec3("up", p0.up, false, true);
                if (std::abs(kf.pose.up.dot(kf.pose.axis)) > 0.999) ko.fail("\"up\" is parallel to \"axis\"");
                kf.pose = orthonormal(kf.pose);
                kf.opening_deg = ko.num("opening_deg", k > 0 ? prev.opening_deg : 0.0, 0, 120);
                kf.button = ko.flag("button", k > 0 ? prev.button : false);
                kf.load = ko.str("load", "");
                kf.release = ko.flag("release", false);
                kf.grasp = ko.flag("grasp", false);
                if (!kf.load.empty() && !s.clip_models.count(kf.load)) {
                    ko.fail("\"load\" names clip model \"" + kf.load + "\", which clip_models does not define");
                }
                if ((kf.release || kf.grasp || !kf.load.empty()) && ins.kind != InstrumentSpec::Kind::CLIP_APPLIER) {
                    ko.fail("load/release/grasp are actions of a clip_applier");
                }
                ko.done();
                ins.keys.push_back(kf);
                prev = kf;
            }
        }
        if (!s.live_input && ins.keys.empty()) o.fail("\"keyframes\" missing (needed unless the scene has live_input)");
        o.done();
        s.instruments.push_back(std::move(ins));
    }
    if (s.duration_s == 0.0 && !s.live_input) {
        for (const auto& ins : s.instruments) s.duration_s = std::max(s.duration_s, ins.keys.back().t);
    }
    top.done();
    return s;
}

Keyframe sample(const InstrumentSpec& ins, double t) {
    const auto& k = ins.keys;
    if (k.empty()) return {};
    if (t <= k.front().t) return k.front();
    if (t >= k.back().t) return k.back();
    size_t i = 0;
    while (i + 1 < k.size() && k[i + 1].t <= t) ++i;
    const Keyframe& a = k[i];
    const Keyframe& b = k[i + 1];
    const double h = b.t - a.t, s = (t - a.t) / h;
    // Tangents: Catmull–Rom, limited per component so that a coordinate never overshoots its keyframes
    // (monotone cubic, Fritsch–Carlson): zero where the neighbouring segments change direction or one of
    // them does not move, and at the first and last keyframe (the motion starts and stops smoothly).
    auto tangent = [&](size_t j, auto get) -> Eigen::Vector3d {
        if (j == 0 || j + 1 >= k.size()) return Eigen::Vector3d::Zero();
        const Eigen::Vector3d s0 = (get(k[j]) - get(k[j - 1])) / (k[j].t - k[j - 1].t);
        const Eigen::Vector3d s1 = (get(k[j + 1]) - get(k[j])) / (k[j + 1].t - k[j].t);
        Eigen::Vector3d m = (get(k[j + 1]) - get(k[j - 1])) / (k[j + 1].t - k[j - 1].t);
        for (int c = 0; c < 3; ++c) {
            if (s0[c] * s1[c] <= 0) {
                m[c] = 0;
            } else {
                const double lim = 3 * std::min(std::abs(s0[c]), std::abs(s1[c]));
                m[c] = std::copysign(std::min(std::abs(m[c]), lim), m[c]);
            }
        }
        return m;
    };
    auto hermite = [&](auto get) -> Eigen::Vector3d {
        const double s2 = s * s, s3 = s2 * s;
        return (2 * s3 - 3 * s2 + 1) * get(a) + (s3 - 2 * s2 + s) * h * tangent(i, get) + (-2 * s3 + 3 * s2) * get(b) +
               (s3 - s2) * h * tangent(i + 1, get);
    };
    Keyframe out = a;
    out.t = t;
    out.pose.position = hermite([](const Keyframe& q) { return q.pose.position; });
    out.pose.axis = hermite([](const Keyframe& q) { return q.pose.axis; });
    out.pose.up = hermite([](const Keyframe& q) { return q.pose.up; });
    if (out.pose.axis.norm() < 1e-9) out.pose.axis = a.pose.axis;
    out.pose = orthonormal(out.pose);
    out.opening_deg = a.opening_deg + s * (b.opening_deg - a.opening_deg);
    out.button = a.button;
    out.load.clear();
    out.release = out.grasp = false;
    return out;
}

std::optional<LiveSample> parse_live_line(const std::string& line, std::string& why) {
    std::istringstream in(line);
    std::vector<std::string> tok;
    std::string w;
    while (in >> w) tok.push_back(w);
    if (tok.size() < 13) {
        why = "expected `t name px py pz ax ay az ux uy uz opening button [load:MODEL|release|grasp]`, got " +
              std::to_string(tok.size()) + " fields";
        return std::nullopt;
    }
    LiveSample s;
    double v[12];
    const int idx[12] = {0, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
    for (int q = 0; q < 12; ++q) {
        const std::string& f = tok[static_cast<size_t>(idx[q])];
        char* end = nullptr;
        v[q] = std::strtod(f.c_str(), &end);
        if (end == f.c_str() || *end != '\0') {
            why = "field " + std::to_string(idx[q] + 1) + " \"" + f + "\" is not a number";
            return std::nullopt;
        }
        if (!std::isfinite(v[q])) {
            why = "field " + std::to_string(idx[q] + 1) + " is " + f + " (not finite)";
            return std::nullopt;
        }
    }
    s.t = v[0];
    s.instrument = tok[1];
    s.key.t = v[0];
    s.key.pose.position = Eigen::Vector3d(v[1], v[2], v[3]);
    s.key.pose.axis = Eigen::Vector3d(v[4], v[5], v[6]);
    s.key.pose.up = Eigen::Vector3d(v[7], v[8], v[9]);
    if (s.key.pose.axis.norm() < 1e-9 || s.key.pose.up.cross(s.key.pose.axis).norm() < 1e-9 * s.key.pose.up.norm()) {
        why = "axis is zero or parallel to up";
        return std::nullopt;
    }
    s.key.pose = orthonormal(s.key.pose);
    s.key.opening_deg = v[10];
    if (v[11] != 0.0 && v[11] != 1.0) {
        why = "button must be 0 or 1";
        return std::nullopt;
    }
    s.key.button = v[11] != 0.0;
    for (size_t q = 13; q < tok.size(); ++q) {
        if (tok[q] == "release") {
            s.key.release = true;
        } else if (tok[q] == "grasp") {
            s.key.grasp = true;
        } else if (tok[q].rfind("load:", 0) == 0) {
            s.key.load = tok[q].substr(5);
        } else {
            why = "unknown action \"" + tok[q] + "\" (expected load:MODEL, release or grasp)";
            return std::nullopt;
        }
    }
    return s;
}

LiveReader::LiveReader(std::istream& in, std::function<int(const std::string&)> instrument_index)
    : LiveReader([&in](std::string& line) { return std::getline(in, line) ? Fetch::LINE : Fetch::END; }, std::move(instrument_index)) {}

LiveReader::LiveReader(Source source, std::function<int(const std::string&)> instrument_index) : m_source(std::move(source)), m_index(std::move(instrument_index)) {}

std::optional<LiveReader::Sample> LiveReader::next(const std::function<void(long, const std::string&)>& skipped) {
    std::string line;
    while (!m_ended) {
        const Fetch f = m_source(line);
        if (f == Fetch::NONE_NOW) return std::nullopt;
        if (f == Fetch::END) {
            m_ended = true;
            break;
        }
        ++m_line;
        const auto first = line.find_first_not_of(" \t\r");
        if (first == std::string::npos || line[first] == '#') continue;
        std::string why;
        const auto s = parse_live_line(line, why);
        int idx = -1;
        if (s) {
            idx = m_index(s->instrument);
            if (idx < 0) why = "unknown instrument \"" + s->instrument + "\"";
            else if (s->t + 1e-12 < m_t) why = "time " + std::to_string(s->t) + " s goes back (the stream was at " + std::to_string(m_t) + " s)";
        }
        if (!s || !why.empty()) {
            skipped(m_line, why);
            continue;
        }
        m_t = s->t;
        return Sample{*s, idx};
    }
    return std::nullopt;
}

}  // namespace aneu::sim
