// SPDX-License-Identifier: MIT
// `aneuprep flow`: the lumen's blood domain, an OpenFOAM case (blockMesh + snappyHexMesh with prism layers at the
// wall, simpleFoam laminar and Newtonian), run as child processes with a time budget, and its results read back:
// flow and mean pressure per end, wall shear stress and pressure on the lumen's faces.
#include "aneu/pipeline/flow.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include <unistd.h>

#include <Eigen/Geometry>
#include <H5Cpp.h>

#include "aneu/core/bundle_io.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/label_loops.hpp"
#include "aneu/core/program.hpp"
#include "aneu/core/text.hpp"
#include "aneu/fem/static_solve.hpp"
#include "aneu/pipeline/surface_ops.hpp"
#include "aneu/pipeline/tetmesh.hpp"
#include "stage_util.hpp"

namespace fs = std::filesystem;

namespace aneu::pipeline {

namespace {

constexpr double PI = 3.14159265358979323846;

double tri_area(const SurfaceData& s, Eigen::Index f) {
    const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    return 0.5 * (b - a).cross(c - a).norm();
}

// ---------------------------------------------------------------- child processes

/// Runs an OpenFOAM tool in the case folder `dir`, its output into `log`; `on_output` sees each line as it comes.
/// Killed at `deadline`: a stage failure.
int run_logged(const std::vector<std::string>& argv, const fs::path& dir, const fs::path& log,
               std::chrono::steady_clock::time_point deadline, const std::function<void(const std::string&)>& on_output) {
    const ProgramExit e = run_program({argv, dir.string(), log.string(), deadline, on_output});
    if (e.timed_out) throw Error("flow: " + argv[0] + " stopped: past the time budget (--time-budget-s); its log: " + log.string());
    if (e.code == 127) throw Error("flow: " + argv[0] + " not found (OpenFOAM: apt-get install openfoam)");
    return e.code;
}

// ---------------------------------------------------------------- OpenFOAM ASCII fields

/// The text of a field file, its FoamFile header and comments removed.
std::string read_text(const fs::path& p) {
    std::ifstream in(p);
    if (!in) throw Error("flow: OpenFOAM wrote no " + p.string());
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

/// Parses `value`/`internalField` data at `pos` (after the keyword): "uniform x", "uniform (x y z)" or
/// "nonuniform List<T> N ( ... )"; k = 1 or 3 numbers per entry; n = the expected count for "uniform".
std::vector<double> parse_field_data(const std::string& t, size_t pos, int k, size_t n_uniform) {
    while (pos < t.size() && std::isspace(static_cast<unsigned char>(t[pos]))) ++pos;
    std::vector<double> out;
    auto read_numbers = [&](size_t& q, int count, std::vector<double>& dst) {
        for (int i = 0; i < count; ++i) {
            while (q < t.size() && (std::isspace(static_cast<unsigned char>(t[q])) || t[q] == '(' || t[q] == ')')) ++q;
            char* end = nullptr;
            const double v = std::strtod(t.c_str() + q, &end);
            if (end == t.c_str() + q) throw Error("flow: cannot read an OpenFOAM field (a number expected)");
            dst.push_back(v);
            q = static_cast<size_t>(end - t.c_str());
        }
    };
    if (t.compare(pos, 7, "uniform") == 0) {
        size_t q = pos + 7;
        std::vector<double> one;
        read_numbers(q, k, one);
        for (size_t i = 0; i < n_uniform; ++i) out.insert(out.end(), one.begin(), one.end());
        return out;
    }
    if (t.compare(pos, 10, "nonuniform") != 0) throw Error("flow: cannot read an OpenFOAM field (uniform or nonuniform expected)");
    size_t q = t.find('>', pos);
    if (q == std::string::npos) throw Error("flow: cannot read an OpenFOAM field (List<...> expected)");
    ++q;
    char* end = nullptr;
    const long count = std::strtol(t.c_str() + q, &end, 10);
    q = static_cast<size_t>(end - t.c_str());
    out.reserve(static_cast<size_t>(count) * static_cast<size_t>(k));
    read_numbers(q, static_cast<int>(count) * k, out);
    return out;
}

/// A field file of the last time folder, read once.
struct FieldFile {
    fs::path path;
    std::string text;
    explicit FieldFile(fs::path p) : path(std::move(p)), text(read_text(path)) {}
    std::vector<double> internal(int k, size_t n) const;
    std::vector<double> patch(const std::string& name, int k, size_t n) const;
};

/// internalField of a field file.
std::vector<double> FieldFile::internal(int k, size_t n) const {
    const std::string& t = text;
    const fs::path& p = path;
    const size_t pos = t.find("internalField");
    if (pos == std::string::npos) throw Error("flow: " + p.string() + " has no internalField");
    return parse_field_data(t, pos + 13, k, n);
}

/// The `value` of patch `patch` in a field file's boundaryField.
std::vector<double> FieldFile::patch(const std::string& patch, int k, size_t n) const {
    const std::string& t = text;
    const fs::path& p = path;
    const size_t bf = t.find("boundaryField");
    if (bf == std::string::npos) throw Error("flow: " + p.string() + " has no boundaryField");
    size_t pos = bf;
    while (true) {
        pos = t.find(patch, pos);
        if (pos == std::string::npos) throw Error("flow: " + p.string() + " has no patch '" + patch + "'");
        const bool word_start = !(std::isalnum(static_cast<unsigned char>(t[pos - 1])) || t[pos - 1] == '_');
        const size_t after = pos + patch.size();
        const bool word_end = after < t.size() && !(std::isalnum(static_cast<unsigned char>(t[after])) || t[after] == '_');
        if (word_start && word_end) break;
        pos = after;
    }
    const size_t open = t.find('{', pos), close = t.find('}', open);
    const size_t v = t.find("value", open);
    if (v == std::string::npos || v > close) throw Error("flow: " + p.string() + ": patch '" + patch + "' has no value");
    return parse_field_data(t, v + 5, k, n);
}

/// A labelList file of the mesh (constant/polyMesh/owner, neighbour): "N ( i0 i1 ... )" after the header.
std::vector<int> read_label_list(const fs::path& p) {
    const std::string t = read_text(p);
    const size_t hdr = t.find("FoamFile");
    const size_t start = hdr == std::string::npos ? 0 : t.find('}', hdr) + 1;
    const size_t open = t.find('(', start);
    if (open == std::string::npos) throw Error("flow: " + p.string() + ": no list");
    size_t e = open;
    while (e > start && std::isspace(static_cast<unsigned char>(t[e - 1]))) --e;
    size_t b = e;
    while (b > start && std::isdigit(static_cast<unsigned char>(t[b - 1]))) --b;
    if (b == e) throw Error("flow: " + p.string() + ": no list size");
    const long n = std::strtol(t.c_str() + b, nullptr, 10);
    std::vector<int> out;
    out.reserve(static_cast<size_t>(n));
    const char* q = t.c_str() + open + 1;
    for (long i = 0; i < n; ++i) {
        char* end = nullptr;
        const long v = std::strtol(q, &end, 10);
        if (end == q) throw Error("flow: " + p.string() + ": fewer than " + std::to_string(n) + " labels");
        out.push_back(static_cast<int>(v));
        q = end;
    }
    return out;
}

/// The last value in column `col` of a function object's .dat file (# comments skipped).
double last_dat_value(const fs::path& p, int col) {
    std::ifstream in(p);
    if (!in) throw Error("flow: OpenFOAM wrote no " + p.string());
    std::string line, last;
    while (std::getline(in, line))
        if (!line.empty() && line[0] != '#') last = line;
    std::istringstream ls(last);
    double v = 0;
    for (int i = 0; i <= col; ++i)
        if (!(ls >> v)) throw Error("flow: " + p.string() + ": no column " + std::to_string(col));
    return v;
}

/// Nearest of a point set, on a uniform bucket grid.
class NearestPoint {
public:
    NearestPoint(const std::vector<Eigen::Vector3d>& pts, double cell) : m_pts(pts), m_h(cell) {
        for (size_t i = 0; i < pts.size(); ++i) m_grid[key(cell_of(pts[i]))].push_back(static_cast<int>(i));
    }
    int nearest(const Eigen::Vector3d& x) const {
        const Eigen::Vector3i c = cell_of(x);
        int best = -1;
        double bd = 1e300;
        for (int r = 0; r < 64 && (best < 0 || (r - 1) * m_h < std::sqrt(bd)); ++r)
            for (int i = -r; i <= r; ++i)
                for (int j = -r; j <= r; ++j)
                    for (int k = -r; k <= r; ++k) {
                        if (std::max({std::abs(i), std::abs(j), std::abs(k)}) != r) continue;
                        const auto it = m_grid.find(key(c + Eigen::Vector3i(i, j, k)));
                        if (it == m_grid.end()) continue;
                        for (int q : it->second) {
                            const double d = (m_pts[static_cast<size_t>(q)] - x).squaredNorm();
                            if (d < bd) {
                                bd = d;
                                best = q;
                            }
                        }
                    }
        return best;
    }

    /// The points within r of x (r at most the bucket size).
    void within(const Eigen::Vector3d& x, double r, std::vector<int>& out) const {
        out.clear();
        const Eigen::Vector3i c = cell_of(x);
        for (int i = -1; i <= 1; ++i)
            for (int j = -1; j <= 1; ++j)
                for (int k = -1; k <= 1; ++k) {
                    const auto it = m_grid.find(key(c + Eigen::Vector3i(i, j, k)));
                    if (it == m_grid.end()) continue;
                    for (int q : it->second)
                        if ((m_pts[static_cast<size_t>(q)] - x).squaredNorm() <= r * r) out.push_back(q);
                }
    }

private:
    Eigen::Vector3i cell_of(const Eigen::Vector3d& x) const { return (x / m_h).array().floor().cast<int>(); }
    static std::int64_t key(const Eigen::Vector3i& c) {
        return (static_cast<std::int64_t>(c.x() + (1 << 20)) << 42) ^ (static_cast<std::int64_t>(c.y() + (1 << 20)) << 21) ^ (c.z() + (1 << 20));
    }
    const std::vector<Eigen::Vector3d>& m_pts;
    double m_h;
    std::unordered_map<std::int64_t, std::vector<int>> m_grid;
};

std::vector<Eigen::Vector3d> as_points(const std::vector<double>& v, double scale) {
    std::vector<Eigen::Vector3d> p(v.size() / 3);
    for (size_t i = 0; i < p.size(); ++i) p[i] = scale * Eigen::Vector3d(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    return p;
}

std::string foam_header(const std::string& cls, const std::string& object) {
    return "FoamFile { version 2.0; format ascii; class " + cls + "; object " + object + "; }\n";
}

void write_file(const fs::path& p, const std::string& text) {
    std::ofstream out(p);
    out << text;
    if (!out) throw IoError("flow: cannot write " + p.string());
}

std::string num(double x) {
    std::ostringstream s;
    s.precision(10);
    s << x;
    return s.str();
}

std::string vec(const Eigen::Vector3d& v) { return "(" + num(v.x()) + " " + num(v.y()) + " " + num(v.z()) + ")"; }

/// An ASCII STL with one solid per label (the patch names).
void write_stl_regions(const fs::path& p, const SurfaceData& s) {
    std::ofstream out(p);
    out.precision(10);
    for (size_t l = 0; l < s.label_names.size(); ++l) {
        out << "solid " << s.label_names[l] << "\n";
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            if (s.face_label[f] != static_cast<int>(l)) continue;
            const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
            const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
            out << "facet normal " << n.x() << " " << n.y() << " " << n.z() << "\n outer loop\n";
            for (const auto* v : {&a, &b, &c}) out << "  vertex " << v->x() << " " << v->y() << " " << v->z() << "\n";
            out << " endloop\nendfacet\n";
        }
        out << "endsolid " << s.label_names[l] << "\n";
    }
    if (!out) throw IoError("flow: cannot write " + p.string());
}

struct EndCap {
    int id = 0;
    std::string patch;
    double area_mm2 = 0;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(), normal = Eigen::Vector3d::Zero();  // normal out of the domain
};

std::vector<EndCap> caps_of(const SurfaceData& blood) {
    std::vector<EndCap> caps;
    for (size_t l = 1; l < blood.label_names.size(); ++l) {
        EndCap c;
        c.patch = blood.label_names[l];
        c.id = std::stoi(c.patch.substr(4));
        Eigen::Vector3d an = Eigen::Vector3d::Zero();
        for (Eigen::Index f = 0; f < blood.F.rows(); ++f) {
            if (blood.face_label[f] != static_cast<int>(l)) continue;
            const Eigen::Vector3d a = blood.V.row(blood.F(f, 0)), b = blood.V.row(blood.F(f, 1)), cc = blood.V.row(blood.F(f, 2));
            const Eigen::Vector3d n2 = (b - a).cross(cc - a);
            an += 0.5 * n2;
            c.centre += 0.5 * n2.norm() * (a + b + cc) / 3.0;
            c.area_mm2 += 0.5 * n2.norm();
        }
        c.centre /= c.area_mm2;
        c.normal = an.normalized();
        caps.push_back(c);
    }
    return caps;
}

/// The neck of the labelled sac: the longest loop of edges between sac ("aneurysm") and artery faces, its
/// centroid, the area of the fan it spans and the direction into the sac. Area 0 when there is no sac.
struct SacNeck {
    std::vector<Eigen::Vector3d> loop;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(), into_sac = Eigen::Vector3d::Zero();
    double area_mm2 = 0;
    int sac_label = -1;
};

SacNeck sac_neck(const SurfaceData& s) {
    SacNeck n;
    const auto it = std::find(s.label_names.begin(), s.label_names.end(), "aneurysm");
    if (it == s.label_names.end() || s.face_label.size() != s.F.rows()) return n;
    const int sac = static_cast<int>(it - s.label_names.begin());
    Eigen::Vector3d sac_c = Eigen::Vector3d::Zero();
    double sac_a = 0;
    for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
        if (s.face_label[f] != sac) continue;
        const double a = tri_area(s, f);
        sac_c += a * (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3.0;
        sac_a += a;
    }
    if (sac_a <= 0) return n;
    sac_c /= sac_a;
    // The neck: the longest border loop of the sac (the simulator's neck line, aneu/core/label_loops.hpp).
    std::vector<int> best;
    double best_len = 0;
    for (const auto& loop : label_border_loops(s.F, s.face_label, sac)) {
        double len = 0;
        for (size_t i = 0; i < loop.size(); ++i) len += (s.V.row(loop[(i + 1) % loop.size()]) - s.V.row(loop[i])).norm();
        if (len > best_len) {
            best_len = len;
            best = loop;
        }
    }
    if (best.size() < 3) return n;
    for (int v : best) {
        n.loop.push_back(s.V.row(v).transpose());
        n.centre += n.loop.back();
    }
    n.centre /= static_cast<double>(best.size());
    for (size_t i = 0; i < n.loop.size(); ++i) n.area_mm2 += 0.5 * (n.loop[i] - n.centre).cross(n.loop[(i + 1) % n.loop.size()] - n.centre).norm();
    n.into_sac = (sac_c - n.centre).normalized();
    n.sac_label = sac;
    return n;
}

}  // namespace

SurfaceData blood_domain(const SurfaceData& lumen) {
    const Eigen::Index nloops = lumen.loop_end_id.size();
    if (nloops == 0 || lumen.loop_offsets.size() != nloops + 1)
        throw InputError("flow: the lumen has no open end: without an inlet there is no flow (a lumen from `aneuprep surface` has one per end plane)");
    SurfaceData b;
    b.label_names = {"wall"};
    const Eigen::Index nv0 = lumen.V.rows(), nf0 = lumen.F.rows();
    // Directed edges of the lumen: a loop edge a→b that a face has runs b→a in the cap.
    std::set<std::pair<int, int>> directed;
    for (Eigen::Index f = 0; f < nf0; ++f)
        for (int k = 0; k < 3; ++k) directed.insert({lumen.F(f, k), lumen.F(f, (k + 1) % 3)});
    std::vector<Eigen::RowVector3d> extra_v;
    std::vector<Eigen::RowVector3i> extra_f;
    std::vector<int> extra_l;
    for (Eigen::Index l = 0; l < nloops; ++l) {
        const int o0 = lumen.loop_offsets[l], o1 = lumen.loop_offsets[l + 1];
        if (o1 - o0 < 3) throw InputError("flow: end " + std::to_string(lumen.loop_end_id[l]) + "'s loop has fewer than 3 vertices");
        Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
        for (int i = o0; i < o1; ++i) c += lumen.V.row(lumen.loop_vertices[i]);
        c /= static_cast<double>(o1 - o0);
        const int ci = static_cast<int>(nv0 + static_cast<Eigen::Index>(extra_v.size()));
        extra_v.push_back(c);
        b.label_names.push_back("end_" + std::to_string(lumen.loop_end_id[l]));
        for (int i = o0; i < o1; ++i) {
            const int a = lumen.loop_vertices[i], bb = lumen.loop_vertices[i + 1 < o1 ? i + 1 : o0];
            extra_f.push_back(directed.count({a, bb}) ? Eigen::RowVector3i(ci, bb, a) : Eigen::RowVector3i(ci, a, bb));
            extra_l.push_back(static_cast<int>(l) + 1);
        }
    }
    b.V.resize(nv0 + static_cast<Eigen::Index>(extra_v.size()), 3);
    b.V.topRows(nv0) = lumen.V;
    for (size_t i = 0; i < extra_v.size(); ++i) b.V.row(nv0 + static_cast<Eigen::Index>(i)) = extra_v[i];
    b.F.resize(nf0 + static_cast<Eigen::Index>(extra_f.size()), 3);
    b.F.topRows(nf0) = lumen.F;
    b.face_label = Eigen::VectorXi::Zero(b.F.rows());
    for (size_t i = 0; i < extra_f.size(); ++i) {
        b.F.row(nf0 + static_cast<Eigen::Index>(i)) = extra_f[i];
        b.face_label[nf0 + static_cast<Eigen::Index>(i)] = extra_l[i];
    }
    check_closed_surface(b, "flow: the blood domain (the lumen closed by a flat cap at each end)");
    return b;
}

namespace {

/// What one solve gives: the QA figures, the blood surface with its face fields, the flows of interest.
struct Solved {
    std::vector<std::pair<std::string, double>> qa;
    SurfaceData blood;
    FlowFieldData field;
    double inflow_m3_s = 0, sac_inflow_m3_s = -1;  // -1: no sac
    double seconds = 0;
};

/// The capped lumen's part reachable from `seed` as a clean closed surface, its faces labelled like the capped
/// surface's: a face in a cap's plane (within 0.6 of the grid's spacing, normal within 25°) and disc is that end's.
/// Ends that the reachable part does not touch are dropped from the labels (returned in `lost`).
SurfaceData reachable_blood(const SurfaceData& capped, const std::vector<EndCap>& caps, const Eigen::Vector3d& seed, double g, Volume<float>& field,
                            std::vector<int>& lost, Reporter& rep) {
    ReachableStats st;
    constexpr std::size_t MAX_VOXELS = 150'000'000;  // about 1.5 GB of grids
    field = reachable_distance(capped, seed, g, MAX_VOXELS, &st);
    SurfaceData iso = isosurface(field, 0.0, true, true);
    std::vector<double> rmax(caps.size(), 0);
    for (Eigen::Index f = 0; f < capped.F.rows(); ++f) {
        const int l = capped.face_label[f];
        if (l <= 0) continue;
        for (int k = 0; k < 3; ++k)
            rmax[static_cast<size_t>(l - 1)] = std::max(rmax[static_cast<size_t>(l - 1)], (capped.V.row(capped.F(f, k)).transpose() - caps[static_cast<size_t>(l - 1)].centre).norm());
    }
    iso.face_label = Eigen::VectorXi::Zero(iso.F.rows());
    std::vector<Eigen::Index> count(caps.size(), 0);
    for (Eigen::Index f = 0; f < iso.F.rows(); ++f) {
        const Eigen::Vector3d a = iso.V.row(iso.F(f, 0)), b = iso.V.row(iso.F(f, 1)), c = iso.V.row(iso.F(f, 2));
        const Eigen::Vector3d x = (a + b + c) / 3.0, n = (b - a).cross(c - a).normalized();
        for (size_t e = 0; e < caps.size(); ++e) {
            const double off = caps[e].normal.dot(x - caps[e].centre);
            if (std::abs(off) > 0.6 * g || n.dot(caps[e].normal) < std::cos(25 * PI / 180)) continue;
            if ((x - caps[e].centre - off * caps[e].normal).norm() > rmax[e] + g) continue;
            iso.face_label[f] = static_cast<int>(e) + 1;
            ++count[e];
            break;
        }
    }
    // Labels of the ends reached, renumbered.
    iso.label_names = {"wall"};
    std::vector<int> relabel(caps.size() + 1, 0);
    for (size_t e = 0; e < caps.size(); ++e) {
        if (count[e] == 0) {
            lost.push_back(caps[e].id);
            continue;
        }
        iso.label_names.push_back(caps[e].patch);
        relabel[e + 1] = static_cast<int>(iso.label_names.size()) - 1;
    }
    for (Eigen::Index f = 0; f < iso.F.rows(); ++f) iso.face_label[f] = relabel[static_cast<size_t>(iso.face_label[f])];
    rep.info("flow: reachable blood domain on a " + std::to_string(field.grid.size[0]) + "x" + std::to_string(field.grid.size[1]) + "x" +
             std::to_string(field.grid.size[2]) + " grid of " + shortest(g) + " mm: " + std::to_string(st.reachable) + " voxels reached, " +
             std::to_string(st.blocked) + " of " + std::to_string(st.segment_tests) + " links near the wall blocked; " + std::to_string(iso.F.rows()) +
             " triangles");
    return iso;
}

/// Meshes and solves one lumen in `dir`. `what` names it in the log ("pre-clip", "frame 12").
Solved solve_lumen(const SurfaceData& lumen, const FlowParams& p, bool voxel, const fs::path& dir, bool keep, const std::string& out,
                   std::chrono::steady_clock::time_point deadline, Reporter& rep, const std::string& what) {
    const Stopwatch t0;
    Solved res;
    SurfaceData blood = blood_domain(lumen);
    std::vector<EndCap> caps = caps_of(blood);
    if (caps.size() < 2) throw InputError("flow: the lumen has one open end: the blood needs an inlet and at least one outlet");
    // The inlet.
    size_t inlet = 0;
    if (p.inlet_end >= 0) {
        const auto f = std::find_if(caps.begin(), caps.end(), [&](const EndCap& c) { return c.id == p.inlet_end; });
        if (f == caps.end()) {
            std::string ids;
            for (const auto& c : caps) ids += (ids.empty() ? "" : ", ") + std::to_string(c.id);
            throw InputError("flow: --inlet-end " + std::to_string(p.inlet_end) + ": the lumen has no such end (its ends: " + ids + ")");
        }
        inlet = static_cast<size_t>(f - caps.begin());
    } else {
        for (size_t i = 1; i < caps.size(); ++i)
            if (caps[i].area_mm2 > caps[inlet].area_mm2) inlet = i;
    }
    // Cells: an eighth of the inlet's radius (the parent vessel; a real tree's smallest outlets would make the
    // mesh 10× larger: C0096 at a fifth of its 0.4 mm outlet, 1.3 M cells and 510 s of snappyHexMesh).
    const double h = p.cell_mm > 0 ? p.cell_mm : std::clamp(std::sqrt(caps[inlet].area_mm2 / PI) / 8.0, 0.1, 0.3);
    // A point inside the blood: from the inlet's centre, inwards, off the cell faces.
    const EndCap ic = caps[inlet];
    const Eigen::Vector3d inside =
        ic.centre - ic.normal * std::min(0.5 * std::sqrt(ic.area_mm2 / PI), 4 * h) + Eigen::Vector3d(0.0137, 0.0291, 0.0173) * h;
    const double lumen_volume = enclosed_volume(blood);
    // The reachable part (a pinched lumen), on a grid of half cells.
    Volume<float> field;
    if (voxel) {
        std::vector<int> lost;
        blood = reachable_blood(blood, caps, inside, 0.5 * h, field, lost, rep);
        std::vector<EndCap> kept;
        for (const EndCap& c : caps)
            if (std::find(lost.begin(), lost.end(), c.id) == lost.end()) kept.push_back(c);
        if (std::find(lost.begin(), lost.end(), ic.id) != lost.end())
            throw Error("flow: " + what + ": the inlet end " + std::to_string(ic.id) + " is not part of the reachable blood domain");
        if (kept.size() < 2)
            throw Error("flow: " + what + ": no outlet is reachable from the inlet end " + std::to_string(ic.id) +
                        ": the lumen is closed off (the parent vessel occluded); nothing to solve");
        if (!lost.empty()) {
            std::string ids;
            for (int id : lost) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
            rep.warn("flow: " + what + ": the ends " + ids + " are not reachable from the inlet (closed off): no flow through them");
        }
        // The caps as the clean surface has them (areas of the isosurface's cap faces).
        const std::vector<EndCap> measured = caps_of(blood);
        caps = measured;
        inlet = static_cast<size_t>(std::find_if(caps.begin(), caps.end(), [&](const EndCap& c) { return c.id == ic.id; }) - caps.begin());
        // The cap's plane and centre are the lumen's (the isosurface rounds the rim by a grid cell).
        for (EndCap& c : caps)
            for (const EndCap& o : kept)
                if (o.id == c.id) {
                    c.normal = o.normal;
                    c.centre = o.centre;
                }
        res.qa.emplace_back("ends_closed_off", static_cast<double>(lost.size()));
    }
    // Outlets narrower than three cells across cannot be meshed (snappyHexMesh cuts the branch off before its end):
    // they are closed as wall, with a warning. By Murray's law they carry (r/R)³ of the flow: a 0.25 mm branch off
    // a 2.7 mm parent, 0.08 %.
    {
        std::vector<int> closed;
        std::vector<int> relabel(blood.label_names.size(), 0);
        std::vector<std::string> names = {"wall"};
        std::vector<EndCap> kept;
        for (const EndCap& c : caps) {
            const double r = std::sqrt(c.area_mm2 / PI);
            const auto l = static_cast<size_t>(std::find(blood.label_names.begin(), blood.label_names.end(), c.patch) - blood.label_names.begin());
            if (c.id != ic.id && r < 1.5 * h) {
                closed.push_back(c.id);
                rep.warn("flow: " + what + ": end " + std::to_string(c.id) + " (radius " + shortest(std::round(r * 100) / 100) + " mm) is narrower than three " +
                         shortest(h) + " mm cells: closed as wall (by Murray's law " + shortest(std::round(std::pow(r / std::sqrt(ic.area_mm2 / PI), 3) * 1e4) / 100) +
                         " % of the flow; --cell-mm " + shortest(std::floor(r / 1.5 * 1000) / 1000) + " keeps it open)");
                continue;
            }
            if (l < relabel.size()) relabel[l] = static_cast<int>(names.size());
            names.push_back(c.patch);
            kept.push_back(c);
        }
        if (!closed.empty()) {
            for (Eigen::Index f = 0; f < blood.F.rows(); ++f) blood.face_label[f] = relabel[static_cast<size_t>(blood.face_label[f])];
            blood.label_names = names;
            caps = kept;
            inlet = static_cast<size_t>(std::find_if(caps.begin(), caps.end(), [&](const EndCap& c) { return c.id == ic.id; }) - caps.begin());
            if (caps.size() < 2)
                throw InputError("flow: " + what + ": every outlet is narrower than three " + shortest(h) + " mm cells: give a smaller --cell-mm");
        }
        res.qa.emplace_back("ends_closed_as_wall", static_cast<double>(closed.size()));
    }
    const double domain_volume = enclosed_volume(blood);
    res.qa.emplace_back("domain_voxel", voxel ? 1.0 : 0.0);
    res.qa.emplace_back("lumen_volume_mm3", lumen_volume);
    res.qa.emplace_back("domain_volume_mm3", domain_volume);
    // Background box of cells 4h (snappyHexMesh refines twice, to h, at the wall and everywhere inside the blood,
    // so the cell count follows the lumen's volume, not its box), a coarse cell of margin. Refuse an impossible
    // size before any work: the lumen's volume in cells of h.
    const double hb = 4 * h;
    Eigen::Vector3d lo = blood.V.colwise().minCoeff().transpose(), hi = blood.V.colwise().maxCoeff().transpose();
    lo.array() -= hb;
    hi.array() += hb;
    const Eigen::Vector3i nb = ((hi - lo) / hb).array().ceil().cast<int>();
    const double n_cells = domain_volume / (h * h * h);
    constexpr double MAX_CELLS = 4e6;
    if (n_cells > MAX_CELLS)
        throw InputError("flow: --cell-mm " + shortest(h) + " in a lumen of " + shortest(std::round(domain_volume)) + " mm³ means " +
                         shortest(std::round(n_cells / 1e5) / 10) + " million cells (at most " + shortest(MAX_CELLS / 1e6) +
                         " million on this machine class): give a larger --cell-mm");
    rep.info("flow: " + what + ": blood domain " + std::to_string(blood.F.rows()) + " triangles, " + std::to_string(caps.size()) + " ends, inlet end " +
             std::to_string(caps[inlet].id) + " (" + shortest(std::round(caps[inlet].area_mm2 * 100) / 100) + " mm²); cells " + shortest(h) + " mm, " +
             std::to_string(p.layers) + " wall layers");

    // The case folder.
    std::error_code ec;
    fs::remove_all(dir, ec);
    fs::create_directories(dir / "system");
    fs::create_directories(dir / "constant" / "triSurface");
    fs::create_directories(dir / "0");
    write_file(dir / "case.foam", "");
    write_stl_regions(dir / "constant" / "triSurface" / "blood.stl", blood);
    const double nu = BLOOD_VISCOSITY_PA_S / BLOOD_DENSITY_KG_M3;
    const double U = p.inflow_cm_s / 100.0;
    {
        std::string s = foam_header("dictionary", "blockMeshDict") + "convertToMeters 0.001;\nvertices (";
        for (int k = 0; k < 8; ++k) {
            const Eigen::Vector3d v(k & 1 ? lo.x() + nb.x() * hb : lo.x(), k & 2 ? lo.y() + nb.y() * hb : lo.y(), k & 4 ? lo.z() + nb.z() * hb : lo.z());
            s += vec(v) + " ";
        }
        s += ");\nblocks (hex (0 1 3 2 4 5 7 6) (" + std::to_string(nb.x()) + " " + std::to_string(nb.y()) + " " + std::to_string(nb.z()) +
             ") simpleGrading (1 1 1));\nedges ();\nboundary ();\n";
        write_file(dir / "system" / "blockMeshDict", s);
    }
    {
        // Each cap refined until its radius spans three cells at least (a real tree's small outlets are narrower
        // than the parent's cells: without this snappyHexMesh leaves them a face or none), at most level 5.
        std::string regions, patch_info;
        for (const auto& name : blood.label_names) {
            regions += name + " { name " + name + "; } ";
            if (name == "wall") continue;
            int level = 2;
            for (const EndCap& c : caps)
                if (c.patch == name)
                    while (level < 5 && hb / std::pow(2.0, level) > std::sqrt(c.area_mm2 / PI) / 3) ++level;
            patch_info += name + " { level (" + std::to_string(level) + " " + std::to_string(level) + "); patchInfo { type patch; } } ";
        }
        std::string s = foam_header("dictionary", "snappyHexMeshDict");
        s += "castellatedMesh true; snap true; addLayers " + std::string(p.layers > 0 ? "true" : "false") + ";\n";
        s += "geometry { blood.stl { type triSurfaceMesh; scale 0.001; name blood; regions { " + regions + "} } }\n";
        s += "castellatedMeshControls { maxLocalCells 20000000; maxGlobalCells 40000000; minRefinementCells 0; nCellsBetweenLevels 2;\n"
             "  resolveFeatureAngle 30; features ();\n"
             "  refinementSurfaces { blood { level (2 2); patchInfo { type wall; } regions { " + patch_info + "} } }\n"
             "  refinementRegions { blood { mode inside; levels ((1e15 2)); } } locationInMesh " + vec(inside * 1e-3) + "; allowFreeStandingZoneFaces false; }\n";
        s += "snapControls { nSmoothPatch 3; tolerance 2.0; nSolveIter 100; nRelaxIter 5; nFeatureSnapIter 10; implicitFeatureSnap true; explicitFeatureSnap false; }\n";
        s += "addLayersControls { relativeSizes true; layers { wall { nSurfaceLayers " + std::to_string(p.layers) +
             "; } } expansionRatio 1.2; finalLayerThickness 0.4;\n"
             "  minThickness 0.05; nGrow 0; featureAngle 130; slipFeatureAngle 30; nRelaxIter 3; nSmoothSurfaceNormals 1; nSmoothNormals 3;\n"
             "  nSmoothThickness 10; maxFaceThicknessRatio 0.5; maxThicknessToMedialRatio 0.3; minMedialAxisAngle 90; nBufferCellsNoExtrude 0;\n"
             "  nLayerIter 50; }\n";
        s += "meshQualityControls { maxNonOrtho 65; maxBoundarySkewness 20; maxInternalSkewness 4; maxConcave 80; minVol 1e-20; minTetQuality 1e-15;\n"
             "  minArea -1; minTwist 0.02; minDeterminant 0.001; minFaceWeight 0.05; minVolRatio 0.01; minTriangleTwist -1; nSmoothScale 4;\n"
             "  errorReduction 0.75; relaxed { maxNonOrtho 75; } }\nmergeTolerance 1e-6;\n";
        write_file(dir / "system" / "snappyHexMeshDict", s);
        write_file(dir / "system" / "meshQualityDict", foam_header("dictionary", "meshQualityDict") + "#includeEtc \"caseDicts/mesh/generation/meshQualityDict\"\n");
    }
    {
        std::string fo;
        for (const auto& c : caps) {
            fo += "  " + c.patch + "_p { type surfaceFieldValue; libs (\"libfieldFunctionObjects.so\"); regionType patch; name " + c.patch +
                  "; operation areaAverage; fields (p); writeFields false; log false; writeControl timeStep; writeInterval 1; }\n";
            fo += "  " + c.patch + "_phi { type surfaceFieldValue; libs (\"libfieldFunctionObjects.so\"); regionType patch; name " + c.patch +
                  "; operation sum; fields (phi); writeFields false; log false; writeControl timeStep; writeInterval 1; }\n";
        }
        fo += "  wss { type wallShearStress; libs (\"libfieldFunctionObjects.so\"); patches (wall); writeControl writeTime; log false; }\n";
        write_file(dir / "system" / "controlDict", foam_header("dictionary", "controlDict") + "application simpleFoam; startFrom startTime; startTime 0; stopAt endTime; endTime " +
                                                       std::to_string(p.max_iterations) + "; deltaT 1;\nwriteControl timeStep; writeInterval " +
                                                       std::to_string(p.max_iterations) +
                                                       "; purgeWrite 0; writeFormat ascii; writePrecision 10; runTimeModifiable false;\nfunctions {\n" + fo + "}\n");
        write_file(dir / "system" / "fvSchemes", foam_header("dictionary", "fvSchemes") +
                                                     "ddtSchemes { default steadyState; }\ngradSchemes { default Gauss linear; }\n"
                                                     "divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U); div((nuEff*dev2(T(grad(U))))) Gauss linear; }\n"
                                                     "laplacianSchemes { default Gauss linear limited corrected 0.5; }\ninterpolationSchemes { default linear; }\n"
                                                     "snGradSchemes { default limited corrected 0.5; }\nwallDist { method meshWave; }\n");
        write_file(dir / "system" / "fvSolution", foam_header("dictionary", "fvSolution") +
                                                      "solvers {\n  p { solver GAMG; smoother GaussSeidel; tolerance 1e-10; relTol 0.05; }\n"
                                                      "  U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-11; relTol 0.1; }\n}\n"
                                                      "SIMPLE { nNonOrthogonalCorrectors 2; consistent yes; residualControl { p " + num(p.residual) + "; U " +
                                                      num(p.residual / 10) + "; } }\nrelaxationFactors { equations { U 0.9; } }\n");
        // Carreau–Yasuda as OpenFOAM's BirdCarreau with its exponent a (kinematic: μ / ρ).
        const std::string transport =
            p.viscosity == "carreau-yasuda"
                ? "transportModel BirdCarreau;\nBirdCarreauCoeffs { nu0 " + num(CY_MU0_PA_S / BLOOD_DENSITY_KG_M3) + "; nuInf " + num(CY_MUINF_PA_S / BLOOD_DENSITY_KG_M3) +
                      "; k " + num(CY_LAMBDA_S) + "; n " + num(CY_N) + "; a " + num(CY_A) + "; }\n"
                : "transportModel Newtonian; nu " + num(nu) + ";\n";
        write_file(dir / "constant" / "transportProperties", foam_header("dictionary", "transportProperties") + transport);
        write_file(dir / "constant" / "turbulenceProperties", foam_header("dictionary", "turbulenceProperties") + "simulationType laminar;\n");
        std::string ub = "  wall { type noSlip; }\n", pb = "  wall { type zeroGradient; }\n";
        // Murray's law: Q_i = Q r_i³ / Σ r_j³ over the outlets, r from each outlet's area; the largest outlet keeps
        // p = 0 (and so takes its share as the rest).
        const double q_in = U * caps[inlet].area_mm2 * 1e-6;  // m³/s
        double r3_sum = 0;
        size_t largest_out = caps.size();
        for (size_t i = 0; i < caps.size(); ++i) {
            if (i == inlet) continue;
            r3_sum += std::pow(caps[i].area_mm2 / PI, 1.5);
            if (largest_out == caps.size() || caps[i].area_mm2 > caps[largest_out].area_mm2) largest_out = i;
        }
        for (size_t i = 0; i < caps.size(); ++i) {
            if (i == inlet) {
                ub += "  " + caps[i].patch + " { type fixedValue; value uniform " + vec(-U * caps[i].normal) + "; }\n";
                pb += "  " + caps[i].patch + " { type zeroGradient; }\n";
            } else if (p.outlets == "murray" && i != largest_out) {
                const double qi = q_in * std::pow(caps[i].area_mm2 / PI, 1.5) / r3_sum;
                ub += "  " + caps[i].patch + " { type flowRateOutletVelocity; volumetricFlowRate constant " + num(qi) + "; value uniform (0 0 0); }\n";
                pb += "  " + caps[i].patch + " { type zeroGradient; }\n";
            } else {
                ub += "  " + caps[i].patch + " { type inletOutlet; inletValue uniform (0 0 0); value uniform (0 0 0); }\n";
                pb += "  " + caps[i].patch + " { type fixedValue; value uniform 0; }\n";
            }
        }
        write_file(dir / "0" / "U", foam_header("volVectorField", "U") + "dimensions [0 1 -1 0 0 0 0]; internalField uniform (0 0 0);\nboundaryField {\n" + ub + "}\n");
        write_file(dir / "0" / "p", foam_header("volScalarField", "p") + "dimensions [0 2 -2 0 0 0 0]; internalField uniform 0;\nboundaryField {\n" + pb + "}\n");
    }
    const auto ignore = [](const std::string&) {};
    // Mesh.
    const Stopwatch tm;
    rep.info("flow: " + what + ": meshing (blockMesh, snappyHexMesh)");
    if (run_logged({"blockMesh"}, dir, dir / "log.blockMesh", deadline, ignore) != 0)
        throw MeshingError("flow: blockMesh failed (log: " + (dir / "log.blockMesh").string() + (keep ? "" : "; keep it with --case-dir") + ")");
    int snappy_phase = 0;
    if (run_logged({"snappyHexMesh", "-overwrite"}, dir, dir / "log.snappyHexMesh", deadline, [&](const std::string& l) {
            const int ph = l.rfind("Castellated mesh", 0) == 0 ? 1 : l.rfind("Morph input mesh", 0) == 0 ? 2 : l.rfind("Shrinking and layer", 0) == 0 ? 3 : 0;
            if (ph > snappy_phase) {
                snappy_phase = ph;
                rep.progress("flow: snappyHexMesh", ph, 4);
            }
        }) != 0)
        throw MeshingError("flow: snappyHexMesh failed (log: " + (dir / "log.snappyHexMesh").string() + (keep ? "" : "; keep it with --case-dir") + ")");
    rep.progress("flow: snappyHexMesh", 4, 4);
    long cells = 0;
    run_logged({"checkMesh"}, dir, dir / "log.checkMesh", deadline, [&](const std::string& l) {
        const auto q = l.find("cells:");
        if (q != std::string::npos && cells == 0) cells = std::atol(l.c_str() + q + 6);
    });
    if (cells <= 0) throw MeshingError("flow: snappyHexMesh made no cells inside the lumen (log: " + (dir / "log.snappyHexMesh").string() + ")");
    // Every end must have become a patch with faces: an outlet narrower than the cells can vanish.
    {
        const std::string bt = read_text(dir / "constant" / "polyMesh" / "boundary");
        for (const EndCap& c : caps) {
            long faces = 0;
            for (size_t at = bt.find(c.patch); at != std::string::npos; at = bt.find(c.patch, at + 1)) {
                const size_t after = at + c.patch.size();
                if (after < bt.size() && (std::isalnum(static_cast<unsigned char>(bt[after])) || bt[after] == '_')) continue;
                const size_t nf = bt.find("nFaces", after), close = bt.find('}', after);
                if (nf != std::string::npos && nf < close) faces = std::atol(bt.c_str() + nf + 6);
                break;
            }
            if (faces <= 0)
                throw InputError("flow: " + what + ": end " + std::to_string(c.id) + " (radius " + shortest(std::round(std::sqrt(c.area_mm2 / PI) * 100) / 100) +
                                 " mm) got no face in the fluid mesh of " + shortest(h) + " mm cells: give a smaller --cell-mm (a third of that radius)");
        }
    }
    const double mesh_s = tm.seconds();
    rep.info("flow: " + std::to_string(cells) + " cells in " + shortest(std::round(mesh_s * 10) / 10) + " s; solving (simpleFoam, laminar, blood)");
    // Solve, with the residual history.
    const Stopwatch ts;
    std::vector<std::array<double, 2>> history;  // per iteration: initial residual of p, largest of U's
    bool converged = false, diverged = false;
    int iteration = 0;
    const int rc = run_logged({"simpleFoam"}, dir, dir / "log.simpleFoam", deadline, [&](const std::string& l) {
        if (l.rfind("Time = ", 0) == 0) {
            if (!history.empty() && iteration % 100 == 0)  // the residuals of the iteration just finished
                rep.info("flow: iteration " + std::to_string(iteration) + ", initial residuals p " + num(history.back()[0]) + ", U " +
                         num(history.back()[1]) + " (converged below " + num(p.residual) + ", " + num(p.residual / 10) + ")");
            iteration = std::atoi(l.c_str() + 7);
            history.push_back({0.0, 0.0});
            if (iteration % 25 == 0) rep.progress("flow: simpleFoam", iteration, p.max_iterations);
            return;
        }
        const auto q = l.find("Initial residual = ");
        if (q != std::string::npos && !history.empty()) {
            const double r = std::atof(l.c_str() + q + 19);
            if (!std::isfinite(r)) diverged = true;
            if (l.find("for p,") != std::string::npos)
                history.back()[0] = std::max(history.back()[0], r);
            else if (l.find("for U") != std::string::npos)
                history.back()[1] = std::max(history.back()[1], r);
        }
        if (l.find("SIMPLE solution converged") != std::string::npos) converged = true;
        if (q != std::string::npos && (l.find("nan", q) != std::string::npos || l.find("inf", q) != std::string::npos)) diverged = true;
    });
    const double solve_s = ts.seconds();
    {
        std::string csv = "iteration,p_initial_residual,U_initial_residual\n";
        for (size_t i = 0; i < history.size(); ++i) csv += std::to_string(i + 1) + "," + num(history[i][0]) + "," + num(history[i][1]) + "\n";
        write_file(dir / "residuals.csv", csv);
    }
    if (rc != 0 || diverged) {
        // Keep what shows why: the residual history and the solver's log, beside the output.
        const fs::path kept = fs::path(out).string() + ".failed-flow-case";
        std::error_code e2;
        if (!keep) {
            fs::remove_all(kept, e2);
            fs::copy(dir, kept, fs::copy_options::recursive, e2);
        }
        const std::string last = history.empty() ? "none" : "p " + num(history.back()[0]) + ", U " + num(history.back()[1]);
        throw NumericalError("flow: simpleFoam " + std::string(diverged ? "diverged" : "failed (exit " + std::to_string(rc) + ")") + " at iteration " +
                             std::to_string(iteration) + " (last initial residuals: " + last + "); residual history and log in " +
                             (keep ? dir : kept).string());
    }
    if (!converged)
        rep.warn("flow: not converged in " + std::to_string(p.max_iterations) + " iterations (initial residuals p " + num(history.back()[0]) + ", U " +
                 num(history.back()[1]) + " against " + num(p.residual) + "): raise --max-iterations");
    rep.info("flow: " + std::to_string(iteration) + " iterations in " + shortest(std::round(solve_s * 10) / 10) + " s" + (converged ? ", converged" : ""));
    for (const char* fn : {"writeCellCentres", "writeCellVolumes"})
        if (run_logged({"postProcess", "-func", fn, "-latestTime"}, dir, dir / (std::string("log.") + fn), deadline, ignore) != 0)
            throw Error(std::string("flow: postProcess ") + fn + " failed (log: " + (dir / (std::string("log.") + fn)).string() + ")");
    // Results: the last time folder.
    std::string last_time;
    double last_t = -1;
    for (const auto& e : fs::directory_iterator(dir)) {
        if (!e.is_directory()) continue;
        char* end = nullptr;
        const std::string name = e.path().filename().string();
        const double t = std::strtod(name.c_str(), &end);
        if (end != name.c_str() && *end == '\0' && t > last_t) {
            last_t = t;
            last_time = name;
        }
    }
    if (last_t <= 0) throw Error("flow: simpleFoam wrote no result (log: " + (dir / "log.simpleFoam").string() + ")");
    const fs::path td = dir / last_time;
    const double rho = BLOOD_DENSITY_KG_M3;
    std::vector<std::pair<std::string, double>>& qa = res.qa;
    double inflow = 0, net = 0, p_in = 0, p_out_mean = 0;
    for (size_t i = 0; i < caps.size(); ++i) {
        const double q = last_dat_value(dir / "postProcessing" / (caps[i].patch + "_phi") / "0" / "surfaceFieldValue.dat", 1);
        const double pk = last_dat_value(dir / "postProcessing" / (caps[i].patch + "_p") / "0" / "surfaceFieldValue.dat", 1);
        net += q;
        if (i == inlet) {
            inflow = -q;
            p_in = pk * rho;
        } else {
            p_out_mean += pk * rho / static_cast<double>(caps.size() - 1);
        }
        qa.emplace_back("flow_ml_s_end_" + std::to_string(caps[i].id), q * 1e6);
        qa.emplace_back("pressure_pa_end_" + std::to_string(caps[i].id), pk * rho);
        qa.emplace_back("area_mm2_end_" + std::to_string(caps[i].id), caps[i].area_mm2);
    }
    // The wall: face centres and wall shear stress (kinematic in OpenFOAM: × density); pressure from the nearest cell.
    const FieldFile centres(td / "C");
    const std::vector<double> cw = centres.patch("wall", 3, 0);
    const std::vector<double> ww = FieldFile(td / "wallShearStress").patch("wall", 3, cw.size() / 3);
    const std::vector<double> cc = centres.internal(3, 0);
    const std::vector<double> pc = FieldFile(td / "p").internal(1, cc.size() / 3);
    if (ww.size() != cw.size() || pc.size() * 3 != cc.size()) throw Error("flow: OpenFOAM's wall or cell fields disagree in size");
    const auto wall_pts = as_points(cw, 1e3), cell_pts = as_points(cc, 1e3);
    const std::vector<double> uc = FieldFile(td / "U").internal(3, cell_pts.size());
    const std::vector<double> vol = FieldFile(td / "V").internal(1, cell_pts.size());
    if (uc.size() != cc.size() || vol.size() * 3 != cc.size()) throw Error("flow: OpenFOAM's velocity or cell volumes disagree in size with its cells");
    {
        const auto n = static_cast<Eigen::Index>(cell_pts.size());
        FlowFieldData& fd = res.field;
        fd.centre.resize(n, 3);
        fd.velocity.resize(n, 3);
        fd.pressure.resize(n);
        fd.volume.resize(n);
        for (Eigen::Index c = 0; c < n; ++c) {
            const auto i = static_cast<size_t>(c);
            fd.centre.row(c) = cell_pts[i].transpose();
            fd.velocity.row(c) << 1e3 * uc[3 * i], 1e3 * uc[3 * i + 1], 1e3 * uc[3 * i + 2];
            fd.pressure[c] = pc[i] * rho;
            fd.volume[c] = vol[i] * 1e9;
        }
    }
    const NearestPoint near_wall(wall_pts, 2 * h), near_cell(cell_pts, 2 * h);
    const Eigen::Index nf = blood.F.rows();
    Eigen::MatrixXd wss = Eigen::MatrixXd::Zero(nf, 1), wssv = Eigen::MatrixXd::Zero(nf, 3), pres = Eigen::MatrixXd::Zero(nf, 1);
    std::vector<double> wall_wss;
    double wall_area = 0, wss_area = 0;
    for (Eigen::Index f = 0; f < nf; ++f) {
        const Eigen::Vector3d x = (blood.V.row(blood.F(f, 0)) + blood.V.row(blood.F(f, 1)) + blood.V.row(blood.F(f, 2))).transpose() / 3.0;
        const int c = near_cell.nearest(x);
        if (c >= 0) pres(f, 0) = pc[static_cast<size_t>(c)] * rho;
        if (blood.face_label[f] != 0) continue;
        const int w = near_wall.nearest(x);
        if (w < 0) continue;
        const Eigen::Vector3d v = rho * Eigen::Vector3d(ww[3 * static_cast<size_t>(w)], ww[3 * static_cast<size_t>(w) + 1], ww[3 * static_cast<size_t>(w) + 2]);
        wssv.row(f) = v.transpose();
        wss(f, 0) = v.norm();
        const double a = tri_area(blood, f);
        wall_area += a;
        wss_area += a * v.norm();
        wall_wss.push_back(v.norm());
    }
    std::sort(wall_wss.begin(), wall_wss.end());
    // The flow into the sac: through the neck, the disc spanned by the border between the sac's faces and the
    // artery's (a fan from its centroid), sampled every half cell with the velocity of the nearest cell. Into a
    // sac without an outlet the net flux is zero; what enters (and leaves again) is the sac inflow.
    const SacNeck neck = sac_neck(lumen);
    if (neck.area_mm2 > 0) {
        // The sac's cells: beyond the neck's plane, their nearest lumen face sac (CGAL AABB tree).
        // Every cell's nearest lumen face (CGAL AABB tree): the sac's cells are those beyond the neck's plane
        // nearest to a sac face.
        const size_t nc = cell_pts.size();
        Eigen::MatrixX3d q(static_cast<Eigen::Index>(nc), 3);
        for (size_t c = 0; c < nc; ++c) q.row(static_cast<Eigen::Index>(c)) = cell_pts[c].transpose();
        Eigen::VectorXi nearest_face;
        distance_to_faces(lumen.V, lumen.F, q, &nearest_face);
        std::vector<char> beyond(nc, 0), near_sac(nc, 0), in_sac(nc, 0);
        double v_sum = 0, vs_sum = 0;
        for (size_t c = 0; c < nc; ++c) {
            beyond[c] = neck.into_sac.dot(cell_pts[c] - neck.centre) > 0;
            const int f = nearest_face[static_cast<Eigen::Index>(c)];
            near_sac[c] = f >= 0 && lumen.face_label[f] == neck.sac_label;
            if (!beyond[c] || !near_sac[c]) continue;
            in_sac[c] = 1;
            v_sum += vol[c];
            vs_sum += vol[c] * Eigen::Vector3d(uc[3 * c], uc[3 * c + 1], uc[3 * c + 2]).norm();
        }
        // The flow into the sac: through the neck, the disc spanned by its loop (a fan from the centroid), sampled
        // every half cell with the velocity of the nearest cell. Into a sac without an outlet what enters leaves
        // again: the inflow is the positive part. A planar quadrature, not the cells' faces: the positive part of
        // the fluxes through a staircase of faces grows with the tangential flow past it (measured: 10 % between
        // the sample's default mesh and one refinement, against 1 % on the disc).
        // Only what reaches the sac counts: a sample whose nearest cell lies on the sac's side of the disc or next
        // to one. The sac's side: the cells reached from the dome's cells (below), through links that do not cross
        // the disc, into cells beyond the plane or nearest to a sac face (so the flood
        // cannot leak past the disc's rim into the parent vessel, whose cells below the plane are nearest to
        // artery). A neck pinched shut leaves no sac cell: no inflow, even where the deformed disc crosses the
        // parent vessel.
        const std::vector<int> owner = read_label_list(dir / "constant" / "polyMesh" / "owner");
        const std::vector<int> neighbour = read_label_list(dir / "constant" / "polyMesh" / "neighbour");
        if (owner.size() < neighbour.size()) throw Error("flow: OpenFOAM's owner and neighbour lists disagree in size");
        std::vector<std::vector<int>> adjacent(nc);
        for (size_t f = 0; f < neighbour.size(); ++f) {
            const auto o = static_cast<size_t>(owner[f]), n = static_cast<size_t>(neighbour[f]);
            if (o >= nc || n >= nc) throw Error("flow: OpenFOAM's face " + std::to_string(f) + " names a cell beyond the mesh");
            adjacent[o].push_back(static_cast<int>(n));
            adjacent[n].push_back(static_cast<int>(o));
        }
        double disc_r = 0;
        for (const auto& x : neck.loop) disc_r = std::max(disc_r, (x - neck.centre).norm());
        // Does the segment p–q cross the disc (a fan of triangles from the centre)? Möller–Trumbore per triangle.
        auto crosses_disc = [&](const Eigen::Vector3d& p0, const Eigen::Vector3d& q0) {
            const Eigen::Vector3d d = q0 - p0;
            if ((p0 - neck.centre).norm() > disc_r + d.norm() + 1e-9) return false;
            for (size_t i = 0; i < neck.loop.size(); ++i) {
                const Eigen::Vector3d& a = neck.centre;
                const Eigen::Vector3d e1 = neck.loop[i] - a, e2 = neck.loop[(i + 1) % neck.loop.size()] - a;
                const Eigen::Vector3d pv = d.cross(e2);
                const double det = e1.dot(pv);
                if (std::abs(det) < 1e-14) continue;
                const Eigen::Vector3d tv = p0 - a;
                const double u = tv.dot(pv) / det;
                if (u < 0 || u > 1) continue;
                const Eigen::Vector3d qv = tv.cross(e1);
                const double v = d.dot(qv) / det, t = e2.dot(qv) / det;
                if (v >= 0 && u + v <= 1 && t >= 0 && t <= 1) return true;
            }
            return false;
        };
        // The seeds: cells nearest to the dome, the sac's faces beyond half its height over the neck. A clip that
        // pushes the sac's wall into the parent vessel makes parent cells nearest to sac faces; only a dome blood
        // still reaches makes inflow count.
        double height = 0;
        std::vector<double> rise(static_cast<size_t>(lumen.F.rows()), 0.0);
        for (Eigen::Index f = 0; f < lumen.F.rows(); ++f) {
            if (lumen.face_label[f] != neck.sac_label) continue;
            const Eigen::Vector3d x = (lumen.V.row(lumen.F(f, 0)) + lumen.V.row(lumen.F(f, 1)) + lumen.V.row(lumen.F(f, 2))).transpose() / 3.0;
            rise[static_cast<size_t>(f)] = neck.into_sac.dot(x - neck.centre);
            height = std::max(height, rise[static_cast<size_t>(f)]);
        }
        std::vector<char> sac_side(nc, 0);
        std::vector<size_t> queue;
        for (size_t c = 0; c < nc; ++c)
            if (in_sac[c] && rise[static_cast<size_t>(nearest_face[static_cast<Eigen::Index>(c)])] > 0.5 * height) {
                sac_side[c] = 1;
                queue.push_back(c);
            }
        for (size_t k = 0; k < queue.size(); ++k)
            for (int m : adjacent[queue[k]]) {
                const auto mm = static_cast<size_t>(m);
                if (!sac_side[mm] && (beyond[mm] || near_sac[mm]) && !crosses_disc(cell_pts[queue[k]], cell_pts[mm])) {
                    sac_side[mm] = 1;
                    queue.push_back(mm);
                }
            }
        std::vector<char> counts = sac_side;
        for (size_t c = 0; c < nc; ++c)
            if (sac_side[c])
                for (int m : adjacent[c]) counts[static_cast<size_t>(m)] = 1;
        double q_in = 0, q_out = 0;
        for (size_t i = 0; i < neck.loop.size(); ++i) {
            const Eigen::Vector3d a = neck.centre, b1 = neck.loop[i], c1 = neck.loop[(i + 1) % neck.loop.size()];
            Eigen::Vector3d n = (b1 - a).cross(c1 - a);
            const double area = 0.5 * n.norm();
            if (area <= 0) continue;
            n.normalize();
            if (n.dot(neck.into_sac) < 0) n = -n;
            const int k = std::max(2, static_cast<int>(std::ceil(std::max((b1 - a).norm(), (c1 - a).norm()) / (0.5 * h))));
            const double da = area / (k * k);  // k² sub-triangles of equal area
            for (int ii = 0; ii < k; ++ii)
                for (int jj = 0; jj < k - ii; ++jj)
                    for (int up = 0; up < (jj < k - ii - 1 ? 2 : 1); ++up) {
                        // centroid of sub-triangle (ii, jj, up) in barycentric steps of 1/k
                        const double u = (ii + (up ? 2.0 / 3 : 1.0 / 3)) / k, v = (jj + (up ? 2.0 / 3 : 1.0 / 3)) / k;
                        const Eigen::Vector3d x = a + u * (b1 - a) + v * (c1 - a);
                        const int c = near_cell.nearest(x);
                        if (c < 0 || !counts[static_cast<size_t>(c)] || (cell_pts[static_cast<size_t>(c)] - x).norm() > h) continue;
                        const Eigen::Vector3d vel(uc[3 * static_cast<size_t>(c)], uc[3 * static_cast<size_t>(c) + 1], uc[3 * static_cast<size_t>(c) + 2]);
                        const double q = vel.dot(n) * da * 1e-6;  // m³/s
                        (q > 0 ? q_in : q_out) += q;
                    }
        }
        qa.emplace_back("neck_area_mm2", neck.area_mm2);
        qa.emplace_back("sac_inflow_ml_s", q_in * 1e6);
        qa.emplace_back("sac_outflow_ml_s", -q_out * 1e6);
        qa.emplace_back("sac_inflow_fraction", inflow > 0 ? q_in / inflow : 0.0);
        res.sac_inflow_m3_s = q_in;
        qa.emplace_back("sac_volume_mm3", v_sum * 1e9);
        qa.emplace_back("sac_mean_speed_cm_s", v_sum > 0 ? vs_sum / v_sum * 100 : 0.0);
        rep.info("flow: " + what + ": sac inflow " + shortest(std::round(q_in * 1e9) / 1000) + " mL/s (" + shortest(std::round(q_in / inflow * 1000) / 10) +
                 " % of the inflow) through a neck of " + shortest(std::round(neck.area_mm2 * 100) / 100) + " mm²; mean speed in the sac " +
                 shortest(std::round(vs_sum / std::max(v_sum, 1e-300) * 1000) / 10) + " cm/s over " + shortest(std::round(v_sum * 1e10) / 10) + " mm³");
    }
    blood.face_fields["wall_shear_stress_pa"] = wss;
    blood.face_fields["wall_shear_stress_vector_pa"] = wssv;
    blood.face_fields["pressure_pa"] = pres;
    const double imbalance = inflow > 0 ? std::abs(net) / inflow : 0.0;
    qa.insert(qa.begin(), {{"cells", static_cast<double>(cells)},
                           {"cell_mm", h},
                           {"iterations", static_cast<double>(iteration)},
                           {"converged", converged ? 1.0 : 0.0},
                           {"final_residual_p", history.empty() ? 0.0 : history.back()[0]},
                           {"final_residual_U", history.empty() ? 0.0 : history.back()[1]},
                           {"inlet_end", static_cast<double>(caps[inlet].id)},
                           {"inflow_ml_s", inflow * 1e6},
                           {"mass_imbalance", imbalance},
                           {"pressure_drop_pa", p_in - p_out_mean},
                           {"wss_mean_pa", wall_area > 0 ? wss_area / wall_area : 0.0},
                           {"wss_median_pa", wall_wss.empty() ? 0.0 : wall_wss[wall_wss.size() / 2]},
                           {"wss_max_pa", wall_wss.empty() ? 0.0 : wall_wss.back()},
                           {"time_mesh_s", mesh_s},
                           {"time_solve_s", solve_s}});
    rep.info("flow: " + what + ": inflow " + shortest(std::round(inflow * 1e8) / 100) + " mL/s, mass imbalance " + shortest(imbalance) + ", pressure drop " +
             shortest(std::round((p_in - p_out_mean) * 100) / 100) + " Pa, wall shear stress mean " + shortest(std::round(wss_area / std::max(wall_area, 1e-300) * 1000) / 1000) + " Pa");
    res.inflow_m3_s = inflow;
    res.blood = std::move(blood);
    res.seconds = t0.seconds();
    return res;
}

}  // namespace

std::vector<Streamline> trace_streamlines(const FlowFieldData& field, const SurfaceData& blood, const std::string& inlet_patch, int seeds,
                                          double max_length_mm) {
    const auto n = field.centre.rows();
    if (n == 0) return {};
    // The cell size: the median cell's edge.
    std::vector<double> edge(static_cast<size_t>(n));
    for (Eigen::Index c = 0; c < n; ++c) edge[static_cast<size_t>(c)] = std::cbrt(std::max(field.volume[c], 0.0));
    std::nth_element(edge.begin(), edge.begin() + static_cast<std::ptrdiff_t>(edge.size() / 2), edge.end());
    const double h = std::max(edge[edge.size() / 2], 1e-3), r = 1.5 * h;
    std::vector<Eigen::Vector3d> pts(static_cast<size_t>(n));
    for (Eigen::Index c = 0; c < n; ++c) pts[static_cast<size_t>(c)] = field.centre.row(c).transpose();
    const NearestPoint grid(pts, r);
    std::vector<int> near;
    double vmax = 0;
    for (Eigen::Index c = 0; c < n; ++c) vmax = std::max(vmax, field.velocity.row(c).norm());
    // Velocity at x: inverse-distance weights of the cells within r; none near: outside the blood.
    auto velocity = [&](const Eigen::Vector3d& x, Eigen::Vector3d& v) {
        grid.within(x, r, near);
        if (near.empty()) return false;
        double wsum = 0;
        v.setZero();
        for (int c : near) {
            const double w = 1.0 / ((pts[static_cast<size_t>(c)] - x).norm() + 0.05 * h);
            v += w * field.velocity.row(c).transpose();
            wsum += w;
        }
        v /= wsum;
        return true;
    };
    // Seeds: area-weighted over the inlet cap's faces, at fixed fractions (deterministic), a cell inwards.
    const auto it = std::find(blood.label_names.begin(), blood.label_names.end(), inlet_patch);
    if (it == blood.label_names.end()) throw InputError("streamlines: the blood surface has no patch '" + inlet_patch + "'");
    const int lab = static_cast<int>(it - blood.label_names.begin());
    std::vector<Eigen::Index> faces;
    std::vector<double> cum;
    double area = 0;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (Eigen::Index f = 0; f < blood.F.rows(); ++f) {
        if (blood.face_label[f] != lab) continue;
        const Eigen::Vector3d a = blood.V.row(blood.F(f, 0)), b = blood.V.row(blood.F(f, 1)), c = blood.V.row(blood.F(f, 2));
        const Eigen::Vector3d n2 = (b - a).cross(c - a);
        area += 0.5 * n2.norm();
        normal += n2;
        faces.push_back(f);
        cum.push_back(area);
    }
    if (faces.empty()) return {};
    normal.normalize();  // out of the blood
    std::vector<Streamline> lines;
    for (int k = 0; k < seeds; ++k) {
        const double t = (k + 0.5) / seeds * area;
        const size_t i = static_cast<size_t>(std::lower_bound(cum.begin(), cum.end(), t) - cum.begin());
        const Eigen::Index f = faces[std::min(i, faces.size() - 1)];
        // A point of the face by a low-discrepancy pair (golden ratio), folded into the triangle.
        double u = std::fmod(0.5 + k * 0.6180339887498949, 1.0), w = std::fmod(0.5 + k * 0.7548776662466927, 1.0);
        if (u + w > 1) {
            u = 1 - u;
            w = 1 - w;
        }
        const Eigen::Vector3d a = blood.V.row(blood.F(f, 0)), b = blood.V.row(blood.F(f, 1)), c = blood.V.row(blood.F(f, 2));
        Eigen::Vector3d x = a + u * (b - a) + w * (c - a) - h * normal;
        Streamline sl;
        Eigen::Vector3d v1, v2;
        double length = 0;
        while (length < max_length_mm && velocity(x, v1)) {
            const double sp = v1.norm();
            sl.points.push_back(x);
            sl.speed_cm_s.push_back(sp / 10.0);
            if (sp < 1e-4 * vmax) break;
            const double dt = h / 3 / sp;
            if (!velocity(x + 0.5 * dt * v1, v2)) break;
            x += dt * v2;
            length += dt * v2.norm();
        }
        if (sl.points.size() > 2) lines.push_back(std::move(sl));
    }
    return lines;
}

SurfaceData deformed_lumen(const Bundle& bundle, const SurfaceData& lumen, const std::string& series, int frame, Reporter& rep, int* frame_used) {
    if (!bundle.volume || !bundle.fem)
        throw InputError("flow: --series needs the case bundle (CASE.h5, with /volume and /fem) as input, not a surface file");
    const VolumeData& vol = *bundle.volume;
    const FemData& fem = *bundle.fem;
    std::vector<int> node;
    std::vector<float> disp;
    int steps = 0;
    try {
        H5::Exception::dontPrint();
        H5::H5File f(series, H5F_ACC_RDONLY);
        if (!f.nameExists("node"))
            throw InputError(series + ": no /node (the simulated surface's mesh nodes): written by an older aneusim; run the scene again");
        H5::DataSet dn = f.openDataSet("node");
        node.resize(static_cast<size_t>(dn.getSpace().getSimpleExtentNpoints()));
        dn.read(node.data(), H5::PredType::NATIVE_INT);
        steps = static_cast<int>(f.openGroup("steps").getNumObjs());
        if (steps == 0) throw InputError(series + ": the series has no frame");
        const int k = frame < 0 ? steps - 1 : frame;
        if (k >= steps) throw InputError("flow: --frame " + std::to_string(frame) + ": " + series + " has frames 0 to " + std::to_string(steps - 1));
        if (frame_used != nullptr) *frame_used = k;
        H5::DataSet dd = f.openDataSet("steps/" + std::to_string(k) + "/displacement");
        if (static_cast<size_t>(dd.getSpace().getSimpleExtentNpoints()) != 3 * node.size())
            throw InputError(series + ": frame " + std::to_string(k) + " has " + std::to_string(dd.getSpace().getSimpleExtentNpoints() / 3) +
                             " displacements for " + std::to_string(node.size()) + " nodes");
        disp.resize(3 * node.size());
        dd.read(disp.data(), H5::PredType::NATIVE_FLOAT);
    } catch (const H5::Exception& e) {
        throw InputError(series + ": not a simulator series (" + e.getDetailMsg() + ")");
    }
    // The whole mesh's displacement with the simulated surface's nodes prescribed (the condensed model's own
    // field: no load elsewhere, the ends fixed).
    const Eigen::Index n_nodes = vol.nodes.rows();
    std::set<int> fixed(fem.fixed_dofs.data(), fem.fixed_dofs.data() + fem.fixed_dofs.size());
    std::vector<std::pair<int, double>> prescribed;
    std::set<int> seen;
    for (size_t s = 0; s < node.size(); ++s) {
        if (node[s] < 0 || node[s] >= n_nodes)
            throw InputError(series + ": node " + std::to_string(node[s]) + " is not in the case's mesh (" + std::to_string(n_nodes) +
                             " nodes): the series belongs to another case");
        if (!seen.insert(node[s]).second) continue;
        for (int a = 0; a < 3; ++a) {
            const int dof = 3 * node[s] + a;
            if (!fixed.count(dof)) prescribed.emplace_back(dof, static_cast<double>(disp[3 * s + static_cast<size_t>(a)]));
        }
    }
    const Eigen::VectorXd u = fem::solve_dirichlet(fem, prescribed).u;
    // The lumen's vertices are mesh nodes (TetGen keeps its input's vertices).
    std::vector<Eigen::Vector3d> pts(static_cast<size_t>(n_nodes));
    for (Eigen::Index i = 0; i < n_nodes; ++i) pts[static_cast<size_t>(i)] = vol.nodes.row(i).transpose();
    const NearestPoint near(pts, 0.5);
    SurfaceData moved = lumen;
    double max_u = 0;
    for (Eigen::Index v = 0; v < lumen.V.rows(); ++v) {
        const Eigen::Vector3d x = lumen.V.row(v).transpose();
        const int n = near.nearest(x);
        if (n < 0 || (pts[static_cast<size_t>(n)] - x).norm() > 1e-3)
            throw InputError("flow: the lumen's vertex " + std::to_string(v) + " is not a node of the case's mesh: the case bundle's surfaces and volume disagree");
        const Eigen::Vector3d d = u.segment<3>(3 * static_cast<Eigen::Index>(n));
        moved.V.row(v) += d.transpose();
        max_u = std::max(max_u, d.norm());
    }
    rep.info("flow: the lumen moved by the wall's deformation in frame " + std::to_string(frame_used ? *frame_used : frame) + " of " + series + " (" +
             std::to_string(prescribed.size()) + " prescribed DOFs, largest lumen displacement " + shortest(std::round(max_u * 1000) / 1000) + " mm)");
    return moved;
}

void flow_file(const std::string& in, const std::string& out, const FlowParams& p, StageRecord stage, Reporter& rep) {
    flow_spec().validate(p);
    const Stopwatch t0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(p.time_budget_s * 1000));
    const bool with_series = !p.series.empty();
    BundleParts parts;
    parts.volume = with_series;
    parts.fem = with_series;
    parts.condensed_W = false;
    Bundle b = read_bundle(in, parts);
    const auto it = b.surfaces.find("lumen");
    if (it == b.surfaces.end()) throw InputError(in + ": no /surface/lumen (run `aneuprep surface` first)");
    const SurfaceData lumen = it->second;
    const bool voxel = p.domain == "voxel" || (p.domain == "auto" && with_series);
    // The case folder(s).
    const bool keep = !p.case_dir.empty();
    const fs::path dir = keep ? fs::absolute(p.case_dir) : fs::temp_directory_path() / ("aneu_flow_" + std::to_string(::getpid()));
    struct Cleanup {
        fs::path d;
        bool keep;
        ~Cleanup() {
            std::error_code ec;
            if (!keep) fs::remove_all(d, ec);
        }
    } cleanup{dir, keep};
    if (std::getenv("WM_PROJECT_DIR") == nullptr) ::setenv("WM_PROJECT_DIR", "/usr/share/openfoam", 1);
    std::vector<std::pair<std::string, double>> qa;
    if (!with_series) {
        Solved r = solve_lumen(lumen, p, voxel, dir, keep, out, deadline, rep, "lumen");
        qa = std::move(r.qa);
        b.surfaces["blood"] = std::move(r.blood);
        b.flow = std::move(r.field);
    } else {
        int frame = p.frame;
        SurfaceData moved = deformed_lumen(b, lumen, p.series, p.frame, rep, &frame);
        const std::string what = "frame " + std::to_string(frame);
        // The pre-clip baseline first, by the same domain method (the ratio compares like with like).
        Solved pre = solve_lumen(lumen, p, voxel, dir / "pre_clip", keep, out, deadline, rep, "pre-clip");
        Solved fr = solve_lumen(moved, p, voxel, dir / ("frame_" + std::to_string(frame)), keep, out, deadline, rep, what);
        qa = std::move(fr.qa);
        qa.insert(qa.begin(), {"frame", static_cast<double>(frame)});
        for (const auto& [k, v] : pre.qa)
            if (k == "inflow_ml_s" || k == "sac_inflow_ml_s" || k == "sac_inflow_fraction" || k == "sac_mean_speed_cm_s" || k == "cells" ||
                k == "domain_volume_mm3" || k == "sac_volume_mm3" || k == "pressure_drop_pa" || k == "mass_imbalance")
                qa.emplace_back("pre_clip_" + k, v);
        if (pre.sac_inflow_m3_s > 0 && fr.sac_inflow_m3_s >= 0) {
            const double ratio = fr.sac_inflow_m3_s / pre.sac_inflow_m3_s;
            qa.emplace_back("residual_sac_inflow_ratio", ratio);
            rep.info("flow: residual sac inflow " + shortest(std::round(ratio * 1000) / 10) + " % of pre-clip (" + shortest(std::round(fr.sac_inflow_m3_s * 1e9) / 1000) +
                     " of " + shortest(std::round(pre.sac_inflow_m3_s * 1e9) / 1000) + " mL/s)");
        } else {
            rep.warn("flow: no sac inflow to compare (no labelled sac, or none before the clip)");
        }
        b.surfaces["blood"] = std::move(fr.blood);
        b.flow = std::move(fr.field);
        b.surfaces["blood_pre_clip"] = std::move(pre.blood);
        b.surfaces["lumen_deformed"] = std::move(moved);
    }
    for (auto& q : qa) stage.qa.push_back(q);
    b.volume.reset();
    b.fem.reset();
    b.condensed.reset();
    finish(b, stage, t0, out, rep);
}

}  // namespace aneu::pipeline
