// SPDX-License-Identifier: MIT
// aneuview: a VTK desktop view of a running `aneusim serve` (issue #18). It connects as an OpenIGTLink client and
// draws the deformed vessel (label colours: artery red, aneurysm yellow), the deposited and held clips (a bar along
// each clip's axis), the instruments where the simulator has them (`<ins>.pose`) with their force as an arrow, a
// heads-up line (force per instrument, surfaces and frames per second, the last event), screenshots on 's';
// `--steer` drives one instrument from the keyboard, `--stereo side-by-side` renders a stereo pair.
// It is not the simulator: it may link VTK; aneusim does not.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlPolyDataMessage.h>
#include <igtlSensorMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <vtkActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCoordinate.h>
#include <vtkCubeSource.h>
#include <vtkFloatArray.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkLineSource.h>
#include <vtkLookupTable.h>
#include <vtkObjectFactory.h>
#include <vtkTubeFilter.h>
#include <vtkMath.h>
#include <vtkNew.h>
#include <vtkPNGWriter.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkTransform.h>
#include <vtkWindowToImageFilter.h>

#include "aneuview_window.hpp"

#include "aneu/core/common.hpp"

namespace {

const double ARTERY[3] = {0.85, 0.33, 0.27}, ANEURYSM[3] = {0.95, 0.80, 0.35};  // the snapshot's palette

struct Frame {
    std::vector<float> points, labels;
    std::vector<unsigned> triangles;
    long serial = 0;
};

// What the network thread has received (the latest of each), under one mutex.
struct Shared {
    std::mutex mx;
    Frame frame;
    std::map<std::string, std::array<float, 12>> clips;  // name → 3×4 matrix (rows)
    std::map<std::string, std::array<float, 12>> instruments;  // `<ins>.pose` → 3×4 matrix (rows)
    std::map<std::string, std::array<double, 3>> force;
    std::string last_status;
    long surfaces = 0;
    std::atomic<bool> connected{false}, done{false};
};

bool ends_with(const std::string& s, const std::string& tail) {
    return s.size() > tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

void receive_loop(igtl::ClientSocket* s, Shared& sh) {
    while (!sh.done) {
        auto h = igtl::MessageHeader::New();
        h->InitPack();
        if (s->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) break;
        h->Unpack();
        const std::string type = h->GetDeviceType(), name = h->GetDeviceName();
        igtl::MessageBase::Pointer m;
        if (type == "POLYDATA") m = igtl::PolyDataMessage::New();
        else if (type == "TRANSFORM") m = igtl::TransformMessage::New();
        else if (type == "SENSOR") m = igtl::SensorMessage::New();
        else if (type == "STATUS") m = igtl::StatusMessage::New();
        if (m.IsNull()) {
            s->Skip(h->GetBodySizeToRead());
            continue;
        }
        m->SetMessageHeader(h);
        m->AllocatePack();
        if (s->Receive(m->GetPackBodyPointer(), m->GetPackBodySize()) != m->GetPackBodySize()) break;
        if (!(m->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) continue;
        std::lock_guard<std::mutex> lk(sh.mx);
        if (type == "POLYDATA" && name == "vessel") {
            auto* p = static_cast<igtl::PolyDataMessage*>(m.GetPointer());
            Frame f;
            const int n = p->GetPoints()->GetNumberOfPoints();
            f.points.resize(static_cast<size_t>(3 * n));
            for (int i = 0; i < n; ++i) p->GetPoints()->GetPoint(static_cast<unsigned>(i), &f.points[static_cast<size_t>(3 * i)]);
            auto* polys = p->GetPolygons();
            for (unsigned c = 0; polys && c < polys->GetNumberOfCells(); ++c) {
                std::list<igtlUint32> cell;
                polys->GetCell(c, cell);
                if (cell.size() == 3)
                    for (auto v : cell) f.triangles.push_back(v);
            }
            f.labels.assign(static_cast<size_t>(n), 0.0f);
            for (int a = 0; a < p->GetNumberOfAttributes(); ++a) {
                auto* att = p->GetAttribute(a);
                if (std::string(att->GetName()) == "label" && att->GetSize() == static_cast<unsigned>(n)) att->GetData(f.labels.data());
            }
            f.serial = sh.frame.serial + 1;
            sh.frame = std::move(f);
            ++sh.surfaces;
        } else if (type == "TRANSFORM" && (name.rfind("clip", 0) == 0 || ends_with(name, ".pose"))) {
            igtl::Matrix4x4 M;
            static_cast<igtl::TransformMessage*>(m.GetPointer())->GetMatrix(M);
            std::array<float, 12> r{};
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 4; ++j) r[static_cast<size_t>(4 * i + j)] = M[i][j];
            if (ends_with(name, ".pose")) sh.instruments[name.substr(0, name.size() - 5)] = r;
            else sh.clips[name] = r;
        } else if (type == "SENSOR" && ends_with(name, ".force")) {
            auto* f = static_cast<igtl::SensorMessage*>(m.GetPointer());
            if (f->GetLength() == 3) sh.force[name.substr(0, name.size() - 6)] = {f->GetValue(0), f->GetValue(1), f->GetValue(2)};
        } else if (type == "STATUS") {
            sh.last_status = static_cast<igtl::StatusMessage*>(m.GetPointer())->GetStatusString();
        }
    }
    sh.connected = false;
}

struct View {
    Shared* sh = nullptr;
    vtkPolyData* vessel = nullptr;
    vtkRenderer* ren = nullptr;
    vtkRenderWindow* win = nullptr;
    vtkTextActor* hud = nullptr;
    std::map<std::string, vtkSmartPointer<vtkActor>> clip_actors;
    struct Tool {  // an instrument the server reports: a shaft back from its tip, and its force as an arrow
        vtkSmartPointer<vtkLineSource> line, arrow_line;
    };
    std::map<std::string, Tool> tools;
    vtkSmartPointer<vtkPoints> points;
    long shown = 0;
    double min_period = 1.0 / 60;  // --max-fps
    std::chrono::steady_clock::time_point next_frame = std::chrono::steady_clock::now();
    bool camera_set = false;
    std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
    long renders = 0;
    double render_s = 0;  // time in Render()
    /// When each steady frame finished rendering: from the first frame that showed a surface (before it: the window,
    /// the connection, the server loading its bundle). The rates and intervals end at the last frame: the
    /// screenshot's PNG and the exit after it are not frames.
    std::vector<std::chrono::steady_clock::time_point> frame_ends;
    // Steering one instrument from the keyboard (without a haptic device).
    igtl::ClientSocket* sock = nullptr;
    std::string steer, clip_model;
    double p[3] = {0, 0, 0}, axis[3] = {0, 0, -1}, up[3] = {0, 1, 0}, opening = 40;
    double start_p[3] = {0, 0, 0};  // where the steered instrument was placed
    double drag_from[3] = {0, 0, 0}, drag_to[3] = {0, 0, 0};  // the last pointer drag's ends (world)
    bool dragged = false;
    bool button = false, placed = false;
    std::string action;
    std::vector<std::string> keys;  // scripted key presses, one per frame once the instrument is placed
    size_t next_key = 0;
    // Screenshot mode.
    std::string screenshot, points_out;
    long after_surfaces = 0;
    bool finished = false;
};

void send(igtl::ClientSocket* s, igtl::MessageBase* m) {
    m->Pack();
    s->Send(m->GetPackPointer(), m->GetPackSize());
}

/// The steered instrument's state to the server: opening, button, a pending action, then its pose.
void send_steer(View& v) {
    auto o = igtl::SensorMessage::New();
    o->SetDeviceName((v.steer + ".opening").c_str());
    o->SetLength(1);
    o->SetValue(0u, v.opening);
    send(v.sock, o);
    auto b = igtl::SensorMessage::New();
    b->SetDeviceName((v.steer + ".button").c_str());
    b->SetLength(1);
    b->SetValue(0u, v.button ? 1.0 : 0.0);
    send(v.sock, b);
    if (!v.action.empty()) {
        auto a = igtl::StringMessage::New();
        a->SetDeviceName((v.steer + ".action").c_str());
        a->SetString(v.action.c_str());
        send(v.sock, a);
        v.action.clear();
    }
    auto tm = igtl::TransformMessage::New();
    tm->SetDeviceName(v.steer.c_str());
    igtl::Matrix4x4 M;
    igtl::IdentityMatrix(M);
    double y[3];
    vtkMath::Cross(v.axis, v.up, y);
    for (int r = 0; r < 3; ++r) {
        M[r][0] = static_cast<float>(v.up[r]);
        M[r][1] = static_cast<float>(-y[r]);
        M[r][2] = static_cast<float>(v.axis[r]);
        M[r][3] = static_cast<float>(v.p[r]);
    }
    tm->SetMatrix(M);
    send(v.sock, tm);
}

/// One key of the steering: 0.25 mm moves in the view plane (arrows) and along the instrument (i/k), 5° of
/// opening (o/c), the actions (l/r/g) and the suction button (b).
void steer_key(View& v, const std::string& key) {
    constexpr double STEP = 0.25;
    double right[3];
    vtkMath::Cross(v.axis, v.up, right);
    auto move = [&](const double* d, double k) {
        for (int a = 0; a < 3; ++a) v.p[a] += k * STEP * d[a];
    };
    if (key == "Left") move(right, -1);
    else if (key == "Right") move(right, 1);
    else if (key == "Up") move(v.up, 1);
    else if (key == "Down") move(v.up, -1);
    else if (key == "i") move(v.axis, 1);
    else if (key == "k") move(v.axis, -1);
    else if (key == "o") v.opening = std::min(90.0, v.opening + 5);
    else if (key == "c") v.opening = std::max(0.0, v.opening - 5);
    else if (key == "l" && !v.clip_model.empty()) v.action = "load " + v.clip_model;
    else if (key == "r") v.action = "release";
    else if (key == "g") v.action = "grasp";
    else if (key == "b") v.button = !v.button;
    else return;
    send_steer(v);
}

/// A pointer drag of (dx, dy) pixels moves the steered instrument in the view plane by as much as the pointer
/// moves at the instrument's depth (perspective: the view height at that distance over the window's height).
void drag(View& v, int dx, int dy) {
    auto* cam = v.ren->GetActiveCamera();
    double pos[3], fp[3], vup[3], dir[3], right[3];
    cam->GetPosition(pos);
    cam->GetFocalPoint(fp);
    cam->GetViewUp(vup);
    for (int a = 0; a < 3; ++a) dir[a] = fp[a] - pos[a];
    vtkMath::Normalize(dir);
    vtkMath::Cross(dir, vup, right);
    vtkMath::Normalize(right);
    vtkMath::Cross(right, dir, vup);
    double depth = 0;
    for (int a = 0; a < 3; ++a) depth += (v.p[a] - pos[a]) * dir[a];
    const int* size = v.ren->GetSize();
    const double mm_per_px = 2.0 * std::max(depth, 1e-3) * std::tan(vtkMath::RadiansFromDegrees(cam->GetViewAngle()) / 2) / std::max(1, size[1]);
    for (int a = 0; a < 3; ++a) {
        v.drag_from[a] = v.p[a];
        v.p[a] += mm_per_px * (dx * right[a] + dy * vup[a]);
        v.drag_to[a] = v.p[a];
    }
    v.dragged = true;
    send_steer(v);
}

/// Each frame: scripted keys (one a frame; `drag:DX:DY` a pointer drag in pixels), then the pose (devices stream
/// theirs continuously).
void steer_frame(View& v) {
    if (v.next_key < v.keys.size()) {
        const std::string& k = v.keys[v.next_key++];
        int dx = 0, dy = 0;
        if (std::sscanf(k.c_str(), "drag:%d:%d", &dx, &dy) == 2) drag(v, dx, dy);
        else steer_key(v, k);
    }
    send_steer(v);
}

void write_png(vtkRenderWindow* win, const std::string& path) {
    vtkNew<vtkWindowToImageFilter> w2i;
    w2i->SetInput(win);
    w2i->ReadFrontBufferOff();
    w2i->Update();
    vtkNew<vtkPNGWriter> png;
    png->SetFileName(path.c_str());
    png->SetInputConnection(w2i->GetOutputPort());
    png->Write();
}

/// An instrument's drawing: a shaft (a capped tube) back from its tip and its force as a green line; made on first use.
View::Tool& tool_of(View& v, const std::string& name) {
    auto& t = v.tools[name];
    if (!t.line) {
        t.line = vtkSmartPointer<vtkLineSource>::New();
        t.arrow_line = vtkSmartPointer<vtkLineSource>::New();
        vtkNew<vtkTubeFilter> tube;
        tube->SetInputConnection(t.line->GetOutputPort());
        tube->SetRadius(0.4);
        tube->SetNumberOfSides(16);
        tube->CappingOn();
        vtkNew<vtkPolyDataMapper> tm, am;
        tm->SetInputConnection(tube->GetOutputPort());
        am->SetInputConnection(t.arrow_line->GetOutputPort());
        vtkNew<vtkActor> ta, aa;
        ta->SetMapper(tm);
        ta->GetProperty()->SetColor(0.3, 0.55, 0.85);
        aa->SetMapper(am);
        aa->GetProperty()->SetColor(0.1, 0.6, 0.2);
        aa->GetProperty()->SetLineWidth(3);
        v.ren->AddActor(ta);
        v.ren->AddActor(aa);
    }
    return t;
}

void place_tool(View::Tool& t, const double* tip, const double* ax, const std::array<double, 3>& f) {
    t.line->SetPoint1(tip);
    t.line->SetPoint2(tip[0] - 15 * ax[0], tip[1] - 15 * ax[1], tip[2] - 15 * ax[2]);
    t.arrow_line->SetPoint1(tip);
    t.arrow_line->SetPoint2(tip[0] + 5 * f[0], tip[1] + 5 * f[1], tip[2] + 5 * f[2]);  // 1 N = 5 mm
}

void update(View& v) {
    Frame f;
    std::map<std::string, std::array<float, 12>> clips, instruments;
    std::map<std::string, std::array<double, 3>> forces;
    std::string status;
    long surfaces = 0;
    {
        std::lock_guard<std::mutex> lk(v.sh->mx);
        if (v.sh->frame.serial != v.shown) f = v.sh->frame;
        clips = v.sh->clips;
        instruments = v.sh->instruments;
        forces = v.sh->force;
        status = v.sh->last_status;
        surfaces = v.sh->surfaces;
    }
    if (f.serial != 0) {
        const vtkIdType n = static_cast<vtkIdType>(f.points.size() / 3);
        // The connectivity and labels do not change in a session: set once; the positions are copied in place.
        if (!v.points || v.points->GetNumberOfPoints() != n) {
            v.points = vtkSmartPointer<vtkPoints>::New();
            v.points->SetDataTypeToFloat();
            v.points->SetNumberOfPoints(n);
            v.vessel->SetPoints(v.points);
            vtkNew<vtkCellArray> tris;
            for (size_t t = 0; t + 2 < f.triangles.size(); t += 3) {
                const vtkIdType ids[3] = {f.triangles[t], f.triangles[t + 1], f.triangles[t + 2]};
                tris->InsertNextCell(3, ids);
            }
            v.vessel->SetPolys(tris);
            vtkNew<vtkFloatArray> lab;
            lab->SetName("label");
            for (float l : f.labels) lab->InsertNextValue(l);
            v.vessel->GetPointData()->SetScalars(lab);
        }
        auto* dst = static_cast<float*>(v.points->GetVoidPointer(0));
        std::copy(f.points.begin(), f.points.end(), dst);
        v.points->Modified();
        v.vessel->Modified();
        v.shown = f.serial;
        if (!v.camera_set) {  // look along the vessel's least extent (its principal axes), the longest axis across
            double c[3] = {0, 0, 0}, A[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
            for (vtkIdType i = 0; i < n; ++i)
                for (int a = 0; a < 3; ++a) c[a] += f.points[static_cast<size_t>(3 * i + a)] / static_cast<double>(n);
            for (vtkIdType i = 0; i < n; ++i)
                for (int a = 0; a < 3; ++a)
                    for (int b = 0; b < 3; ++b) A[a][b] += (f.points[static_cast<size_t>(3 * i + a)] - c[a]) * (f.points[static_cast<size_t>(3 * i + b)] - c[b]);
            double* rows[3] = {A[0], A[1], A[2]}, w[3], V[3][3], *vrows[3] = {V[0], V[1], V[2]};
            vtkMath::Jacobi(rows, w, vrows);  // eigenvalues decreasing, eigenvectors in the columns
            auto* cam = v.ren->GetActiveCamera();
            cam->SetFocalPoint(c);
            cam->SetPosition(c[0] + V[0][2], c[1] + V[1][2], c[2] + V[2][2]);
            cam->SetViewUp(V[0][1], V[1][1], V[2][1]);
            v.ren->ResetCamera();
            v.camera_set = true;
            if (!v.steer.empty()) {  // the steered instrument starts 3 mm in front of the vessel, pointing into the view
                double d[3] = {V[0][2], V[1][2], V[2][2]}, reach = 0;
                for (vtkIdType i = 0; i < n; ++i) {
                    double proj = 0;
                    for (int a = 0; a < 3; ++a) proj += (f.points[static_cast<size_t>(3 * i + a)] - c[a]) * d[a];
                    reach = std::max(reach, proj);
                }
                for (int a = 0; a < 3; ++a) {
                    v.p[a] = v.start_p[a] = c[a] + (reach + 3.0) * d[a];
                    v.axis[a] = -d[a];
                    v.up[a] = V[a][1];
                }
                v.placed = true;
            }
        }
    }
    for (const auto& [name, M] : clips) {
        auto& a = v.clip_actors[name];
        if (!a) {
            vtkNew<vtkCubeSource> bar;  // a clip: 8 mm along its axis, 1 mm wide
            bar->SetXLength(1.0);
            bar->SetYLength(1.0);
            bar->SetZLength(8.0);
            bar->SetCenter(0, 0, 4.0);
            vtkNew<vtkPolyDataMapper> m;
            m->SetInputConnection(bar->GetOutputPort());
            a = vtkSmartPointer<vtkActor>::New();
            a->SetMapper(m);
            a->GetProperty()->SetColor(0.75, 0.75, 0.8);
            v.ren->AddActor(a);
        }
        double e[16] = {M[0], M[1], M[2], M[3], M[4], M[5], M[6], M[7], M[8], M[9], M[10], M[11], 0, 0, 0, 1};
        vtkNew<vtkTransform> tf;
        tf->SetMatrix(e);
        a->SetUserTransform(tf);
    }
    const auto force_of = [&](const std::string& name) {
        const auto it = forces.find(name);
        return it == forces.end() ? std::array<double, 3>{0, 0, 0} : it->second;
    };
    for (const auto& [name, M] : instruments) {  // the instruments the server reports (the steered one is drawn as steered)
        if (name == v.steer) continue;
        const double tip[3] = {M[3], M[7], M[11]}, ax[3] = {M[2], M[6], M[10]};
        place_tool(tool_of(v, name), tip, ax, force_of(name));
    }
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - v.start).count();
    std::string line;
    for (const auto& [ins, fv] : forces) {
        char b[96];
        std::snprintf(b, sizeof b, "%s %.2f N   ", ins.c_str(), std::sqrt(fv[0] * fv[0] + fv[1] * fv[1] + fv[2] * fv[2]));
        line += b;
    }
    if (!v.steer.empty() && v.placed) {
        steer_frame(v);
        place_tool(tool_of(v, v.steer), v.p, v.axis, force_of(v.steer));
        char b[128];
        std::snprintf(b, sizeof b, "[%s: arrows/i/k move, o/c open %.0f deg, l load, r release, g grasp, b button%s]   ", v.steer.c_str(), v.opening,
                      v.button ? " ON" : "");
        line += b;
    }
    char b[160];
    std::snprintf(b, sizeof b, "surfaces %.0f/s   view %.0f Hz   %s", secs > 0 ? static_cast<double>(surfaces) / secs : 0.0,
                  secs > 0 ? static_cast<double>(v.renders) / secs : 0.0, v.sh->connected ? "" : "(disconnected)");
    v.hud->SetInput((line + b + (status.empty() ? "" : "\n" + status)).c_str());
    v.ren->ResetCameraClippingRange();  // the instruments move: keep them inside the depth range
    const auto r0 = std::chrono::steady_clock::now();
    v.win->Render();
    v.render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - r0).count();
    ++v.renders;
    if (v.shown > 0) v.frame_ends.push_back(std::chrono::steady_clock::now());
    if (!v.screenshot.empty() && !v.finished && v.shown >= v.after_surfaces && v.shown > 0 && v.next_key >= v.keys.size()) {
        write_png(v.win, v.screenshot);
        if (!v.points_out.empty()) {
            // Where a few vertices land on the screenshot (display coordinates, origin bottom left), with their label.
            std::ofstream o(v.points_out);
            vtkNew<vtkCoordinate> c;
            c->SetCoordinateSystemToWorld();
            const vtkIdType n = v.vessel->GetNumberOfPoints();
            auto* lab = v.vessel->GetPointData()->GetScalars();
            const int* size = v.win->GetSize();
            o << size[0] << " " << size[1] << "\n";
            for (vtkIdType i = 0; i < n; i += std::max<vtkIdType>(1, n / 400)) {
                double p[3];
                v.vessel->GetPoint(i, p);
                c->SetValue(p);
                const double* d = c->GetComputedDoubleDisplayValue(v.ren);
                o << i << " " << d[0] << " " << d[1] << " " << lab->GetTuple1(i) << " " << p[0] << " " << p[1] << " " << p[2] << "\n";
            }
            const auto point = [&](const char* what, const double* w) {
                c->SetValue(w[0], w[1], w[2]);
                const double* d = c->GetComputedDoubleDisplayValue(v.ren);
                o << what << " " << v.steer << " 0 " << d[0] << " " << d[1] << " " << w[0] << " " << w[1] << " " << w[2] << "\n";
            };
            if (!v.steer.empty() && v.placed) point("start", v.start_p);  // where the steered instrument started
            if (v.dragged) {  // the last pointer drag's ends
                point("drag_from", v.drag_from);
                point("drag_to", v.drag_to);
            }
            for (const auto& [name, M] : clips) {  // each clip's near end (its hinge) and the bar's middle
                for (const double along : {0.25, 4.0}) {
                    const double w[3] = {M[3] + along * M[2], M[7] + along * M[6], M[11] + along * M[10]};
                    c->SetValue(w[0], w[1], w[2]);
                    const double* d = c->GetComputedDoubleDisplayValue(v.ren);
                    o << "clip " << name << " " << along << " " << d[0] << " " << d[1] << " " << w[0] << " " << w[1] << " " << w[2] << "\n";
                }
            }
        }
        v.finished = true;
    }
}

void on_timer(vtkObject* caller, unsigned long, void* data, void*) {
    auto& v = *static_cast<View*>(data);
    // Frames on a fixed schedule (--max-fps; a display shows no more): a late frame moves the schedule, it does not
    // bunch frames to catch up.
    const auto now = std::chrono::steady_clock::now();
    if (now < v.next_frame) return;
    const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(v.min_period));
    v.next_frame += period;
    if (v.next_frame < now) v.next_frame = now + period;
    update(v);
    if (v.finished || (!v.sh->connected && !v.screenshot.empty())) static_cast<vtkRenderWindowInteractor*>(caller)->TerminateApp();
}

