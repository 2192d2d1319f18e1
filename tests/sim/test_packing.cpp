// SPDX-License-Identifier: GPL-3.0-or-later
// Lattice packing (Colagrossi et al. 2012): relaxation lowers the background-pressure residual
// below the tolerance; the cache round-trips exactly and survives damaged files.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>

#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/packing.hpp"

namespace sphles::sim {

using scene::parse_scene;
using scene::scene_to_json;
namespace {

class PackingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cache_ = std::filesystem::temp_directory_path() /
             ("sphles_pack_" + std::to_string(::getpid()) + "_" +
              ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(cache_);
  }
  void TearDown() override { std::filesystem::remove_all(cache_); }

  Scene scene(int dim, int per_side) const {
    nlohmann::json doc = {{"case", dim == 3 ? "tgv3d" : "tgv2d"},
                          {"particles_per_side", per_side},
                          {"kernel", {{"diameter_over_spacing", 6}}}};
    return parse_scene(doc);
  }
  SetupOptions options() const { return {.packing_cache_dir = cache_}; }
  std::filesystem::path cache_;
};

TEST_F(PackingTest, PerfectLatticeHasZeroResidual) {
  const Scene s = scene(3, 12);
  PeriodicBox box{3, {s.box_length(), s.box_length(), s.box_length()}};
  const ParticleArrays lattice = make_lattice(box, 12);
  EXPECT_LT(
      packing_residual(box, s.kernel, 0.5 * s.kernel_diameter(), s.particle_spacing(), lattice),
      1e-12);
}

TEST_F(PackingTest, RelaxationReachesTolerance) {
  for (const int dim : {2, 3}) {
    const Scene s = scene(dim, dim == 3 ? 12 : 32);
    PackingReport report;
    const ParticleArrays packed = packed_positions(s, &report, options());
    EXPECT_TRUE(report.converged) << dim << "D";
    EXPECT_FALSE(report.from_cache);
    EXPECT_GT(report.initial_residual, 10.0 * s.packing.tolerance) << "perturbation too weak";
    EXPECT_LE(report.final_residual, s.packing.tolerance);
    PeriodicBox box{dim, {s.box_length(), s.box_length(), s.box_length()}};
    // The residual reported equals an independent evaluation of the returned arrangement.
    EXPECT_NEAR(
        packing_residual(box, s.kernel, 0.5 * s.kernel_diameter(), s.particle_spacing(), packed),
        report.final_residual, 1e-6);
    // Identities are in lattice order.
    for (std::size_t i = 0; i < packed.size(); ++i) ASSERT_EQ(packed.id[i], i);
  }
}

TEST_F(PackingTest, CacheRoundTripsBitForBitAndRecoversFromDamage) {
  const Scene s = scene(2, 24);
  PackingReport first, second, third;
  const ParticleArrays a = packed_positions(s, &first, options());
  ASSERT_FALSE(first.from_cache);
  ASSERT_TRUE(std::filesystem::exists(first.cache_file)) << first.cache_file;
  const ParticleArrays b = packed_positions(s, &second, options());
  EXPECT_TRUE(second.from_cache);
  for (int d = 0; d < 2; ++d)
    EXPECT_EQ(std::memcmp(a.position[d].data(), b.position[d].data(), a.size() * sizeof(double)),
              0);

  // Flip one byte in the middle of the positions: the checksum rejects the file, packing reruns
  // and rewrites a valid cache.
  {
    std::fstream f(first.cache_file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(std::filesystem::file_size(first.cache_file) / 2));
    f.put('\x5a');
  }
  const ParticleArrays c = packed_positions(s, &third, options());
  EXPECT_FALSE(third.from_cache);
  for (int d = 0; d < 2; ++d)
    EXPECT_EQ(std::memcmp(a.position[d].data(), c.position[d].data(), a.size() * sizeof(double)),
              0);
  // Truncated file: also rejected.
  std::filesystem::resize_file(first.cache_file, 100);
  PackingReport fourth;
  packed_positions(s, &fourth, options());
  EXPECT_FALSE(fourth.from_cache);
  PackingReport fifth;
  packed_positions(s, &fifth, options());
  EXPECT_TRUE(fifth.from_cache);
}

TEST_F(PackingTest, DifferentParametersUseDifferentCacheFiles) {
  Scene s = scene(2, 16);
  PackingReport a, b;
  packed_positions(s, &a, options());
  s.packing.seed = 2;
  packed_positions(s, &b, options());
  EXPECT_NE(a.cache_file, b.cache_file);
  EXPECT_FALSE(b.from_cache);
}

TEST_F(PackingTest, DisabledPackingGivesTheLattice) {
  Scene s = scene(3, 10);
  s.packing.enabled = false;
  const ParticleArrays p = packed_positions(s, nullptr, options());
  EXPECT_DOUBLE_EQ(p.position[0][0], 0.5 * s.particle_spacing());
  EXPECT_DOUBLE_EQ(p.position[2][p.size() - 1], s.box_length() - 0.5 * s.particle_spacing());
  EXPECT_FALSE(std::filesystem::exists(cache_));
}

// A stop request or a signal must not wait for a packing that may run for minutes: the set-up polls
// `cancelled` every iteration and leaves no cache file behind.
TEST_F(PackingTest, CancelledPackingStopsWithinAnIterationAndCachesNothing) {
  Scene s = scene(2, 32);
  s.packing.tolerance = 1e-300;  // never converges: only the cancellation can end it
  s.packing.max_iterations = 1000000;
  int polls = 0;
  SetupOptions o = options();
  o.cancelled = [&] { return ++polls > 3; };
  PackingReport report;
  EXPECT_THROW(packed_positions(s, &report, o), SetupCancelled);
  EXPECT_EQ(polls, 4);
  EXPECT_FALSE(std::filesystem::exists(cache_) && !std::filesystem::is_empty(cache_));
  EXPECT_THROW(setup_run(s, o), SetupCancelled);
}

// A scene sent to the server must not choose where the server writes.
TEST(PackingCacheDirectory, IsAProgramSettingNotASceneKey) {
  try {
    parse_scene({{"case", "tgv2d"}, {"packing", {{"cache_dir", "/etc/sphles"}}}});
    FAIL() << "a scene chose the packing cache directory";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("'packing.cache_dir'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--packing-cache"), std::string::npos) << e.what();
  }
  // Documents written by earlier versions hold an empty cache_dir: still accepted.
  EXPECT_NO_THROW(parse_scene({{"case", "tgv2d"}, {"packing", {{"cache_dir", ""}}}}));
  EXPECT_FALSE(scene_to_json(parse_scene({{"case", "tgv2d"}}))["packing"].contains("cache_dir"));
}

