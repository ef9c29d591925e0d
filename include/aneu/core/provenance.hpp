// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Provenance helpers: content hashes of inputs, UTC timestamps, command lines, stage records.
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"

namespace aneu {

/// SHA-256 of a byte string, lowercase hex (64 characters).
std::string sha256_hex(const std::string& bytes);
/// SHA-256 of a file's content; for a directory, of the sorted "relative-path sha256\n" lines of every
/// regular file below it (so a DICOM series directory has one stable hash).
/// @throws IoError if the path cannot be read
std::string sha256_path(const std::string& path);

/// The whole content of a file. @throws IoError if it cannot be read
std::string read_file(const std::string& path);

/// Current UTC time as ISO 8601 with seconds, e.g. "2026-11-21T11:44:47Z".
std::string utc_now_iso8601();

/// The command line as one string, each argument shell-quoted where needed.
std::string shell_join(const std::vector<std::string>& argv);

/// A stage record filled with this build's version and revision, the current UTC time, and the hash of
/// every input path.
StageRecord make_stage_record(const std::string& stage, const std::string& command_line,
                              std::vector<std::pair<std::string, std::string>> parameters,
                              const std::vector<std::string>& input_paths);

}  // namespace aneu
