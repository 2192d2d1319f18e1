// SPDX-License-Identifier: GPL-3.0-or-later
// Validation against analytic and reference behaviour (SPEC §6.1, §6.2).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "scene/document.hpp"
#include "scene_test_support.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::sim {

using scene::parse_scene;
namespace {

/// Runs a 2D Taylor-Green vortex at Re = 100 to t = 2 and returns the largest relative error of
/// e_v(t) against e_v(0) exp(-4νt) (SPEC §6.2) over all steps.
double taylor_green_2d_error(int per_side, double diameter_over_spacing) {
  const Scene scene =
      parse_scene(testing::taylor_green_2d_scene(per_side, diameter_over_spacing, 2.0));
  RunSetup setup = setup_run(scene, testing::validation_packing_cache());
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  const double nu = scene.fluid.kinematic_viscosity();
  const double e0 = sim->diagnostics().kinetic_energy;
  EXPECT_NEAR(e0, 0.25, 0.25 * 1e-3);
  double max_error = 0.0;
  while (sim->time() < scene.end_time - 1e-12) {
    sim->step(scene.end_time - sim->time());
    const double exact = e0 * std::exp(-4.0 * nu * sim->time());
    max_error = std::max(max_error, std::abs(sim->diagnostics().kinetic_energy / exact - 1.0));
  }
  return max_error;
}

// Re = 100: e_v(t) within 2 % of the analytic decay up to t = 2 at N = 128², D_K = 12 Δl, and
// the error falls as N grows at fixed D_K/Δl. The observed order is printed and recorded.
TEST(TaylorGreen2D, EnergyDecayMatchesAnalyticAndConverges) {
  const std::array<int, 3> resolutions{64, 96, 128};
  std::array<double, 3> errors{};
  for (std::size_t k = 0; k < resolutions.size(); ++k) {
    errors[k] = taylor_green_2d_error(resolutions[k], 12.0);
    std::printf("tgv2d Re=100 N=%d^2 D_K=12dl: max |e_v/e_exact - 1| over t<=2 = %.4f\n",
                resolutions[k], errors[k]);
  }
  for (std::size_t k = 1; k < resolutions.size(); ++k) {
    EXPECT_LT(errors[k], errors[k - 1]) << "error must fall when N rises";
    const double order = std::log(errors[k - 1] / errors[k]) /
                         std::log(static_cast<double>(resolutions[k]) / resolutions[k - 1]);
    std::printf("observed order between N=%d and N=%d: %.2f\n", resolutions[k - 1], resolutions[k],
                order);
    ::testing::Test::RecordProperty("order_" + std::to_string(resolutions[k]),
                                    std::to_string(order));
  }
  EXPECT_LT(errors.back(), 0.02);
}

// 3D Taylor-Green at 20³ (WC4, D_K = 8Δl, SPEC §6.1 parameters): e_v(0) = 0.125 within 1 % and
// e_v decays monotonically to t = 1.
TEST(TaylorGreen3D, InitialEnergyAndMonotoneDecay) {
  const nlohmann::json doc = {
      {"case", "tgv3d"}, {"particles_per_side", 20}, {"time", {{"end", 1.0}}}};
  const Scene scene = parse_scene(doc);
  RunSetup setup = setup_run(scene, testing::validation_packing_cache());
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  EXPECT_NEAR(sim->diagnostics().kinetic_energy, 0.125, 0.125 * 0.01);
  double previous = sim->diagnostics().kinetic_energy;
  int steps = 0;
  while (sim->time() < 1.0 - 1e-12) {
    sim->step(1.0 - sim->time());
    const double e = sim->diagnostics().kinetic_energy;
    ASSERT_LE(e, previous) << "e_v increased at t = " << sim->time();
    previous = e;
    ++steps;
  }
  EXPECT_GT(steps, 10);
  // At 20³ (N_ngb ≈ 250 but D_K = 2.5 m) the laminar phase already dissipates strongly (SPEC §7,
  // finding 1; the DNS keeps 99.8 % of e_v to t = 1); guard only against a collapse.
  EXPECT_GT(previous, 0.8 * 0.125);
  std::printf("tgv3d 20^3: e_v(1) = %.6f after %d steps\n", previous, steps);
}

}  // namespace
}  // namespace sphles::sim
