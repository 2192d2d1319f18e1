// SPDX-License-Identifier: GPL-3.0-or-later
// The transport-velocity formulation (Adami, Hu & Adams 2013; sim/physics/transport_velocity.hpp)
// beside the thesis model: conservation, exact restart, the scene key, Galilean invariance (2D,
// and case 21 in 3D with both forms of the extra stress) and the 2D Taylor-Green decay of both
// schemes side by side (docs/models.md).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene_test_support.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::sim {

using scene::parse_scene;
using scene::scene_to_json;
namespace {

using testing::same_bits;
using testing::scene_error;

testing::RandomFlow transport_velocity_flow(int dim, std::uint64_t seed) {
  auto flow = testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, seed);
  flow.config.scheme.type = SchemeType::TransportVelocity;
  return flow;
}

TEST(SchemeNames, RoundTripAndUnknownNameListsTheValidOnes) {
  for (const SchemeType t : {SchemeType::Thesis, SchemeType::TransportVelocity})
    EXPECT_EQ(kSchemeNames.find(scheme_name(t)), t);
  EXPECT_EQ(scheme_name(SchemeType::TransportVelocity), "transport_velocity");
  EXPECT_FALSE(scheme_uses_transport_velocity(SchemeType::Thesis));
  EXPECT_TRUE(scheme_uses_transport_velocity(SchemeType::TransportVelocity));
  try {
    parse_name(kSchemeNames, "tvf", "scheme.type");
    FAIL() << "expected SceneError";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("one of thesis, transport_velocity"), std::string::npos)
        << e.what();
  }
}

// The pair formulas are symmetric where the antisymmetry of the pair terms needs them to be.
TEST(TransportVelocityPairs, AveragesAreSymmetricAndReduceToTheCommonValue) {
  EXPECT_EQ(transport_velocity_averaged_pressure(1.1, 0.9, 3.0, -2.0),
            transport_velocity_averaged_pressure(0.9, 1.1, -2.0, 3.0));
  EXPECT_DOUBLE_EQ(transport_velocity_averaged_pressure(1.0, 1.0, 3.0, -2.0), 0.5);
  // p̃_ij weights the pressure of the lighter neighbour: (ρ_j p_i + ρ_i p_j)/(ρ_i + ρ_j).
  EXPECT_DOUBLE_EQ(transport_velocity_averaged_pressure(1.0, 3.0, 4.0, 0.0), 3.0);
  EXPECT_EQ(transport_velocity_pair_weight(0.2, 0.3), transport_velocity_pair_weight(0.3, 0.2));
  EXPECT_DOUBLE_EQ(transport_velocity_averaged_viscosity(0.01, 0.01), 0.01);
  EXPECT_EQ(transport_velocity_averaged_viscosity(0.0, 0.0), 0.0);
  EXPECT_EQ(transport_velocity_stress_term(1.1, 0.3, -0.2, 0.9, -0.7, 0.4),
            transport_velocity_stress_term(0.9, -0.7, 0.4, 1.1, 0.3, -0.2));
  FluidParameters fluid{.reference_density = 2.0, .sound_speed = 3.0, .reference_pressure = 50.0};
  EXPECT_DOUBLE_EQ(transport_velocity_momentum_pressure(2.5, fluid), 4.5);  // p_b left out
}

class TransportVelocityMomentumTest : public ::testing::TestWithParam<int> {};

// Every pair term of M_i a_i is antisymmetric, so Σ M v changes only by round-off: over 100
// steps of a random flow the drift stays below 1e-12 of Σ M |v| (as for the thesis model,
// test_conservation.cpp). The background acceleration is large here (p_b = 20 on a disordered
// lattice), so the transport velocity does move the particles off v.
TEST_P(TransportVelocityMomentumTest, ConservedToRoundOffOver100Steps) {
  const int dim = GetParam();
  auto flow = transport_velocity_flow(dim, 7);
  auto sim = make_simulation(flow.config, flow.particles);
  const std::array<double, 3> initial = sim->diagnostics().momentum;
  const double scale = testing::momentum_scale(sim->particles());
  for (int step = 0; step < 100; ++step) sim->step();
  for (int d = 0; d < dim; ++d)
    EXPECT_NEAR(sim->diagnostics().momentum[d], initial[d], 1e-12 * scale) << "component " << d;
  EXPECT_GT(std::abs(sim->diagnostics().kinetic_energy - 0.5), 1e-3);
}

