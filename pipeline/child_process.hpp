// SPDX-License-Identifier: MIT
#pragma once
// Internal to pipeline/: runs a third-party mesher in a forked child process with a timeout.
#include <functional>
#include <string>
#include <vector>

namespace aneu::pipeline {

/// A mesher's result as sent back from the child process.
struct RawMesh {
    std::vector<double> points;  // 3 per point
    std::vector<int> cells;      // connectivity, the mesher's layout (4 per tet, 3 per triangle)
};

/// Runs `mesher` in a child process; it returns 0 and fills the mesh, or an error code with a message
/// (which becomes a MeshingError "<name>: <message>"). A crash, abort or a run past `timeout_s` (then
/// killed) is a MeshingError too.
RawMesh run_isolated(const std::function<int(RawMesh&, std::string&)>& mesher, double timeout_s, const std::string& name);

}  // namespace aneu::pipeline
