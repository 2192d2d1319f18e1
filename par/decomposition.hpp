// SPDX-License-Identifier: GPL-3.0-or-later
// The Cartesian decomposition of the periodic box over MPI ranks (docs/scaling.md): a process grid
// periodic along every axis (MPI_Cart_create), each rank owning the particles of one sub-box.
//
// Sub-box bounds are L c / n along an axis split n ways (c = 0 .. n), computed by one expression
// on every rank, so two neighbouring ranks agree bitwise on the face they share and a particle is
// owned by exactly one rank.
#pragma once

#include <mpi.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "sim/particles.hpp"

namespace sphles::par {

/// A decomposition that cannot work: its message names the rank count, the axis and the
/// particles per side that would make it work.
class DecompositionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// This rank's place in the process grid.
class Decomposition {
 public:
  /// Splits `box` over the ranks of `comm` as evenly as the rank count allows (MPI_Dims_create:
  /// 1D, 2D or 3D splits) and checks that every sub-box is at least `halo_width` wide (support
  /// radius + Verlet skin), so that each halo comes from the nearest ranks along each axis.
  /// Collective over `comm`. Throws DecompositionError otherwise, with the particles per side
  /// (at spacing `particle_spacing`) the rank count needs.
  Decomposition(MPI_Comm comm, const sim::PeriodicBox& box, double halo_width,
                double particle_spacing);
  ~Decomposition();
  Decomposition(const Decomposition&) = delete;
  Decomposition& operator=(const Decomposition&) = delete;

  /// The grid's communicator (ranks as in the communicator it was made from).
  MPI_Comm comm() const { return comm_; }
  int rank() const { return rank_; }
  int size() const { return size_; }
  int dimension() const { return box_.dimension; }
  const sim::PeriodicBox& box() const { return box_; }
  double halo_width() const { return halo_width_; }
  /// Ranks along each axis (1 beyond the dimension) and this rank's coordinates.
  const std::array<int, 3>& dims() const { return dims_; }
  const std::array<int, 3>& coords() const { return coords_; }
  /// The rank next to this one along `axis`, below (direction -1) or above (+1), periodic.
  int neighbour(int axis, int direction) const {
    return direction < 0 ? lower_rank_[static_cast<std::size_t>(axis)]
                         : upper_rank_[static_cast<std::size_t>(axis)];
  }
  /// Bound c of the slabs along `axis`: L c / n (c = 0 .. n).
  double bound(int axis, int c) const;
  /// This rank's sub-box [lower, upper) along `axis`.
  double lower(int axis) const { return bound(axis, coords_[static_cast<std::size_t>(axis)]); }
  double upper(int axis) const { return bound(axis, coords_[static_cast<std::size_t>(axis)] + 1); }
  /// The grid coordinate c along `axis` with bound(c) <= x < bound(c + 1), for x in [0, L).
  int coordinate_of(int axis, double x) const;
  /// Whether the position of particle i lies in this rank's sub-box.
  bool owns(const sim::ParticleArrays& p, std::size_t i) const;

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0;
  int size_ = 1;
  sim::PeriodicBox box_;
  double halo_width_ = 0.0;
  std::array<int, 3> dims_{1, 1, 1};
  std::array<int, 3> coords_{0, 0, 0};
  std::array<int, 3> lower_rank_{0, 0, 0};
  std::array<int, 3> upper_rank_{0, 0, 0};
};

}  // namespace sphles::par
