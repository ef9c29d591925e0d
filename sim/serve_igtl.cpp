// SPDX-License-Identifier: MIT
// `aneusim serve`: OpenIGTLink clients drive the simulator's live input and receive its outputs. The only file that
// includes OpenIGTLink. Message names and units: docs/openigtlink.md.
//
// Threads: one accepts clients; per client one reads (frames every message itself from the 58-byte header before
// OpenIGTLink unpacks it, so a garbage header or an absurd declared size never reaches an allocation) and one
// writes (a queue of packed messages: a slow client loses its oldest forces, never holds up the haptic loop). The
// simulation runs in run_scene, its live input a queue of pose lines in the text stream's format, so a session
// over the network and the same poses as a text stream go through the same parser and checks.
#include "aneu/sim/serve.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include <fstream>
#include <sstream>

#include <igtlClientSocket.h>
#include <igtlOSUtil.h>
#include <igtlPolyDataMessage.h>
#include <igtlSensorMessage.h>
#include <igtlServerSocket.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_util.h>

#include <nlohmann/json.hpp>

#include "aneu/core/atomic_file.hpp"
#include "aneu/core/common.hpp"
#include "aneu/core/error.hpp"

namespace aneu::sim {
namespace {

constexpr int HEADER = 58;                    // version 2, type 12, device 20, time 8, body size 8, CRC 8
constexpr std::uint64_t MAX_BODY = 1u << 16;  // TRANSFORM 48 B, SENSOR 10 + 8n B, STRING 4 + n B: nothing a client sends is larger
constexpr size_t FORCE_QUEUE = 64;            // real time: packed force messages a client may have pending

using Bytes = std::shared_ptr<const std::string>;

Bytes packed(igtl::MessageBase* m) {
    m->Pack();
    return std::make_shared<const std::string>(static_cast<const char*>(m->GetPackPointer()), static_cast<size_t>(m->GetPackSize()));
}

void stamp(igtl::MessageBase* m, double t) {
    const double sec = std::floor(std::max(0.0, t));
    m->SetTimeStamp(static_cast<unsigned>(sec), static_cast<unsigned>(std::min(4294967295.0, std::round((t - sec) * 4294967296.0))));
}

/// An n-byte big-endian unsigned integer (OpenIGTLink's byte order), read and written.
std::uint64_t be(const unsigned char* p, int n) {
    std::uint64_t v = 0;
    for (int k = 0; k < n; ++k) v = (v << 8) | p[k];
    return v;
}
void put_be(unsigned char* p, std::uint64_t v, int n) {
    for (int k = 0; k < n; ++k) p[k] = static_cast<unsigned char>(v >> (8 * (n - 1 - k)));
}

std::string field(const unsigned char* p, size_t n) {
    std::string s(reinterpret_cast<const char*>(p), n);
    s.resize(std::strlen(s.c_str()));
    return s;
}

bool printable(const std::string& s) {
    return std::all_of(s.begin(), s.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
}

std::string num(double x) {
    char b[40];
    std::snprintf(b, sizeof b, "%.9g", x);
    return b;
}

struct Client {
    igtl::ClientSocket::Pointer sock;
    std::thread reader, writer;
    std::mutex mx;
    std::condition_variable cv;
    std::deque<Bytes> forces, other;
    Bytes surface;
    bool closing = false;
    std::atomic<bool> alive{true};
};

struct InstrumentState {
    double opening = 0;
    bool button = false;
    std::string action;  // applied with the instrument's next pose
};

class Server {
public:
    Server(Simulator& sim, const ServeOptions& opt) : m_sim(sim), m_opt(opt) {
        for (const auto& ins : sim.scene().instruments) m_state[ins.name] = InstrumentState{};
    }

    ServeCounters counters() {
        std::lock_guard<std::mutex> lk(m_mx);
        return m_c;
    }

    void listen() {
        m_server = igtl::ServerSocket::New();
        if (m_server->CreateServer(m_opt.port) < 0) throw InputError("serve: --port " + std::to_string(m_opt.port) + ": cannot listen there (in use?)");
        m_port = m_server->GetServerPort();
        m_start = std::chrono::steady_clock::now();
        if (m_opt.on_listening) m_opt.on_listening(m_port);  // at the clock's start: a client can put its times on it
        m_accept = std::thread([this] { accept_loop(); });
        if (m_opt.max_seconds > 0) {
            m_timer = std::thread([this] {
                std::unique_lock<std::mutex> lk(m_mx);
                m_cv.wait_for(lk, std::chrono::duration<double>(m_opt.max_seconds), [this] { return m_closed; });
                m_closed = true;
                m_cv.notify_all();
            });
        }
    }

    /// The live input: one line at a time (deterministic: waits for it).
    LiveReader::Fetch next_line(std::string& line) {
        std::unique_lock<std::mutex> lk(m_mx);
        if (m_opt.deterministic) m_cv.wait(lk, [this] { return m_closed || !m_lines.empty(); });
        if (m_lines.empty()) return m_closed ? LiveReader::Fetch::END : LiveReader::Fetch::NONE_NOW;
        line = std::move(m_lines.front().second);
        m_lines.pop_front();
        return LiveReader::Fetch::LINE;
    }

    void haptic(double t, const std::vector<Eigen::Vector3d>& F) {
        const auto& ins = m_sim.scene().instruments;
        std::vector<Bytes> msgs;
        for (size_t i = 0; i < ins.size() && i < F.size(); ++i) {
            auto m = igtl::SensorMessage::New();
            m->SetDeviceName((ins[i].name + ".force").c_str());
            stamp(m, m_opt.deterministic ? t : now());  // real time: the server's clock, the one poses are taken on
            m->SetLength(3);
            for (unsigned k = 0; k < 3; ++k) m->SetValue(k, (m_opt.ras && k < 2 ? -1.0 : 1.0) * F[i][static_cast<Eigen::Index>(k)]);
            msgs.push_back(packed(m));
        }
        {
            std::lock_guard<std::mutex> lk(m_fmx);
            m_last_force = F;
        }
        for_clients([&](Client& c) {
            std::lock_guard<std::mutex> lk(c.mx);
            for (auto& b : msgs) c.forces.push_back(b);
            long skipped = 0;
            while (!m_opt.deterministic && c.forces.size() > FORCE_QUEUE) {
                c.forces.pop_front();
                ++skipped;
            }
            c.cv.notify_one();
            if (skipped) add([&](ServeCounters& s) { s.forces_skipped += skipped; });
        });
    }

    void surface(double t, const Eigen::MatrixX3d& x, const std::vector<Clip>& clips, const std::vector<std::optional<Pose>>& instruments) {
        const SimSurface& s = m_sim.model().surface;
        if (m_vertex_label.size() != static_cast<size_t>(x.rows())) {
            m_vertex_label.assign(static_cast<size_t>(x.rows()), 0.0f);
            for (Eigen::Index f = 0; f < s.F.rows(); ++f)
                for (int k = 0; k < 3; ++k) {
                    float& l = m_vertex_label[static_cast<size_t>(s.F(f, k))];
                    l = std::max(l, static_cast<float>(s.face_region[f]));
                }
        }
        auto pts = igtl::PolyDataPointArray::New();
        const float sx = m_opt.ras ? -1.0f : 1.0f;  // RAS: x and y negated
        for (Eigen::Index v = 0; v < x.rows(); ++v) pts->AddPoint(sx * static_cast<float>(x(v, 0)), sx * static_cast<float>(x(v, 1)), static_cast<float>(x(v, 2)));
        auto tri = igtl::PolyDataCellArray::New();
        for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
            igtlUint32 c[3] = {static_cast<igtlUint32>(s.F(f, 0)), static_cast<igtlUint32>(s.F(f, 1)), static_cast<igtlUint32>(s.F(f, 2))};
            tri->AddCell(3, c);
        }
        auto lab = igtl::PolyDataAttribute::New();
        lab->SetType(igtl::PolyDataAttribute::POINT_SCALAR);
        lab->SetName("label");
        lab->SetSize(static_cast<igtlUint32>(m_vertex_label.size()));
        lab->SetData(m_vertex_label.data());
        auto m = igtl::PolyDataMessage::New();
        m->SetDeviceName("vessel");
        stamp(m, t);
        m->SetPoints(pts);
        m->SetPolygons(tri);
        m->AddAttribute(lab);
        const Bytes poly = packed(m);
        std::vector<Bytes> poses;
        const auto transform = [&](const std::string& name, const Pose& p) {
            auto tm = igtl::TransformMessage::New();
            tm->SetDeviceName(name.c_str());
            stamp(tm, t);
            igtl::Matrix4x4 M;
            const Eigen::Vector3d z = p.axis.normalized(), xa = (p.up - p.up.dot(z) * z).normalized(), y = z.cross(xa);
            for (int r = 0; r < 3; ++r) {
                M[r][0] = static_cast<float>(xa[r]);
                M[r][1] = static_cast<float>(y[r]);
                M[r][2] = static_cast<float>(z[r]);
                M[r][3] = static_cast<float>(p.position[r]);
            }
            M[3][0] = M[3][1] = M[3][2] = 0;
            M[3][3] = 1;
            if (m_opt.ras)
                for (int r = 0; r < 2; ++r)
                    for (int col = 0; col < 4; ++col) M[r][col] = -M[r][col];
            tm->SetMatrix(M);
            poses.push_back(packed(tm));
        };
        for (const Clip& c : clips)
            if (!c.model.empty()) transform("clip" + std::to_string(c.id), c.pose);
        // The instruments as the simulator has them, named apart from the poses that come in (3D Slicer never sends
        // a node back under the name it receives it by), and their force as text for viewers that do not read
        // SENSOR (Slicer shows a STRING as a text node).
        const auto& ins = m_sim.scene().instruments;
        std::vector<Eigen::Vector3d> F;
        {
            std::lock_guard<std::mutex> lk(m_fmx);
            F = m_last_force;
        }
        for (size_t i = 0; i < ins.size() && i < instruments.size(); ++i) {
            if (!instruments[i]) continue;  // no input yet
            transform(ins[i].name + ".pose", *instruments[i]);
            if (i >= F.size()) continue;
            const double sx = m_opt.ras ? -1.0 : 1.0;
            char b[128];
            std::snprintf(b, sizeof b, "%.4f %.4f %.4f N (|F| %.3f N)", sx * F[i].x(), sx * F[i].y(), F[i].z(), F[i].norm());
            auto sm = igtl::StringMessage::New();
            sm->SetDeviceName((ins[i].name + ".force").c_str());
            stamp(sm, t);
            sm->SetString(b);
            poses.push_back(packed(sm));
        }
        for_clients([&](Client& c) {
            std::lock_guard<std::mutex> lk(c.mx);
            if (m_opt.deterministic) c.other.push_back(poly);  // a replay gets every frame
            else c.surface = poly;                             // real time: the latest frame only
            for (auto& b : poses) c.other.push_back(b);
            c.cv.notify_one();
        });
    }

    void status(const std::string& text, int code = 1) {
        auto m = igtl::StatusMessage::New();
        m->SetDeviceName("aneusim");
        m->SetCode(code);
        m->SetSubCode(0);
        m->SetErrorName("");
        m->SetStatusString(text.c_str());
        const Bytes b = packed(m);
        for_clients([&](Client& c) {
            std::lock_guard<std::mutex> lk(c.mx);
            c.other.push_back(b);
            c.cv.notify_one();
        });
    }

    void shutdown() {
        {
            std::lock_guard<std::mutex> lk(m_mx);
            m_closed = true;
            m_stopping = true;
            m_cv.notify_all();
        }
        if (m_accept.joinable()) m_accept.join();
        if (m_timer.joinable()) m_timer.join();
        std::vector<std::shared_ptr<Client>> all;
        {
            std::lock_guard<std::mutex> lk(m_cmx);
            all = m_clients;
        }
        for (auto& c : all) {  // the writers send what is queued (the last STATUS), then every socket closes
            {
                std::lock_guard<std::mutex> lk(c->mx);
                c->closing = true;
                c->cv.notify_one();
            }
            if (c->writer.joinable()) c->writer.join();
            c->alive = false;
            c->sock->CloseSocket();
            if (c->reader.joinable()) c->reader.join();
        }
        if (m_server) m_server->CloseSocket();
    }

private:
    template <class Fn>
    void add(Fn fn) {
        std::lock_guard<std::mutex> lk(m_mx);
        fn(m_c);
    }
    template <class Fn>
    void for_clients(Fn fn) {
        std::lock_guard<std::mutex> lk(m_cmx);
        for (auto& c : m_clients)
            if (c->alive) fn(*c);
    }
    double now() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count(); }

