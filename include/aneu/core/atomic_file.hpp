// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// The one way aneuclip writes an output (core/atomic_file.cpp): it appears under its final name only when
/// complete. The writer — HDF5, VTK, ITK, a text stream, or several files in a directory — writes to tmp(),
/// "<path>.part-<pid><ext>" in the same directory (a file's extension repeated, so writers that choose a format
/// by it still do); commit() flushes it to disk and renames it into place (a
/// directory replaces the old one in two renames, the old one removed only once the new one is in place).
/// Never committed (an exception, a kill): the temporary is removed, or left as "*.part-<pid>" litter that
/// the next `aneuprep run` removes (pipeline::remove_stale_parts). Nothing is ever half-written under a
/// final name.
#include <fstream>
#include <string>

namespace aneu {

class AtomicPath {
public:
    enum class Kind { FILE, DIRECTORY };
    /// @throws InputError the parent directory does not exist, or `path` exists as the other kind
    explicit AtomicPath(std::string path, Kind kind = Kind::FILE);
    ~AtomicPath();
    AtomicPath(const AtomicPath&) = delete;
    AtomicPath& operator=(const AtomicPath&) = delete;
    /// Where to write (a directory is created empty).
    const std::string& tmp() const { return m_tmp; }
    const std::string& path() const { return m_path; }
    /// Flushes to disk and renames into place. @throws IoError
    void commit();

private:
    std::string m_path, m_tmp;
    Kind m_kind;
    bool m_done = false;
};

/// A text output through AtomicPath.
class AtomicTextFile {
public:
    /// @throws InputError missing directory; IoError the temporary file cannot be created
    explicit AtomicTextFile(std::string path);
    std::ofstream& out() { return m_out; }
    /// Closes, checks the stream and renames into place. @throws IoError
    void commit();

private:
    AtomicPath m_target;
    std::ofstream m_out;
};

/// Writes `text` to `path` atomically.
void write_text_atomically(const std::string& path, const std::string& text);

}  // namespace aneu
