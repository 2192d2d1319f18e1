// SPDX-License-Identifier: GPL-3.0-or-later
// Explicit sub-filter models (SPEC §4), the Kolmogorov flow (§6.3) and the presets (Table 5.1).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene/presets.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/packing.hpp"
#include "sim/physics/subfilter_stress.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/subfilter.hpp"
#include "test_support.hpp"

namespace sphles::sim {

using scene::parse_scene;
using scene::preset_names;
using scene::scene_to_json;
namespace {

using nlohmann::json;

VelocityGradient gradient_of(std::initializer_list<std::initializer_list<double>> rows) {
  VelocityGradient g{};
  int a = 0;
  for (const auto& row : rows) {
    int b = 0;
    for (const double v : row) g[a][b++] = v;
    ++a;
  }
  return g;
}

// --- pointwise eddy viscosities ----------------------------------------------------------

TEST(EddyViscosity, SmagorinskyOfLinearShearIsCsDeltaSquaredTimesShearRate) {
  // v = (γ y, 0, 0): D_xy = D_yx = γ/2, 2 D:D = γ², so ν_t = (C_S Δ)² |γ| (A.21).
  for (const double gamma : {0.5, -3.0, 40.0}) {
    const VelocityGradient j = gradient_of({{0, gamma, 0}, {0, 0, 0}, {0, 0, 0}});
    SubfilterConfig c;
    c.model = SubfilterModel::Smagorinsky;
    const double delta = 0.2;
    EXPECT_NEAR(eddy_viscosity(c, delta, j), std::pow(0.15 * delta, 2) * std::abs(gamma),
                1e-15 * std::abs(gamma));
    c.filter_width = 0.05;  // an explicit Δ replaces D_K
    EXPECT_NEAR(eddy_viscosity(c, delta, j), std::pow(0.15 * 0.05, 2) * std::abs(gamma),
                1e-15 * std::abs(gamma));
  }
}

TEST(EddyViscosity, SigmaVanishesForRotationShearAndUniformFlowButNotIn3DStrain) {
  SubfilterConfig c;
  c.model = SubfilterModel::Sigma;
  const double delta = 0.3;
  const VelocityGradient rotation = gradient_of({{0, -2, 0}, {2, 0, 0}, {0, 0, 0}});
  const VelocityGradient rotation3d = gradient_of({{0, -2, 1}, {2, 0, -0.5}, {-1, 0.5, 0}});
  const VelocityGradient shear = gradient_of({{0, 3, 0}, {0, 0, 0}, {0, 0, 0}});
  const VelocityGradient uniform{};
  EXPECT_NEAR(eddy_viscosity(c, delta, rotation), 0.0, 1e-14);
  EXPECT_NEAR(eddy_viscosity(c, delta, rotation3d), 0.0, 1e-14);
  EXPECT_NEAR(eddy_viscosity(c, delta, shear), 0.0, 1e-14);
  EXPECT_EQ(eddy_viscosity(c, delta, uniform), 0.0);
  // A 2D gradient has σ3 = 0: SIGMA is zero for any 2D flow (Nicoud et al. 2011).
  EXPECT_NEAR(eddy_viscosity(c, delta, gradient_of({{1, 2, 0}, {0.5, -1, 0}, {0, 0, 0}})), 0.0,
              1e-14);
  // Axisymmetric strain diag(-2, 1, 1): σ = (2, 1, 1): D_σ = 1·1·0/4 = 0; a generic 3D strain
  // diag(3, -1, -2): σ = (3, 2, 1): D_σ = 1·(3-2)(2-1)/9.
  EXPECT_NEAR(eddy_viscosity(c, delta, gradient_of({{3, 0, 0}, {0, -1, 0}, {0, 0, -2}})),
              std::pow(1.35 * delta, 2) / 9.0, 1e-14);
  // SMAG is not zero for rotation-free shear, and is zero for solid rotation.
  c.model = SubfilterModel::Smagorinsky;
  EXPECT_GT(eddy_viscosity(c, delta, shear), 0.0);
  EXPECT_NEAR(eddy_viscosity(c, delta, rotation), 0.0, 1e-15);
  EXPECT_EQ(eddy_viscosity(c, delta, uniform), 0.0);
  c.model = SubfilterModel::Implicit;
  EXPECT_EQ(eddy_viscosity(c, delta, shear), 0.0);
}

// Every model of the registry (sim::SubfilterRegistry): its name round-trips, and an unknown
// name's error lists them all.
TEST(EddyViscosity, ModelNames) {
  ASSERT_EQ(kSubfilterModels.size(), 4u);
  for (const auto m : kSubfilterModels)
    EXPECT_EQ(kSubfilterModelNames.find(subfilter_model_name(m)), m);
  try {
    parse_name(kSubfilterModelNames, "wale", "subfilter.model");
    ADD_FAILURE() << "an unknown model was accepted";
  } catch (const SceneError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("'wale'"), std::string::npos) << message;
    for (const auto m : kSubfilterModels)
      EXPECT_NE(message.find(subfilter_model_name(m)), std::string::npos) << message;
  }
}

/// The registered explicit models (all but the implicit one).
std::vector<SubfilterModel> explicit_models() {
  std::vector<SubfilterModel> models;
  for (const auto m : kSubfilterModels)
    if (m != SubfilterModel::Implicit) models.push_back(m);
  return models;
}

// --- the velocity gradient (A.20) --------------------------------------------------------

/// Max relative error of J (A.20) against A for v = A x on a lattice (perturbed by `shift` Δl).
double gradient_error(int dim, double diameter_over_spacing, double shift) {
  PeriodicBox box{dim, {1.0, 1.0, 1.0}};
  const int per_side = dim == 3 ? 16 : 40;
  ParticleArrays p = make_lattice(box, per_side);
  const double spacing = 1.0 / per_side;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int d = 0; d < dim; ++d) p.position[d][i] += shift * spacing * u(rng);
  for (double& m : p.mass) m = std::pow(spacing, dim);
  const VelocityGradient a = gradient_of({{0.3, -1.2, 0.7}, {2.0, 0.1, -0.4}, {0.5, 0.9, -0.4}});
  // A linear field is not periodic: check particles at least H + shift from every face, with
  // positions unwrapped (the field is evaluated at the minimum-image offsets through v_j - v_i).
  const double support = 0.5 * diameter_over_spacing * spacing;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int a_ = 0; a_ < dim; ++a_) {
      double v = 0.0;
      for (int b = 0; b < dim; ++b) v += a[a_][b] * p.position[b][i];
      p.velocity[a_][i] = v;
    }
  std::vector<VelocityGradient> j;
  double scale = 0.0;
  for (int r = 0; r < dim; ++r)
    for (int c = 0; c < dim; ++c) scale = std::max(scale, std::abs(a[r][c]));
  return with_kernel(KernelType::WendlandC4, dim, support, [&](const auto& kernel) {
    constexpr int D = std::decay_t<decltype(kernel)>::dimension;
    VerletNeighbourSearch search(box, support, 0.0);
    search.build(view_positions(p));
    FluidParameters fluid;
    density_pass<D>(kernel, box, search.list(), fluid, p);
    velocity_gradient_pass<D>(kernel, box, search.list(), view_velocity(p), p, j);
    double error = 0.0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      bool interior = true;
      for (int d = 0; d < D; ++d)
        interior = interior && p.position[d][i] > support + 0.1 && p.position[d][i] < 0.9 - support;
      if (!interior) continue;
      for (int r = 0; r < D; ++r)
        for (int c = 0; c < D; ++c) error = std::max(error, std::abs(j[i][r][c] - a[r][c]) / scale);
    }
    return error;
  });
}