    void accept_loop() {
        double last_seen = now();
        while (true) {
            {
                std::lock_guard<std::mutex> lk(m_mx);
                if (m_stopping) return;
            }
            igtl::ClientSocket::Pointer s = m_server->WaitForConnection(100);
            if (s.IsNull()) {
                // A client that leaves may come back (a device bridge restarted): the session ends after
                // idle_seconds without any client.
                bool live = false;
                {
                    std::lock_guard<std::mutex> lk(m_cmx);
                    for (auto& c : m_clients) live = live || c->alive;
                }
                if (live) last_seen = now();
                if (m_opt.idle_seconds > 0 && now() - last_seen > m_opt.idle_seconds) {
                    std::lock_guard<std::mutex> lk(m_mx);
                    m_closed = true;
                    m_cv.notify_all();
                }
                continue;
            }
            std::string addr;
            int port = 0;
            s->GetSocketAddressAndPort(addr, port);
            long alive_now = 0;
            {
                std::lock_guard<std::mutex> lk(m_cmx);
                for (auto& c : m_clients) alive_now += c->alive ? 1 : 0;
            }
            if (alive_now >= m_opt.max_clients) {
                s->CloseSocket();
                add([](ServeCounters& c) { ++c.clients_refused; });
                continue;
            }
            // A client that takes nothing (its receive buffer full) must not hold a writer, and so the session's
            // end, forever: a send that cannot go on for 2 s drops it.
            s->SetSendTimeout(2000);
            auto c = std::make_shared<Client>();
            c->sock = s;
            {  // listed before its reader starts: every output of the poses it sends reaches it
                std::lock_guard<std::mutex> lk(m_cmx);
                m_clients.push_back(c);
                c->writer = std::thread([this, c] { write_loop(*c); });
                c->reader = std::thread([this, c] { read_loop(*c); });
            }
            last_seen = now();
            add([](ServeCounters& k) { ++k.clients_connected; });
        }
    }

