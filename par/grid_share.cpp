// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/grid_share.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "par/reduce.hpp"

namespace sphles::par {

analysis::NodeBlock own_block(const Decomposition& d, const analysis::Grid& grid) {
  analysis::NodeBlock block;
  const int m = grid.points_per_side;
  for (int a = 0; a < grid.dimension; ++a) {
    const auto k = static_cast<std::size_t>(a);
    const int mine = d.coords()[k];
    int& first = block.first[k];
    int& count = block.count[k];
    first = m;
    count = 0;
    for (int i = 0; i < m; ++i)
      if (d.coordinate_of(a, i * grid.spacing()) == mine) {
        first = std::min(first, i);
        ++count;
      }
    if (count == 0) first = 0;
  }
  return block;
}

analysis::NearestInBlock nearest_within_halo(const Decomposition& d, const analysis::Grid& grid,
                                             const sim::ParticleArrays& local,
                                             const analysis::NodeBlock& block, std::uint64_t total,
                                             const std::string& who, bool nearest) {
  analysis::NearestInBlock found;
  bool covered = block.size() == 0 || local.size() > 0;
  if (nearest && covered && block.size() > 0) {
    const double per_side = std::pow(static_cast<double>(total), 1.0 / d.dimension());
    found = analysis::nearest_particles_in_block(grid, local, block,
                                                 static_cast<int>(std::lround(per_side)));
    // A particle left out of `local` is at least the halo width from every node of the
    // sub-box; along an axis this rank is alone on, none is left out. The margin covers the
    // ties' window.
    bool alone = true;
    for (int a = 0; a < d.dimension(); ++a)
      alone = alone && d.dims()[static_cast<std::size_t>(a)] == 1;
    covered = alone || found.max_distance2 * (1.0 + 1e-9) < d.halo_width() * d.halo_width();
  }
  if (!on_every_rank(d, covered))
    throw std::invalid_argument(who +
                                ": a grid node's nearest particle may lie on another rank, "
                                "further than the halo width (" +
                                std::to_string(d.halo_width()) +
                                " m): the particles leave a void wider than the halo");
  return found;
}

}  // namespace sphles::par