TEST_F(PackingTest, TaylorGreen3DInitialState) {
  Scene s = scene(3, 16);
  s.packing.enabled = false;
  s.initial.mass = InitialMass::Lattice;
  const RunSetup setup = setup_run(s, options());
  const ParticleArrays& p = setup.particles;
  // (5.1) at a lattice point and mass from (5.2) via the EOS: M0 = ρ0 Δl³.
  const std::size_t i = 123;
  const double x = p.position[0][i], y = p.position[1][i], z = p.position[2][i];
  EXPECT_DOUBLE_EQ(p.velocity[0][i], std::sin(x) * std::cos(y) * std::cos(z));
  EXPECT_DOUBLE_EQ(p.velocity[1][i], -std::cos(x) * std::sin(y) * std::cos(z));
  EXPECT_DOUBLE_EQ(p.velocity[2][i], 0.0);
  const double p0_minus_ref = (2.0 + std::cos(2 * z)) * (std::cos(2 * x) + std::cos(2 * y)) / 16.0;
  EXPECT_NEAR(p.mass[i], (1.0 + p0_minus_ref / 25.0) * std::pow(s.particle_spacing(), 3), 1e-15);
  EXPECT_DOUBLE_EQ(setup.solver.support_radius, 4.0 * s.particle_spacing() * 6.0 / 8.0);
}

}  // namespace
}  // namespace sphles::sim