    void drop(Client& c, long ServeCounters::*what) {
        add([&](ServeCounters& k) {
            if (what) ++(k.*what);
            if (c.alive) ++k.clients_lost;
        });
        c.alive = false;
        std::lock_guard<std::mutex> lk(c.mx);
        c.cv.notify_one();
    }

    void read_loop(Client& c) {
        unsigned char h[HEADER];
        std::string body;
        while (c.alive) {
            if (c.sock->Receive(h, HEADER) != HEADER) return drop(c, nullptr);  // closed
            const auto version = be(h, 2);
            const std::string type = field(h + 2, 12), name = field(h + 14, 20);
            const std::uint64_t size = be(h + 42, 8);
            if ((version != 1 && version != 2) || type.empty() || !printable(type) || !printable(name)) return drop(c, &ServeCounters::dropped_garbage);
            if (size > MAX_BODY) return drop(c, &ServeCounters::dropped_oversize);
            igtl::MessageBase::Pointer msg;
            if (type == "TRANSFORM") msg = igtl::TransformMessage::New();
            else if (type == "SENSOR") msg = igtl::SensorMessage::New();
            else if (type == "STRING") msg = igtl::StringMessage::New();
            if (msg.IsNull()) {
                body.resize(static_cast<size_t>(size));
                if (size > 0 && c.sock->Receive(body.data(), static_cast<int>(size)) != static_cast<int>(size)) return drop(c, nullptr);
                add([](ServeCounters& k) { ++k.dropped_unknown; });
                continue;
            }
            body.resize(static_cast<size_t>(size));
            if (size > 0 && c.sock->Receive(body.data(), static_cast<int>(size)) != static_cast<int>(size)) return drop(c, nullptr);
            if (version == 2) {
                // Version 2 (3D Slicer sends it by default): CRC over the whole body, which is an extended header
                // (u16 its size, u16 metadata header size, u32 metadata size, u32 message id), the content, and the
                // metadata. The library here speaks version 1: hand it the content under a version-1 header.
                auto* b = reinterpret_cast<unsigned char*>(body.data());
                if (size < 12 || crc64(b, size, 0) != be(h + 50, 8)) {
                    add([](ServeCounters& k) { ++k.dropped_malformed; });
                    continue;
                }
                const std::uint64_t ext = be(b, 2), meta_head = be(b + 2, 2), meta = be(b + 4, 4);
                if (ext < 12 || ext + meta_head + meta > size) {
                    add([](ServeCounters& k) { ++k.dropped_malformed; });
                    continue;
                }
                body = body.substr(static_cast<size_t>(ext), static_cast<size_t>(size - ext - meta_head - meta));
                const std::uint64_t n = body.size(), crc = crc64(reinterpret_cast<unsigned char*>(body.data()), n, 0);
                put_be(h, 1, 2);
                put_be(h + 42, n, 8);
                put_be(h + 50, crc, 8);
                add([](ServeCounters& k) { ++k.v2_messages; });
            }
            msg->InitPack();
            std::memcpy(msg->GetPackPointer(), h, HEADER);
            msg->Unpack();
            msg->AllocatePack();
            if (msg->GetPackBodySize() != static_cast<int>(body.size())) {
                add([](ServeCounters& k) { ++k.dropped_malformed; });
                continue;
            }
            if (!body.empty()) std::memcpy(msg->GetPackBodyPointer(), body.data(), body.size());
            if (!(msg->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) {
                add([](ServeCounters& k) { ++k.dropped_malformed; });
                continue;
            }
            unsigned sec = 0, frac = 0;
            msg->GetTimeStamp(&sec, &frac);
            const double t = m_opt.deterministic ? std::round((static_cast<double>(sec) + static_cast<double>(frac) / 4294967296.0) * 1e6) / 1e6 : now();
            handle(type, name, msg, t);
        }
    }

    void handle(const std::string& type, const std::string& name, igtl::MessageBase::Pointer msg, double t) {
        std::lock_guard<std::mutex> lk(m_mx);
        ++m_c.messages;
        const auto dot = name.rfind('.');
        const std::string base = dot == std::string::npos ? name : name.substr(0, dot), what = dot == std::string::npos ? "" : name.substr(dot + 1);
        if (type == "STRING" && name == "aneusim") {
            const std::string cmd = static_cast<igtl::StringMessage*>(msg.GetPointer())->GetString();
            if (cmd == "stop") {
                m_closed = true;
                m_cv.notify_all();
            } else {
                ++m_c.dropped_unknown;
            }
            return;
        }
        const auto it = m_state.find(type == "TRANSFORM" ? name : base);
        if (it == m_state.end()) {
            ++m_c.dropped_unknown;
            return;
        }
        InstrumentState& st = it->second;
        if (type == "TRANSFORM") {
            igtl::Matrix4x4 M;
            static_cast<igtl::TransformMessage*>(msg.GetPointer())->GetMatrix(M);
            if (m_opt.ras)  // back to the bundle's frame
                for (int r = 0; r < 2; ++r)
                    for (int col = 0; col < 4; ++col) M[r][col] = -M[r][col];
            for (int r = 0; r < 3; ++r)
                for (int col : {0, 2, 3})
                    if (!std::isfinite(M[r][col])) {  // a NaN pose never reaches the queue (where a newer pose would replace it)
                        ++m_c.dropped_malformed;
                        return;
                    }
            // The live line: position (column 3), axis (column 2: the instrument's z), up (column 0: its x).
            std::string line = num(t) + " " + name;
            for (int col : {3, 2, 0})
                for (int r = 0; r < 3; ++r) line += " " + num(M[r][col]);
            line += " " + num(st.opening) + " " + (st.button ? "1" : "0");
            if (!st.action.empty()) line += " " + st.action;
            // A newer pose of an instrument replaces one the haptic loop has not taken yet (real time; never an action).
            if (!m_opt.deterministic && st.action.empty())
                for (auto& [who, l] : m_lines)
                    if (who == name) {  // queued lines with an action are filed under "" (never replaced)
                        l = line;
                        ++m_c.poses_coalesced;
                        ++m_c.poses;
                        return;
                    }
            m_lines.emplace_back(st.action.empty() ? name : std::string(), std::move(line));
            st.action.clear();
            ++m_c.poses;
            m_cv.notify_all();
        } else if (type == "SENSOR" && (what == "opening" || what == "button")) {
            auto* s = static_cast<igtl::SensorMessage*>(msg.GetPointer());
            const double v = s->GetLength() >= 1 ? s->GetValue(0) : std::nan("");
            if (!std::isfinite(v)) {
                ++m_c.dropped_malformed;
                return;
            }
            if (what == "opening") st.opening = v;
            else st.button = v != 0;
        } else if (type == "STRING" && what == "action") {
            const std::string a = static_cast<igtl::StringMessage*>(msg.GetPointer())->GetString();
            if (a.rfind("load ", 0) == 0 && a.size() > 5 && a.find(' ', 5) == std::string::npos) st.action = "load:" + a.substr(5);
            else if (a == "release" || a == "grasp") st.action = a;
            else ++m_c.dropped_unknown;
        } else {
            ++m_c.dropped_unknown;
        }
    }

    void write_loop(Client& c) {
        while (true) {
            std::deque<Bytes> batch;
            Bytes surf;
            {
                std::unique_lock<std::mutex> lk(c.mx);
                c.cv.wait(lk, [&] { return !c.alive || c.closing || !c.forces.empty() || !c.other.empty() || c.surface; });
                if (!c.alive) return;
                batch.swap(c.forces);
                for (auto& b : c.other) batch.push_back(b);
                c.other.clear();
                surf = std::move(c.surface);
                c.surface.reset();
                if (batch.empty() && !surf && c.closing) return;
            }
            long forces = 0, polys = 0, transforms = 0, statuses = 0, strings = 0;
            for (const auto& b : batch) {
                if (c.sock->Send(b->data(), static_cast<int>(b->size())) == 0) return drop(c, &ServeCounters::clients_stalled);
                const std::string type = field(reinterpret_cast<const unsigned char*>(b->data()) + 2, 12);
                (type == "SENSOR" ? forces : type == "STATUS" ? statuses : type == "POLYDATA" ? polys : type == "STRING" ? strings : transforms) += 1;
            }
            if (surf) {
                if (c.sock->Send(surf->data(), static_cast<int>(surf->size())) == 0) return drop(c, &ServeCounters::clients_stalled);
                ++polys;
            }
            add([&](ServeCounters& k) {
                k.forces_sent += forces;
                k.polydata_sent += polys;
                k.transforms_sent += transforms;
                k.status_sent += statuses;
                k.strings_sent += strings;
            });
        }
    }

    Simulator& m_sim;
    ServeOptions m_opt;
    std::mutex m_mx;  // lines, instrument state, counters, closed
    std::condition_variable m_cv;
    std::deque<std::pair<std::string, std::string>> m_lines;  // (instrument, live line)
    std::map<std::string, InstrumentState> m_state;
    ServeCounters m_c;
    bool m_closed = false, m_stopping = false;
    std::mutex m_cmx;  // clients
    std::mutex m_fmx;  // the last haptic force
    std::vector<Eigen::Vector3d> m_last_force;
    std::vector<std::shared_ptr<Client>> m_clients;
    igtl::ServerSocket::Pointer m_server;
    int m_port = 0;
    std::chrono::steady_clock::time_point m_start;
    std::thread m_accept, m_timer;
    std::vector<float> m_vertex_label;
};

}  // namespace

Assessment serve_scene(Simulator& sim, const ServeOptions& opt, ServeCounters* counters) {
    if (!sim.scene().live_input) throw InputError(sim.scene().path + ": `aneusim serve` needs a scene with \"live_input\": true");
    for (const auto& ins : sim.scene().instruments)  // OpenIGTLink device names hold 20 bytes: "<name>.opening"
        if (ins.name.size() > 12)
            throw InputError(sim.scene().path + ": instrument \"" + ins.name + "\": `aneusim serve` needs names of at most 12 characters (OpenIGTLink device names hold 20: \"" + ins.name + ".opening\")");
    Server server(sim, opt);
    server.listen();
    RunOptions ro;
    ro.deterministic = opt.deterministic;
    ro.live_source = [&](std::string& line) { return server.next_line(line); };
    ro.on_haptic = [&](double t, const std::vector<Eigen::Vector3d>& F) { server.haptic(t, F); };
    ro.surface_hz = opt.polydata_hz;
    ro.on_surface = [&](double t, const Eigen::MatrixX3d& x, const std::vector<Clip>& clips, const std::vector<std::optional<Pose>>& poses) {
        server.surface(t, x, clips, poses);
    };
    ro.on_message = [&](const std::string& m) {
        server.status(m);
        if (opt.on_message) opt.on_message(m);
    };
    Assessment a;
    try {
        a = run_scene(sim, ro);
    } catch (...) {
        server.shutdown();
        throw;
    }
    server.status("session ended");
    server.shutdown();
    const ServeCounters c = server.counters();
    if (counters) *counters = c;
    // The report gets what the server received, sent and dropped.
    const std::string& rp = sim.scene().report;
    if (!rp.empty()) {
        nlohmann::json j;
        {
            std::ifstream in(rp);
            j = nlohmann::json::parse(in);
        }
        j["igtl"] = {{"clients_connected", c.clients_connected}, {"clients_refused", c.clients_refused}, {"clients_lost", c.clients_lost},
                     {"messages", c.messages}, {"poses", c.poses}, {"poses_coalesced", c.poses_coalesced},
                     {"dropped_unknown", c.dropped_unknown}, {"dropped_malformed", c.dropped_malformed}, {"dropped_oversize", c.dropped_oversize},
                     {"dropped_garbage", c.dropped_garbage}, {"forces_sent", c.forces_sent}, {"forces_skipped", c.forces_skipped},
                     {"polydata_sent", c.polydata_sent}, {"transforms_sent", c.transforms_sent}, {"status_sent", c.status_sent},
                     {"strings_sent", c.strings_sent}, {"v2_messages", c.v2_messages},
                     {"clients_stalled", c.clients_stalled}};
        AtomicTextFile out(rp);
        out.out() << j.dump(2) << '\n';
        out.commit();
        std::stringstream txt;
        {
            std::ifstream in(rp + ".txt");
            txt << in.rdbuf();
        }
        char b[400];
        std::snprintf(b, sizeof b, "  OpenIGTLink                %ld client(s), %ld poses (%ld coalesced); dropped: %ld unknown, %ld malformed, %ld oversize, %ld garbage; %ld forces sent (%ld skipped for a slow client), %ld surfaces\n",
                      c.clients_connected, c.poses, c.poses_coalesced, c.dropped_unknown, c.dropped_malformed, c.dropped_oversize, c.dropped_garbage,
                      c.forces_sent, c.forces_skipped, c.polydata_sent);
        AtomicTextFile ot(rp + ".txt");
        ot.out() << txt.str() << b;
        ot.commit();
    }
    return a;
}

}  // namespace aneu::sim