TEST(VelocityGradient, ExactForLinearFieldsToQuadratureError) {
  // On a lattice the only error is the lattice quadrature of Σ_j x_ij ⊗ ∇W_ij V_j = -I, which
  // for WC4 at D_K = 8Δl is ~1e-4 (the same size as the kernel normalisation error of a lattice,
  // see test_subfilter_stress) times the gradient's sensitivity; disorder of 5 % Δl adds a
  // first-order error of a few per cent.
  for (const int dim : {2, 3}) {
    const double lattice = gradient_error(dim, 8.0, 0.0);
    const double perturbed = gradient_error(dim, 8.0, 0.05);
    std::printf("J of a linear field, %dD, WC4 D_K=8dl: lattice %.2e, 5%% perturbed %.2e\n", dim,
                lattice, perturbed);
    EXPECT_LT(lattice, 2.5e-3);  // measured 1.7e-3 (2D), 0.9e-3 (3D)
    EXPECT_LT(perturbed, 0.05);
    EXPECT_LT(lattice, perturbed);
  }
}

// --- conservation ------------------------------------------------------------------------

class ModelMomentumTest : public ::testing::TestWithParam<std::tuple<int, SubfilterModel>> {};

TEST_P(ModelMomentumTest, LinearMomentumConservedToRoundOff) {
  const auto [dim, model] = GetParam();
  auto flow = testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, 5);
  flow.config.subfilter.model = model;
  auto sim = make_simulation(flow.config, flow.particles);
  const auto initial = sim->diagnostics().momentum;
  double scale = 0.0;
  const ParticleArrays& p0 = sim->particles();
  for (std::size_t i = 0; i < p0.size(); ++i) scale += p0.mass[i];
  for (int step = 0; step < 50; ++step) sim->step();
  for (int d = 0; d < dim; ++d)
    EXPECT_NEAR(sim->diagnostics().momentum[d], initial[d], 1e-12 * scale);
  // The model is active: per-particle ν_t exists and is positive somewhere.
  const auto& nu = sim->particles().eddy_viscosity;
  ASSERT_EQ(nu.size(), p0.size());
  if (!(model == SubfilterModel::Sigma && dim == 2)) {
    EXPECT_GT(*std::max_element(nu.begin(), nu.end()), 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Models, ModelMomentumTest,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::ValuesIn(explicit_models())),
                         [](const auto& info) {
                           return std::to_string(std::get<0>(info.param)) + "D_" +
                                  std::string(subfilter_model_name(std::get<1>(info.param)));
                         });

