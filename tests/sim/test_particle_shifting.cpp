// SPDX-License-Identifier: GPL-3.0-or-later
// Particle shifting with the consistent ALE correction (Sun et al. 2017, 2019;
// sim/physics/particle_shifting.hpp) beside the thesis model and the TVF: the pair formulas, δv on
// a lattice, the drift with v + δv, conservation, thread independence, exact restart, the scene
// keys, Galilean invariance and the 2D Taylor-Green decay (docs/models.md, "Particle shifting").
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstdio>

#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene_test_support.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/packing.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::sim {

using scene::parse_scene;
using scene::scene_to_json;
namespace {

using testing::same_bits;
using testing::scene_error;

testing::RandomFlow shifting_flow(int dim, std::uint64_t seed) {
  auto flow = testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, seed);
  flow.config.scheme.type = SchemeType::ParticleShifting;
  return flow;
}

/// δv of every particle of `p` (positions, and volumes from a density pass run here), with the
/// solver's parameters for `config`.
std::array<std::vector<double>, 3> shifting_velocity_of(const SolverConfig& config,
                                                        ParticleArrays p) {
  std::array<std::vector<double>, 3> shift;
  for (int d = 0; d < p.dimension; ++d) shift[d].assign(p.size(), 0.0);
  p.volume.resize(p.size());
  p.density.resize(p.size());
  p.pressure.resize(p.size());
  VerletNeighbourSearch search(config.box, config.support_radius, 0.0);
  search.build(view_positions(p));
  with_kernel(config.kernel, config.box.dimension, config.support_radius, [&](const auto& kernel) {
    constexpr int Dim = std::decay_t<decltype(kernel)>::dimension;
    const ShiftingParameters parameters =
        shifting_parameters(config.scheme.shifting_mach * config.fluid.sound_speed,
                            config.support_radius, kernel.value(config.particle_spacing));
    density_pass<Dim>(kernel, config.box, search.list(), config.fluid, p);
    shifting_velocity_pass<Dim>(kernel, config.box, search.list(), parameters, p, shift);
  });
  return shift;
}

TEST(ParticleShiftingNames, RegisteredWithTransportVelocityAndListedWhenUnknown) {
  EXPECT_EQ(scheme_name(SchemeType::ParticleShifting), "particle_shifting");
  EXPECT_EQ(kSchemeNames.find("particle_shifting"), SchemeType::ParticleShifting);
  EXPECT_TRUE(scheme_uses_transport_velocity(SchemeType::ParticleShifting));
  try {
    parse_name(kSchemeNames, "shifting", "scheme.type");
    FAIL() << "expected SceneError";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("one of thesis, transport_velocity, particle_shifting"),
              std::string::npos)
        << e.what();
  }
}

// The pair formulas: the anti-clustering factor is 1 + R at one spacing and 1 at the edge of the
// support, the ALE pair term is symmetric in i and j (so its pair term of M a, times ∇W_ij, is
// antisymmetric), and the limiter caps |δv| and leaves smaller shifts alone.
TEST(ParticleShiftingPairs, FactorAleTermAndLimiter) {
  EXPECT_DOUBLE_EQ(shifting_pair_factor(0.7, 0.7), 1.0 + kShiftingClusteringAmplitude);
  EXPECT_EQ(shifting_pair_factor(0.0, 0.7), 1.0);
  EXPECT_DOUBLE_EQ(shifting_pair_factor(1.4, 0.7), 1.0 + kShiftingClusteringAmplitude * 16.0);
  EXPECT_EQ(ale_conservative_term(1.1, 0.3, -0.2, 0.9, -0.7, 0.4),
            ale_conservative_term(0.9, -0.7, 0.4, 1.1, 0.3, -0.2));
  EXPECT_DOUBLE_EQ(ale_conservative_term(2.0, 3.0, 0.5, 1.0, 4.0, 0.25), 4.0);
  EXPECT_EQ(shifting_limiter_scale(0.1, 0.5), 1.0);
  EXPECT_DOUBLE_EQ(shifting_limiter_scale(2.0, 0.5), 0.25);
  // The full correction is unchanged by a uniform velocity U added to v_i and v_j (Galilean);
  // the conservative one changes by U (ρ_i δv_i + ρ_j δv_j)·∇W_ij.
  const double uniform = 1.7;
  EXPECT_NEAR(ale_full_term(1.1, 0.3 + uniform, -0.2, 0.9, -0.7 + uniform, 0.4),
              ale_full_term(1.1, 0.3, -0.2, 0.9, -0.7, 0.4), 1e-15);
  EXPECT_DOUBLE_EQ(ale_full_term(1.1, 0.3, -0.2, 0.9, -0.7, 0.4), 0.9 * (-1.0) * 0.4);
  EXPECT_NEAR(ale_conservative_term(1.1, 0.3 + uniform, -0.2, 0.9, -0.7 + uniform, 0.4) -
                  ale_conservative_term(1.1, 0.3, -0.2, 0.9, -0.7, 0.4),
              uniform * (1.1 * -0.2 + 0.9 * 0.4), 1e-15);
  const ShiftingParameters p = shifting_parameters(2.0, 0.3, 5.0);
  EXPECT_DOUBLE_EQ(p.coefficient, 0.6);  // Ma c_0 (2h)
  EXPECT_EQ(p.reference_kernel, 5.0);
  EXPECT_DOUBLE_EQ(p.speed_limit, kShiftingSpeedLimit * 2.0);
  EXPECT_EQ(p.ale, AleCorrection::Conservative);
  EXPECT_EQ(shifting_parameters(2.0, 0.3, 5.0, AleCorrection::Full).ale, AleCorrection::Full);
}

