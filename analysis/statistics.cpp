// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/statistics.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <stdexcept>

namespace sphles::analysis {
namespace {

/// Bin of u ∈ [0, 1] among `bins` equal bins; u = 1 (and rounding above) goes into the last bin,
/// anything below 0 into the first.
int bin_of(double u, int bins) {
  const double scaled = u * bins;
  if (!(scaled > 0.0)) return 0;
  return std::min(static_cast<int>(scaled), bins - 1);
}

}  // namespace

double max_value(std::span<const double> values) {
  double m = 0.0;
  for (const double v : values) m = std::max(m, v);
  return m;
}

Histogram2D normalised_bivariate_histogram(std::span<const double> x, std::span<const double> y,
                                           int bins_x, int bins_y) {
  return bivariate_histogram(x, y, max_value(x), max_value(y), bins_x, bins_y);
}

Histogram2D bivariate_histogram(std::span<const double> x, std::span<const double> y, double max_x,
                                double max_y, int bins_x, int bins_y) {
  if (x.size() != y.size())
    throw std::invalid_argument("bivariate histogram: x and y differ in length");
  if (bins_x < 1 || bins_y < 1)
    throw std::invalid_argument("bivariate histogram: bin counts must be >= 1");
  Histogram2D h;
  h.bins_x = bins_x;
  h.bins_y = bins_y;
  h.counts.assign(static_cast<std::size_t>(bins_x) * static_cast<std::size_t>(bins_y), 0);
  // (τ*, ω²*) = (τ / max τ, ω² / max ω²) (SPEC §5); a zero maximum maps every value to 0.
  const double scale_x = max_x > 0.0 ? 1.0 / max_x : 0.0;
  const double scale_y = max_y > 0.0 ? 1.0 / max_y : 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const int bx = bin_of(x[i] * scale_x, bins_x);
    const int by = bin_of(y[i] * scale_y, bins_y);
    ++h.counts[static_cast<std::size_t>(bx) +
               static_cast<std::size_t>(bins_x) * static_cast<std::size_t>(by)];
  }
  h.total = x.size();
  return h;
}

AngleHistogram principal_direction_alignment(const SubfilterStressField& stress,
                                             const sim::ParticleArrays& particles, int bins,
                                             double threshold, double max_norm) {
  if (bins < 1) throw std::invalid_argument("angle histogram: bin count must be >= 1");
  if (stress.norm.size() > particles.size() || stress.direction.size() != stress.norm.size())
    throw std::invalid_argument("angle histogram: stress field does not match the particles");
  const int dim = stress.dimension;
  AngleHistogram h;
  h.bins = bins;
  h.threshold = threshold;
  h.counts.assign(static_cast<std::size_t>(bins), 0);
  if (std::isnan(max_norm)) max_norm = max_value(stress.norm);
  if (!(max_norm > 0.0)) return h;  // no stress anywhere: no direction is defined
  for (std::size_t i = 0; i < stress.norm.size(); ++i) {
    if (!(stress.norm[i] / max_norm > threshold)) continue;   // τ_SFS,i / max > threshold (§5)
    const std::array<double, 3>& t = stress.direction[i][0];  // t_I (unit)
    double v[3] = {0.0, 0.0, 0.0};
    for (int d = 0; d < dim; ++d) v[d] = particles.velocity[d][i];
    const double dot = t[0] * v[0] + t[1] * v[1] + t[2] * v[2];
    const double cross[3] = {t[1] * v[2] - t[2] * v[1], t[2] * v[0] - t[0] * v[2],
                             t[0] * v[1] - t[1] * v[0]};
    const double speed2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if (!(speed2 > 0.0)) continue;
    // Smallest angle between the line of t_I and v_i: atan2(|t × v|, |t · v|) ∈ [0, π/2],
    // accurate also near 0 and π/2 (unlike acos).
    const double sine = std::sqrt(cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]);
    const double gamma = std::atan2(sine, std::abs(dot));
    ++h.counts[static_cast<std::size_t>(bin_of(gamma / (0.5 * std::numbers::pi), bins))];
    ++h.total;
  }
  return h;
}

}  // namespace sphles::analysis
