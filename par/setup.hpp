// SPDX-License-Identifier: GPL-3.0-or-later
// A new run's particles made where they will live: no rank holds more than its share while the
// initial state is made, packed and set up, as a run of 512³ particles needs.
#pragma once

#include "par/decomposition.hpp"
#include "sim/packing.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::par {

/// This rank's particles of a new run of `scene`: the lattice points of its sub-box (their ids
/// the lattice indices), relaxed together with the other ranks' (sim::relax_particles over an
/// MpiExchange of `d`, whose halo must be at least sim::packing_list_radius wide), or its block
/// of the packing cache when that holds the scene's packing; then each particle on the rank
/// whose sub-box holds it, with the case's fields and masses (sim::set_case_fields). Bitwise the
/// particles sim::setup_run makes in one process, split by position. A packing made here is
/// cached by every rank writing its block of the file (MPI-IO); a cache that cannot be written
/// is skipped, as in one process. `report` is the same on every rank. `options.cancelled` is
/// polled on the ranks that have one. Collective over d.comm().
sim::ParticleArrays set_up_share(const Decomposition& d, const sim::Scene& scene,
                                 const sim::SolverConfig& config, const sim::SetupOptions& options,
                                 sim::PackingReport& report);

}  // namespace sphles::par
