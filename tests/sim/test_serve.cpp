// SPDX-License-Identifier: MIT
// `aneusim serve` over loopback with a real OpenIGTLink client (the same library): a scripted session gives the
// forces that the same poses give as a text stream in deterministic mode, and bad clients (garbage, an absurd
// declared size, NaN poses, unknown messages, a flood) are counted and dropped while the session goes on.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <future>
#include <map>
#include <sstream>
#include <thread>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlPolyDataMessage.h>
#include <igtlPositionMessage.h>
#include <igtlSensorMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_util.h>
#include <nlohmann/json.hpp>

#include "aneu/sim/serve.hpp"
#include "aneu/sim/simulator.hpp"
#include "sim_fixtures.hpp"
#include "test_bundles.hpp"

using namespace aneu;
using nlohmann::json;

namespace {

const std::string& tube_bundle() {
    static test::TempDir dir("servecase");
    static const std::string file = [] {
        const std::string f = dir.file("tube.h5");
        write_bundle(f, test::tube_case(Precision::FLOAT64, 32, 20, 1.0, 0.5).bundle);
        return f;
    }();
    return file;
}

sim::Simulator make_sim(const std::string& dir, const std::string& report = "") {
    json j{{"bundle", tube_bundle()},
                 {"live_input", true},
                 {"contact", {{"linear_limit", 0}}},
                 {"clip_models", {{"straight", {{"jaw_length_mm", 4.0}, {"jaw_width_mm", 1.2}, {"jaw_thickness_mm", 0.5}, {"max_opening_deg", 45}}}}},
                 {"rates_hz", {{"haptic", 1000}, {"physics", 250}, {"log", 250}}},
                 {"instruments", json::array({{{"name", "applier"}, {"kind", "clip_applier"}}})}};
    if (!report.empty()) j["outputs"] = {{"report", report}};
    const std::string p = dir + "/scene.json";
    std::ofstream(p) << j.dump(2);
    sim::Scene sc = sim::read_scene(p);
    sim::SimModel m = sim::load_model(sc.bundle, sim::LoadOptions{});
    return sim::Simulator(std::move(sc), std::move(m));
}

std::string num(double x) {
    char b[40];
    std::snprintf(b, sizeof b, "%.9g", x);
    return b;
}

// One scripted sample: the applier's pose (single precision, as OpenIGTLink carries it), opening and action.
struct Sample {
    double t;
    float p[3], axis[3], up[3];
    double opening;
    std::string action;  // "", "load straight", "release"
};

std::vector<Sample> session() {
    std::vector<Sample> s;
    auto add = [&](double t, float x, float z, double open, std::string action = "") {
        s.push_back(Sample{t, {x, 0.0f, z}, {-1.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 1.0f}, open, std::move(action)});
    };
    add(0.0005, 5.0f, 4.0f, 40, "load straight");
    for (int k = 1; k <= 40; ++k) add(0.0005 + 0.002 * k, 5.0f - 0.06f * static_cast<float>(k), 4.0f, 40);  // to x = 2.6
    for (int k = 1; k <= 40; ++k) add(0.0805 + 0.002 * k, 2.6f, 4.0f, 40.0 - k);                            // close to 0°
    add(0.1705, 2.6f, 4.0f, 0, "release");
    for (int k = 1; k <= 10; ++k) add(0.1705 + 0.002 * k, 2.6f + 0.2f * static_cast<float>(k), 4.0f, 0);
    return s;
}

// The text stream's line of a sample (what the server builds from the messages).
std::string line(const Sample& s) {
    std::string l = num(s.t) + " applier";
    for (const float* v : {s.p, s.axis, s.up})
        for (int k = 0; k < 3; ++k) l += " " + num(v[k]);
    l += " " + num(s.opening) + " 0";
    if (s.action == "load straight") l += " load:straight";
    if (s.action == "release") l += " release";
    return l + "\n";
}

void stamp(igtl::MessageBase* m, double t) {
    const double sec = std::floor(t);
    m->SetTimeStamp(static_cast<unsigned>(sec), static_cast<unsigned>(std::llround((t - sec) * 4294967296.0)));
}

void put_be(std::string& out, std::uint64_t v, int n) {
    for (int k = n - 1; k >= 0; --k) out.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

// What 3D Slicer's OpenIGTLinkIF sends (header version 2 by default): an extended header (its size 12, the metadata
// header's size, the metadata's size, a message id), the content, then metadata (here MRMLNodeName = the device
// name, as Slicer writes it); body size and CRC over all of it. The library here packs version 1: rebuilt by hand.
std::string as_version2(igtl::MessageBase* m) {
    m->Pack();
    const auto* p = static_cast<const unsigned char*>(m->GetPackPointer());
    const std::string content(reinterpret_cast<const char*>(p) + 58, static_cast<size_t>(m->GetPackBodySize()));
    const std::string key = "MRMLNodeName", value = m->GetDeviceName();
    std::string body;
    put_be(body, 12, 2);
    put_be(body, 2 + 8, 2);  // one metadata entry
    put_be(body, key.size() + value.size(), 4);
    put_be(body, 7, 4);      // message id
    body += content;
    put_be(body, 1, 2);      // index count, then key size, value encoding (3: US-ASCII), value size
    put_be(body, key.size(), 2);
    put_be(body, 3, 2);
    put_be(body, value.size(), 4);
    body += key + value;
    std::string h(reinterpret_cast<const char*>(p), 58);
    h[0] = 0;
    h[1] = 2;
    std::string size_crc;
    put_be(size_crc, body.size(), 8);
    put_be(size_crc, crc64(reinterpret_cast<unsigned char*>(body.data()), body.size(), 0), 8);
    h.replace(42, 16, size_crc);
    return h + body;
}

bool send(igtl::ClientSocket* s, igtl::MessageBase* m, bool v2 = false) {
    if (v2) {
        const std::string b = as_version2(m);
        return s->Send(b.data(), static_cast<int>(b.size())) != 0;
    }
    m->Pack();
    return s->Send(m->GetPackPointer(), m->GetPackSize()) != 0;
}

void send_sample(igtl::ClientSocket* s, const Sample& x, bool v2 = false) {
    auto o = igtl::SensorMessage::New();
    o->SetDeviceName("applier.opening");
    stamp(o, x.t);
    o->SetLength(1);
    o->SetValue(0u, x.opening);
    send(s, o, v2);
    if (!x.action.empty()) {
        auto a = igtl::StringMessage::New();
        a->SetDeviceName("applier.action");
        stamp(a, x.t);
        a->SetString(x.action.c_str());
        send(s, a, v2);
    }
    auto tm = igtl::TransformMessage::New();
    tm->SetDeviceName("applier");
    stamp(tm, x.t);
    igtl::Matrix4x4 M;
    igtl::IdentityMatrix(M);
    for (int r = 0; r < 3; ++r) {
        M[r][0] = x.up[r];
        M[r][1] = 0;
        M[r][2] = x.axis[r];
        M[r][3] = x.p[r];
    }
    M[0][1] = x.axis[1] * x.up[2] - x.axis[2] * x.up[1];  // y = z × x (not read by the server)
    M[1][1] = x.axis[2] * x.up[0] - x.axis[0] * x.up[2];
    M[2][1] = x.axis[0] * x.up[1] - x.axis[1] * x.up[0];
    tm->SetMatrix(M);
    send(s, tm, v2);
}

struct Received {
    std::vector<std::pair<double, std::array<double, 3>>> forces;
    int polydata = 0, polydata_points = 0, clip_transforms = 0;
    std::array<float, 3> first_point{0, 0, 0};  // vertex 0 of the first surface
    std::vector<std::string> status;
    std::vector<std::pair<double, std::string>> force_text;  // STRING applier.force
    int applier_poses = 0;
    double last_applier_pose_t = -1;
    igtl::Matrix4x4 last_applier_pose;
    // What 3D Slicer's OpenIGTLinkIF could not take: message types it does not convert (it does not convert SENSOR:
    // that force also comes as STRING), device names over 20 bytes, polydata attributes other than a 1-component
    // point scalar, STATUS codes of 20 or more.
    std::map<std::string, int> types;
    int long_names = 0, odd_attributes = 0, odd_status = 0;
};

// Reads until the server closes the connection.
Received receive_all(igtl::ClientSocket* s) {
    Received r;
    while (true) {
        auto h = igtl::MessageHeader::New();
        h->InitPack();
        if (s->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) break;
        h->Unpack();
        const std::string type = h->GetDeviceType();
        igtl::MessageBase::Pointer m;
        if (type == "SENSOR") m = igtl::SensorMessage::New();
        else if (type == "POLYDATA") m = igtl::PolyDataMessage::New();
        else if (type == "STATUS") m = igtl::StatusMessage::New();
        else if (type == "TRANSFORM") m = igtl::TransformMessage::New();
        else if (type == "STRING") m = igtl::StringMessage::New();
        ++r.types[type];
        const auto* raw = static_cast<const unsigned char*>(h->GetPackPointer());
        r.long_names += raw[14 + 19] != 0;  // 20 bytes used: no room for the terminating NUL some readers expect
        if (m.IsNull()) {
            s->Skip(h->GetBodySizeToRead());
            continue;
        }
        m->SetMessageHeader(h);
        m->AllocatePack();
        if (s->Receive(m->GetPackBodyPointer(), m->GetPackBodySize()) != m->GetPackBodySize()) break;
        m->Unpack(1);
        unsigned sec = 0, frac = 0;
        m->GetTimeStamp(&sec, &frac);
        const double t = static_cast<double>(sec) + static_cast<double>(frac) / 4294967296.0;
        if (type == "SENSOR") {
            auto* f = static_cast<igtl::SensorMessage*>(m.GetPointer());
            if (std::string(f->GetDeviceName()) == "applier.force" && f->GetLength() == 3) r.forces.push_back({t, {f->GetValue(0), f->GetValue(1), f->GetValue(2)}});
        } else if (type == "POLYDATA") {
            auto* pd = static_cast<igtl::PolyDataMessage*>(m.GetPointer());
            if (r.polydata++ == 0) pd->GetPoints()->GetPoint(0u, r.first_point.data());
            r.polydata_points = pd->GetPoints()->GetNumberOfPoints();
            for (int i = 0; i < pd->GetNumberOfAttributes(); ++i) {
                auto* at = pd->GetAttribute(i);
                r.odd_attributes += at->GetType() != igtl::PolyDataAttribute::POINT_SCALAR || at->GetNumberOfComponents() != 1 ||
                                    std::string(at->GetName()) != "label";
            }
        } else if (type == "STATUS") {
            auto* st = static_cast<igtl::StatusMessage*>(m.GetPointer());
            r.status.push_back(st->GetStatusString());
            r.odd_status += st->GetCode() >= 20 || std::strlen(st->GetErrorName()) > 20;
        } else if (type == "STRING") {
            if (std::string(m->GetDeviceName()) == "applier.force") r.force_text.emplace_back(t, static_cast<igtl::StringMessage*>(m.GetPointer())->GetString());
        } else {
            const std::string name = m->GetDeviceName();
            r.clip_transforms += name.rfind("clip", 0) == 0;
            if (name == "applier.pose") {
                ++r.applier_poses;
                r.last_applier_pose_t = t;
                static_cast<igtl::TransformMessage*>(m.GetPointer())->GetMatrix(r.last_applier_pose);
            }
        }
    }
    return r;
}

igtl::ClientSocket::Pointer connect_to(int port) {
    auto s = igtl::ClientSocket::New();
    for (int k = 0; k < 100 && s->ConnectToServer("127.0.0.1", port) != 0; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return s;
}

}  // namespace

TEST(Serve, ForcesOverLoopbackEqualTheTextStreamsInDeterministicMode) {
    const auto samples = session();
    // Reference: the same poses as a text stream, deterministic.
    test::TempDir d1("serve_ref");
    sim::Simulator ref_sim = make_sim(d1.file(""));
    std::string text;
    for (const auto& s : samples) text += line(s);
    std::istringstream in(text);
    std::vector<std::pair<double, Eigen::Vector3d>> ref;
    sim::RunOptions ro;
    ro.deterministic = true;
    ro.live = &in;
    ro.on_haptic = [&](double t, const std::vector<Eigen::Vector3d>& F) { ref.emplace_back(t, F[0]); };
    const sim::Assessment ra = sim::run_scene(ref_sim, ro);
    ASSERT_EQ(ra.clips_used, 1);
    double peak = 0;
    for (const auto& [t, f] : ref) peak = std::max(peak, f.norm());
    ASSERT_GT(peak, 0.0) << "the session touches the vessel";

    // The server, deterministic, driven by an OpenIGTLink client; then the same in RAS (3D Slicer's frame: x and y
    // negated both ways).
    // Third: as 3D Slicer's OpenIGTLinkIF talks (RAS, header version 2 with metadata, an empty-named STATUS on
    // connecting).
    for (const auto& [ras, slicer] : {std::pair{false, false}, std::pair{true, false}, std::pair{true, true}}) {
        SCOPED_TRACE(slicer ? "slicer" : ras ? "ras" : "bundle frame");
        test::TempDir d2(slicer ? "serve_slicer" : ras ? "serve_ras" : "serve_run");
        sim::Simulator sim = make_sim(d2.file(""));
        std::promise<int> port;
        sim::ServeOptions so;
        so.port = 0;
        so.deterministic = true;
        so.polydata_hz = 50;
        so.ras = ras;
        so.on_listening = [&](int p) { port.set_value(p); };
        sim::ServeCounters c;
        auto served = std::async(std::launch::async, [&] { return sim::serve_scene(sim, so, &c); });
        auto sock = connect_to(port.get_future().get());
        ASSERT_TRUE(sock->GetConnected());
        auto got = std::async(std::launch::async, [&] { return receive_all(sock); });
        long sent = 0;
        if (slicer) {
            auto hello = igtl::StatusMessage::New();
            hello->SetDeviceName("");
            hello->SetCode(igtl::StatusMessage::STATUS_OK);
            send(sock, hello, true);  // a type the server does not take: skipped by its size, counted unknown
        }
        std::vector<Sample> sent_samples;
        for (Sample s : samples) {
            if (ras)
                for (float* v : {s.p, s.axis, s.up}) v[0] = -v[0], v[1] = -v[1];
            send_sample(sock, s, slicer);
            sent += s.action.empty() ? 2 : 3;
            sent_samples.push_back(s);
        }
        auto stop = igtl::StringMessage::New();
        stop->SetDeviceName("aneusim");
        stop->SetString("stop");
        send(sock, stop, slicer);
        ++sent;
        const sim::Assessment a = served.get();
        const Received r = got.get();
        sock->CloseSocket();

        EXPECT_EQ(a.clips_used, 1);
        EXPECT_EQ(a.skipped_inputs, 0);
        EXPECT_EQ(c.poses, static_cast<long>(samples.size()));
        EXPECT_EQ(c.dropped_unknown, slicer ? 1 : 0);  // Slicer's STATUS on connecting: read and set aside
        EXPECT_EQ(c.dropped_malformed + c.dropped_garbage + c.dropped_oversize, 0);
        EXPECT_EQ(c.v2_messages, slicer ? sent : 0);
        ASSERT_EQ(r.forces.size(), ref.size()) << "one force per haptic tick";
        double worst = 0;
        for (size_t k = 0; k < ref.size(); ++k) {
            EXPECT_NEAR(r.forces[k].first, ref[k].first, 1e-9);
            for (int i = 0; i < 3; ++i) worst = std::max(worst, std::abs(r.forces[k].second[static_cast<size_t>(i)] - (ras && i < 2 ? -1 : 1) * ref[k].second[i]));
        }
        std::printf("serve: %zu forces, peak %.4f N, largest difference %.3g N; %d polydata of %d points, %d clip poses, %zu status\n", r.forces.size(), peak,
                    worst, r.polydata, r.polydata_points, r.clip_transforms, r.status.size());
        EXPECT_EQ(worst, 0.0) << "the same samples through the same parser: bit-identical forces";
        EXPECT_EQ(r.polydata, static_cast<int>((ref.size() - 1) / 20 + 1));  // every 20th tick at 1 kHz: 50 Hz, every frame in lockstep
        EXPECT_EQ(r.polydata_points, static_cast<int>(sim.model().surface.size()));
        EXPECT_GT(r.clip_transforms, 0);
        ASSERT_FALSE(r.status.empty());
        EXPECT_EQ(r.status.back(), "session ended");
        EXPECT_NEAR(r.first_point[0], (ras ? -1 : 1) * sim.model().surface.X(0, 0), 1e-5);
        EXPECT_NEAR(r.first_point[1], (ras ? -1 : 1) * sim.model().surface.X(0, 1), 1e-5);
        EXPECT_NEAR(r.first_point[2], sim.model().surface.X(0, 2), 1e-5);
        // Everything sent is something 3D Slicer converts (SENSOR aside, which also comes as text).
        for (const auto& [type, n] : r.types)
            EXPECT_TRUE(type == "SENSOR" || type == "POLYDATA" || type == "TRANSFORM" || type == "STATUS" || type == "STRING") << type;
        EXPECT_EQ(r.long_names, 0);
        EXPECT_EQ(r.odd_attributes, 0);
        EXPECT_EQ(r.odd_status, 0);
        // The force as text, with each surface, equals the SENSOR force of the same tick; the applier's pose as the
        // simulator has it comes with each surface too, and ends where the last sample put it.
        // (the first surface, at t = 0, comes before any input and any haptic tick)
        ASSERT_GE(static_cast<int>(r.force_text.size()), r.polydata - 1);
        int matched = 0;
        for (const auto& [t, text] : r.force_text) {
            double f[3];
            ASSERT_EQ(std::sscanf(text.c_str(), "%lf %lf %lf N", &f[0], &f[1], &f[2]), 3) << text;
            for (const auto& [tf, F] : r.forces)
                if (std::abs(tf - t) < 1e-9) {
                    ++matched;
                    for (int i = 0; i < 3; ++i) EXPECT_NEAR(f[i], F[static_cast<size_t>(i)], 5.1e-5) << text;
                }
        }
        EXPECT_EQ(matched, static_cast<int>(r.force_text.size()));
        EXPECT_GE(r.applier_poses, r.polydata - 1);
        const Sample* last = nullptr;  // the sample in effect at the last surface
        for (const auto& x : sent_samples)
            if (x.t <= r.last_applier_pose_t + 1e-9) last = &x;
        ASSERT_NE(last, nullptr);
        for (int i = 0; i < 3; ++i) EXPECT_NEAR(r.last_applier_pose[i][3], last->p[i], 1e-6);
    }
}

TEST(Serve, BadClientsAreCountedAndDroppedWhileTheSessionGoesOn) {
    test::TempDir d("serve_bad");
    sim::Simulator sim = make_sim(d.file(""), d.file("report.json"));
    std::promise<int> port;
    sim::ServeOptions so;
    so.port = 0;
    so.deterministic = false;
    so.max_seconds = 20;  // a safety net: the test stops the session itself
    so.on_listening = [&](int p) { port.set_value(p); };
    sim::ServeCounters c;
    auto served = std::async(std::launch::async, [&] { return sim::serve_scene(sim, so, &c); });
    const int p = port.get_future().get();
    const auto settle = [] { std::this_thread::sleep_for(std::chrono::milliseconds(150)); };  // the server reads and drops the client
    {  // garbage bytes
        auto s = connect_to(p);
        const std::string junk(200, '\xA5');
        s->Send(junk.data(), static_cast<int>(junk.size()));
        settle();
        s->CloseSocket();
    }
    {  // a header that declares a 2 GB body
        auto tm = igtl::TransformMessage::New();
        tm->SetDeviceName("applier");
        tm->Pack();
        std::string h(static_cast<const char*>(tm->GetPackPointer()), 58);
        const std::uint64_t big = 2ull << 30;
        for (int k = 0; k < 8; ++k) h[static_cast<size_t>(42 + k)] = static_cast<char>((big >> (8 * (7 - k))) & 0xff);
        auto s = connect_to(p);
        s->Send(h.data(), static_cast<int>(h.size()));
        settle();
        s->CloseSocket();
    }
    auto s = connect_to(p);
    ASSERT_TRUE(s->GetConnected());
    // An unknown message type, a NaN pose, an unknown instrument, then a flood of poses.
    auto pos = igtl::PositionMessage::New();
    pos->SetDeviceName("applier");
    send(s, pos);
    Sample bad{0, {std::nanf(""), 0, 4}, {-1, 0, 0}, {0, 0, 1}, 0, ""};
    send_sample(s, bad);
    auto other = igtl::TransformMessage::New();
    other->SetDeviceName("scalpel");
    send(s, other);
    for (int k = 0; k < 5000; ++k) {
        Sample x{0, {6.0f + 0.0001f * static_cast<float>(k), 0, 4}, {-1, 0, 0}, {0, 0, 1}, 0, ""};
        auto tm = igtl::TransformMessage::New();
        tm->SetDeviceName("applier");
        igtl::Matrix4x4 M;
        igtl::IdentityMatrix(M);
        for (int r = 0; r < 3; ++r) {
            M[r][0] = x.up[r];
            M[r][2] = x.axis[r];
            M[r][3] = x.p[r];
        }
        tm->SetMatrix(M);
        send(s, tm);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    auto stop = igtl::StringMessage::New();
    stop->SetDeviceName("aneusim");
    stop->SetString("stop");
    send(s, stop);
    const sim::Assessment a = served.get();
    s->CloseSocket();
    std::printf("bad clients: garbage %ld, oversize %ld, unknown %ld, malformed %ld, poses %ld (coalesced %ld), skipped inputs %d, haptic ticks %ld\n",
                c.dropped_garbage, c.dropped_oversize, c.dropped_unknown, c.dropped_malformed, c.poses, c.poses_coalesced, a.skipped_inputs,
                static_cast<long>(a.haptic_ticks));
    EXPECT_EQ(c.dropped_garbage, 1);
    EXPECT_EQ(c.dropped_oversize, 1);
    EXPECT_GE(c.dropped_unknown, 2);     // the POSITION message and the unknown instrument
    EXPECT_EQ(c.dropped_malformed, 1);   // the NaN pose
    EXPECT_EQ(a.skipped_inputs, 0);
    EXPECT_EQ(c.poses, 5000);            // every finite TRANSFORM of the applier became a pose
    EXPECT_GT(c.poses_coalesced, 0);     // the flood was faster than the haptic loop took it
    EXPECT_GT(a.haptic_ticks, 100);
    // The session report counts them too.
    std::ifstream rin(d.file("report.json"));
    const json rep = json::parse(rin);
    EXPECT_EQ(rep.at("igtl").at("dropped_garbage").get<long>(), 1);
    EXPECT_EQ(rep.at("igtl").at("dropped_oversize").get<long>(), 1);
    EXPECT_EQ(rep.at("igtl").at("poses").get<long>(), 5000);
}
