// SPDX-License-Identifier: GPL-3.0-or-later
// How values become colours: the viridis table, the value range and the lookup index, shared by
// the slice and particle renderers and the colour bar (the same mapping on the CPU and in VTK).
#pragma once

#include <array>
#include <optional>
#include <span>

namespace sphles::render {

/// How slice values become colours. With min and max both given the range is fixed; a missing
/// bound is taken from the percentile of the finite values (for log scale: finite and > 0).
struct ColourMapping {
  bool log_scale = false;
  std::optional<double> min, max;
  double lower_percentile = 0.01;  // fraction in [0, 1]
  double upper_percentile = 0.99;  // fraction in [0, 1]
};

/// Number of entries of the colour map (viridis).
inline constexpr int kColourCount = 256;
using Rgb = std::array<unsigned char, 3>;

/// The 256-entry viridis table, linearly interpolated from 17 control points of the published
/// definition (matplotlib _viridis_data, every 16th entry); 8-bit RGB.
const std::array<Rgb, kColourCount>& viridis_table();

/// Value range [min, max] the mapping uses for these values (see ColourMapping). For log scale
/// both bounds are > 0. min < max always (a degenerate range is widened).
/// Throws std::invalid_argument for a log scale with a given bound <= 0.
std::array<double, 2> colour_range(std::span<const double> values, const ColourMapping& mapping);

/// Lookup-table index of a value: floor(256 t) clamped to [0, 255], t = (v - min) / (max - min),
/// or for log scale t = (log10 v - log10 min) / (log10 max - log10 min), so each decade gets
/// the same number of entries. The transform is done here (on the CPU); the vtkLookupTable the
/// scalar bar uses is set to the same range with SetScaleToLog10 and maps values identically.
/// Values below the range (and for log scale values <= 0) get index 0; NaN gets -1.
int colour_index(double value, const std::array<double, 2>& range, bool log_scale);

/// colour_index of every value (indices.size() == values.size()), with the range transform
/// hoisted out of the loop.
void colour_indices(std::span<const double> values, const std::array<double, 2>& range,
                    bool log_scale, std::span<int> indices);

}  // namespace sphles::render
