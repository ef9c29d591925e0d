// SPDX-License-Identifier: MIT
#pragma once

namespace aneu {
/// Tool version (CMake project version), e.g. "0.1.0".
const char* tool_version();
/// `git describe --always --dirty` of the source tree at build time, or "unknown".
const char* git_revision();
}  // namespace aneu