// On a perfect lattice every particle's neighbours come in ± pairs: δv = 0 to round-off. One
// particle moved off its site is pushed back towards it (δv against the displacement), and a
// large Ma is capped by the limiter.
TEST(ParticleShiftingVelocity, ZeroOnALatticeRestoringOffItAndLimited) {
  for (const int dim : {2, 3}) {
    auto flow = shifting_flow(dim, 1);
    SolverConfig& c = flow.config;
    const int side = dim == 3 ? 10 : 24;
    ParticleArrays lattice = make_lattice(c.box, side);
    for (std::size_t i = 0; i < lattice.size(); ++i)
      lattice.mass[i] = std::pow(c.particle_spacing, dim);
    const double scale = c.scheme.shifting_mach * c.fluid.sound_speed;  // U
    const auto on_lattice = shifting_velocity_of(c, lattice);
    double max_speed = 0.0;
    for (int d = 0; d < dim; ++d)
      for (const double v : on_lattice[d]) max_speed = std::max(max_speed, std::abs(v));
    EXPECT_LT(max_speed, 1e-12 * scale) << dim << "D";

    ParticleArrays moved = lattice;
    const std::size_t k = lattice.size() / 2 + side / 2;
    const double displacement = 0.1 * c.particle_spacing;
    moved.position[0][k] += displacement;
    const auto off = shifting_velocity_of(c, moved);
    EXPECT_LT(off[0][k], -1e-3 * scale) << dim << "D: pushed back towards its site";
    for (int d = 1; d < dim; ++d) EXPECT_LT(std::abs(off[d][k]), 1e-12 * scale);

    SolverConfig strong = c;
    strong.scheme.shifting_mach = 1e3;
    const auto limited = shifting_velocity_of(strong, moved);
    double speed2 = 0.0;
    for (int d = 0; d < dim; ++d) speed2 += limited[d][k] * limited[d][k];
    EXPECT_NEAR(std::sqrt(speed2), kShiftingSpeedLimit * 1e3 * c.fluid.sound_speed,
                1e-9 * 1e3 * c.fluid.sound_speed);
  }
}

