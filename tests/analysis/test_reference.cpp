// SPDX-License-Identifier: GPL-3.0-or-later
// Reference curves (analysis/reference.hpp): the analytic 2D Taylor-Green decay and the DNS of
// the 3D Taylor-Green vortex at Re = 5000 shipped in data/reference/.
#include <gtest/gtest.h>

#include <algorithm>

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "analysis/reference.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"

namespace sphles::analysis {
namespace {

const std::filesystem::path kReferenceDir = SPHLES_SOURCE_DIR "/data/reference";

TEST(Reference, TaylorGreen2dIsTheAnalyticDecay) {
  sim::Scene scene = scene::parse_scene({{"case", "tgv2d"}, {"time", {{"end", 2.0}}}});
  const double nu = scene.fluid.kinematic_viscosity();
  EXPECT_FALSE(missing_reference(scene));
  const ReferenceCurve c = reference_curve(scene, kReferenceDir, 5);
  ASSERT_EQ(c.time.size(), 5u);
  EXPECT_EQ(c.time.front(), 0.0);
  EXPECT_EQ(c.time.back(), 2.0);
  for (std::size_t k = 0; k < c.time.size(); ++k) {
    // e_v = v0²/4 exp(-4νt), -de_v/dt = 4ν e_v (SPEC §6.2), v0 = 1.
    EXPECT_NEAR(c.energy[k], 0.25 * std::exp(-4.0 * nu * c.time[k]), 1e-15);
    EXPECT_NEAR(c.dissipation[k], 4.0 * nu * c.energy[k], 1e-15);
  }
  // A uniform velocity U adds ½|U|² to e_v and nothing to the dissipation.
  scene.uniform_velocity = {3.0, 4.0, 0.0};
  const ReferenceCurve moving = reference_curve(scene, kReferenceDir, 5);
  EXPECT_NEAR(moving.energy[2], c.energy[2] + 12.5, 1e-13);
  EXPECT_EQ(moving.dissipation[2], c.dissipation[2]);
}

TEST(Reference, TaylorGreen3dAtRe5000IsTheDnsUpToTheEndTime) {
  const sim::Scene scene = scene::parse_scene(
      {{"case", "tgv3d"}, {"fluid", {{"dynamic_viscosity", 2e-4}}}, {"time", {{"end", 10.0}}}});
  EXPECT_FALSE(missing_reference(scene));
  const ReferenceCurve c = reference_curve(scene, kReferenceDir);
  ASSERT_EQ(c.time.size(), 501u);  // t = 0, 0.02, ..., 10
  EXPECT_EQ(c.energy.front(), 0.125);
  EXPECT_NEAR(c.time.back(), 10.0, 1e-12);
  // data/reference/README.md: peak -dE/dt = 0.0155441 at t = 8.74.
  std::size_t peak = 0;
  for (std::size_t k = 0; k < c.time.size(); ++k)
    if (c.dissipation[k] > c.dissipation[peak]) peak = k;
  EXPECT_NEAR(c.time[peak], 8.74, 1e-9);
  EXPECT_NEAR(c.dissipation[peak], 0.0155441, 1e-7);
}

TEST(Reference, TaylorGreen3dAtRe1600IsTheWorkshopsSpectralDns) {
  const sim::Scene scene = scene::parse_scene({{"case", "tgv3d"},
                                               {"fluid", {{"dynamic_viscosity", 1.0 / 1600.0}}},
                                               {"time", {{"end", 20.0}}}});
  EXPECT_FALSE(missing_reference(scene));
  const ReferenceCurve c = reference_curve(scene, kReferenceDir);
  EXPECT_EQ(c.label, "DNS, Re = 1600");
  ASSERT_EQ(c.time.size(), 2000u);  // t = 0, 0.01, ..., 19.99 (CRLF lines)
  EXPECT_EQ(c.energy.front(), 0.125);
  // data/reference/README.md: peak -dE/dt = 0.012857528 at t = 8.97.
  const auto peak = std::max_element(c.dissipation.begin(), c.dissipation.end());
  EXPECT_NEAR(c.time[peak - c.dissipation.begin()], 8.97, 1e-9);
  EXPECT_NEAR(*peak, 0.012857528, 1e-9);
}

TEST(Reference, KolmogorovIsTheLaminarSpinUpFromRest) {
  sim::Scene scene = scene::parse_scene({{"preset", "kolmogorov2d"}, {"time", {{"end", 4.0}}}});
  EXPECT_FALSE(missing_reference(scene));
  const ReferenceCurve c = reference_curve(scene, kReferenceDir, 4001);
  const double nu = scene.fluid.kinematic_viscosity(), k = scene.forcing_wavenumber();
  const double lambda = nu * k * k + scene.forcing.friction;
  // The laminar steady state of SPEC §6.3: e_v → ¼ (χ/λ)², the mean of ½ v_x² of the profile
  // sim::kolmogorov_laminar_velocity, approached as (1 - e^{-λt})².
  const double peak =
      sim::kolmogorov_laminar_velocity(scene.forcing, k, nu, std::numbers::pi / (2.0 * k));
  EXPECT_EQ(c.energy.front(), 0.0);
  EXPECT_NEAR(c.energy.back(), 0.25 * peak * peak * std::pow(1.0 - std::exp(-lambda * 4.0), 2),
              1e-15);
  // -de_v/dt is the derivative of the energy curve (central differences over dt = 1e-3 s:
  // relative error below (λ dt)²/6 + λ dt²/(2t) < 1.3e-4 from t = 0.01 on).
  for (std::size_t i = 10; i + 1 < c.time.size(); i += 250) {
    const double slope = (c.energy[i + 1] - c.energy[i - 1]) / (c.time[i + 1] - c.time[i - 1]);
    EXPECT_NEAR(c.dissipation[i], -slope, 2e-4 * std::abs(slope)) << c.time[i];
  }
  // A uniform drift along x decays by the friction: ½ U² e^{-2μt} more energy.
  scene.uniform_velocity = {0.2, 0.0, 0.0};
  const ReferenceCurve drifting = reference_curve(scene, kReferenceDir, 4001);
  EXPECT_NEAR(drifting.energy[1000] - c.energy[1000],
              0.5 * 0.04 * std::exp(-2.0 * scene.forcing.friction * c.time[1000]), 1e-15);
}

TEST(Reference, OtherRunsHaveNoneAndSayWhy) {
  const sim::Scene re10000 = scene::parse_scene({{"case", "tgv3d"}});  // ν = 1e-4, the thesis' Re
  const auto why = missing_reference(re10000);
  ASSERT_TRUE(why);
  EXPECT_NE(why->find("Re = 5000"), std::string::npos) << *why;
  EXPECT_NE(why->find("0.0001"), std::string::npos) << *why;
  EXPECT_THROW(reference_curve(re10000, kReferenceDir), std::invalid_argument);
  const sim::Scene sideways = scene::parse_scene(
      {{"preset", "kolmogorov2d"}, {"flow", {{"uniform_velocity", {0.0, 0.1}}}}});
  ASSERT_TRUE(missing_reference(sideways));
  EXPECT_NE(missing_reference(sideways)->find("y component"), std::string::npos);
  // A missing file is an error naming it.
  const sim::Scene dns =
      scene::parse_scene({{"case", "tgv3d"}, {"fluid", {{"dynamic_viscosity", 2e-4}}}});
  try {
    reference_curve(dns, "/nonexistent");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/" + std::string(kTgv3dDnsFile)),
              std::string::npos);
  }
}

}  // namespace
}  // namespace sphles::analysis
