// SPDX-License-Identifier: GPL-3.0-or-later
// Viridis colour table, robust value ranges and value → colour index.
#include "render/colour_map.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "render/lookup_table.hpp"

namespace sphles::render {
namespace {

// Every 16th entry (and the last) of matplotlib's 256-entry _viridis_data (van der Walt & Smith).
constexpr int kControlPointCount = 17;
constexpr double kViridisControlPoints[kControlPointCount][3] = {
    {0.267004, 0.004874, 0.329415},  // 0
    {0.282327, 0.094955, 0.417331},  // 16
    {0.278826, 0.175490, 0.483397},  // 32
    {0.258965, 0.251537, 0.524736},  // 48
    {0.229739, 0.322361, 0.545706},  // 64
    {0.199430, 0.387607, 0.554642},  // 80
    {0.172719, 0.448791, 0.557885},  // 96
    {0.149039, 0.508051, 0.557250},  // 112
    {0.127568, 0.566949, 0.550556},  // 128
    {0.120638, 0.625828, 0.533488},  // 144
    {0.157851, 0.683765, 0.501686},  // 160
    {0.246070, 0.738910, 0.452024},  // 176
    {0.369214, 0.788888, 0.382914},  // 192
    {0.515992, 0.831158, 0.294279},  // 208
    {0.678489, 0.863742, 0.189503},  // 224
    {0.845561, 0.887322, 0.099702},  // 240
    {0.993248, 0.906157, 0.143936},  // 255
};
constexpr int kControlPointIndex[kControlPointCount] = {0,   16,  32,  48,  64,  80,  96,  112, 128,
                                                        144, 160, 176, 192, 208, 224, 240, 255};

std::array<Rgb, kColourCount> build_viridis() {
  std::array<Rgb, kColourCount> table{};
  int segment = 0;
  for (int i = 0; i < kColourCount; ++i) {
    while (i > kControlPointIndex[segment + 1]) ++segment;
    const int i0 = kControlPointIndex[segment], i1 = kControlPointIndex[segment + 1];
    const double f = static_cast<double>(i - i0) / (i1 - i0);
    for (int c = 0; c < 3; ++c) {
      const double value =
          kViridisControlPoints[segment][c] +
          f * (kViridisControlPoints[segment + 1][c] - kViridisControlPoints[segment][c]);
      table[i][c] = static_cast<unsigned char>(std::lround(255.0 * value));
    }
  }
  return table;
}

// Value at fraction p of the sorted values, linear between order statistics. Reorders values.
double percentile(std::vector<double>& values, double p) {
  p = std::clamp(p, 0.0, 1.0);
  const double position = p * static_cast<double>(values.size() - 1);
  const auto lower = static_cast<std::size_t>(std::floor(position));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(lower),
                   values.end());
  const double lower_value = values[lower];
  if (lower + 1 >= values.size()) return lower_value;
  const double upper_value =
      *std::min_element(values.begin() + static_cast<std::ptrdiff_t>(lower) + 1, values.end());
  return lower_value + (position - static_cast<double>(lower)) * (upper_value - lower_value);
}

}  // namespace

const std::array<Rgb, kColourCount>& viridis_table() {
  static const std::array<Rgb, kColourCount> table = build_viridis();
  return table;
}

std::array<double, 2> colour_range(std::span<const double> values, const ColourMapping& mapping) {
  const bool log = mapping.log_scale;
  if (log && ((mapping.min && !(*mapping.min > 0.0)) || (mapping.max && !(*mapping.max > 0.0)))) {
    throw std::invalid_argument("colour_range: log scale needs positive bounds");
  }
  // Work in the mapped coordinate (log10 for log scale) so that widening is symmetric there.
  const auto forward = [log](double v) { return log ? std::log10(v) : v; };
  const auto backward = [log](double v) { return log ? std::pow(10.0, v) : v; };

  double lower = 0.0, upper = 1.0;
  if (!mapping.min || !mapping.max) {
    std::vector<double> valid;
    valid.reserve(values.size());
    for (const double v : values) {
      if (std::isfinite(v) && (!log || v > 0.0)) valid.push_back(forward(v));
    }
    if (!valid.empty()) {
      lower = percentile(valid, mapping.lower_percentile);
      upper = percentile(valid, mapping.upper_percentile);
    }
  }
  if (mapping.min) lower = forward(*mapping.min);
  if (mapping.max) upper = forward(*mapping.max);
  if (!(upper > lower)) {
    const double half_width = lower != 0.0 && !log ? 0.5 * std::abs(lower) : 0.5;
    if (mapping.max && !mapping.min) {
      lower = upper - 2.0 * half_width;
    } else if (mapping.min && !mapping.max) {
      upper = lower + 2.0 * half_width;
    } else {
      const double centre = 0.5 * (lower + upper);
      lower = centre - half_width;
      upper = centre + half_width;
    }
  }
  return {backward(lower), backward(upper)};
}

int colour_index(double value, const std::array<double, 2>& range, bool log_scale) {
  int index = 0;
  colour_indices(std::span(&value, 1), range, log_scale, std::span(&index, 1));
  return index;
}

void colour_indices(std::span<const double> values, const std::array<double, 2>& range,
                    bool log_scale, std::span<int> indices) {
  if (indices.size() != values.size()) {
    throw std::invalid_argument("colour_indices: indices and values differ in size");
  }
  const double a = log_scale ? std::log10(range[0]) : range[0];
  const double b = log_scale ? std::log10(range[1]) : range[1];
  const double inverse_width = 1.0 / (b - a);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double value = values[i];
    int index;
    if (std::isnan(value)) {
      index = -1;
    } else if (log_scale && !(value > 0.0)) {
      index = 0;
    } else {
      const double t = ((log_scale ? std::log10(value) : value) - a) * inverse_width;
      index = !(t > 0.0) ? 0
              : t >= 1.0 ? kColourCount - 1
                         : std::min(kColourCount - 1, static_cast<int>(t * kColourCount));
    }
    indices[i] = index;
  }
}

vtkSmartPointer<vtkLookupTable> make_lookup_table(const std::array<double, 2>& range,
                                                  bool log_scale) {
  auto table = vtkSmartPointer<vtkLookupTable>::New();
  if (log_scale) {
    table->SetScaleToLog10();
  } else {
    table->SetScaleToLinear();
  }
  table->SetRange(range[0], range[1]);
  table->SetNumberOfTableValues(kColourCount);
  const auto& viridis = viridis_table();
  for (int i = 0; i < kColourCount; ++i) {
    table->SetTableValue(i, viridis[i][0] / 255.0, viridis[i][1] / 255.0, viridis[i][2] / 255.0,
                         1.0);
  }
  table->SetNanColor(0.5, 0.5, 0.5, 1.0);
  return table;
}

}  // namespace sphles::render
