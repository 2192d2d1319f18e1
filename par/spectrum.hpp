// SPDX-License-Identifier: GPL-3.0-or-later
// The kinetic-energy spectrum of SPEC §5 where the particles live (docs/scaling.md). Each rank
// grids the velocity on the nodes inside its sub-box from its own particles and a halo (nearest
// particle, as analysis::nearest_particle_map decides it for the whole set), the nodes go to the
// slabs of FFTW's MPI r2c transform (libfftw3-mpi), each rank bins its slab's modes into shells
// (analysis::ShellSums, the binning of the one-process spectrum), and the ranks' shell sums are
// added in rank order. No rank holds more than its particles, its halo, its nodes and its slab: the
// grid and the particles are never gathered.
//
// The answer equals analysis::energy_spectrum(sample_velocity(nearest_particle_map(...), ...,
// true)) of all particles to round-off (the distributed transform adds in another order; the
// tests ask for 1e-12 relative), and is the same bits on every rank.
#pragma once

#include <memory>

#include "analysis/spectrum.hpp"
#include "par/decomposition.hpp"
#include "sim/particles.hpp"

namespace sphles::par {

/// The spectrum of SPEC §5 of the particles spread over the ranks of d, on M^n nodes over the
/// box (M = points_per_side), with FFTW's plan, the node layout and the buffers kept from one
/// call to the next (a run asks for a spectrum at every analysis time; on this machine fresh
/// buffers cost more in page faults than the transform). The box must be a cube.
class DistributedSpectrum {
 public:
  /// Collective over d.comm() (FFTW plans the transform); d must outlive this object. Throws
  /// std::invalid_argument (on every rank) for a box that is not a cube, M < 2, or a grid whose
  /// velocity values on one rank would exceed MPI's int counts (2^31).
  DistributedSpectrum(const Decomposition& d, int points_per_side);
  ~DistributedSpectrum();
  DistributedSpectrum(const DistributedSpectrum&) = delete;
  DistributedSpectrum& operator=(const DistributedSpectrum&) = delete;

  /// The spectrum of the velocity of the particles that `owned` holds on the ranks (on each rank
  /// its own particles, with ids, each particle on one rank: inside that rank's sub-box or at
  /// most one sub-box away along each axis, as between two migrations), gridded by nearest
  /// particle, the spatial mean removed. Collective over d.comm(); returns the same spectrum on
  /// every rank. Throws std::invalid_argument (on every rank) when a node's nearest particle is
  /// further than d's halo width, so that a particle of another rank might be nearer (a void in
  /// the particles wider than the halo).
  analysis::EnergySpectrum compute(const sim::ParticleArrays& owned);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// DistributedSpectrum(d, points_per_side).compute(owned), for a single call.
analysis::EnergySpectrum distributed_energy_spectrum(const Decomposition& d,
                                                     const sim::ParticleArrays& owned,
                                                     int points_per_side);

}  // namespace sphles::par
