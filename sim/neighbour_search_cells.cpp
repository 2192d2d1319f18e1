// SPDX-License-Identifier: GPL-3.0-or-later
// VerletNeighbourSearch's cells: each particle's cell and the particles sorted cell by cell, for
// the locality order a caller applies and for a build's binning (the positions in cell order that
// the candidate scans of neighbour_search.cpp read), and order_by_key for a global cell order.
#include <algorithm>

#include "sim/neighbour_search.hpp"

namespace sphles::sim {

namespace {

/// Particle indices sorted by cell into `members`, and where each cell's members begin into
/// `start` (num_cells + 1 entries). Within a cell, members follow `visit` when it is not empty (a
/// permutation of the indices), else ascending index (a stable counting sort).
void counting_sort_by_cell(const std::vector<std::uint32_t>& cell, std::size_t num_cells,
                           std::vector<std::uint32_t>& members, std::vector<std::size_t>& start,
                           std::span<const std::uint32_t> visit = {}) {
  start.assign(num_cells + 1, 0);
  for (const std::uint32_t c : cell) ++start[c + 1];
  for (std::size_t c = 0; c < num_cells; ++c) start[c + 1] += start[c];
  members.resize(cell.size());
  if (visit.empty()) {
    for (std::size_t i = 0; i < cell.size(); ++i)
      members[start[cell[i]]++] = static_cast<std::uint32_t>(i);
  } else {
    for (const std::uint32_t i : visit) members[start[cell[i]]++] = i;
  }
  // start[c] now holds where cell c ends, the start of c + 1: shift back.
  for (std::size_t c = num_cells; c > 0; --c) start[c] = start[c - 1];
  start[0] = 0;
}

}  // namespace

std::vector<std::uint32_t> order_by_key(std::span<const std::uint64_t> keys) {
  const std::size_t n = keys.size();
  std::vector<std::uint32_t> order(n);
  const bool permutation =
      std::all_of(keys.begin(), keys.end(), [n](std::uint64_t k) { return k < n; });
  if (permutation) {  // unique keys below n: each index's place is its key
    for (std::size_t i = 0; i < n; ++i) order[keys[i]] = static_cast<std::uint32_t>(i);
    return order;
  }
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
  return order;
}

void VerletNeighbourSearch::cell_of(const PositionsView& positions,
                                    std::vector<std::uint32_t>& cell) const {
  cell.resize(positions.size);
  const auto n = static_cast<std::ptrdiff_t>(positions.size);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    std::uint32_t c = 0;
    for (int d = positions.dimension - 1; d >= 0; --d) {
      int k = static_cast<int>(positions.x[d][i] * inv_cell_size_[d]);
      k = std::clamp(k, 0, cells_[d] - 1);
      c = c * static_cast<std::uint32_t>(cells_[d]) + static_cast<std::uint32_t>(k);
    }
    cell[i] = c;
  }
}

std::vector<std::uint32_t> VerletNeighbourSearch::locality_order(
    const PositionsView& positions) const {
  std::vector<std::uint32_t> cell, order;
  std::vector<std::size_t> start;
  cell_of(positions, cell);
  counting_sort_by_cell(cell, num_cells(), order, start);
  return order;
}

template <int Dim>
void VerletNeighbourSearch::bin_particles(const PositionsView& positions,
                                          std::span<const std::uint32_t> cell_order) {
  const std::size_t n = positions.size;
  std::vector<std::uint32_t>& cell = scratch_.cell;
  std::vector<std::uint32_t>& cell_members = scratch_.cell_members;
  cell_of(positions, cell);
  counting_sort_by_cell(cell, num_cells(), cell_members, scratch_.cell_start, cell_order);

  // Positions in cell order, so that a run of neighbouring cells along x is one contiguous run of
  // candidates: the distance test of a build is a vectorised loop over contiguous memory.
  // rank[i] is particle i's place in that order.
  std::array<std::vector<double>, 3>& sorted = scratch_.sorted;
  for (int d = 0; d < Dim; ++d) sorted[d].resize(n);
  std::vector<std::uint32_t>& rank = scratch_.rank;
  rank.resize(n);
  const auto signed_n = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t sk = 0; sk < signed_n; ++sk) {
    const auto k = static_cast<std::size_t>(sk);
    for (int d = 0; d < Dim; ++d) sorted[d][k] = positions.x[d][cell_members[k]];
    rank[cell_members[k]] = static_cast<std::uint32_t>(k);
  }
}

template void VerletNeighbourSearch::bin_particles<2>(const PositionsView&,
                                                      std::span<const std::uint32_t>);
template void VerletNeighbourSearch::bin_particles<3>(const PositionsView&,
                                                      std::span<const std::uint32_t>);

}  // namespace sphles::sim
