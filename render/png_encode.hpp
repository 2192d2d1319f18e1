// SPDX-License-Identifier: GPL-3.0-or-later
// Direct libpng encoder with a fixed row filter (an alternative to vtkPNGWriter's adaptive one).
#pragma once

#include <span>
#include <vector>

namespace sphles::render {

/// PNG row filters (libpng's PNG_FILTER_* flags); several flags make libpng choose per row.
enum class PngFilter { None, Sub, Up, Paeth, Adaptive };

/// PNG zlib level the renderers use by default: 1 (Z_BEST_SPEED); several times faster than the
/// default level 6 for these frames.
inline constexpr int kDefaultPngCompressionLevel = 1;
/// PNG row filter the renderers use by default: none. The frames are nearest-neighbour upscaled
/// colour fields with flat margins, so unfiltered rows compress better (long LZ77 matches) and
/// faster than libpng's adaptive choice, which vtkPNGWriter always uses.
inline constexpr PngFilter kDefaultPngFilter = PngFilter::None;

/// Encodes 8-bit RGB pixels stored bottom row first (VTK's convention) as a PNG with the given
/// zlib level (0..9) and row filter. Deterministic. Throws std::runtime_error on libpng errors.
std::vector<unsigned char> encode_png_rgb(std::span<const unsigned char> rgb_bottom_up, int width,
                                          int height, int compression_level, PngFilter filter);

}  // namespace sphles::render
