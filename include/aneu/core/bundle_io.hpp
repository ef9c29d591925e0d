// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Reading and writing case bundles (HDF5, schema v1; layout in docs/hdf5_layout.md).
#include <string>
#include <vector>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"

namespace aneu {

/// How to write a bundle.
struct BundleWriteOptions {
    int deflate_level = 4;   ///< gzip level for large integer/float datasets (0 = off); W is never compressed
};

/// Which groups read_bundle loads.
struct BundleParts {
    bool image = true;
    bool surfaces = true;
    bool volume = true;
    bool fem = true;
    bool condensed_W = true;  ///< the W matrix itself (may be GBs); the rest of /condensed is always read
    bool flow = true;         ///< /flow (the flow stage's cell fields)
};

/// Writes a bundle atomically: to "<path>.part-<pid>" in the same directory, renamed to `path` only once
/// complete. On any failure (including an exception thrown by `rep.on_progress`, which is how a caller
/// cancels) the temporary file is removed and an existing file at `path` is left untouched.
///
/// W is stored as its TiledSymmetric tiles, in the same order as in memory: dataset
/// /condensed/W_tiles [nb(nb+1)/2, b, b], one HDF5 chunk per tile, so any set of columns is read without
/// reading the rest (read_condensed_columns).
/// @param[in] path  output file (.h5)
/// @param[in] b     bundle; b.meta.schema_version must be BUNDLE_SCHEMA_VERSION
/// @throws InputError  inconsistent shapes in b, or the directory does not exist;
///         IoError  the file cannot be written
void write_bundle(const std::string& path, const Bundle& b, const BundleWriteOptions& opt = {},
                  Reporter& rep = null_reporter());

/// Reads a bundle, checking the format marker, schema version, and every dataset's presence, type and
/// shape. Messages name the file, the dataset and what was expected.
/// @throws InputError  missing, unreadable or truncated file, not a bundle, other schema version, missing
///         dataset, wrong shape or type (a defect of the input file: exit code 2 in the tools)
Bundle read_bundle(const std::string& path, const BundleParts& parts = {});

/// Reads only /meta (cheap). @throws InputError as read_bundle
Meta read_meta(const std::string& path);

/// /condensed without W: the DOF map, precision, method, diagnostics.
CondensedData read_condensed_header(const std::string& path);

/// Columns `cols` (0-based rows of the DOF map, any order, duplicates allowed) of W, all #M rows, in
/// double, reading only the tiles of the column blocks they fall in.
/// @return #M×cols.size()
Eigen::MatrixXd read_condensed_columns(const std::string& path, const std::vector<int>& cols);
/// Same, converted to float32 (the simulator's working precision for a float32 W).
Eigen::MatrixXf read_condensed_columns_f(const std::string& path, const std::vector<int>& cols);

}  // namespace aneu
