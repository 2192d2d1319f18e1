// SPDX-License-Identifier: GPL-3.0-or-later
// sim::Cadence (sim/cadence.hpp): the points k · every a run lands on, the same in a fresh and in
// a restarted run.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "sim/cadence.hpp"

namespace sphles::sim {
namespace {

TEST(Cadence, LandsOnEveryPointAndTakesEachOnce) {
  Cadence c(0.1, 0.0);
  ASSERT_TRUE(c.active());
  double t = 0.0;
  int taken = 0;
  // Steps of 0.035: cut to land on 0.1, 0.2, ... (as a run's loop does).
  while (t < 1.0 - 1e-12) {
    t += c.limit_step(t, std::min(0.035, 1.0 - t));
    if (c.take(t)) {
      ++taken;
      EXPECT_NEAR(t, 0.1 * taken, 1e-15);
    }
    EXPECT_FALSE(c.take(t)) << "a point taken twice at t = " << t;
  }
  EXPECT_EQ(taken, 10);
  EXPECT_NEAR(c.next(), 1.1, 1e-15);
}

TEST(Cadence, RestartOnAPointContinuesWithTheSamePoints) {
  Cadence fresh(0.25, 0.0);
  for (double t : {0.25, 0.5, 0.75}) ASSERT_TRUE(fresh.take(t));
  // A restart at t = 0.75 (as stored, within rounding of the point) counts 0.75 as taken.
  for (double t0 : {0.75, std::nextafter(0.75, 0.0), std::nextafter(0.75, 1.0)}) {
    const Cadence restarted(0.25, t0);
    EXPECT_EQ(restarted.next(), fresh.next()) << t0;
    EXPECT_EQ(restarted.limit_step(t0, 1.0), fresh.next() - t0);
  }
  // A step that lands within 1e-12 of the cadence below a point reaches it.
  Cadence c(0.25, 0.0);
  EXPECT_FALSE(c.take(0.25 - 1e-11));
  EXPECT_TRUE(c.take(0.25 - 1e-14));
}

TEST(Cadence, InactiveHasNoPoints) {
  Cadence c(0.0, 3.0);
  EXPECT_FALSE(c.active());
  EXPECT_EQ(c.next(), std::numeric_limits<double>::infinity());
  EXPECT_EQ(c.limit_step(3.0, 0.5), 0.5);
  EXPECT_FALSE(c.take(1e9));
}

TEST(Cadence, EndTimeIsReachedWithinTheLastStepsRounding) {
  EXPECT_TRUE(reached_end(2.0, 2.0));
  EXPECT_TRUE(reached_end(2.0 - 1e-13, 2.0));
  EXPECT_FALSE(reached_end(2.0 - 1e-10, 2.0));
}

}  // namespace
}  // namespace sphles::sim
