// Shared set-up for solver tests: small random flows on perturbed lattices.
#pragma once

#include <cmath>
#include <random>

#include "sim/packing.hpp"
#include "sim/solver.hpp"

namespace sphles::sim::testing {

struct RandomFlow {
  SolverConfig config;
  ParticleArrays particles;
};

/// A perturbed lattice of per_side^dim particles in a periodic box of side 1 m with random
/// velocities of amplitude `speed` (zero mean not enforced) and random masses around ρ = 1.
inline RandomFlow random_flow(int dim, int per_side, double diameter_over_spacing, double speed,
                              std::uint64_t seed, KernelType kernel = KernelType::WendlandC4) {
  RandomFlow flow;
  SolverConfig& c = flow.config;
  c.box.dimension = dim;
  for (int d = 0; d < dim; ++d) c.box.length[d] = 1.0;
  c.kernel = kernel;
  c.particle_spacing = 1.0 / per_side;
  c.support_radius = 0.5 * diameter_over_spacing * c.particle_spacing;
  c.fluid = {.reference_density = 1.0,
             .sound_speed = 10.0,
             .reference_pressure = 20.0,
             .dynamic_viscosity = 1e-3};
  flow.particles = make_lattice(c.box, per_side);
  ParticleArrays& p = flow.particles;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const double cell_volume = std::pow(c.particle_spacing, dim);
  for (std::size_t i = 0; i < p.size(); ++i) {
    for (int d = 0; d < dim; ++d) {
      p.position[d][i] = wrap_periodic(p.position[d][i] + 0.2 * c.particle_spacing * uniform(rng),
                                       c.box.length[d]);
      p.velocity[d][i] = speed * uniform(rng);
    }
    p.mass[i] = cell_volume * (1.0 + 0.05 * uniform(rng));
  }
  return flow;
}

}  // namespace sphles::sim::testing
