// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// A text output that appears under its final name only when complete (core/atomic_file.cpp): written to
/// "<path>.part-<pid>" in the same directory and renamed by commit(); removed if it is never committed.
#include <fstream>
#include <string>

namespace aneu {

class AtomicTextFile {
public:
    /// @throws IoError the temporary file cannot be created (the message names `path`)
    explicit AtomicTextFile(std::string path);
    ~AtomicTextFile();
    AtomicTextFile(const AtomicTextFile&) = delete;
    AtomicTextFile& operator=(const AtomicTextFile&) = delete;
    std::ofstream& out() { return m_out; }
    /// Closes and renames into place. @throws IoError
    void commit();

private:
    std::string m_path, m_tmp;
    std::ofstream m_out;
    bool m_done = false;
};

}  // namespace aneu