// SMAG-MCG (A.23), like the pressure (A.9) and viscous (A.14) terms, acts along x_ij, so a
// cluster that never meets its periodic images keeps Σ M x × v to round-off.
TEST(AngularMomentum, ConservedWithSmagorinskyMcg) {
  for (const int dim : {2, 3}) {
    testing::RotatingCluster cluster = testing::rotating_cluster(dim);
    cluster.config.subfilter.model = SubfilterModel::SmagorinskyMcg;
    auto sim = make_simulation(cluster.config, cluster.particles);
    const auto l0 = testing::angular_momentum(sim->particles());
    for (int step = 0; step < 40; ++step) sim->step();
    const auto l1 = testing::angular_momentum(sim->particles());
    for (int d = 0; d < 3; ++d)
      EXPECT_NEAR(l1[d], l0[d], 1e-12 * cluster.scale) << dim << "D, component " << d;
    EXPECT_GT(*std::max_element(sim->particles().eddy_viscosity.begin(),
                                sim->particles().eddy_viscosity.end()),
              0.0);
  }
}

// --- dissipation -------------------------------------------------------------------------

double tgv_energy_after(const std::string& model, double cs, double end_time) {
  const json doc = {{"case", "tgv3d"},
                    {"particles_per_side", 16},
                    {"kernel", {{"diameter_over_spacing", 6}}},
                    {"subfilter", {{"model", model}, {"smagorinsky_constant", cs}}},
                    {"packing", {{"enabled", false}}}};
  const Scene scene = parse_scene(doc);
  RunSetup setup = setup_run(scene);
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  while (sim->time() < end_time - 1e-12) sim->step(end_time - sim->time());
  return sim->diagnostics().kinetic_energy;
}

// SPEC §7 finding 6: every explicit model removes kinetic energy compared with the implicit
// model, and a larger C_S removes more.
TEST(ModelDissipation, EveryModelRemovesEnergyAndMoreWithLargerConstant) {
  const double t = 0.5;
  const double implicit = tgv_energy_after("implicit", 0.15, t);
  const double smag = tgv_energy_after("smag", 0.15, t);
  const double smag_small = tgv_energy_after("smag", 0.075, t);
  const double smag_large = tgv_energy_after("smag", 0.3, t);
  const double sigma = tgv_energy_after("sigma", 0.15, t);
  const double mcg = tgv_energy_after("smag_mcg", 0.15, t);
  std::printf(
      "e_v(0.5), TGV 16^3: implicit %.6f, SMAG(0.075) %.6f, SMAG(0.15) %.6f, "
      "SMAG(0.3) %.6f, SIGMA %.6f, SMAG-MCG %.6f\n",
      implicit, smag_small, smag, smag_large, sigma, mcg);
  EXPECT_LT(smag, implicit);
  EXPECT_LT(sigma, implicit);
  EXPECT_LT(mcg, implicit);
  EXPECT_LT(smag_small, implicit);
  EXPECT_LT(smag, smag_small);
  EXPECT_LT(smag_large, smag);
}

// --- Kolmogorov flow ---------------------------------------------------------------------

