// SPDX-License-Identifier: GPL-3.0-or-later
// Shared set-up for solver tests: small random flows on perturbed lattices.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <vector>

#include "sim/packing.hpp"
#include "sim/solver.hpp"

namespace sphles::sim::testing {

/// The packing cache shared by the validation tests (packed arrangements are reused between
/// tests and runs of the suite).
inline SetupOptions validation_packing_cache() {
  return {.packing_cache_dir =
              std::filesystem::temp_directory_path() / "sphles_validation_packing"};
}

/// Σ M |v|: the scale of the momentum-conservation bounds.
inline double momentum_scale(const ParticleArrays& p) {
  double s = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    double v2 = 0.0;
    for (int d = 0; d < p.dimension; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
    s += p.mass[i] * std::sqrt(v2);
  }
  return s;
}

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

struct RotatingCluster {
  SolverConfig config;
  ParticleArrays particles;
  double scale = 0.0;  // Σ M R² with R = 1.5 m: the size of Σ M x × v for the test bounds
};

/// The periodic-safe setting of angular-momentum tests: a disc (ball) of lattice particles of
/// radius 0.5 m in the middle of a box of side 3 m, spinning rigidly with random noise on top,
/// so that it never meets its periodic images. p_ref = 0, fixed step 1e-3 s.
inline RotatingCluster rotating_cluster(int dim) {
  RotatingCluster cluster;
  SolverConfig& c = cluster.config;
  c.box.dimension = dim;
  for (int d = 0; d < dim; ++d) c.box.length[d] = 3.0;
  c.particle_spacing = dim == 3 ? 0.1 : 0.05;
  c.support_radius = 2.0 * c.particle_spacing;
  c.fluid = {.reference_density = 1.0,
             .sound_speed = 5.0,
             .reference_pressure = 0.0,
             .dynamic_viscosity = 1e-3};
  c.time_step.fixed = 1e-3;
  ParticleArrays lattice =
      make_lattice(c.box, static_cast<int>(std::lround(3.0 / c.particle_spacing)));
  ParticleArrays& p = cluster.particles;
  p.dimension = dim;
  std::vector<std::size_t> keep;
  for (std::size_t i = 0; i < lattice.size(); ++i) {
    double r2 = 0.0;
    for (int d = 0; d < dim; ++d) r2 += std::pow(lattice.position[d][i] - 1.5, 2);
    if (r2 < 0.5 * 0.5) keep.push_back(i);
  }
  p.resize(keep.size());
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t k = 0; k < keep.size(); ++k) {
    for (int d = 0; d < dim; ++d) {
      p.position[d][k] = lattice.position[d][keep[k]];
      p.velocity[d][k] = 0.5 * u(rng);
    }
    p.velocity[0][k] += -(p.position[1][k] - 1.5);  // a rigid spin on top of the noise
    p.velocity[1][k] += (p.position[0][k] - 1.5);
    p.mass[k] = std::pow(c.particle_spacing, dim);
    cluster.scale += p.mass[k] * 1.5 * 1.5;
  }
  return cluster;
}

/// Σ M x × v (z component in 2D).
inline std::array<double, 3> angular_momentum(const ParticleArrays& p) {
  std::array<double, 3> l{0, 0, 0};
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double x = p.position[0][i], y = p.position[1][i];
    const double z = p.dimension == 3 ? p.position[2][i] : 0.0;
    const double vx = p.velocity[0][i], vy = p.velocity[1][i];
    const double vz = p.dimension == 3 ? p.velocity[2][i] : 0.0;
    l[0] += p.mass[i] * (y * vz - z * vy);
    l[1] += p.mass[i] * (z * vx - x * vz);
    l[2] += p.mass[i] * (x * vy - y * vx);
  }
  return l;
}

/// Equal bit for bit (NaN payloads and signed zeros included), which == is not.
inline bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

/// Restoring from state() continues bitwise identically: a run of 23 + 40 steps from `initial`
/// against one restored after 23 steps and run 40 more, with neighbour-list rebuilds on both
/// sides of the restart.
inline void expect_restore_continues_bitwise(const SolverConfig& config,
                                             const ParticleArrays& initial) {
  const int dim = config.box.dimension;
  auto uninterrupted = make_simulation(config, initial);
  auto first_leg = make_simulation(config, initial);
  for (int k = 0; k < 23; ++k) first_leg->step();
  auto second_leg = restore_simulation(first_leg->config(), first_leg->state());
  for (int k = 0; k < 23 + 40; ++k) uninterrupted->step();
  for (int k = 0; k < 40; ++k) second_leg->step();
  EXPECT_GT(uninterrupted->diagnostics().neighbour_builds, 2u);
  EXPECT_EQ(second_leg->time(), uninterrupted->time());
  const ParticleArrays& a = second_leg->particles();
  const ParticleArrays& b = uninterrupted->particles();
  EXPECT_EQ(a.id, b.id);
  for (int d = 0; d < dim; ++d) {
    EXPECT_TRUE(same_bits(a.position[d], b.position[d])) << dim << "D position " << d;
    EXPECT_TRUE(same_bits(a.velocity[d], b.velocity[d])) << dim << "D velocity " << d;
    EXPECT_TRUE(same_bits(a.acceleration[d], b.acceleration[d])) << dim << "D acceleration";
  }
  EXPECT_TRUE(same_bits(a.density, b.density));
}

}  // namespace sphles::sim::testing
