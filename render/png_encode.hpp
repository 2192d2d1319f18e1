// SPDX-License-Identifier: GPL-3.0-or-later
// Direct libpng encoder with a fixed row filter (an alternative to vtkPNGWriter's adaptive one).
#pragma once

#include <span>
#include <vector>

namespace sphles::render {

/// PNG row filters (libpng's PNG_FILTER_* flags); several flags make libpng choose per row.
enum class PngFilter { None, Sub, Up, Paeth, Adaptive };

/// Encodes 8-bit RGB pixels stored bottom row first (VTK's convention) as a PNG with the given
/// zlib level (0..9) and row filter. Deterministic. Throws std::runtime_error on libpng errors.
std::vector<unsigned char> encode_png_rgb(std::span<const unsigned char> rgb_bottom_up, int width,
                                          int height, int compression_level, PngFilter filter);

}  // namespace sphles::render
