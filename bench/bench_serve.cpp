// SPDX-License-Identifier: MIT
// `aneusim serve` in real time on a case: a scripted scene's keyframes replayed by an OpenIGTLink client as a device
// would stream them (a pose per instrument every millisecond, opening with it, actions at their keyframes), and a
// second client that only watches (a viewer). Measures:
//   - pose-in -> force-out latency: from sending a TRANSFORM to receiving the first force SENSOR stamped at or after
//     it (the haptic loop takes the inputs that arrived before a tick, then computes that tick's force; both
//     time stamps are on the server's clock, which starts when it listens), p50/p99/max;
//   - the haptic loop's rate and period p99 (the session report), the physics rate;
//   - the surfaces (POLYDATA) each client received per second, and their size.
// With --flood, a third client meanwhile sends 10,000 messages a second (TRANSFORMs of an unknown device, every
// 100th a NaN pose of the first instrument) and a fourth connects every 0.5 s, sends garbage and is dropped: the
// haptic loop's rate and period under that load.
// Usage: aneu_bench_serve SCENE [--seconds S] [--out results.md] [--flood 1]   (the scene's instruments and keyframes are used;
// its bundle, relative to the scene file)
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlPolyDataMessage.h>
#include <igtlSensorMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <nlohmann/json.hpp>

#include "aneu/core/common.hpp"
#include "aneu/sim/serve.hpp"

using namespace aneu;
using Clock = std::chrono::steady_clock;

namespace {

void stamp(igtl::MessageBase* m, double t) {
    const double sec = std::floor(t);
    m->SetTimeStamp(static_cast<unsigned>(sec), static_cast<unsigned>(std::llround((t - sec) * 4294967296.0)));
}

double stamp_of(igtl::MessageBase* m) {
    unsigned sec = 0, frac = 0;
    m->GetTimeStamp(&sec, &frac);
    return static_cast<double>(sec) + static_cast<double>(frac) / 4294967296.0;
}

void send(igtl::ClientSocket* s, igtl::MessageBase* m) {
    m->Pack();
    s->Send(m->GetPackPointer(), m->GetPackSize());
}

igtl::ClientSocket::Pointer connect_to(int port) {
    auto s = igtl::ClientSocket::New();
    for (int k = 0; k < 100 && s->ConnectToServer("127.0.0.1", port) != 0; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return s;
}

struct Reader {
    std::vector<std::pair<double, double>> forces;  // (server stamp, arrival on the server's clock)
    long polydata = 0;
    long polydata_bytes = 0;
    int points = 0;
};

// Reads until the connection closes; arrival times on the server's clock (t0 = when it started listening).
Reader read_all(igtl::ClientSocket* s, Clock::time_point t0, const std::string& force_name) {
    Reader r;
    while (true) {
        auto h = igtl::MessageHeader::New();
        h->InitPack();
        if (s->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) break;
        const double arrival = std::chrono::duration<double>(Clock::now() - t0).count();
        h->Unpack();
        const std::string type = h->GetDeviceType();
        if (type == "SENSOR" && std::string(h->GetDeviceName()) == force_name) {
            auto m = igtl::SensorMessage::New();
            m->SetMessageHeader(h);
            m->AllocatePack();
            if (s->Receive(m->GetPackBodyPointer(), m->GetPackBodySize()) != m->GetPackBodySize()) break;
            m->Unpack();
            r.forces.emplace_back(stamp_of(m), arrival);
        } else if (type == "POLYDATA") {
            auto m = igtl::PolyDataMessage::New();
            m->SetMessageHeader(h);
            m->AllocatePack();
            if (s->Receive(m->GetPackBodyPointer(), m->GetPackBodySize()) != m->GetPackBodySize()) break;
            m->Unpack();
            ++r.polydata;
            r.polydata_bytes += m->GetPackSize();
            r.points = m->GetPoints()->GetNumberOfPoints();
        } else {
            s->Skip(h->GetBodySizeToRead());
        }
    }
    return r;
}

double pct(std::vector<double> v, double q) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return percentile(v, q);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s SCENE [--seconds S] [--out results.md]\n", argv[0]);
        return 2;
    }
    double seconds = 0;
    bool flood = false;
    std::string out;
    for (int a = 2; a + 1 < argc; a += 2) {
        if (!std::strcmp(argv[a], "--seconds")) seconds = std::atof(argv[a + 1]);
        if (!std::strcmp(argv[a], "--out")) out = argv[a + 1];
        if (!std::strcmp(argv[a], "--flood")) flood = std::atoi(argv[a + 1]) != 0;
    }
    sim::Scene scene = sim::read_scene(argv[1]);
    const sim::Scene script = scene;  // the keyframes the client replays
    scene.live_input = true;
    const std::string report = "/tmp/aneu_bench_serve_report_" + std::to_string(::getpid()) + ".json";
    scene.report = report;
    scene.log.clear();
    scene.series.clear();
    double duration = seconds;
    for (const auto& ins : script.instruments)
        if (!ins.keys.empty()) duration = std::max(duration, ins.keys.back().t);
    if (seconds > 0) duration = seconds;
    sim::LoadOptions lo;
    lo.region = scene.region;
    lo.working_precision = scene.working_precision;
    sim::SimModel model = sim::load_model(scene.bundle, lo);
    const size_t n_vertices = static_cast<size_t>(model.surface.size());
    sim::Simulator sim(std::move(scene), std::move(model));

