// The "mls" vorticity products of the analysis (analysis/vorticity.hpp, local_fit.hpp) where the
// particles live (issue 19: distributed analysis). Each rank fits ω at its own particles from
// them and their halo, refreshes its halo's ω, and fits ω² at the slice's nodes inside its
// sub-box; the ranks add Σ V ω² and Σ V exactly, and rank 0 collects the slice. No rank holds
// more than its particles, its halo and its slice nodes.
//
// The answer is the same bits as analyse computes from all particles in one process: a fit
// visits the particles within its radius in cell and id order (analysis/cell_list.hpp), and
// the halo holds every particle within the radius of a rank's particles and nodes.
#pragma once

#include "analysis/snapshot.hpp"
#include "par/decomposition.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::par {

/// ⟨ω²⟩ = Σ V ω² / Σ V of the "mls" estimate over the particles `owned` holds on the ranks (on
/// each rank its own particles with volumes and ids, each inside its rank's sub-box or at most
/// one sub-box away, as between two migrations), with the fits' weight `kernel`, and, when the
/// request asks for it, ω² at the slice's nodes (analysis::slice_nodes order) on rank 0 (empty
/// on the others). Collective over d.comm(). Throws std::invalid_argument on every rank when the
/// box is not a cube or the fits reach further than the halo (request.fit_radius >
/// d.halo_width() with more than one rank along an axis).
analysis::RanksVorticity distributed_fitted_vorticity(const Decomposition& d,
                                                      const sim::ParticleArrays& owned,
                                                      sim::KernelType kernel,
                                                      const analysis::VorticityRequest& request);

}  // namespace sphles::par
