// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/cell_list.hpp"

#include <limits>
#include <stdexcept>
#include <string>

#include "sim/neighbour_search.hpp"

namespace sphles::analysis {

void check_grid(const Grid& grid) {
  if (grid.dimension != 2 && grid.dimension != 3)
    throw std::invalid_argument("grid: dimension must be 2 or 3");
  if (grid.points_per_side <= 0) throw std::invalid_argument("grid: points_per_side must be > 0");
  if (!(grid.length > 0.0)) throw std::invalid_argument("grid: length must be > 0");
}

/// The particles can be gridded on `grid`: same dimension, at least one, 32-bit indices,
/// positions in [0, L].
void check_particles(const Grid& grid, const sim::ParticleArrays& particles, const char* what) {
  check_grid(grid);
  const std::string name(what);
  if (particles.dimension != grid.dimension)
    throw std::invalid_argument(name + ": grid and particle dimensions differ");
  const std::size_t n = particles.size();
  if (n == 0) throw std::invalid_argument(name + ": no particles");
  if (n > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument(name + ": too many particles for 32-bit indices");
  for (int d = 0; d < grid.dimension; ++d) {
    if (particles.position[d].size() != n)
      throw std::invalid_argument(name + ": position arrays do not match the particles");
    const auto [lo, hi] =
        std::minmax_element(particles.position[d].begin(), particles.position[d].end());
    if (*lo < 0.0 || *hi > grid.length)
      throw std::invalid_argument(name + ": positions must lie in [0, L] (axis " +
                                  std::to_string(d) + ")");
  }
}

/// C^n cells of side L/C over the grid's box.
CellList build_cell_list(const Grid& grid, const sim::ParticleArrays& particles,
                         int cells_per_side) {
  const int dim = grid.dimension;
  const std::size_t n = particles.size();
  CellList cells;
  cells.cells_per_side = std::max(1, cells_per_side);
  cells.cell_size = grid.length / cells.cells_per_side;
  const auto c_side = static_cast<std::size_t>(cells.cells_per_side);
  std::size_t num_cells = 1;
  for (int d = 0; d < dim; ++d) num_cells *= c_side;

  std::vector<std::size_t> cell(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t c = 0;
    for (int d = dim - 1; d >= 0; --d)
      c = c * c_side + static_cast<std::size_t>(cells.cell_of(particles.position[d][i]));
    cell[i] = c;
  }
  // Counting sort by cell, a cell's members in ascending id: a gather visits the same particles
  // in the same order whatever their order in `particles` (one process, or a rank's own particles
  // and halo, par/), so its sums are the same bits.
  std::vector<std::uint32_t> visit;
  if (particles.id.size() == n) visit = sim::order_by_key(particles.id);
  cells.cell_start.assign(num_cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++cells.cell_start[cell[i] + 1];
  for (std::size_t c = 0; c < num_cells; ++c) cells.cell_start[c + 1] += cells.cell_start[c];
  std::vector<std::size_t> fill(cells.cell_start.begin(), cells.cell_start.end() - 1);
  for (int d = 0; d < dim; ++d) cells.sorted_position[d].resize(n);
  cells.sorted_id.resize(n);
  cells.sorted_index.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    const std::size_t i = visit.empty() ? v : visit[v];
    const std::size_t k = fill[cell[i]]++;
    for (int d = 0; d < dim; ++d) cells.sorted_position[d][k] = particles.position[d][i];
    cells.sorted_id[k] = i < particles.id.size() ? particles.id[i] : i;  // ids: nearest map only
    cells.sorted_index[k] = static_cast<std::uint32_t>(i);
  }
  return cells;
}

CellList build_gather_cell_list(const Grid& grid, const sim::ParticleArrays& particles,
                                double radius) {
  if (!(radius > 0.0)) throw std::invalid_argument("cell list: gather radius must be > 0");
  const double cell_size = radius / kCellsPerRadius;
  const int cells_per_side = std::max(1, static_cast<int>(std::floor(grid.length / cell_size)));
  return build_cell_list(grid, particles, cells_per_side);
}

std::vector<int> gather_offsets(const CellList& cells) {
  std::vector<int> offsets;
  if (cells.cells_per_side >= 2 * kCellsPerRadius + 1) {
    for (int o = -kCellsPerRadius; o <= kCellsPerRadius; ++o) offsets.push_back(o);
  } else {
    for (int o = 0; o < cells.cells_per_side; ++o) offsets.push_back(o);
  }
  return offsets;
}

}  // namespace sphles::analysis
