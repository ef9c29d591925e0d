// SPDX-License-Identifier: MIT
#pragma once
/// @file
/// Pictures of stage results (VTK, rendered off screen to PNG).
#include <string>

#include "aneu/core/bundle.hpp"

namespace aneu::pipeline {

/// What colours the faces of a surface snapshot.
enum class ColorBy { LABEL, REGION };

/// Renders a surface to a PNG, faces coloured by label or region, from a camera looking at the surface's
/// centre along −y with +z up, one view. Debian's VTK renders through X11 only: needs a display
/// (run under `xvfb-run -a`).
/// @throws InputError no X display (DISPLAY unset); IoError the PNG cannot be written
void snapshot_surface(const SurfaceData& s, ColorBy by, const std::string& png, int width = 1000, int height = 800);

}  // namespace aneu::pipeline
