// SPDX-License-Identifier: MIT
#include "aneu/core/atomic_file.hpp"

#include <filesystem>
#include <system_error>

#include <fcntl.h>
#include <unistd.h>

#include "aneu/core/error.hpp"

namespace aneu {

namespace fs = std::filesystem;

namespace {

void fsync_path(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd >= 0) {
        ::fsync(fd);
        ::close(fd);
    }
}

}  // namespace

AtomicPath::AtomicPath(std::string path, Kind kind)
    : m_path(std::move(path)), m_kind(kind) {
    // The extension is repeated, so writers that pick a format by it (ITK, VTK) still do.
    m_tmp = m_path + ".part-" + std::to_string(::getpid()) + (kind == Kind::FILE ? fs::path(m_path).extension().string() : "");
    const fs::path target = fs::path(m_path).lexically_normal();
    const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw InputError(m_path + ": cannot write, parent directory '" + dir.string() + "' does not exist");
    if (kind == Kind::DIRECTORY && fs::exists(target, ec) && !fs::is_directory(target, ec)) {
        throw InputError(m_path + ": exists and is not a directory");
    }
    if (kind == Kind::FILE && fs::is_directory(target, ec)) throw InputError(m_path + ": is a directory, expected a file name");
    fs::remove_all(m_tmp, ec);
    if (kind == Kind::DIRECTORY && !fs::create_directory(m_tmp, ec)) throw IoError(m_tmp + ": cannot create the output directory: " + ec.message());
}

AtomicPath::~AtomicPath() {
    if (m_done) return;
    std::error_code ec;
    fs::remove_all(m_tmp, ec);
}

void AtomicPath::commit() {
    std::error_code ec;
    if (m_kind == Kind::FILE) {
        fsync_path(m_tmp);
        fs::rename(m_tmp, m_path, ec);
        if (ec) throw IoError(m_path + ": cannot rename the finished output into place: " + ec.message());
        m_done = true;
        return;
    }
    const std::string old = m_path + ".old-" + std::to_string(::getpid());
    const bool had_old = fs::exists(m_path, ec);
    if (had_old) {
        fs::rename(m_path, old, ec);
        if (ec) throw IoError(m_path + ": cannot move the previous output aside: " + ec.message());
    }
    fs::rename(m_tmp, m_path, ec);
    if (ec) {
        std::error_code ec2;
        if (had_old) fs::rename(old, m_path, ec2);
        throw IoError(m_path + ": cannot move the completed output into place: " + ec.message());
    }
    m_done = true;
    if (had_old) fs::remove_all(old, ec);
}

AtomicTextFile::AtomicTextFile(std::string path) : m_target(std::move(path)) {
    m_out.open(m_target.tmp());
    if (!m_out) throw IoError(m_target.path() + ": cannot write");
}

void AtomicTextFile::commit() {
    m_out.close();
    if (!m_out) throw IoError(m_target.path() + ": write failed");
    m_target.commit();
}

void write_text_atomically(const std::string& path, const std::string& text) {
    AtomicTextFile f(path);
    f.out() << text;
    f.commit();
}

}  // namespace aneu
