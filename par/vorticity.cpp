#include "par/vorticity.hpp"

#include <mpi.h>

#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/products.hpp"
#include "analysis/vorticity.hpp"
#include "par/halo.hpp"
#include "par/reduce.hpp"

namespace sphles::par {

analysis::RanksVorticity distributed_fitted_vorticity(const Decomposition& d,
                                                      const sim::ParticleArrays& owned,
                                                      sim::KernelType kernel,
                                                      const analysis::VorticityRequest& request) {
  const int dim = d.dimension();
  const sim::PeriodicBox& box = d.box();
  for (int a = 1; a < dim; ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0])
      throw std::invalid_argument("distributed vorticity: the box must be a cube");
  if (request.points_per_side < 1 || !(request.fit_radius > 0.0) ||
      2.0 * request.fit_radius > box.length[0])
    throw std::invalid_argument(
        "distributed vorticity: needs points_per_side >= 1 and a fit radius in (0, L/2]");
  bool alone = true;
  for (int a = 0; a < dim; ++a) alone = alone && d.dims()[static_cast<std::size_t>(a)] == 1;
  if (!alone && request.fit_radius > d.halo_width())
    throw std::invalid_argument(
        "distributed vorticity: the fits' radius " + std::to_string(request.fit_radius) +
        " m reaches further than the halo (" + std::to_string(d.halo_width()) + " m)");
  analysis::Grid grid;
  grid.dimension = dim;
  grid.points_per_side = request.points_per_side;
  grid.length = box.length[0];
  const analysis::FitSettings fit{kernel, request.fit_radius};

  // This rank's particles (those that left its sub-box since the last migration moved to their
  // owners), then the halo around its sub-box at their own positions in [0, L).
  sim::ParticleArrays local = owned;
  migrate(d, local);
  const Halo halo = Halo::build(d, local, HaloPositions::Wrapped);
  const std::size_t mine = halo.owned();

  // ω at the own particles, and the exact sums of V ω² and V over them.
  analysis::ParticleVorticity omega;
  omega.dimension = dim;
  if (mine > 0) omega = analysis::fitted_particle_vorticity(local, grid, fit, mine);
  std::array<sim::ExactSum, 2> sums = analysis::volume_weighted_sums(
      local, mine > 0 ? omega.squared_magnitude() : std::vector<double>{});
  allreduce(d, std::span<sim::ExactSum>(sums));
  analysis::RanksVorticity result;
  result.request = request;
  result.mean_vorticity_squared = sums[0].value() / sums[1].value();
  if (!request.slice) return result;

  // ω of the halo from its owners, then ω² at the slice nodes inside this rank's sub-box.
  std::vector<std::vector<double>*> fields;
  for (std::vector<double>& c : omega.component)
    if (dim == 3 || &c == &omega.component[2]) {
      c.resize(local.size());
      fields.push_back(&c);
    }
  halo.update(d, fields);
  analysis::SliceConfig slice;
  slice.axis = request.slice_axis;
  slice.position = request.slice_position;
  const std::vector<std::size_t> nodes = analysis::slice_nodes(grid, slice);
  std::array<int, 3> first{0, 0, 0}, count{1, 1, 1};
  for (int a = 0; a < dim; ++a) {
    const auto k = static_cast<std::size_t>(a);
    own_nodes(d, a, grid.points_per_side, grid.spacing(), first[k], count[k]);
  }
  const auto m = static_cast<std::size_t>(grid.points_per_side);
  const auto inside = [&](std::size_t node) {
    const std::array<std::size_t, 3> at{node % m, (node / m) % m, node / (m * m)};
    for (int a = 0; a < dim; ++a) {
      const auto k = static_cast<std::size_t>(a);
      const auto i = static_cast<int>(at[k]);
      if (i < first[k] || i >= first[k] + count[k]) return false;
    }
    return true;
  };
  std::vector<int> where;  // positions in the slice of this rank's nodes
  std::vector<std::size_t> my_nodes;
  for (std::size_t k = 0; k < nodes.size(); ++k)
    if (inside(nodes[k])) {
      where.push_back(static_cast<int>(k));
      my_nodes.push_back(nodes[k]);
    }
  int fits = my_nodes.empty() || local.size() > 0 ? 1 : 0, every = 0;
  MPI_Allreduce(&fits, &every, 1, MPI_INT, MPI_MIN, d.comm());
  if (every == 0)
    throw std::invalid_argument(
        "distributed vorticity: a rank has slice nodes but no particle near them");
  std::vector<double> values;
  if (!my_nodes.empty())
    values = analysis::fitted_vorticity_squared(grid, local, fit, omega, my_nodes);

  // Rank 0 places every rank's values at their positions.
  const int sent = static_cast<int>(where.size());
  std::vector<int> counts(static_cast<std::size_t>(d.size())), offsets(counts.size(), 0);
  MPI_Gather(&sent, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, d.comm());
  for (std::size_t r = 1; r < counts.size(); ++r) offsets[r] = offsets[r - 1] + counts[r - 1];
  const bool root = d.rank() == 0;
  std::vector<int> all_where(root ? nodes.size() : 0);
  std::vector<double> all_values(root ? nodes.size() : 0);
  MPI_Gatherv(where.data(), sent, MPI_INT, all_where.data(), counts.data(), offsets.data(), MPI_INT,
              0, d.comm());
  MPI_Gatherv(values.data(), sent, MPI_DOUBLE, all_values.data(), counts.data(), offsets.data(),
              MPI_DOUBLE, 0, d.comm());
  if (root) {
    result.slice.resize(nodes.size());
    for (std::size_t k = 0; k < nodes.size(); ++k)
      result.slice[static_cast<std::size_t>(all_where[k])] = all_values[k];
  }
  return result;
}

}  // namespace sphles::par
