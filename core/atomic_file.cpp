// SPDX-License-Identifier: MIT
#include "aneu/core/atomic_file.hpp"

#include <cstdio>
#include <filesystem>
#include <system_error>

#include <unistd.h>

#include "aneu/core/error.hpp"

namespace aneu {

AtomicTextFile::AtomicTextFile(std::string path) : m_path(std::move(path)), m_tmp(m_path + ".part-" + std::to_string(::getpid())) {
    m_out.open(m_tmp);
    if (!m_out) throw IoError(m_path + ": cannot write (does the directory exist?)");
}

AtomicTextFile::~AtomicTextFile() {
    if (m_done) return;
    m_out.close();
    std::remove(m_tmp.c_str());
}

void AtomicTextFile::commit() {
    m_out.close();
    if (!m_out) throw IoError(m_path + ": write failed");
    std::error_code ec;
    std::filesystem::rename(m_tmp, m_path, ec);
    if (ec) throw IoError(m_path + ": cannot rename the finished output into place: " + ec.message());
    m_done = true;
}

}  // namespace aneu
