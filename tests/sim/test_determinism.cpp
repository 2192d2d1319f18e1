// SPDX-License-Identifier: GPL-3.0-or-later
// Bitwise-identical results for any thread count: gather-form passes and fixed-order reductions.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cstring>
#include <random>

#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::sim {
namespace {

ParticleArrays run_with_threads(int threads, int dim, SchemeType scheme) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  auto flow = testing::random_flow(dim, dim == 3 ? 12 : 40, dim == 3 ? 6.0 : 8.0, 1.0, 11);
  flow.config.scheme.type = scheme;
  auto sim = make_simulation(flow.config, flow.particles);
  for (int step = 0; step < 60; ++step) sim->step();
  omp_set_num_threads(saved);
  return sim->particles();
}

bool bitwise_equal(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

class DeterminismTest : public ::testing::TestWithParam<std::tuple<int, SchemeType>> {};

TEST_P(DeterminismTest, OneAndTwoThreadsGiveIdenticalState) {
  const auto [dim, scheme] = GetParam();
  const ParticleArrays one = run_with_threads(1, dim, scheme);
  for (const int threads : {2, 3}) {
    const ParticleArrays many = run_with_threads(threads, dim, scheme);
    EXPECT_EQ(one.id, many.id) << threads << " threads";
    for (int d = 0; d < dim; ++d) {
      EXPECT_TRUE(bitwise_equal(one.position[d], many.position[d])) << threads << " threads";
      EXPECT_TRUE(bitwise_equal(one.velocity[d], many.velocity[d])) << threads << " threads";
      EXPECT_TRUE(bitwise_equal(one.acceleration[d], many.acceleration[d]))
          << threads << " threads";
    }
    EXPECT_TRUE(bitwise_equal(one.density, many.density)) << threads << " threads";
    EXPECT_TRUE(bitwise_equal(one.pressure, many.pressure)) << threads << " threads";
  }
}

// The state does not depend on where the particles sit in the arrays: the same particles given
// in a shuffled order (ids kept) give the same particle states, by id, bit for bit after 60
// steps, because each particle's neighbours are listed in id order within a cell. This is what
// lets a rank that holds a subset of the particles (par/) compute the one-process answer.
TEST_P(DeterminismTest, ShuffledInputGivesIdenticalStateById) {
  const auto [dim, scheme] = GetParam();
  auto flow = testing::random_flow(dim, dim == 3 ? 12 : 40, dim == 3 ? 6.0 : 8.0, 1.0, 11);
  flow.config.scheme.type = scheme;
  std::vector<std::uint32_t> shuffle(flow.particles.size());
  for (std::uint32_t k = 0; k < shuffle.size(); ++k) shuffle[k] = k;
  std::shuffle(shuffle.begin(), shuffle.end(), std::mt19937_64(5));
  ParticleArrays shuffled = flow.particles;
  shuffled.reorder(shuffle);
  auto a = make_simulation(flow.config, flow.particles);
  auto b = make_simulation(flow.config, shuffled);
  for (int step = 0; step < 60; ++step) {
    a->step();
    b->step();
  }
  const ParticleArrays& pa = a->particles();
  const ParticleArrays& pb = b->particles();
  std::vector<std::size_t> where(pb.size());
  for (std::size_t i = 0; i < pb.size(); ++i) where[pb.id[i]] = i;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    const std::size_t k = where[pa.id[i]];
    bool same = pa.density[i] == pb.density[k];
    for (int d = 0; d < dim; ++d)
      same =
          same && pa.position[d][i] == pb.position[d][k] && pa.velocity[d][i] == pb.velocity[d][k];
    differ += same ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u) << differ << " of " << pa.size() << " particles differ";
  EXPECT_EQ(a->time(), b->time());
}

INSTANTIATE_TEST_SUITE_P(DimensionsAndSchemes, DeterminismTest,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::Values(SchemeType::Thesis,
                                                              SchemeType::TransportVelocity)),
                         [](const auto& info) {
                           return std::to_string(std::get<0>(info.param)) + "D_" +
                                  std::string(scheme_name(std::get<1>(info.param)));
                         });

}  // namespace
}  // namespace sphles::sim