// The drift is x^{n+1} - x^n = dt (v^{n+1/2} + δv(x^n)), particle by particle (ids, as the
// list may reorder them), and the scheme differs from the thesis model.
TEST(ParticleShifting, DriftsWithVelocityPlusShiftingVelocity) {
  auto flow = shifting_flow(2, 3);
  flow.config.time_step.fixed = 1e-4;
  auto sim = make_simulation(flow.config, flow.particles);
  SolverConfig thesis_config = flow.config;
  thesis_config.scheme.type = SchemeType::Thesis;
  auto thesis = make_simulation(thesis_config, flow.particles);
  for (int step = 0; step < 5; ++step) {
    sim->step();
    thesis->step();
  }
  EXPECT_FALSE(same_bits(sim->particles().position[0], thesis->particles().position[0]));
  const ParticleArrays before = sim->particles();
  const auto shift = shifting_velocity_of(flow.config, before);
  sim->step();
  const ParticleArrays& after = sim->particles();
  std::vector<std::size_t> index_of(after.size());
  for (std::size_t k = 0; k < after.size(); ++k) index_of[after.id[k]] = k;
  const double dt = 1e-4;
  double max_error = 0.0, max_shift = 0.0;
  for (std::size_t i = 0; i < before.size(); ++i) {
    const std::size_t k = index_of[before.id[i]];
    for (int d = 0; d < 2; ++d) {
      const double half_kick = before.velocity[d][i] + 0.5 * dt * before.acceleration[d][i];
      double moved = after.position[d][k] - before.position[d][i];
      moved -= std::round(moved);  // unit box
      max_error = std::max(max_error, std::abs(moved - dt * (half_kick + shift[d][i])));
      max_shift = std::max(max_shift, std::abs(dt * shift[d][i]));
    }
  }
  EXPECT_GT(max_shift, 1e-7);  // the shift is resolved by the bound below
  EXPECT_LT(max_error, 1e-14);
}

class ParticleShiftingMomentumTest : public ::testing::TestWithParam<int> {};

// Every pair term of M_i a_i is antisymmetric (pressure, viscous and the conservative ALE term),
// so Σ M v changes only by round-off over 100 steps of a random flow on a disordered lattice.
// (With ale_correction = full this fails: the drift is 2-3e-3 of Σ M |v| here.)
TEST_P(ParticleShiftingMomentumTest, ConservedToRoundOffOver100Steps) {
  const int dim = GetParam();
  auto flow = shifting_flow(dim, 7);
  auto sim = make_simulation(flow.config, flow.particles);
  const std::array<double, 3> initial = sim->diagnostics().momentum;
  const double scale = testing::momentum_scale(sim->particles());
  for (int step = 0; step < 100; ++step) sim->step();
  for (int d = 0; d < dim; ++d)
    EXPECT_NEAR(sim->diagnostics().momentum[d], initial[d], 1e-12 * scale) << "component " << d;
  EXPECT_GT(std::abs(sim->diagnostics().kinetic_energy - 0.5), 1e-3);
}

INSTANTIATE_TEST_SUITE_P(Dimensions, ParticleShiftingMomentumTest, ::testing::Values(2, 3),
                         [](const auto& info) { return std::to_string(info.param) + "D"; });

ParticleArrays run_with_threads(int threads, int dim, AleCorrection ale) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  auto flow = shifting_flow(dim, 11);
  flow.config.scheme.ale_correction = ale;
  auto sim = make_simulation(flow.config, flow.particles);
  for (int step = 0; step < 40; ++step) sim->step();
  omp_set_num_threads(saved);
  return sim->particles();
}

// Gather-form passes: 1 and 2 threads give the same state bit for bit.
TEST(ParticleShifting, OneAndTwoThreadsGiveIdenticalState) {
  for (const auto& [dim, ale] :
       {std::pair{2, AleCorrection::Conservative}, std::pair{3, AleCorrection::Conservative},
        std::pair{2, AleCorrection::Full}}) {
    const ParticleArrays one = run_with_threads(1, dim, ale);
    const ParticleArrays two = run_with_threads(2, dim, ale);
    EXPECT_EQ(one.id, two.id);
    for (int d = 0; d < dim; ++d) {
      EXPECT_TRUE(same_bits(one.position[d], two.position[d])) << dim << "D position " << d;
      EXPECT_TRUE(same_bits(one.velocity[d], two.velocity[d])) << dim << "D velocity " << d;
      EXPECT_TRUE(same_bits(one.acceleration[d], two.acceleration[d])) << dim << "D accel " << d;
    }
    EXPECT_TRUE(same_bits(one.density, two.density)) << dim << "D";
  }
}

// Restoring from state() continues bitwise identically: δv^n is recomputed from the positions
// (it is not in the checkpoint), with neighbour-list rebuilds on both sides of the restart.
TEST(ParticleShifting, RestoreContinuesBitwise) {
  for (const auto& [dim, ale] :
       {std::pair{2, AleCorrection::Conservative}, std::pair{3, AleCorrection::Conservative},
        std::pair{2, AleCorrection::Full}}) {
    auto flow = shifting_flow(dim, 21);
    flow.config.scheme.ale_correction = ale;
    testing::expect_restore_continues_bitwise(flow.config, flow.particles);
  }
}