// Small forcing: the flow converges to v_x = χ sin(k_y y)/(ν k_y² + μ) (SPEC §6.3). One forcing
// period per box and a strong friction μ = 4 1/s (time constant 0.25 s) keep the run short;
// the check covers forcing, friction and the periodic set-up. The background pressure is
// lowered from 400 Pa to 1 Pa: with laminar speeds of 5 mm/s, p_ref/(ρ v²) would be 16000, and
// the zero-order background-pressure force (5.7) of the sheared lattice then drives the flow
// (measured: v_x overshoots the laminar profile by 35 % and oscillates with period ~1.6 s). At
// the thesis' turbulent speeds (0.1 m/s) the ratio is 40.
TEST(Kolmogorov, LaminarStateMatchesAnalytic) {
  const json doc = {{"case", "kolmogorov2d"},
                    {"particles_per_side", 32},
                    {"fluid", {{"reference_pressure", 1.0}}},
                    {"forcing", {{"amplitude", 0.02}, {"periods", 1}, {"friction", 4.0}}},
                    {"time", {{"end", 2.0}}},
                    {"packing", {{"enabled", false}}}};
  const Scene scene = parse_scene(doc);
  EXPECT_NEAR(scene.forcing_wavenumber(), 2.0 * M_PI / 0.042, 1e-9);
  RunSetup setup = setup_run(scene);
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  while (sim->time() < scene.end_time - 1e-12) sim->step(scene.end_time - sim->time());
  const ParticleArrays& p = sim->particles();
  const double nu = scene.fluid.kinematic_viscosity();
  const double peak =
      kolmogorov_laminar_velocity(scene.forcing, scene.forcing_wavenumber(), nu, 0.042 / 4);
  double max_error = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double exact = kolmogorov_laminar_velocity(scene.forcing, scene.forcing_wavenumber(), nu,
                                                     p.position[1][i]);
    max_error = std::max(max_error, std::abs(p.velocity[0][i] - exact));
    EXPECT_LT(std::abs(p.velocity[1][i]), 0.02 * peak);
  }
  std::printf("Kolmogorov laminar: max |v_x - exact| / peak = %.4f (peak %.5f m/s)\n",
              max_error / peak, peak);
  EXPECT_LT(max_error, 0.02 * peak);
  // Energy budget at steady state: injection = friction (+ the tiny viscous part).
  const auto budget = case_diagnostics(scene, p);
  ASSERT_EQ(budget.size(), 3u);
  const double viscous = nu * std::pow(scene.forcing_wavenumber(), 2) * 0.5 * peak * peak;
  EXPECT_NEAR(budget[0], budget[1] + viscous, 0.03 * budget[0]);
  EXPECT_NEAR(budget[2], peak / std::sqrt(2.0), 0.02 * peak);
}

// --- scenes and presets ------------------------------------------------------------------

TEST(Presets, EveryPresetLoadsAndRunsFiveStepsAtReducedResolution) {
  const auto names = preset_names();
  EXPECT_EQ(names.size(), 25u);
  for (const std::string& name : names) {
    const Scene full = parse_scene({{"preset", name}});
    EXPECT_EQ(full.name, name);
    const int reduced = full.case_type == CaseType::Kolmogorov2D ? 24 : 12;
    const Scene s = parse_scene(
        {{"preset", name}, {"particles_per_side", reduced}, {"packing", {{"enabled", false}}}});
    // Scaling N keeps kernel, D_K/Δl and model.
    EXPECT_EQ(s.kernel, full.kernel) << name;
    EXPECT_EQ(s.kernel_diameter_over_spacing, full.kernel_diameter_over_spacing) << name;
    EXPECT_EQ(s.subfilter.model, full.subfilter.model) << name;
    EXPECT_EQ(s.subfilter.smagorinsky_constant, full.subfilter.smagorinsky_constant) << name;
    RunSetup setup = setup_run(s);
    auto sim = make_simulation(setup.solver, std::move(setup.particles));
    for (int step = 0; step < 5; ++step) sim->step();
    EXPECT_EQ(sim->step_count(), 5u) << name;
    EXPECT_TRUE(std::isfinite(sim->diagnostics().kinetic_energy)) << name;
  }
}

