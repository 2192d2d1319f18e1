// SPDX-License-Identifier: GPL-3.0-or-later
// Reductions (sim/reduction.hpp): the exact sum is independent of order and splitting, exact,
// and rounds to nearest; deterministic_sum is independent of the thread count.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "sim/reduction.hpp"

namespace sphles::sim {
namespace {

double exact(const std::vector<double>& values) {
  ExactSum s;
  for (const double v : values) s.add(v);
  return s.value();
}

/// Values of every magnitude, both signs, with cancellations and subnormals.
std::vector<double> wild_values(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-1070, 1000);
  std::vector<double> v;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = std::ldexp(mantissa(rng), exponent(rng) / (i % 3 == 0 ? 1 : 20));
    v.push_back(x);
    if (i % 10 == 0) v.push_back(-x);  // exact cancellation
  }
  v.push_back(std::numeric_limits<double>::denorm_min());
  v.push_back(-3.0 * std::numeric_limits<double>::denorm_min());
  return v;
}

TEST(ExactSum, SameBitsForAnyOrderAndAnySplit) {
  std::vector<double> v = wild_values(20000, 1);
  const double reference = exact(v);
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 5; ++trial) {
    std::shuffle(v.begin(), v.end(), rng);
    EXPECT_EQ(exact(v), reference);
    // Split into partial sums merged in another order (threads, ranks).
    ExactSum a, b, c;
    for (std::size_t i = 0; i < v.size(); ++i) (i % 3 == 0 ? a : i % 3 == 1 ? b : c).add(v[i]);
    c.add(a);
    c.add(b);
    EXPECT_EQ(c.value(), reference);
    const ExactSum back = ExactSum::from_limbs(c.normalized_limbs(), c.special());
    EXPECT_EQ(back.value(), reference);
  }
  // exact_sum: the same for 1 and 2 threads and equal to the sequential exact sum.
  const auto term = [&](std::size_t i) { return v[i]; };
  omp_set_num_threads(1);
  const double one = exact_sum(v.size(), term).value();
  omp_set_num_threads(2);
  EXPECT_EQ(exact_sum(v.size(), term).value(), one);
  EXPECT_EQ(one, reference);
}

TEST(ExactSum, ExactWhereFloatingPointSumsAreNot) {
  EXPECT_EQ(exact({1e16, 1.0, -1e16}), 1.0);        // naive: 0
  EXPECT_EQ(exact({1e308, 1e308, -1e308}), 1e308);  // naive: ∞
  const double tiny = std::numeric_limits<double>::denorm_min();
  EXPECT_EQ(exact({tiny, -tiny}), 0.0);
  EXPECT_EQ(exact({tiny, tiny, tiny}), 3.0 * tiny);
  EXPECT_EQ(exact({-2.5, 1.0}), -1.5);
  EXPECT_EQ(exact({}), 0.0);
  EXPECT_EQ(exact({-0.0, 0.0, -0.0}), 0.0);
  // The ends of the range: the largest double, and subnormals adding up to the smallest normal.
  const double huge = std::numeric_limits<double>::max();
  EXPECT_EQ(exact({huge, -huge, huge}), huge);
  EXPECT_EQ(exact({-huge, tiny}), -huge);
  const double smallest_normal = std::numeric_limits<double>::min();
  EXPECT_EQ(exact({smallest_normal - tiny, tiny}), smallest_normal);
  EXPECT_EQ(exact({smallest_normal, -tiny}), smallest_normal - tiny);
  // Ten times the double nearest 0.1 is 1 + 5.55e-17, which rounds to 1 (the naive sum gives
  // 0.9999999999999999).
  EXPECT_EQ(exact(std::vector<double>(10, 0.1)), 1.0);
}

// Against exact integer arithmetic: integers of up to 62 bits times 2^-40 sum exactly in
// __int128, and the exact sum must come out as the correctly rounded value of that.
TEST(ExactSum, RoundsTheExactSumToNearest) {
  __extension__ using Int128 = __int128;
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    ExactSum s;
    Int128 total = 0;
    const int count = 1 + trial % 50;
    for (int k = 0; k < count; ++k) {
      // 53-bit integers shifted by up to 9 bits: exact as doubles.
      const auto m = static_cast<std::int64_t>(rng() >> 11) * ((rng() & 1) ? 1 : -1);
      const int shift = static_cast<int>(rng() % 10);
      total += static_cast<Int128>(m) << shift;
      s.add(std::ldexp(static_cast<double>(m), shift - 40));
    }
    // (double) of an __int128 rounds to nearest, ties to even; scaling by 2^-40 is exact.
    EXPECT_EQ(s.value(), std::ldexp(static_cast<double>(total), -40)) << "trial " << trial;
  }
}

TEST(ExactSum, NonFiniteValuesSumAsIeeeAdditionDoes) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(exact({1.0, inf, 2.0}), inf);
  EXPECT_EQ(exact({-inf, 1.0}), -inf);
  EXPECT_TRUE(std::isnan(exact({inf, -inf})));
  EXPECT_TRUE(std::isnan(exact({1.0, std::nan("")})));
}

}  // namespace
}  // namespace sphles::sim
