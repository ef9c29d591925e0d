// SPDX-License-Identifier: MIT
#include "aneu/core/program.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <thread>

#include "aneu/core/error.hpp"

namespace aneu {

ProgramExit run_program(const ProgramRun& run) {
    if (run.argv.empty()) throw Error("run_program: no program named");
    const pid_t pid = ::fork();
    if (pid < 0) throw Error("cannot start " + run.argv[0] + " (fork: " + std::strerror(errno) + ")");
    if (pid == 0) {
        ::setpgid(0, 0);  // its own group: a deadline kills what it started too
        if (!run.log.empty()) {
            const int fd = ::open(run.log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
            if (fd >= 0) {
                ::dup2(fd, 1);
                ::dup2(fd, 2);
                ::close(fd);
            }
        }
        if (!run.dir.empty()) {
            if (::chdir(run.dir.c_str()) != 0) ::_exit(126);
            ::setenv("PWD", run.dir.c_str(), 1);
        }
        std::vector<char*> a;
        for (const auto& s : run.argv) a.push_back(const_cast<char*>(s.c_str()));
        a.push_back(nullptr);
        ::execvp(a[0], a.data());
        ::_exit(127);
    }
    ProgramExit out;
    int status = 0;
    if (!run.deadline && !run.on_line) {
        while (::waitpid(pid, &status, 0) < 0)
            if (errno != EINTR) throw Error("waiting for " + run.argv[0] + " failed (" + std::strerror(errno) + ")");
    } else {
        std::ifstream in;
        std::string pending;
        auto drain = [&] {
            if (!run.on_line || run.log.empty()) return;
            if (!in.is_open()) in.open(run.log);
            if (!in.is_open()) return;
            in.clear();
            pending.append(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
            size_t start = 0;
            for (size_t nl; (nl = pending.find('\n', start)) != std::string::npos; start = nl + 1) run.on_line(pending.substr(start, nl - start));
            pending.erase(0, start);
        };
        while (true) {
            const pid_t r = ::waitpid(pid, &status, WNOHANG);
            if (r == pid) break;
            if (r < 0 && errno != EINTR) throw Error("waiting for " + run.argv[0] + " failed (" + std::strerror(errno) + ")");
            drain();
            if (run.deadline && std::chrono::steady_clock::now() > *run.deadline) {
                ::kill(-pid, SIGKILL);
                ::kill(pid, SIGKILL);
                ::waitpid(pid, &status, 0);
                out.timed_out = true;
                break;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
        }
        drain();
    }
    out.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    return out;
}

}  // namespace aneu