// The Re = 1600 preset starts from a glass (the lattice displaced by 0.45Δl, then packed): the
// strained near-lattice of the default 0.05Δl rearranges at t ≈ 0.8-1 and throws resolved energy
// into particle-scale motion (16³: e_v(1.5) 14 % below e_v(0)); the glass loses a few per cent
// (16³: 3.3 %; the DNS loses 0.6 %, data/reference/tgv_re1600_spectral_512_hiocfd.gdiag).
TEST(Presets, TheRe1600PresetStartsFromAGlassWithoutTheStartUpBurst) {
  Scene s = parse_scene({{"preset", "tgv3d-re1600"}, {"particles_per_side", 16}});
  EXPECT_DOUBLE_EQ(s.fluid.kinematic_viscosity(), 1.0 / 1600.0);
  EXPECT_EQ(s.packing.perturbation, 0.45);
  s.packing.cache = false;
  RunSetup setup = setup_run(s);
  ASSERT_TRUE(setup.packing.converged);
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  const double e0 = sim->diagnostics().kinetic_energy;
  while (sim->time() < 1.5 - 1e-12) sim->step(1.5 - sim->time());
  const double loss = 1.0 - sim->diagnostics().kinetic_energy / e0;
  std::printf("glass start, 16^3, Re = 1600: e_v(1.5) %.2f %% below e_v(0)\n", 100.0 * loss);
  EXPECT_GT(loss, 0.0);
  EXPECT_LT(loss, 0.06);
}

TEST(Presets, ThesisTableValues) {
  const Scene c4 = parse_scene({{"preset", "tgv3d-case4"}});
  EXPECT_EQ(c4.kernel, KernelType::QuinticSpline);
  EXPECT_EQ(c4.particles_per_side, 512);
  EXPECT_EQ(c4.kernel_diameter_over_spacing, 6.0);
  const Scene c5 = parse_scene({{"preset", "tgv3d-case5"}});
  EXPECT_EQ(c5.kernel_diameter_over_spacing, 4.0);
  const Scene c16 = parse_scene({{"preset", "tgv3d-case16"}});
  EXPECT_EQ(c16.subfilter.model, SubfilterModel::Sigma);
  const Scene c17 = parse_scene({{"preset", "tgv3d-case17"}});
  EXPECT_EQ(c17.subfilter.model, SubfilterModel::SmagorinskyMcg);
  EXPECT_EQ(parse_scene({{"preset", "tgv3d-case18"}}).subfilter.smagorinsky_constant, 0.075);
  EXPECT_EQ(parse_scene({{"preset", "tgv3d-case19"}}).subfilter.smagorinsky_constant, 0.3);
  EXPECT_EQ(parse_scene({{"preset", "tgv3d-case20"}}).fluid.reference_pressure, 68.0);
  const Scene c21 = parse_scene({{"preset", "tgv3d-case21"}});
  EXPECT_EQ(c21.fluid.sound_speed, 16.5);
  EXPECT_EQ(c21.fluid.reference_pressure, 68.0);
  EXPECT_DOUBLE_EQ(c21.uniform_velocity[2], M_PI);
  const Scene k = parse_scene({{"preset", "kolmogorov2d"}});
  EXPECT_EQ(k.particles_per_side, 336);
  EXPECT_NEAR(k.particle_spacing(), 125e-6, 1e-12);
  EXPECT_NEAR(k.kernel_diameter(), 1e-3, 1e-12);
  EXPECT_NEAR(k.forcing_wavenumber(), 1047.2, 0.01);
  EXPECT_EQ(k.forcing.amplitude, 1.8);
  // The scene written out re-parses to the same scene.
  EXPECT_EQ(scene_to_json(parse_scene(scene_to_json(c21))), scene_to_json(c21));
}

TEST(Presets, Errors) {
  const auto error_of = [](const json& doc) -> std::string {
    try {
      parse_scene(doc);
    } catch (const SceneError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(error_of({{"preset", "tgv3d-case99"}}).find("unknown preset 'tgv3d-case99'"),
            std::string::npos);
  EXPECT_NE(error_of({{"preset", 3}}).find("'preset' must be a string"), std::string::npos);
  EXPECT_NE(error_of({{"subfilter", {{"model", "wale"}}}}).find("'subfilter.model'"),
            std::string::npos);
  EXPECT_NE(error_of({{"subfilter", {{"smagorinsky_constant", -1}}}})
                .find("'subfilter.smagorinsky_constant' must be > 0"),
            std::string::npos);
  EXPECT_NE(
      error_of({{"forcing", {{"amplitude", 1}}}}).find("'forcing' applies to case kolmogorov2d"),
      std::string::npos);
  EXPECT_NE(error_of({{"case", "kolmogorov2d"}, {"forcing", {{"periods", 0}}}})
                .find("'forcing.periods' must be in [1, 100000]"),
            std::string::npos);
  EXPECT_NE(error_of({{"box_length", 1}}).find("'box_length' is fixed at 2π"), std::string::npos);
}

}  // namespace
}  // namespace sphles::sim
