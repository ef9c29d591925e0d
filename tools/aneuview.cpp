// SPDX-License-Identifier: MIT
// aneuview: a VTK desktop view of a running `aneusim serve` (issue #18). It connects as an OpenIGTLink client and
// draws the deformed vessel (label colours: artery red, aneurysm yellow), the deposited and held clips (a bar along
// each clip's axis), a heads-up line (force per instrument, surfaces per second, the last event) and takes
// screenshots. Not in this first version: steering the instruments from keyboard and mouse, --stereo.
// It is not the simulator: it may link VTK; aneusim does not.
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
#include <igtlTransformMessage.h>
#include <vtkActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCoordinate.h>
#include <vtkCubeSource.h>
#include <vtkFloatArray.h>
#include <vtkLookupTable.h>
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
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkTransform.h>
#include <vtkWindowToImageFilter.h>

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
    std::map<std::string, double> force_n;
    std::string last_status;
    long surfaces = 0;
    std::atomic<bool> connected{false}, done{false};
};

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
        } else if (type == "TRANSFORM" && name.rfind("clip", 0) == 0) {
            igtl::Matrix4x4 M;
            static_cast<igtl::TransformMessage*>(m.GetPointer())->GetMatrix(M);
            std::array<float, 12> r{};
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 4; ++j) r[static_cast<size_t>(4 * i + j)] = M[i][j];
            sh.clips[name] = r;
        } else if (type == "SENSOR" && name.size() > 6 && name.compare(name.size() - 6, 6, ".force") == 0) {
            auto* f = static_cast<igtl::SensorMessage*>(m.GetPointer());
            if (f->GetLength() == 3) sh.force_n[name.substr(0, name.size() - 6)] = std::sqrt(f->GetValue(0) * f->GetValue(0) + f->GetValue(1) * f->GetValue(1) + f->GetValue(2) * f->GetValue(2));
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
    long shown = 0;
    bool camera_set = false;
    std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
    long renders = 0;
    // Screenshot mode.
    std::string screenshot, points_out;
    long after_surfaces = 0;
    bool finished = false;
};

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

void update(View& v) {
    Frame f;
    std::map<std::string, std::array<float, 12>> clips;
    std::map<std::string, double> forces;
    std::string status;
    long surfaces = 0;
    {
        std::lock_guard<std::mutex> lk(v.sh->mx);
        if (v.sh->frame.serial != v.shown) f = v.sh->frame;
        clips = v.sh->clips;
        forces = v.sh->force_n;
        status = v.sh->last_status;
        surfaces = v.sh->surfaces;
    }
    if (f.serial != 0) {
        const vtkIdType n = static_cast<vtkIdType>(f.points.size() / 3);
        vtkNew<vtkPoints> pts;
        pts->SetNumberOfPoints(n);
        for (vtkIdType i = 0; i < n; ++i) pts->SetPoint(i, f.points[static_cast<size_t>(3 * i)], f.points[static_cast<size_t>(3 * i + 1)], f.points[static_cast<size_t>(3 * i + 2)]);
        v.vessel->SetPoints(pts);
        if (v.vessel->GetNumberOfPolys() == 0) {
            vtkNew<vtkCellArray> tris;
            for (size_t t = 0; t + 2 < f.triangles.size(); t += 3) {
                const vtkIdType ids[3] = {f.triangles[t], f.triangles[t + 1], f.triangles[t + 2]};
                tris->InsertNextCell(3, ids);
            }
            v.vessel->SetPolys(tris);
        }
        vtkNew<vtkFloatArray> lab;
        lab->SetName("label");
        for (float l : f.labels) lab->InsertNextValue(l);
        v.vessel->GetPointData()->SetScalars(lab);
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
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - v.start).count();
    std::string line;
    for (const auto& [ins, fn] : forces) {
        char b[96];
        std::snprintf(b, sizeof b, "%s %.2f N   ", ins.c_str(), fn);
        line += b;
    }
    char b[160];
    std::snprintf(b, sizeof b, "surfaces %.0f/s   view %.0f Hz   %s", secs > 0 ? static_cast<double>(surfaces) / secs : 0.0,
                  secs > 0 ? static_cast<double>(v.renders) / secs : 0.0, v.sh->connected ? "" : "(disconnected)");
    v.hud->SetInput((line + b + (status.empty() ? "" : "\n" + status)).c_str());
    v.win->Render();
    ++v.renders;
    if (!v.screenshot.empty() && !v.finished && v.shown >= v.after_surfaces && v.shown > 0) {
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
        }
        v.finished = true;
    }
}

void on_timer(vtkObject* caller, unsigned long, void* data, void*) {
    auto& v = *static_cast<View*>(data);
    update(v);
    if (v.finished || (!v.sh->connected && !v.screenshot.empty())) static_cast<vtkRenderWindowInteractor*>(caller)->TerminateApp();
}

void on_key(vtkObject* caller, unsigned long, void* data, void*) {
    auto* iren = static_cast<vtkRenderWindowInteractor*>(caller);
    auto& v = *static_cast<View*>(data);
    const std::string key = iren->GetKeySym() ? iren->GetKeySym() : "";
    if (key == "s" || key == "S") {
        char name[64];
        std::snprintf(name, sizeof name, "aneuview_%ld.png", static_cast<long>(std::time(nullptr)));
        write_png(v.win, name);
        std::printf("screenshot %s\n", name);
    }
}

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
    app.add_option("--wait-seconds", wait_s, "keep trying to connect this long (the server may still be loading its bundle)")->check(CLI::NonNegativeNumber)->capture_default_str();
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
    vtkNew<vtkRenderWindow> win;
    win->AddRenderer(ren);
    win->SetSize(size[0], size[1]);
    win->SetWindowName("aneuview");
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
    iren->Initialize();
    vtkNew<vtkCallbackCommand> timer;
    timer->SetCallback(on_timer);
    timer->SetClientData(&v);
    iren->AddObserver(vtkCommand::TimerEvent, timer);
    vtkNew<vtkCallbackCommand> key;
    key->SetCallback(on_key);
    key->SetClientData(&v);
    iren->AddObserver(vtkCommand::KeyPressEvent, key);
    iren->CreateRepeatingTimer(10);
    win->Render();
    iren->Start();
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - v.start).count();
    std::printf("surfaces_received %ld\nframes_rendered %ld\nframe_rate_hz %.1f\n", sh.surfaces, v.renders, secs > 0 ? static_cast<double>(v.renders) / secs : 0.0);
    sh.done = true;
    sock->CloseSocket();
    net.join();
    return screenshot.empty() || v.finished ? 0 : 1;
}
