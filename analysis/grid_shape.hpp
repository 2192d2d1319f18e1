// SPDX-License-Identifier: GPL-3.0-or-later
// The analysis grid's shape: M points per side of a periodic box of side L, in 2D or 3D, stored
// x fastest. Apart from grid.hpp so that the cell list, which the gridding uses, needs only this.
#pragma once

#include <cstddef>

namespace sphles::analysis {

struct Grid {
  int dimension = 3;
  int points_per_side = 0;  // M
  double length = 0.0;      // L [m]

  double spacing() const { return length / points_per_side; }
  std::size_t size() const {
    std::size_t n = 1;
    for (int d = 0; d < dimension; ++d) n *= static_cast<std::size_t>(points_per_side);
    return n;
  }
  std::size_t index(int i, int j, int k = 0) const {
    const auto m = static_cast<std::size_t>(points_per_side);
    return static_cast<std::size_t>(i) +
           m * (static_cast<std::size_t>(j) + m * static_cast<std::size_t>(k));
  }
};

}  // namespace sphles::analysis
