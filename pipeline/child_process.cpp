// SPDX-License-Identifier: MIT
// Child-process isolation of third-party meshers: a mesher that aborts, crashes or loops forever on a bad
// input becomes a MeshingError in the parent, never a dead or hung tool.
#include "child_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>

#include "aneu/core/error.hpp"
#include "aneu/core/text.hpp"

namespace aneu::pipeline {

namespace {
bool write_all(int fd, const void* p, size_t n) {
    const char* c = static_cast<const char*>(p);
    while (n > 0) {
        const ssize_t w = ::write(fd, c, n);
        if (w <= 0) return false;
        c += w;
        n -= static_cast<size_t>(w);
    }
    return true;
}

}  // namespace

/// Runs `mesher` in a child; it returns 0 and fills the mesh, or an error code with a message.
RawMesh run_isolated(const std::function<int(RawMesh&, std::string&)>& mesher, double timeout_s, const std::string& name) {
    int fds[2];
    if (::pipe(fds) != 0) throw MeshingError(name + ": cannot create a pipe to the mesher process");
    const pid_t pid = ::fork();
    if (pid < 0) throw MeshingError(name + ": cannot fork the mesher process");
    if (pid == 0) {  // child: mesh, send, exit without running the parent's destructors
        ::close(fds[0]);
        const int devnull = ::open("/dev/null", O_WRONLY);
        if (devnull >= 0) {  // meshers print progress to stdout; stdout belongs to the parent's user
            ::dup2(devnull, 1);
        }
        RawMesh m;
        std::string msg;
        int code = 0;
        try {
            code = mesher(m, msg);
        } catch (int c) {
            code = 100 + c;
        } catch (const std::exception& e) {
            code = 99;
            msg = e.what();
        }
        const std::int64_t hdr[4] = {code, static_cast<std::int64_t>(msg.size()), static_cast<std::int64_t>(m.points.size()),
                                     static_cast<std::int64_t>(m.cells.size())};
        bool ok = write_all(fds[1], hdr, sizeof hdr) && write_all(fds[1], msg.data(), msg.size()) &&
                  write_all(fds[1], m.points.data(), m.points.size() * sizeof(double)) &&
                  write_all(fds[1], m.cells.data(), m.cells.size() * sizeof(int));
        ::_exit(ok ? 0 : 1);
    }
    ::close(fds[1]);
    std::string buf;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    char chunk[1 << 16];
    bool timed_out = false;
    for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
        if (left <= 0) {
            timed_out = true;
            break;
        }
        pollfd pf{fds[0], POLLIN, 0};
        const int r = ::poll(&pf, 1, static_cast<int>(std::min<long long>(left, 1000)));
        if (r < 0 && errno != EINTR) break;
        if (r <= 0) continue;
        const ssize_t n = ::read(fds[0], chunk, sizeof chunk);
        if (n <= 0) break;
        buf.append(chunk, static_cast<size_t>(n));
    }
    ::close(fds[0]);
    if (timed_out) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, nullptr, 0);
        throw MeshingError(name + ": no result after " + shortest(timeout_s) + " s; killed (raise --timeout-s, or check the surface)");
    }
    int status = 0;
    ::waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) throw MeshingError(name + ": the mesher crashed (signal " + std::to_string(WTERMSIG(status)) + ")");
    std::int64_t hdr[4];
    if (buf.size() < sizeof hdr) throw MeshingError(name + ": the mesher process ended without a result");
    std::memcpy(hdr, buf.data(), sizeof hdr);
    const size_t need = sizeof hdr + static_cast<size_t>(hdr[1]) + static_cast<size_t>(hdr[2]) * sizeof(double) +
                        static_cast<size_t>(hdr[3]) * sizeof(int);
    if (buf.size() != need) throw MeshingError(name + ": truncated result from the mesher process");
    const std::string msg = buf.substr(sizeof hdr, static_cast<size_t>(hdr[1]));
    if (hdr[0] != 0) throw MeshingError(name + ": " + msg);
    RawMesh m;
    m.points.resize(static_cast<size_t>(hdr[2]));
    m.cells.resize(static_cast<size_t>(hdr[3]));
    const char* p = buf.data() + sizeof hdr + hdr[1];
    std::memcpy(m.points.data(), p, m.points.size() * sizeof(double));
    std::memcpy(m.cells.data(), p + m.points.size() * sizeof(double), m.cells.size() * sizeof(int));
    return m;
}


}  // namespace aneu::pipeline