    std::promise<int> port_p;
    Clock::time_point t0;
    sim::ServeOptions so;
    so.port = 0;
    so.max_clients = flood ? 4 : 2;
    so.on_listening = [&](int p) {
        t0 = Clock::now();
        port_p.set_value(p);
    };
    sim::ServeCounters counters;
    auto served = std::async(std::launch::async, [&] { return sim::serve_scene(sim, so, &counters); });
    const int port = port_p.get_future().get();
    auto device = connect_to(port), viewer = connect_to(port);
    const std::string first = script.instruments.front().name;
    auto dev_reader = std::async(std::launch::async, [&] { return read_all(device, t0, first + ".force"); });
    auto view_reader = std::async(std::launch::async, [&] { return read_all(viewer, t0, "-"); });

    std::atomic<bool> flooding{flood};
    std::thread flooder, garbler;
    if (flood) {
        flooder = std::thread([&] {
            auto s = connect_to(port);
            const auto f0 = Clock::now();
            for (long k = 0; flooding; ++k) {
                std::this_thread::sleep_until(f0 + std::chrono::microseconds(100 * k));
                auto tm = igtl::TransformMessage::New();
                igtl::Matrix4x4 M;
                igtl::IdentityMatrix(M);
                if (k % 100 == 0) {
                    tm->SetDeviceName(script.instruments.front().name.c_str());
                    M[0][3] = std::nanf("");
                } else {
                    tm->SetDeviceName("flood");
                }
                tm->SetMatrix(M);
                send(s, tm);
            }
            s->CloseSocket();
        });
        garbler = std::thread([&] {
            const std::string junk(256, '\x5a');
            while (flooding) {
                auto s = connect_to(port);
                s->Send(junk.data(), static_cast<int>(junk.size()));
                std::this_thread::sleep_for(std::chrono::milliseconds(500));
                s->CloseSocket();
            }
        });
    }
    // The device: every instrument's pose each millisecond of the script, on the wall clock; the time each pose of
    // the first instrument left, on the server's clock.
    std::vector<double> sent;
    const auto start = Clock::now();
    std::vector<size_t> next_key(script.instruments.size(), 0);
    for (long k = 0;; ++k) {
        const double ts = 1e-3 * static_cast<double>(k);
        if (ts > duration) break;
        std::this_thread::sleep_until(start + std::chrono::microseconds(1000 * k));
        for (size_t i = 0; i < script.instruments.size(); ++i) {
            const auto& ins = script.instruments[i];
            if (ins.keys.empty()) continue;
            const sim::Keyframe kf = sim::sample(ins, ts);
            auto o = igtl::SensorMessage::New();
            o->SetDeviceName((ins.name + (ins.kind == sim::InstrumentSpec::Kind::SUCTION ? ".button" : ".opening")).c_str());
            o->SetLength(1);
            o->SetValue(0u, ins.kind == sim::InstrumentSpec::Kind::SUCTION ? (kf.button ? 1.0 : 0.0) : kf.opening_deg);
            send(device, o);
            while (next_key[i] < ins.keys.size() && ins.keys[next_key[i]].t <= ts) {  // the keyframes' actions, once
                const auto& key = ins.keys[next_key[i]++];
                std::string action = !key.load.empty() ? "load " + key.load : key.release ? "release" : key.grasp ? "grasp" : "";
                if (action.empty()) continue;
                auto a = igtl::StringMessage::New();
                a->SetDeviceName((ins.name + ".action").c_str());
                a->SetString(action.c_str());
                send(device, a);
            }
            auto tm = igtl::TransformMessage::New();
            tm->SetDeviceName(ins.name.c_str());
            stamp(tm, ts);
            igtl::Matrix4x4 M;
            igtl::IdentityMatrix(M);
            const Eigen::Vector3d z = kf.pose.axis.normalized(), x = (kf.pose.up - kf.pose.up.dot(z) * z).normalized(), y = z.cross(x);
            for (int r = 0; r < 3; ++r) {
                M[r][0] = static_cast<float>(x[r]);
                M[r][1] = static_cast<float>(y[r]);
                M[r][2] = static_cast<float>(z[r]);
                M[r][3] = static_cast<float>(kf.pose.position[r]);
            }
            tm->SetMatrix(M);
            if (i == 0) sent.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
            send(device, tm);
        }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    flooding = false;
    if (flooder.joinable()) flooder.join();
    if (garbler.joinable()) garbler.join();
    auto stop = igtl::StringMessage::New();
    stop->SetDeviceName("aneusim");
    stop->SetString("stop");
    send(device, stop);
    const sim::Assessment a = served.get();
    const Reader dr = dev_reader.get(), vr = view_reader.get();

    // Latency: for each pose, the first force stamped at or after its sending, and when that force arrived.
    std::vector<double> lat;
    size_t j = 0;
    for (double s : sent) {
        while (j < dr.forces.size() && dr.forces[j].first < s) ++j;
        if (j == dr.forces.size()) break;
        lat.push_back(1e3 * (dr.forces[j].second - s));
    }
    nlohmann::json rep;
    {
        std::ifstream in(report);
        rep = nlohmann::json::parse(in);
    }
    std::remove(report.c_str());
    std::remove((report + ".txt").c_str());
    const double span = dr.forces.empty() ? 0 : dr.forces.back().second - dr.forces.front().second;
    char buf[2048];
    std::snprintf(buf, sizeof buf,
                  "| %s%s | %zu | %.2f | %.3f | %.3f | %.3f | %.0f | %.2f | %.0f | %.1f | %.1f | %d | %.0f | %ld | %ld |\n", argv[1],
                  flood ? " + flood (10 kHz, NaN, garbage)" : "", n_vertices, duration,
                  pct(lat, 0.5), pct(lat, 0.99), pct(lat, 1.0), rep["haptic_loop"].value("rate_hz", 0.0),
                  rep["haptic_loop"]["period_ms"].value("p99", 0.0), rep.value("physics_rate_hz", 0.0),
                  span > 0 ? static_cast<double>(dr.polydata) / span : 0.0, span > 0 ? static_cast<double>(vr.polydata) / span : 0.0, vr.points,
                  vr.polydata ? static_cast<double>(vr.polydata_bytes) / static_cast<double>(vr.polydata) / 1024.0 : 0.0, counters.poses_coalesced,
                  counters.forces_skipped);
    std::printf("scene | surface vertices | session (s) | latency p50 (ms) | p99 (ms) | max (ms) | haptic rate (Hz) | haptic period p99 (ms) | physics rate (Hz) | surfaces/s to the device client | to the viewer | points per surface | KiB per surface | poses coalesced | forces skipped\n%s", buf);
    std::printf("peak force %.3f N, neck closed %.1f %%, clips used %d, poses %ld, forces sent %ld, latency samples %zu; dropped unknown %ld, "
                "malformed %ld, garbage %ld, oversize %ld\n",
                a.peak_force_n, 100 * a.neck_closed_fraction, a.clips_used, counters.poses, counters.forces_sent, lat.size(), counters.dropped_unknown,
                counters.dropped_malformed, counters.dropped_garbage, counters.dropped_oversize);
    if (!out.empty()) std::ofstream(out, std::ios::app) << buf;
    return 0;
}