void on_key(vtkObject* caller, unsigned long, void* data, void*) {
    auto* iren = static_cast<vtkRenderWindowInteractor*>(caller);
    auto& v = *static_cast<View*>(data);
    const std::string key = iren->GetKeySym() ? iren->GetKeySym() : "";
    if (!v.steer.empty() && v.placed && key != "s") {
        steer_key(v, key);
        return;
    }
    if (key == "s" || key == "S") {
        char name[64];
        std::snprintf(name, sizeof name, "aneuview_%ld.png", static_cast<long>(std::time(nullptr)));
        write_png(v.win, name);
        std::printf("screenshot %s\n", name);
    }
}

/// VTK's character bindings (r reset, c camera mode, w/s wireframe, e/q exit, …) are off: the keys steer.
/// Trackball camera for the mouse; with --steer, Shift + left drag moves the instrument in the view plane (it
/// follows the pointer at its depth) and Shift + wheel moves it along its axis (0.25 mm a notch).
class ViewStyle : public vtkInteractorStyleTrackballCamera {
public:
    static ViewStyle* New();
    vtkTypeMacro(ViewStyle, vtkInteractorStyleTrackballCamera)
    View* view = nullptr;
    void OnChar() override {}
    void OnLeftButtonDown() override {
        if (steering()) {
            m_drag = true;
            const int* e = Interactor->GetEventPosition();
            m_last[0] = e[0];
            m_last[1] = e[1];
            return;
        }
        vtkInteractorStyleTrackballCamera::OnLeftButtonDown();
    }
    void OnLeftButtonUp() override {
        if (m_drag) {
            m_drag = false;
            return;
        }
        vtkInteractorStyleTrackballCamera::OnLeftButtonUp();
    }
    void OnMouseMove() override {
        if (m_drag) {
            const int* e = Interactor->GetEventPosition();
            drag(*view, e[0] - m_last[0], e[1] - m_last[1]);
            m_last[0] = e[0];
            m_last[1] = e[1];
            return;
        }
        vtkInteractorStyleTrackballCamera::OnMouseMove();
    }
    void OnMouseWheelForward() override {
        if (steering()) return steer_key(*view, "i");
        vtkInteractorStyleTrackballCamera::OnMouseWheelForward();
    }
    void OnMouseWheelBackward() override {
        if (steering()) return steer_key(*view, "k");
        vtkInteractorStyleTrackballCamera::OnMouseWheelBackward();
    }

private:
    bool steering() const { return view && !view->steer.empty() && view->placed && Interactor->GetShiftKey(); }
    bool m_drag = false;
    int m_last[2] = {0, 0};
};
vtkStandardNewMacro(ViewStyle)

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"aneuclip viewer: connects to a running `aneusim serve` and shows the deforming vessel and the clips", "aneuview"};
    std::string host = "127.0.0.1", screenshot, points_out;
    int port = 18944;
    long after = 1;
    double wait_s = 30;
    std::vector<int> size{900, 700};
    app.add_option("--host", host, "host of `aneusim serve`")->capture_default_str();
    app.add_option("--port", port, "its port")->check(CLI::Range(1, 65535))->capture_default_str();
    app.add_option("--screenshot", screenshot, "write a PNG once --after-surfaces surfaces have arrived, then exit (tests, reports)");
    app.add_option("--after-surfaces", after, "surfaces to wait for before the screenshot")->check(CLI::PositiveNumber)->capture_default_str();
    app.add_option("--points", points_out, "with --screenshot: where some vertices land on it (text: index x y label wx wy wz)");
    std::string steer, clip_model, keys, stereo;
    app.add_option("--stereo", stereo, "side-by-side: a stereo pair, left and right eye in the two halves of the window (as the published system's display)")
        ->check(CLI::IsMember({"side-by-side"}));
    app.add_option("--steer", steer, "instrument of the scene to steer from the keyboard (e.g. applier, suction); starts 3 mm in front of the vessel");
    app.add_option("--clip-model", clip_model, "clip model the 'l' key loads (a name from the scene's clip_models)");
    app.add_option("--keys", keys, "with --steer: key presses to apply one a frame (comma separated: Left,Right,Up,Down,i,k,o,c,l,r,g,b; drag:DX:DY a Shift+drag of DX,DY pixels) — demos, tests");
    app.add_option("--wait-seconds", wait_s, "keep trying to connect this long (the server may still be loading its bundle)")->check(CLI::NonNegativeNumber)->capture_default_str();
    std::string antialias = "none";
    app.add_option("--antialias", antialias, "none, fxaa or msaa (8 samples): smoother edges, at a cost under a software renderer")
        ->check(CLI::IsMember({"none", "fxaa", "msaa"}))->capture_default_str();
    double max_fps = 60;
    app.add_option("--max-fps", max_fps, "frames per second to render at most (a display shows no more; 0: as fast as it can, for benchmarks)")
        ->check(CLI::NonNegativeNumber)->capture_default_str();
    app.add_option("--size", size, "window size W,H")->delimiter(',')->expected(2)->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    if (!std::getenv("DISPLAY")) {
        std::fprintf(stderr, "aneuview: error: no X display (DISPLAY is unset); run it under xvfb-run -a for screenshots without a screen\n");
        return 2;
    }
    auto sock = igtl::ClientSocket::New();
    bool ok = false;
    for (int k = 0; k <= static_cast<int>(wait_s * 10) && !ok; ++k) {
        ok = sock->ConnectToServer(host.c_str(), port) == 0;
        if (!ok) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (!ok) {
        std::fprintf(stderr, "aneuview: error: no `aneusim serve` at %s:%d (expected a running server: aneusim serve SCENE --port %d)\n", host.c_str(), port, port);
        return 1;
    }
    Shared sh;
    sh.connected = true;
    std::thread net([&] { receive_loop(sock, sh); });

    vtkNew<vtkPolyData> vessel;
    vtkNew<vtkLookupTable> lut;
    lut->SetNumberOfTableValues(2);
    lut->SetTableRange(0, 1);
    lut->SetTableValue(0, ARTERY[0], ARTERY[1], ARTERY[2], 1.0);
    lut->SetTableValue(1, ANEURYSM[0], ANEURYSM[1], ANEURYSM[2], 1.0);
    lut->Build();
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputData(vessel);
    mapper->SetLookupTable(lut);
    mapper->SetScalarRange(0, 1);
    mapper->SetScalarModeToUsePointData();
    mapper->InterpolateScalarsBeforeMappingOff();
    vtkNew<vtkActor> actor;
    actor->SetMapper(mapper);
    actor->GetProperty()->SetAmbient(0.35);
    actor->GetProperty()->SetDiffuse(0.65);
    vtkNew<vtkRenderer> ren;
    ren->AddActor(actor);
    ren->SetBackground(1, 1, 1);
    vtkNew<vtkTextActor> hud;
    hud->GetTextProperty()->SetFontSize(16);
    hud->GetTextProperty()->SetColor(0.1, 0.1, 0.1);
    hud->SetPosition(10, 10);
    ren->AddActor2D(hud);
    const vtkSmartPointer<vtkRenderWindow> win = make_view_window();
    win->AddRenderer(ren);
    win->SetSize(size[0], size[1]);
    win->SetWindowName("aneuview");
    // Multisampling (VTK's default, 8 samples) triples the frame time of a software renderer (Xvfb's llvmpipe:
    // 24 ms against 8 ms a frame at 600 x 500, FXAA 18 ms): off unless asked for (a GPU does it for free).
    win->SetMultiSamples(antialias == "msaa" ? 8 : 0);
    if (antialias == "fxaa") ren->UseFXAAOn();
    if (stereo == "side-by-side") {
        win->SetStereoCapableWindow(1);
        win->SetStereoTypeToSplitViewportHorizontal();
        win->StereoRenderOn();
    }
    vtkNew<vtkRenderWindowInteractor> iren;
    iren->SetRenderWindow(win);
    View v;
    v.sh = &sh;
    v.vessel = vessel;
    v.ren = ren;
    v.win = win;
    v.hud = hud;
    v.screenshot = screenshot;
    v.points_out = points_out;
    v.after_surfaces = after;
    v.sock = sock;
    v.steer = steer;
    v.clip_model = clip_model;
    v.min_period = max_fps > 0 ? 1.0 / max_fps : 0.0;
    for (size_t a = 0, b; a < keys.size(); a = b + 1) {
        b = keys.find(',', a);
        if (b == std::string::npos) b = keys.size();
        if (b > a) v.keys.push_back(keys.substr(a, b - a));
    }
    vtkNew<ViewStyle> style;
    style->view = &v;
    iren->SetInteractorStyle(style);
    iren->Initialize();
    vtkNew<vtkCallbackCommand> timer;
    timer->SetCallback(on_timer);
    timer->SetClientData(&v);
    iren->AddObserver(vtkCommand::TimerEvent, timer);
    vtkNew<vtkCallbackCommand> key;
    key->SetCallback(on_key);
    key->SetClientData(&v);
    iren->AddObserver(vtkCommand::KeyPressEvent, key);
    iren->CreateRepeatingTimer(1);
    win->Render();
    iren->Start();
    // The rates up to the last frame rendered (not the screenshot written after it, nor the exit).
    const auto last = v.frame_ends.empty() ? std::chrono::steady_clock::now() : v.frame_ends.back();
    const double secs = std::chrono::duration<double>(last - v.start).count();
    std::vector<double> gaps;  // the steady frames' intervals
    for (size_t k = 1; k < v.frame_ends.size(); ++k) gaps.push_back(std::chrono::duration<double>(v.frame_ends[k] - v.frame_ends[k - 1]).count());
    const double steady_s = gaps.empty() ? 0.0 : std::chrono::duration<double>(last - v.frame_ends.front()).count();
    std::printf("surfaces_received %ld\nframes_rendered %ld\nframe_rate_hz %.1f\nframe_rate_steady_hz %.1f\nrender_ms_mean %.2f\n", sh.surfaces, v.renders,
                secs > 0 ? static_cast<double>(v.renders) / secs : 0.0, steady_s > 0 ? static_cast<double>(gaps.size()) / steady_s : 0.0,
                v.renders > 0 ? 1e3 * v.render_s / static_cast<double>(v.renders) : 0.0);
    // The steady frames' intervals: median, 99th percentile, longest, and with --max-fps the periods of a display at
    // that rate over the steady span and how many of them got no new frame (periods less frames: as the steady rate).
    if (!gaps.empty()) {
        const long missed = v.min_period > 0 ? std::max(0L, std::lround(steady_s / v.min_period) - static_cast<long>(gaps.size())) : 0;
        std::printf("frame_interval_ms_p50 %.2f\nframe_interval_ms_p99 %.2f\nframe_interval_ms_max %.2f\n", 1e3 * aneu::percentile(gaps, 0.5),
                    1e3 * aneu::percentile(gaps, 0.99), 1e3 * aneu::percentile(gaps, 1.0));
        if (v.min_period > 0) std::printf("display_periods %ld\ndisplay_periods_missed %ld\n", static_cast<long>(gaps.size()) + missed, missed);
    }
    sh.done = true;
    sock->CloseSocket();
    net.join();
    return screenshot.empty() || v.finished ? 0 : 1;
}
