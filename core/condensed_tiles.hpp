// SPDX-License-Identifier: MIT
#pragma once
// /condensed group I/O: W stored as lower-triangle square tiles, one HDF5 chunk per tile, so a set of
// columns is read by hyperslab without touching the rest of the matrix.
#include <H5Cpp.h>

#include "aneu/core/bundle.hpp"
#include "aneu/core/reporter.hpp"
#include "h5_detail.hpp"

namespace aneu::detail {

void write_condensed_group(H5::H5File& f, const CondensedData& c, Reporter& rep);
/// Reads /condensed; W (full symmetric, both triangles filled) only when with_W.
CondensedData read_condensed_group(const H5::H5File& f, const h5::Ctx& ctx, bool with_W);

}  // namespace aneu::detail
