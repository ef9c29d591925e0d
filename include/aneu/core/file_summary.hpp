// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// What a bundle file holds, without reading its large datasets (for `aneuprep inspect`).
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "aneu/core/bundle.hpp"

namespace aneu {

/// One group or dataset of an HDF5 file.
struct H5Entry {
    std::string path;                 ///< e.g. "/volume/tets"
    bool is_group = false;
    std::vector<std::uint64_t> shape;  ///< datasets only
    std::string dtype;                ///< "float64", "int32", "uint8", "string", ...
    std::string units;                ///< the `units` attribute, if any
    std::uint64_t stored_bytes = 0;   ///< bytes on disk (after compression)
    std::string filters;              ///< e.g. "chunked shuffle+gzip" or "contiguous"
    std::vector<std::pair<std::string, std::string>> attributes;  ///< other scalar attributes, as text
};

/// Summary of a bundle: its /meta and every entry outside /meta.
struct FileSummary {
    std::string path;
    std::uint64_t file_bytes = 0;
    Meta meta;
    std::vector<H5Entry> entries;  ///< depth-first, sorted by name

    /// The entry with this path, or nullptr.
    const H5Entry* find(const std::string& p) const;
};

/// Opens a bundle (checking format and schema version) and lists its content.
/// @throws IoError as read_bundle
FileSummary summarize_bundle(const std::string& path);

}  // namespace aneu
