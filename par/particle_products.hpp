// SPDX-License-Identifier: GPL-3.0-or-later
// The analysis' particle products where the particles live, so that no rank gathers them all:
// the "mls" vorticity (analysis/vorticity.hpp, local_fit.hpp), τ_SFS (3.27) and the chapter-4
// statistics, and the ω² and |τ_SFS| slices. Each rank computes them for its own particles
// from them and a halo (refreshed with ω and |τ_SFS| where a slice node needs a halo
// particle's), and for the slice nodes inside its sub-box; the ranks add Σ V ω², Σ V and
// Σ |τ_SFS| exactly, take the maxima, add the histograms' counts, and rank 0 collects the
// slices. The particle snapshot (product "particles") is written by every rank into one file,
// each its equal block of the particles in id order with their ω² and |τ_SFS|. No rank holds
// more than its particles, its halo and its slice nodes (and its block, while writing).
//
// The answer is the same bits as analyse computes from all particles in one process: a fit and
// a τ_SFS sum visit their particles in an order set by positions and ids alone
// (analysis/cell_list.hpp, analysis/subfilter_stress.hpp), the halo holds every particle they
// see, at its own position, and a slice node's nearest particle is the whole set's.
#pragma once

#include "analysis/snapshot.hpp"
#include "par/decomposition.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::par {

/// The particle products of `request` over the particles `owned` holds on the ranks (on each
/// rank its own particles with velocities, masses, volumes and ids, each inside its rank's
/// sub-box or at most one sub-box away, as between two migrations), for the run's kernel
/// (`kernel`, support H): ⟨ω²⟩ and the statistics on every rank, the slices on rank 0 (empty on
/// the others); with request.particles.path, the particle snapshot written there (last, after
/// every refusal below; io::write_particle_snapshot_collective, whose CheckpointError it throws
/// on every rank alike). Collective over d.comm(). Throws std::invalid_argument on every rank when
/// the box is not a cube, the fits reach further than the halo (request.fit_radius > d.halo_width()
/// with more than one rank along an axis), or a slice node's nearest particle lies further than the
/// halo width (a void wider than the halo).
analysis::RanksProducts distributed_particle_products(const Decomposition& d,
                                                      const sim::ParticleArrays& owned,
                                                      sim::KernelType kernel, double support_radius,
                                                      const analysis::RanksRequest& request);

}  // namespace sphles::par
