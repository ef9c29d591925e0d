// SPDX-License-Identifier: MIT
#include "cli_common.hpp"

#include "aneu/core/dependency_info.hpp"

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iterator>

#include <unistd.h>
#include <filesystem>
#include <map>

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include "aneu/core/dependency_info.hpp"
#include "aneu/core/error.hpp"
#include "aneu/core/provenance.hpp"

namespace aneu::tools {

spdlog::logger& logger() {
    static std::shared_ptr<spdlog::logger> l = [] {
        auto lg = std::make_shared<spdlog::logger>("aneu", std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
        lg->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
        return lg;
    }();
    return *l;
}

void add_logging_options(CLI::App& app, LoggingOptions& o) {
    app.add_option("--log-level", o.level, "log level: trace, debug, info, warn, error, off")
        ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
        ->capture_default_str();
    app.add_flag("-q,--quiet", o.quiet, "only warnings and errors");
    app.add_option("--log-file", o.file, "also write the log to this file");
}

void apply_logging_options(const LoggingOptions& o) {
    auto& l = logger();
    l.set_level(o.quiet ? spdlog::level::warn : spdlog::level::from_str(o.level));
    if (!o.file.empty()) {
        auto sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(o.file, false);
        sink->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%l] %v");
        l.sinks().push_back(sink);
    }
}

Reporter make_log_reporter() {
    Reporter r;
    r.on_message = [](Level lv, const std::string& m) {
        auto& l = logger();
        if (lv == Level::WARN) {
            l.warn(m);
        } else if (lv == Level::INFO) {
            l.info(m);
        } else {
            l.debug(m);
        }
    };
    auto last = std::make_shared<std::map<std::string, std::chrono::steady_clock::time_point>>();
    r.on_progress = [last](const std::string& stage, std::int64_t done, std::int64_t total) {
        const auto now = std::chrono::steady_clock::now();
        auto it = last->find(stage);
        const bool due = it == last->end() || now - it->second > std::chrono::milliseconds(500);
        if (!due && done < total) return;
        (*last)[stage] = now;
        const double pct = total > 0 ? 100.0 * static_cast<double>(done) / static_cast<double>(total) : 100.0;
        logger().info("{}: {}/{} ({:.0f} %)", stage, done, total, pct);
    };
    return r;
}

int run_guarded(const std::string& name, const std::function<void()>& body) {
    try {
        body();
        return 0;
    } catch (const UnknownOptionError& e) {
        logger().flush();
        fmt::print(stderr, "{}: error: {}\n", name, e.what());
        return EXIT_UNKNOWN_OPTION;
    } catch (const InputError& e) {
        logger().flush();
        fmt::print(stderr, "{}: error: {}\n", name, e.what());
        return EXIT_INPUT;
    } catch (const std::filesystem::filesystem_error& e) {
        logger().flush();
        std::string paths;
        if (!e.path1().empty()) paths += " '" + e.path1().string() + "'";
        if (!e.path2().empty()) paths += " '" + e.path2().string() + "'";
        fmt::print(stderr, "{}: error: file system:{} {}\n", name, paths, e.code().message());
        return EXIT_PROCESSING;
    } catch (const std::exception& e) {
        logger().flush();
        fmt::print(stderr, "{}: error: {}\n", name, e.what());
        return EXIT_PROCESSING;
    }
}

std::vector<std::string> args_of(int argc, char** argv) { return {argv, argv + argc}; }

namespace {
/// glibc.malloc.hugetlb=1 added to GLIBC_TUNABLES (reexec_for_this_machine); true if it was.
bool set_huge_pages_env() {
    const char* opt = std::getenv("ANEU_HUGE_PAGES");
    if (opt != nullptr && std::string(opt) == "0") return false;
    const char* old = std::getenv("GLIBC_TUNABLES");
    const std::string tunables = old != nullptr ? old : "";
    if (tunables.find("glibc.malloc.hugetlb") != std::string::npos) return false;  // set already (or by the user: kept)
    // Only where the kernel gives huge pages on request: with "[always]" it does so without being asked.
    std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string mode((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (mode.find("[madvise]") == std::string::npos) return false;
    const std::string value = (tunables.empty() ? "" : tunables + ":") + "glibc.malloc.hugetlb=1";
    return ::setenv("GLIBC_TUNABLES", value.c_str(), 1) == 0;
}
}  // namespace

void reexec_for_this_machine(char** argv, bool huge_pages) {
    const bool pages = huge_pages && set_huge_pages_env();
    const bool blas = aneu::set_blas_kernels_env();
    if (pages || blas) ::execv("/proc/self/exe", argv);
    // exec failed: go on as we are, with the variables set (children still benefit)
}



}  // namespace aneu::tools
