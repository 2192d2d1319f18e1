// SPDX-License-Identifier: GPL-3.0-or-later
// Conservation and rest-state properties of the discrete model (SPEC §2).
#include <gtest/gtest.h>

#include <cmath>

#include "sim/packing.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::sim {
namespace {

class MomentumTest : public ::testing::TestWithParam<std::tuple<int, KernelType>> {};

// Pair forces are antisymmetric, so Σ M v changes only by round-off: over 100 steps of a random
// flow the drift stays below 1e-12 of Σ M |v| (a sign or symmetry error gives O(1)).
TEST_P(MomentumTest, ConservedToRoundOffOver100Steps) {
  const auto [dim, kernel] = GetParam();
  auto flow = testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, 7, kernel);
  auto sim = make_simulation(flow.config, flow.particles);
  const std::array<double, 3> initial = sim->diagnostics().momentum;
  const double scale = testing::momentum_scale(sim->particles());
  for (int step = 0; step < 100; ++step) sim->step();
  ASSERT_EQ(sim->step_count(), 100u);
  for (int d = 0; d < dim; ++d)
    EXPECT_NEAR(sim->diagnostics().momentum[d], initial[d], 1e-12 * scale) << "component " << d;
  // The flow did move: the kinetic energy changed by a visible amount.
  EXPECT_GT(std::abs(sim->diagnostics().kinetic_energy - 0.5), 1e-3);
}

INSTANTIATE_TEST_SUITE_P(DimensionsAndKernels, MomentumTest,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::Values(KernelType::WendlandC4,
                                                              KernelType::QuinticSpline)),
                         [](const auto& info) {
                           return std::to_string(std::get<0>(info.param)) + "D_" +
                                  std::string(kernel_name(std::get<1>(info.param)));
                         });

class RestTest : public ::testing::TestWithParam<std::tuple<int, KernelType, double>> {};

// A uniform lattice at rest with p_ref > 0: all pair forces cancel by symmetry, so accelerations
// are round-off (relative to the size of one pressure term p_ref/(ρ H)) and stay so.
TEST_P(RestTest, UniformLatticeStaysAtRest) {
  const auto [dim, kernel, diameter_over_spacing] = GetParam();
  SolverConfig c;
  c.box.dimension = dim;
  const int per_side = dim == 3 ? 12 : 32;
  for (int d = 0; d < dim; ++d) c.box.length[d] = 2.0;
  c.kernel = kernel;
  c.particle_spacing = 2.0 / per_side;
  c.support_radius = 0.5 * diameter_over_spacing * c.particle_spacing;
  c.fluid = {.reference_density = 1.0,
             .sound_speed = 5.0,
             .reference_pressure = 6.25,
             .dynamic_viscosity = 1e-3};
  ParticleArrays p = make_lattice(c.box, per_side);
  for (double& m : p.mass) m = std::pow(c.particle_spacing, dim);
  auto sim = make_simulation(c, p);
  const double force_scale = c.fluid.reference_pressure / c.support_radius;
  for (int step = 0; step < 20; ++step) sim->step();
  const ParticleArrays& q = sim->particles();
  double max_a = 0.0, max_v = 0.0;
  for (std::size_t i = 0; i < q.size(); ++i)
    for (int d = 0; d < dim; ++d) {
      max_a = std::max(max_a, std::abs(q.acceleration[d][i]));
      max_v = std::max(max_v, std::abs(q.velocity[d][i]));
    }
  EXPECT_LT(max_a, 1e-12 * force_scale);
  EXPECT_LT(max_v, 1e-12 * force_scale * sim->time());
  // Density is uniform to round-off.
  const double rho0 = q.density[0];
  for (double rho : q.density) EXPECT_NEAR(rho, rho0, 1e-13 * rho0);
}

INSTANTIATE_TEST_SUITE_P(Lattices, RestTest,
                         ::testing::Values(std::tuple{3, KernelType::WendlandC4, 4.0},
                                           std::tuple{3, KernelType::WendlandC2, 6.0},
                                           std::tuple{3, KernelType::QuinticSpline, 6.0},
                                           std::tuple{2, KernelType::WendlandC6, 8.0},
                                           std::tuple{2, KernelType::QuinticSpline, 6.0}),
                         [](const auto& info) {
                           return std::to_string(std::get<0>(info.param)) + "D_" +
                                  std::string(kernel_name(std::get<1>(info.param))) + "_DK" +
                                  std::to_string(static_cast<int>(std::get<2>(info.param)));
                         });

// The external-acceleration hook: a uniform acceleration g on a lattice at rest gives v = g t
// (pair forces of a uniform velocity field vanish) and momentum Σ M g t.
TEST(ExternalAcceleration, UniformAccelerationGivesGT) {
  SolverConfig c;
  c.box.dimension = 3;
  for (int d = 0; d < 3; ++d) c.box.length[d] = 1.0;
  c.particle_spacing = 0.1;
  c.support_radius = 0.2;
  c.fluid = {.reference_density = 1.0,
             .sound_speed = 5.0,
             .reference_pressure = 1.0,
             .dynamic_viscosity = 1e-2};
  c.time_step.fixed = 0.01;
  const std::array<double, 3> g{0.3, -0.2, 0.1};
  c.external = [g](double, const ParticleArrays& p, const VelocityView&,
                   std::array<std::vector<double>, 3>& a) {
    for (int d = 0; d < p.dimension; ++d)
      for (double& ai : a[d]) ai += g[d];
  };
  ParticleArrays p = make_lattice(c.box, 10);
  for (double& m : p.mass) m = 1e-3;
  auto sim = make_simulation(c, p);
  for (int step = 0; step < 50; ++step) sim->step();
  EXPECT_NEAR(sim->time(), 0.5, 1e-14);
  const ParticleArrays& q = sim->particles();
  for (std::size_t i = 0; i < q.size(); ++i)
    for (int d = 0; d < 3; ++d) ASSERT_NEAR(q.velocity[d][i], g[d] * 0.5, 1e-12);
  for (int d = 0; d < 3; ++d)
    EXPECT_NEAR(sim->diagnostics().momentum[d], sim->diagnostics().total_mass * g[d] * 0.5, 1e-12);
}

TEST(Solver, NonFiniteStateStopsWithLocation) {
  auto flow = testing::random_flow(2, 16, 4.0, 0.1, 3);
  flow.particles.velocity[0][5] = std::nan("");
  try {
    auto sim = make_simulation(flow.config, flow.particles);
    sim->step();
    FAIL() << "expected SimulationError";
  } catch (const SimulationError& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite state"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("particle id"), std::string::npos);
  }
}

}  // namespace
}  // namespace sphles::sim
