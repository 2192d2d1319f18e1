// Chapter-4 statistics (SPEC §5): bivariate histogram of (τ*, ω²*) and the polar histogram of
// the angle between the major principal direction t_I and the velocity.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "analysis/subfilter_stress.hpp"

namespace sphles::analysis {

/// Counts on a regular bins_x × bins_y grid over [0, 1]²; values equal to 1 go into the last
/// bin. counts[bx + bins_x * by].
struct Histogram2D {
  int bins_x = 0;
  int bins_y = 0;
  std::vector<std::uint64_t> counts;
  std::uint64_t total = 0;
};

/// Histogram of (x_i / max x, y_i / max y) for all i (a zero maximum maps every value to 0).
Histogram2D normalised_bivariate_histogram(std::span<const double> x, std::span<const double> y,
                                           int bins_x, int bins_y);

/// Counts of the smallest angle γ ∈ [0, π/2] between the line of t_I and v_i, over `bins`
/// equal bins, for particles with norm_i / max norm > threshold and |v_i| > 0.
struct AngleHistogram {
  int bins = 0;
  double threshold = 0.1;
  std::vector<std::uint64_t> counts;
  std::uint64_t total = 0;
};

AngleHistogram principal_direction_alignment(const SubfilterStressField& stress,
                                             const sim::ParticleArrays& particles, int bins,
                                             double threshold);

}  // namespace sphles::analysis