INSTANTIATE_TEST_SUITE_P(Dimensions, TransportVelocityMomentumTest, ::testing::Values(2, 3),
                         [](const auto& info) { return std::to_string(info.param) + "D"; });

// The TVF moves particles with ṽ ≠ v: the same initial state ends elsewhere than under the
// thesis model, and a TVF run with p_b = 0 (ã = 0, so ṽ = v and A = 0) differs from the thesis
// model only through its own pressure and viscous operators.
TEST(TransportVelocity, DiffersFromTheThesisModelAndDriftsWithTheTransportVelocity) {
  auto flow = transport_velocity_flow(2, 3);
  auto tvf = make_simulation(flow.config, flow.particles);
  SolverConfig thesis_config = flow.config;
  thesis_config.scheme.type = SchemeType::Thesis;
  auto thesis = make_simulation(thesis_config, flow.particles);
  SolverConfig no_background = flow.config;
  no_background.fluid.reference_pressure = 0.0;
  no_background.time_step.fixed = 1e-4;
  auto plain = make_simulation(no_background, flow.particles);
  for (int step = 0; step < 10; ++step) {
    tvf->step();
    thesis->step();
    plain->step();
  }
  EXPECT_FALSE(same_bits(tvf->particles().position[0], thesis->particles().position[0]));
  // With p_b = 0 the positions advance with the velocity only: x^{n+1} - x^n = dt v^{n+1/2}.
  // One more step, checked particle by particle (ids, as the list may reorder them).
  const ParticleArrays before = plain->particles();
  plain->step();
  const ParticleArrays& after = plain->particles();
  std::vector<std::size_t> index_of(after.size());
  for (std::size_t k = 0; k < after.size(); ++k) index_of[after.id[k]] = k;
  const double dt = 1e-4;
  double max_error = 0.0;
  for (std::size_t i = 0; i < before.size(); ++i) {
    const std::size_t k = index_of[before.id[i]];
    for (int d = 0; d < 2; ++d) {
      const double half_kick = before.velocity[d][i] + 0.5 * dt * before.acceleration[d][i];
      double moved = after.position[d][k] - before.position[d][i];
      moved -= std::round(moved);  // unit box
      max_error = std::max(max_error, std::abs(moved - dt * half_kick));
    }
  }
  EXPECT_LT(max_error, 1e-15);
}

// Restoring from state() continues bitwise identically: ã^n is recomputed from the positions
// (it is not in the checkpoint), with neighbour-list rebuilds (and reorders of the transport
// shift) on both sides of the restart.
TEST(TransportVelocity, RestoreContinuesBitwise) {
  for (const int dim : {2, 3}) {
    auto flow = transport_velocity_flow(dim, 21);
    testing::expect_restore_continues_bitwise(flow.config, flow.particles);
  }
}

TEST(SchemeScene, ParsedWrittenAndBadNamesRejectedNamingTheField) {
  EXPECT_EQ(parse_scene({{"case", "tgv2d"}}).scheme.type, SchemeType::Thesis);
  const Scene tvf = parse_scene({{"case", "tgv2d"}, {"scheme", {{"type", "transport_velocity"}}}});
  EXPECT_EQ(tvf.scheme.type, SchemeType::TransportVelocity);
  EXPECT_EQ(make_solver_config(tvf).scheme.type, SchemeType::TransportVelocity);
  const nlohmann::json written = scene_to_json(tvf);
  EXPECT_EQ(written["scheme"]["type"], "transport_velocity");
  EXPECT_EQ(parse_scene(written).scheme.type, SchemeType::TransportVelocity);
  EXPECT_EQ(scene_to_json(parse_scene({{"case", "tgv2d"}}))["scheme"]["type"], "thesis");

  const std::string bad = scene_error({{"scheme", {{"type", "tvf"}}}});
  EXPECT_NE(bad.find("'scheme.type'"), std::string::npos) << bad;
  EXPECT_NE(bad.find("got 'tvf'"), std::string::npos) << bad;
  EXPECT_NE(bad.find("thesis, transport_velocity"), std::string::npos) << bad;
  EXPECT_NE(scene_error({{"scheme", {{"type", 3}}}}).find("'scheme.type' must be a string"),
            std::string::npos);
  EXPECT_NE(scene_error({{"scheme", "transport_velocity"}}).find("'scheme'"), std::string::npos);
  EXPECT_NE(scene_error({{"scheme", {{"typ", "thesis"}}}}).find("unknown key 'scheme.typ'"),
            std::string::npos);
}

