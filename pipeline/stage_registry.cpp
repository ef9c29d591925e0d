// SPDX-License-Identifier: MIT
// The stage table: each stage's spec (with the options only the file-level stage has: a snapshot picture,
// the phantom's output formats) and the function that runs it.
#include "aneu/pipeline/stage_registry.hpp"

#include <functional>

#include "aneu/core/error.hpp"
#include "aneu/pipeline/flow.hpp"
#include "aneu/pipeline/geometry.hpp"
#include "aneu/pipeline/phantom.hpp"
#include "aneu/pipeline/stages.hpp"
#include "aneu/pipeline/tetmesh.hpp"

namespace aneu::pipeline {

namespace {

template <class J>
class Job final : public StageJob {
public:
    using Runner = std::function<void(const J&, const std::string&, const std::string&, StageRecord, Reporter&)>;
    Job(const StageInfo& info, const opt::Spec<J>& spec, Runner run) : m_info(info), m_spec(spec), m_run(std::move(run)) {}
    const StageInfo& info() const override { return m_info; }
    std::vector<opt::Option> options() const override { return m_spec.options(); }
    void set(const std::string& key, const std::vector<std::string>& values) override { m_spec.set(m_job, key, values); }
    void validate() const override { m_spec.validate(m_job); }
    std::vector<std::pair<std::string, std::string>> parameters() const override { return m_spec.parameters(m_job); }
    void run(const std::string& input, const std::string& output, StageRecord record, Reporter& rep) const override {
        validate();
        m_run(m_job, input, output, std::move(record), rep);
    }

private:
    const StageInfo& m_info;
    const opt::Spec<J>& m_spec;
    Runner m_run;
    J m_job{};
};

/// A geometry stage's parameters and its optional snapshot picture.
template <class P>
struct WithSnapshot {
    P p;
    std::string snapshot;
};
template <class P>
opt::Spec<WithSnapshot<P>> with_snapshot(const opt::Spec<P>& base, const std::string& what) {
    using J = WithSnapshot<P>;
    opt::Spec<J> s(base.stage());
    s.include(base, [](J& j) -> P& { return j.p; })
        .text("snapshot", &J::snapshot, {}, "render " + what + " to this PNG (needs X: xvfb-run -a)")
        .not_provenance();
    return s;
}

struct PhantomJob {
    PhantomParams p;
    std::vector<std::string> formats{"nii", "nrrd", "mha", "dicom"};
};

const std::vector<StageInfo>& infos() {
    static const std::vector<StageInfo> v{
        {"phantom", "synthetic CT angiography of an aneurysm, with ground truth", false, "", "output directory (replaced atomically)"},
        {"segment", "CT volume -> lumen mask, centerline and end planes (ITK)", true,
         "CT volume: .nii/.nii.gz, .nrrd, .mha, or a directory with one DICOM series", "output stage file (.h5), written atomically"},
        {"surface", "lumen surface: isosurface, cut, smooth, remesh, artery/aneurysm labels", true,
         "segment stage file (.h5), or a lumen surface from another tool (.stl, .vtp, .vtk, .obj, .ply)", "output stage file (.h5), written atomically"},
        {"wall", "closed vessel-wall surface: distance field, varying thickness, annular caps", true, "input stage file (.h5)",
         "output stage file (.h5), written atomically"},
        {"tetmesh", "quality tetrahedral mesh of the closed wall surface", true, "input stage file (.h5)", "output stage file (.h5), written atomically"},
        {"assemble", "linear-elastic stiffness of the wall mesh", true, "input stage file (.h5)", "output stage file (.h5), written atomically"},
        {"condense", "W = (K^-1) on the simulated surface DOFs: the case bundle", true, "input stage file (.h5)",
         "output stage file (.h5), written atomically"},
        {"flow", "blood flow in the lumen: OpenFOAM mesh and steady solve, flow per end, wall shear stress", true,
         "stage file with /surface/lumen (surface, wall, ... or the case bundle)", "output stage file (.h5), written atomically"},
        {"tubewall", "closed wall surface of a tube of known dimensions (tests, examples)", false, "", "output stage file (.h5), written atomically"},
    };
    return v;
}

const StageInfo& info_of(const std::string& name) {
    for (const auto& i : infos()) {
        if (i.name == name) return i;
    }
    std::string names;
    for (const auto& i : infos()) names += (names.empty() ? "" : ", ") + i.name;
    throw InputError("no stage '" + name + "' (expected one of: " + names + ")");
}

template <class J>
std::unique_ptr<StageJob> job(const std::string& name, const opt::Spec<J>& spec, typename Job<J>::Runner run) {
    return std::make_unique<Job<J>>(info_of(name), spec, std::move(run));
}

}  // namespace

const std::vector<StageInfo>& stage_infos() { return infos(); }

std::unique_ptr<StageJob> make_stage_job(const std::string& name) {
    info_of(name);
    if (name == "phantom") {
        static const opt::Spec<PhantomJob> spec = [] {
            opt::Spec<PhantomJob> s("phantom");
            s.include(phantom_spec(), [](PhantomJob& j) -> PhantomParams& { return j.p; })
                .choice_list("formats", &PhantomJob::formats, {"nii", "nrrd", "mha", "dicom"}, "CT formats to write");
            return s;
        }();
        return job<PhantomJob>(name, spec, [](const PhantomJob& j, const std::string&, const std::string& out, StageRecord r, Reporter& rep) {
            PhantomOutputs o{false, false, false, false};
            for (const auto& f : j.formats) {
                o.nifti |= f == "nii";
                o.nrrd |= f == "nrrd";
                o.mha |= f == "mha";
                o.dicom |= f == "dicom";
            }
            write_phantom(j.p, o, out, r, rep);
        });
    }
    if (name == "segment") {
        using J = WithSnapshot<SegmentParams>;
        static const auto spec = with_snapshot(segment_spec(), "the mask, centerline and planes");
        return job<J>(name, spec, [](const J& j, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            segment_file(in, out, j.p, std::move(r), j.snapshot, rep);
        });
    }
    if (name == "surface") {
        using J = WithSnapshot<SurfaceParams>;
        static const auto spec = with_snapshot(surface_spec(), "the labelled surface");
        return job<J>(name, spec, [](const J& j, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            surface_file(in, out, j.p, std::move(r), j.snapshot, rep);
        });
    }
    if (name == "wall") {
        using J = WithSnapshot<WallParams>;
        static const auto spec = with_snapshot(wall_spec(), "the wall coloured by thickness");
        return job<J>(name, spec, [](const J& j, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            wall_file(in, out, j.p, std::move(r), j.snapshot, rep);
        });
    }
    if (name == "tetmesh") {
        return job<TetMeshParams>(name, tetmesh_spec(), [](const TetMeshParams& p, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            tetmesh_file(in, out, p, std::move(r), rep);
        });
    }
    if (name == "assemble") {
        return job<AssembleParams>(name, assemble_spec(), [](const AssembleParams& p, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            assemble_file(in, out, p, std::move(r), rep);
        });
    }
    if (name == "condense") {
        return job<CondenseStageParams>(name, condense_spec(),
                                        [](const CondenseStageParams& p, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
                                            condense_file(in, out, p, std::move(r), rep);
                                        });
    }
    if (name == "flow") {
        return job<FlowParams>(name, flow_spec(), [](const FlowParams& p, const std::string& in, const std::string& out, StageRecord r, Reporter& rep) {
            flow_file(in, out, p, std::move(r), rep);
        });
    }
    return job<TubeWallParams>(name, tubewall_spec(), [](const TubeWallParams& p, const std::string&, const std::string& out, StageRecord r, Reporter& rep) {
        tubewall_file(p, out, std::move(r), rep);
    });
}

std::string phantom_ct_name(const std::vector<std::pair<std::string, std::string>>& phantom_parameters) {
    std::string formats;
    for (const auto& [k, v] : phantom_parameters) {
        if (k == "formats") formats = v;
    }
    for (const auto& [fmt, file] : std::vector<std::pair<std::string, std::string>>{
             {"nrrd", "ct.nrrd"}, {"mha", "ct.mha"}, {"nii", "ct.nii.gz"}, {"dicom", "dicom"}}) {
        if (formats.find(fmt) != std::string::npos) return file;
    }
    throw InputError("[phantom] formats '" + formats + "': expected at least one of nrrd, mha, nii, dicom");
}

}  // namespace aneu::pipeline
