// SPDX-License-Identifier: GPL-3.0-or-later
// The analysis' periodic cell list over the grid's box, and the checks its users share
// (nearest-particle map, Shepard and local-fit interpolation). Internal to the analysis library.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "analysis/grid_shape.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::analysis {

/// A usable grid: dimension 2 or 3, at least one point per side, positive length.
void check_grid(const Grid& grid);

/// The particles can be gridded on `grid`: same dimension, at least one, 32-bit indices,
/// positions in [0, L]. `what` names the caller in the error.
void check_particles(const Grid& grid, const sim::ParticleArrays& particles, const char* what);

/// Periodic cell list of C^n cubic cells of side w = L/C, particle data copied in cell-major
/// order so that a cell's members are contiguous.
struct CellList {
  int cells_per_side = 1;                              // C
  double cell_size = 0.0;                              // w [m]
  std::vector<std::size_t> cell_start;                 // members of c: [start[c], start[c+1])
  std::array<std::vector<double>, 3> sorted_position;  // x of the members, cell-major
  std::vector<std::uint64_t> sorted_id;
  std::vector<std::uint32_t> sorted_index;  // index into ParticleArrays

  int cell_of(double x) const {
    return std::clamp(static_cast<int>(std::floor(x / cell_size)), 0, cells_per_side - 1);
  }
};

/// C^n cells of side L/C over the grid's box.
CellList build_cell_list(const Grid& grid, const sim::ParticleArrays& particles,
                         int cells_per_side);

/// Cells per gather radius: cells of side >= R / kCellsPerRadius, so the particles within R of a
/// point lie at most kCellsPerRadius cells from the point's cell. Two cells per R scan (5/3)^n
/// radius cubes per point, against 3^n with one.
inline constexpr int kCellsPerRadius = 2;

/// A cell list whose cells are at least R / kCellsPerRadius wide.
CellList build_gather_cell_list(const Grid& grid, const sim::ParticleArrays& particles,
                                double radius);

/// The cell offsets along one axis that a gather of radius R visits: -reach..reach, or every
/// cell once when the box has fewer than 2 reach + 1 cells.
std::vector<int> gather_offsets(const CellList& cells);

/// Calls visit(index, offset, r2) for every particle within `radius` of `point` (minimum image),
/// offset = x_j - point, in a fixed order (z, y, x cell offsets ascending, then the cell's
/// members in cell-list order): sums over the visits do not depend on the thread count.
/// `offsets` is gather_offsets(cells) for a list built by build_gather_cell_list(radius).
template <int Dim, class Visit>
void for_each_particle_within(const CellList& cells, const std::vector<int>& offsets,
                              const std::array<double, 3>& point, double radius, double length,
                              Visit&& visit) {
  const int c_side = cells.cells_per_side;
  const auto side = static_cast<std::size_t>(c_side);
  const double half_length = 0.5 * length;
  const double radius2 = radius * radius;
  const auto wrap = [c_side](int k) {
    return static_cast<std::size_t>(((k % c_side) + c_side) % c_side);
  };
  int home[3] = {0, 0, 0};
  for (int d = 0; d < Dim; ++d) home[d] = cells.cell_of(point[d]);
  static const std::vector<int> kNoOffset{0};
  const std::vector<int>& z_offsets = Dim == 3 ? offsets : kNoOffset;
  for (const int oz : z_offsets)
    for (const int oy : offsets)
      for (const int ox : offsets) {
        std::size_t c = wrap(home[0] + ox) + side * wrap(home[1] + oy);
        if constexpr (Dim == 3) c += side * side * wrap(home[2] + oz);
        for (std::size_t s = cells.cell_start[c]; s < cells.cell_start[c + 1]; ++s) {
          std::array<double, 3> offset{0.0, 0.0, 0.0};
          double r2 = 0.0;
          for (int d = 0; d < Dim; ++d) {
            offset[d] =
                sim::minimum_image(cells.sorted_position[d][s] - point[d], length, half_length);
            r2 += offset[d] * offset[d];
          }
          if (r2 < radius2) visit(cells.sorted_index[s], offset, r2);
        }
      }
}

}  // namespace sphles::analysis