TEST(ParticleShiftingScene, ParsedWrittenAndBadValuesRejectedNamingTheField) {
  const nlohmann::json doc = {{"case", "tgv2d"},
                              {"scheme",
                               {{"type", "particle_shifting"},
                                {"shifting_mach", 0.05},
                                {"viscous_operator", "corrected"}}}};
  const Scene scene = parse_scene(doc);
  EXPECT_EQ(scene.scheme.type, SchemeType::ParticleShifting);
  EXPECT_EQ(scene.scheme.shifting_mach, 0.05);
  EXPECT_EQ(scene.scheme.viscous_operator, ViscousOperator::Corrected);
  EXPECT_EQ(make_solver_config(scene).scheme.shifting_mach, 0.05);
  const nlohmann::json written = scene_to_json(scene);
  EXPECT_EQ(written["scheme"]["type"], "particle_shifting");
  EXPECT_EQ(written["scheme"]["shifting_mach"], 0.05);
  const Scene again = parse_scene(written);
  EXPECT_EQ(again.scheme.type, SchemeType::ParticleShifting);
  EXPECT_EQ(again.scheme.shifting_mach, 0.05);
  EXPECT_EQ(again.scheme.viscous_operator, ViscousOperator::Corrected);
  EXPECT_EQ(parse_scene({{"case", "tgv2d"}}).scheme.shifting_mach, SchemeConfig{}.shifting_mach);
  EXPECT_EQ(again.scheme.ale_correction, AleCorrection::Conservative);
  EXPECT_EQ(written["scheme"]["ale_correction"], "conservative");
  const Scene full =
      parse_scene({{"scheme", {{"type", "particle_shifting"}, {"ale_correction", "full"}}}});
  EXPECT_EQ(full.scheme.ale_correction, AleCorrection::Full);
  EXPECT_EQ(parse_scene(scene_to_json(full)).scheme.ale_correction, AleCorrection::Full);
  EXPECT_EQ(make_solver_config(full).scheme.ale_correction, AleCorrection::Full);
  const std::string bad_ale =
      scene_error({{"scheme", {{"type", "particle_shifting"}, {"ale_correction", "sun"}}}});
  EXPECT_NE(bad_ale.find("'scheme.ale_correction' must be one of conservative, full, got 'sun'"),
            std::string::npos)
      << bad_ale;
  EXPECT_NE(scene_error({{"scheme", {{"type", "thesis"}, {"ale_correction", "full"}}}})
                .find("'scheme.ale_correction' applies to scheme.type transport_velocity and "
                      "particle_shifting only"),
            std::string::npos);
  EXPECT_EQ(parse_scene({{"scheme", {{"type", "transport_velocity"}, {"ale_correction", "full"}}}})
                .scheme.ale_correction,
            AleCorrection::Full);

  for (const double bad : {0.0, -0.1}) {
    const std::string e =
        scene_error({{"scheme", {{"type", "particle_shifting"}, {"shifting_mach", bad}}}});
    EXPECT_NE(e.find("'scheme.shifting_mach'"), std::string::npos) << e;
    EXPECT_NE(e.find("> 0"), std::string::npos) << e;
  }
  const std::string other = scene_error({{"scheme", {{"type", "thesis"}, {"shifting_mach", 0.2}}}});
  EXPECT_NE(other.find("'scheme.shifting_mach' applies to scheme.type particle_shifting"),
            std::string::npos)
      << other;
  const std::string unknown = scene_error({{"scheme", {{"type", "shifting"}}}});
  EXPECT_NE(unknown.find("'scheme.type'"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("particle_shifting"), std::string::npos) << unknown;
  EXPECT_NE(scene_error({{"scheme", {{"type", "particle_shifting"}, {"shifting_mach", "x"}}}})
                .find("'scheme.shifting_mach'"),
            std::string::npos);
}

// --- 2D Taylor-Green vortex (SPEC §6.2): Re = 100, 64², WC4, D_K = 8Δl, as the TVF's test ------

constexpr int kTaylorGreenSide = 64;
constexpr double kTaylorGreenEnd = 1.0;

struct TaylorGreenRun {
  double max_error = 0.0;    // max over steps of |e_v'/e_exact - 1|
  double final_ratio = 0.0;  // e_v'(end) / e_v'(0), e_v' relative to the mean flow
};

/// e_v' = ½ Σ M |v - ⟨v⟩|² / Σ M (the energy relative to the mass-weighted mean velocity).
double relative_energy(const ParticleArrays& p) {
  double mass = 0.0, momentum[2] = {0.0, 0.0};
  for (std::size_t i = 0; i < p.size(); ++i) {
    mass += p.mass[i];
    for (int d = 0; d < 2; ++d) momentum[d] += p.mass[i] * p.velocity[d][i];
  }
  double energy = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int d = 0; d < 2; ++d) {
      const double dv = p.velocity[d][i] - momentum[d] / mass;
      energy += 0.5 * p.mass[i] * dv * dv;
    }
  return energy / mass;
}

