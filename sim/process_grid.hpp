// SPDX-License-Identifier: GPL-3.0-or-later
// How a distributed run splits its periodic box among processes (par/decomposition.hpp), as a
// pure function, so that what a run will need per process can be estimated before MPI exists
// (control/resources.hpp) with the very split the run will use.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace sphles::sim {

/// Processes per axis of a `ranks`-process Cartesian grid in `dimension` dimensions: factors as
/// equal as possible, in non-increasing order, unused axes 1 (what MPI_Dims_create gives: each
/// prime factor of `ranks`, largest first, multiplies the axis with the fewest processes so far).
inline std::array<int, 3> process_grid(int ranks, int dimension) {
  if (ranks < 1 || dimension < 1 || dimension > 3)
    throw std::invalid_argument("process grid: needs ranks >= 1 and a dimension of 1 to 3");
  std::vector<int> primes;
  for (int rest = ranks, p = 2; rest > 1;) {
    if (static_cast<long>(p) * p > rest) {
      primes.push_back(rest);
      break;
    }
    if (rest % p == 0) {
      primes.push_back(p);
      rest /= p;
    } else {
      ++p;
    }
  }
  std::sort(primes.rbegin(), primes.rend());
  std::array<int, 3> grid{1, 1, 1};
  for (const int p : primes) {
    int* fewest = std::min_element(grid.begin(), grid.begin() + dimension);
    *fewest *= p;
  }
  std::sort(grid.begin(), grid.begin() + dimension, [](int a, int b) { return a > b; });
  return grid;
}

/// Why `ranks` processes cannot split a periodic box of side lengths `length` (the first
/// `dimension`) by process_grid with every sub-box at least `halo_width` wide, naming the rank
/// count, the axis and the particles per side it would need; "" when they can. The one check of
/// par::Decomposition (which refuses such a split) and of the resource estimates (which name it
/// before a run starts).
inline std::string split_refusal(int ranks, int dimension, const std::array<double, 3>& length,
                                 double halo_width, double particle_spacing) {
  static const char* const axis_names[] = {"x", "y", "z"};
  const std::array<int, 3> dims = process_grid(ranks, dimension);
  for (int a = 0; a < dimension; ++a) {
    const auto k = static_cast<std::size_t>(a);
    const double width = length[k] / dims[k];
    if (width >= halo_width) continue;
    const auto per_side = static_cast<long>(std::lround(length[k] / particle_spacing));
    const auto needed = static_cast<long>(std::ceil(dims[k] * halo_width / particle_spacing));
    const auto max_ranks = static_cast<long>(std::floor(length[k] / halo_width));
    std::ostringstream message;
    message << ranks << (ranks == 1 ? " MPI rank" : " MPI ranks") << " split the box " << dims[0]
            << " x " << dims[1];
    if (dimension == 3) message << " x " << dims[2];
    message << "; along " << axis_names[a] << " a sub-box is " << width
            << " wide, narrower than the halo width " << halo_width
            << " (kernel support radius + Verlet skin). With " << dims[k]
            << (dims[k] == 1 ? " rank along " : " ranks along ") << axis_names[a]
            << " that needs at least " << needed << " particles per side (the scene has "
            << per_side << "); at " << per_side << " per side use at most " << max_ranks
            << (max_ranks == 1 ? " rank" : " ranks") << " along an axis";
    return message.str();
  }
  return {};
}

}  // namespace sphles::sim
