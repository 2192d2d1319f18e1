// SPDX-License-Identifier: GPL-3.0-or-later
// The discrete SPH-LES model of SPEC §2: the density and force passes of the thesis model.
//
// The pair formulas are small free functions (sim/physics/fluid.hpp) used by evaluators
// (sim/physics/density.hpp, thesis_momentum.hpp) that the pair loop (sim/pair_loop.hpp) runs in
// gather form (each particle sums over its own neighbours), which makes the result independent
// of the thread count. Pair terms V_i F_ij are antisymmetric in i and j (∇W_ji = -∇W_ij exactly,
// coefficients symmetric), so linear momentum is conserved to round-off.
#pragma once

#include <cmath>
#include <cstddef>
#include <string_view>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/density.hpp"
#include "sim/physics/fluid.hpp"
#include "sim/physics/thesis_momentum.hpp"
#include "sim/physics/viscous_operator.hpp"

namespace sphles::sim {

/// Volume (A.1), density (A.2) and pressure (EOS) of every particle from a neighbour list whose
/// radius is at least the kernel support. The self term W(0) is included. With `interactions`,
/// also records the pairs inside the support for the passes that follow at these positions.
template <int Dim, class KernelT>
void density_pass(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& neighbours,
                  const FluidParameters& fluid, ParticleArrays& p,
                  InteractionList* interactions = nullptr) {
  const SummationDensity<Dim, KernelT> density(kernel, fluid, p);
  const PeriodicGeometry<Dim> geometry(box, p);
  if (interactions)
    compacting_pair_pass<Dim>(density, geometry, neighbours, kernel.support_radius(), 0,
                              neighbours.num_particles(), *interactions);
  else
    pair_pass<Dim>(density, geometry, neighbours, kernel.support_radius(), 0,
                   neighbours.num_particles());
}

/// Acceleration (F^p + F^visc)/ρ_i of (3.25) with (A.9) and (A.14), evaluated at the given
/// velocities; overwrites p.acceleration. Requires density_pass on the same positions; `pairs`
/// is the Verlet list or the InteractionList of that density pass. With non-null
/// `viscous_weights` (the g_i of viscous_correction_pass) each viscous pair is scaled by
/// pair_weight (ViscousOperator::Corrected, viscous_operator.hpp).
template <int Dim, class KernelT, class List>
void force_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                const FluidParameters& fluid, const VelocityView& velocity, ParticleArrays& p,
                const double* viscous_weights = nullptr) {
  const PeriodicGeometry<Dim> geometry(box, p);
  if (viscous_weights)
    pair_pass<Dim>(ThesisMomentum<Dim, KernelT, true>(kernel, fluid, velocity, p, viscous_weights),
                   geometry, pairs, kernel.support_radius(), 0, pairs.num_particles());
  else
    pair_pass<Dim>(ThesisMomentum<Dim, KernelT, false>(kernel, fluid, velocity, p, nullptr),
                   geometry, pairs, kernel.support_radius(), 0, pairs.num_particles());
}

}  // namespace sphles::sim
