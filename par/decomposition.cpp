// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/decomposition.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "sim/process_grid.hpp"

namespace sphles::par {

Decomposition::Decomposition(MPI_Comm comm, const sim::PeriodicBox& box, double halo_width,
                             double particle_spacing)
    : box_(box), halo_width_(halo_width) {
  const int dim = box.dimension;
  if (dim < 2 || dim > 3) throw DecompositionError("decomposition: dimension must be 2 or 3");
  if (!(halo_width > 0.0) || !(particle_spacing > 0.0))
    throw DecompositionError("decomposition: halo width and particle spacing must be > 0");
  int size = 1;
  MPI_Comm_size(comm, &size);
  // The split estimates see too (sim::process_grid; MPI_Dims_create's, test_par.cpp).
  dims_ = sim::process_grid(size, dim);
  int dims[3] = {dims_[0], dims_[1], dims_[2]};

  // Every rank checks the same numbers, so every rank throws the same error (no rank is left
  // waiting in a collective call).
  if (const std::string refusal =
          sim::split_refusal(size, dim, box.length, halo_width, particle_spacing);
      !refusal.empty())
    throw DecompositionError("decomposition: " + refusal);

  int periods[3] = {1, 1, 1};
  MPI_Cart_create(comm, dim, dims, periods, /*reorder=*/0, &comm_);
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
  int coords[3] = {0, 0, 0};
  MPI_Cart_coords(comm_, rank_, dim, coords);
  for (int a = 0; a < dim; ++a) {
    const auto k = static_cast<std::size_t>(a);
    coords_[k] = coords[a];
    MPI_Cart_shift(comm_, a, 1, &lower_rank_[k], &upper_rank_[k]);
  }
  for (int a = dim; a < 3; ++a) {
    lower_rank_[static_cast<std::size_t>(a)] = rank_;
    upper_rank_[static_cast<std::size_t>(a)] = rank_;
  }
}

Decomposition::~Decomposition() {
  if (comm_ != MPI_COMM_NULL) MPI_Comm_free(&comm_);
}

double Decomposition::bound(int axis, int c) const {
  const auto k = static_cast<std::size_t>(axis);
  if (c >= dims_[k]) return box_.length[k];  // exactly L: the last slab ends at the box' end
  return box_.length[k] * c / dims_[k];
}

int Decomposition::coordinate_of(int axis, double x) const {
  const auto k = static_cast<std::size_t>(axis);
  const int n = dims_[k];
  int c = static_cast<int>(std::floor(x / box_.length[k] * n));
  c = c < 0 ? 0 : (c >= n ? n - 1 : c);
  // The estimate may be one off where x is within round-off of a bound: the bounds decide.
  while (c > 0 && x < bound(axis, c)) --c;
  while (c + 1 < n && x >= bound(axis, c + 1)) ++c;
  return c;
}

bool Decomposition::owns(const sim::ParticleArrays& p, std::size_t i) const {
  for (int a = 0; a < box_.dimension; ++a) {
    const double x = p.position[static_cast<std::size_t>(a)][i];
    if (x < lower(a) || x >= upper(a)) return false;
  }
  return true;
}

}  // namespace sphles::par