TaylorGreenRun taylor_green(const std::string& ale, double reference_pressure,
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
                              {"scheme", {{"type", "particle_shifting"}, {"ale_correction", ale}}},
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

// e_v(t) against e_v(0) exp(-4νt) to t = 1, at p_ref = 0 (the δ⁺-SPH pressure c_0²(ρ - ρ_0)) and
// at the tgv2d preset's p_ref = 1, and with the full ALE correction at p_ref = 0. Measured
// (Release, packed start): conservative 0.0067 (p_ref 0), 0.0111 (p_ref 1); full 0.0013 (thesis
// 0.0248 at p_ref 0, TVF 0.0071 at p_b = ρ c_s²). The bounds leave a margin of about 1.5x.
TEST(ParticleShiftingTaylorGreen2D, EnergyDecayFollowsTheAnalyticSolution) {
  const TaylorGreenRun zero = taylor_green("conservative", 0.0, {0.0, 0.0});
  const TaylorGreenRun one = taylor_green("conservative", 1.0, {0.0, 0.0});
  const TaylorGreenRun full = taylor_green("full", 0.0, {0.0, 0.0});
  std::printf(
      "tgv2d Re=100 64^2 D_K=8dl t<=1, max |e_v/e_exact - 1|: particle_shifting conservative "
      "p_ref 0 %.5f, p_ref 1 %.5f; full p_ref 0 %.5f\n",
      zero.max_error, one.max_error, full.max_error);
  ::testing::Test::RecordProperty("shifting_pref0_error", std::to_string(zero.max_error));
  ::testing::Test::RecordProperty("shifting_pref1_error", std::to_string(one.max_error));
  ::testing::Test::RecordProperty("shifting_full_pref0_error", std::to_string(full.max_error));
  EXPECT_LT(zero.max_error, 0.01);
  EXPECT_LT(one.max_error, 0.017);
  EXPECT_LT(full.max_error, 0.002);
}

// The same vortex convected with a uniform velocity U = (1, ½) keeps its decay: e_v relative to
// the mean flow at t = 1 changes by < 1 %. The conservative ALE term ∇·(ρ v ⊗ δv) holds v
// itself (a uniform U adds (U/ρ) ∇·(ρ δv)): measured change 8.0e-4. The full correction is
// Galilean invariant: 2.8e-6 (thesis 1.2e-6), asserted < 1e-4.
TEST(ParticleShiftingTaylorGreen2D, UniformVelocityShiftLeavesTheDecayUnchanged) {
  for (const auto& [ale, bound] : {std::pair{"conservative", 0.01}, std::pair{"full", 1e-4}}) {
    const TaylorGreenRun rest = taylor_green(ale, 0.0, {0.0, 0.0});
    const TaylorGreenRun moving = taylor_green(ale, 0.0, {1.0, 0.5});
    const double change = std::abs(moving.final_ratio / rest.final_ratio - 1.0);
    std::printf(
        "particle_shifting %s p_ref 0: e_v'(1)/e_v'(0) at rest %.6f, convected %.6f, change "
        "%.2e\n",
        ale, rest.final_ratio, moving.final_ratio, change);
    EXPECT_LT(change, bound) << ale;
  }
}

}  // namespace
}  // namespace sphles::sim