// --- 2D Taylor-Green vortex (SPEC §6.2): Re = 100, 64², WC4, D_K = 8Δl ----------------------

constexpr int kTaylorGreenSide = 64;
constexpr double kTaylorGreenEnd = 1.0;

struct TaylorGreenRun {
  double max_error = 0.0;    // max over steps of |e_v'/e_exact - 1|
  double final_ratio = 0.0;  // e_v'(end) / e_v'(0), e_v' relative to the mean flow
};

/// e_v' = ½ Σ M |v - ⟨v⟩|² / Σ M (the energy relative to the mass-weighted mean velocity).
double relative_energy(const ParticleArrays& p, int dim = 2) {
  double mass = 0.0, momentum[3] = {0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < p.size(); ++i) {
    mass += p.mass[i];
    for (int d = 0; d < dim; ++d) momentum[d] += p.mass[i] * p.velocity[d][i];
  }
  double energy = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int d = 0; d < dim; ++d) {
      const double dv = p.velocity[d][i] - momentum[d] / mass;
      energy += 0.5 * p.mass[i] * dv * dv;
    }
  return energy / mass;
}

TaylorGreenRun taylor_green(const std::string& scheme, double reference_pressure,
                            std::array<double, 2> uniform) {
  const nlohmann::json doc = {{"case", "tgv2d"},
                              {"particles_per_side", kTaylorGreenSide},
                              {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
                              {"fluid",
                               {{"reference_density", 1.0},
                                {"dynamic_viscosity", 0.01},
                                {"sound_speed", 10.0},
                                {"reference_pressure", reference_pressure}}},
                              {"flow", {{"uniform_velocity", {uniform[0], uniform[1]}}}},
                              {"scheme", {{"type", scheme}}},
                              {"time", {{"end", kTaylorGreenEnd}}}};
  const Scene scene = parse_scene(doc);
  RunSetup setup = setup_run(scene, testing::validation_packing_cache());
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  const double nu = scene.fluid.kinematic_viscosity();
  const double e0 = relative_energy(sim->particles());
  TaylorGreenRun run;
  while (sim->time() < scene.end_time - 1e-12) {
    sim->step(scene.end_time - sim->time());
    const double exact = e0 * std::exp(-4.0 * nu * sim->time());
    run.max_error =
        std::max(run.max_error, std::abs(relative_energy(sim->particles()) / exact - 1.0));
  }
  run.final_ratio = relative_energy(sim->particles()) / e0;
  return run;
}

/// PySPH's background pressure for the TVF (examples/taylor_green.py): p_b = ρ c_s².
constexpr double kPysphBackgroundPressure = 1.0 * 10.0 * 10.0;

// e_v(t) against e_v(0) exp(-4νt) to t = 1, both schemes side by side (printed and recorded).
// Measured (Release, packed start): thesis at p_ref = 1 (the tgv2d preset) 0.0386; TVF at
// p_b = 1 0.0273, at p_b = ρ c_s² = 100 0.0071. The bounds leave a margin of about 1.5x.
TEST(TransportVelocityTaylorGreen2D, EnergyDecayFollowsTheAnalyticSolution) {
  const TaylorGreenRun thesis = taylor_green("thesis", 1.0, {0.0, 0.0});
  const TaylorGreenRun tvf_low = taylor_green("transport_velocity", 1.0, {0.0, 0.0});
  const TaylorGreenRun tvf = taylor_green("transport_velocity", kPysphBackgroundPressure, {0, 0});
  std::printf(
      "tgv2d Re=100 64^2 D_K=8dl t<=1, max |e_v/e_exact - 1|: thesis (p_ref 1) %.5f, "
      "transport_velocity p_b 1 %.5f, p_b 100 %.5f\n",
      thesis.max_error, tvf_low.max_error, tvf.max_error);
  ::testing::Test::RecordProperty("thesis_error", std::to_string(thesis.max_error));
  ::testing::Test::RecordProperty("tvf_pb1_error", std::to_string(tvf_low.max_error));
  ::testing::Test::RecordProperty("tvf_pb100_error", std::to_string(tvf.max_error));
  EXPECT_LT(tvf.max_error, 0.011);
  EXPECT_LT(tvf_low.max_error, 0.04);
  // The point of the scheme: a large background pressure regularises without the thesis
  // model's dissipation (its error grows with p_ref: 0.21 at p_ref = 100, docs/models.md).
  EXPECT_LT(tvf.max_error, 0.5 * thesis.max_error);
}

// The thesis' case 21 idea in 2D: the same vortex convected with a uniform velocity U = (1, ½)
// (|U| ≈ 1.1 v0) keeps its decay: e_v relative to the mean flow at t = 1 changes by < 1 %.
// The TVF at p_b = ρ c_s², where the extra stress A = ρ v ⊗ (ṽ - v) (not Galilean invariant:
// it holds v itself) is largest. Measured changes: thesis 1.2e-6, TVF 5.9e-5.
TEST(TransportVelocityTaylorGreen2D, UniformVelocityShiftLeavesTheDecayUnchanged) {
  const std::pair<const char*, double> cases[] = {{"thesis", 1.0},
                                                  {"transport_velocity", kPysphBackgroundPressure}};
  for (const auto& [scheme, pressure] : cases) {
    const TaylorGreenRun rest = taylor_green(scheme, pressure, {0.0, 0.0});
    const TaylorGreenRun moving = taylor_green(scheme, pressure, {1.0, 0.5});
    const double change = std::abs(moving.final_ratio / rest.final_ratio - 1.0);
    std::printf("%s p %.0f: e_v'(1)/e_v'(0) at rest %.6f, convected %.6f, change %.2e\n", scheme,
                pressure, rest.final_ratio, moving.final_ratio, change);
    EXPECT_LT(change, 0.01) << scheme;
  }
}

// --- The thesis' case 21 in 3D (SPEC §6.1, finding 7) -------------------------------------

/// e_v'(t_end)/e_v'(0) of the 3D TGV at Re = 5000 (16³, WC4 8Δl, c_s = 16.5, p_b = 68, as case
/// 21) under the TVF with the given extra stress, at rest or convected with v_z = π.
double convected_taylor_green_3d(const std::string& ale, double uniform_z, double end) {
  const nlohmann::json doc = {{"case", "tgv3d"},
                              {"particles_per_side", 16},
                              {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
                              {"fluid",
                               {{"reference_density", 1.0},
                                {"dynamic_viscosity", 2e-4},
                                {"sound_speed", 16.5},
                                {"reference_pressure", 68.0}}},
                              {"scheme", {{"type", "transport_velocity"}, {"ale_correction", ale}}},
                              {"initial", {{"mass", "summation"}}},
                              {"flow", {{"uniform_velocity", {0.0, 0.0, uniform_z}}}},
                              {"time", {{"end", end}}}};
  const Scene scene = parse_scene(doc);
  RunSetup setup = setup_run(scene, testing::validation_packing_cache());
  auto sim = make_simulation(setup.solver, std::move(setup.particles));
  const double e0 = relative_energy(sim->particles(), 3);
  while (sim->time() < scene.end_time - 1e-12) sim->step(scene.end_time - sim->time());
  return relative_energy(sim->particles(), 3) / e0;
}

// Case 21 against case 20 for the TVF at the same c_s and p_b, to t = 5 (docs/models.md): Adami
// et al.'s extra stress A = ρ v ⊗ δv holds v itself, so the convected vortex keeps measurably
// more energy (e_v'(5)/e_v'(0) 0.745 at rest, 0.792 convected: +6.3 %); with the full ALE form
// (ρ δv·∇v, ale_correction.hpp) the change is 0.75 % (24³: 4.8 % against 0.31 %).
TEST(TransportVelocityTaylorGreen3D, FullAleStressKeepsTheConvectedDecayWithinOnePercent) {
  constexpr double kEnd = 5.0;
  constexpr double kShift = 3.141592653589793;  // case 21's v_z = π
  double change[2] = {0.0, 0.0};
  const char* forms[2] = {"conservative", "full"};
  for (int k = 0; k < 2; ++k) {
    const double rest = convected_taylor_green_3d(forms[k], 0.0, kEnd);
    const double moving = convected_taylor_green_3d(forms[k], kShift, kEnd);
    change[k] = std::abs(moving / rest - 1.0);
    std::printf("tgv3d 16^3 TVF %s: e_v'(5)/e_v'(0) at rest %.5f, convected %.5f, change %.2e\n",
                forms[k], rest, moving, change[k]);
  }
  EXPECT_LT(change[1], 0.01);
  // The test can fail: the conservative stress is not Galilean invariant.
  EXPECT_GT(change[0], 0.03);
}

}  // namespace
}  // namespace sphles::sim
