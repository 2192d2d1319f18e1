// SPDX-License-Identifier: GPL-3.0-or-later
// The chapter-4 statistics as plain data (SPEC §5): the bivariate histogram of (τ*, ω²*), the
// polar histogram of the angle between t_I and the velocity, and the sfs_stats product that
// holds them (statistics.hpp computes them; a distributed solver's ranks too, snapshot.hpp).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

namespace sphles::analysis {

/// Counts on a regular bins_x × bins_y grid over [0, 1]²; values equal to 1 go into the last
/// bin. counts[bx + bins_x * by].
struct Histogram2D {
  int bins_x = 0;
  int bins_y = 0;
  std::vector<std::uint64_t> counts;
  std::uint64_t total = 0;
};

/// Counts of the smallest angle γ ∈ [0, π/2] between the line of t_I and v_i, over `bins`
/// equal bins, for particles with norm_i / max norm > threshold and |v_i| > 0.
struct AngleHistogram {
  int bins = 0;
  double threshold = 0.1;
  std::vector<std::uint64_t> counts;
  std::uint64_t total = 0;
};

struct SubfilterStatisticsProduct {
  double max_norm = 0.0;                    // max_i |τ_SFS,i| [Pa]
  double mean_norm = 0.0;                   // mean_i |τ_SFS,i| [Pa]
  Histogram2D joint;                        // (τ*, ω²*)
  std::optional<AngleHistogram> alignment;  // 2D runs: γ between t_I and v (chapter 4)
};

}  // namespace sphles::analysis
