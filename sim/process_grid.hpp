// How a distributed run splits its periodic box among processes (par/decomposition.hpp), as a
// pure function, so that what a run will need per process can be estimated before MPI exists
// (control/resources.hpp) with the very split the run will use.
#pragma once

#include <algorithm>
#include <array>
#include <stdexcept>
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

}  // namespace sphles::sim
