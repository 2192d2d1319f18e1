// SPDX-License-Identifier: GPL-3.0-or-later
// control::ProgressReporter (control/progress.hpp): the progress line's rate and ETA, measured over
// the last minute of wall time, so that one short step (cut to land on an output time) or one slow
// one (a checkpoint) does not make them jump.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <string>

#include "control/progress.hpp"

namespace sphles::control {
using sim::StepDiagnostics;
namespace {

using Clock = ProgressReporter::Clock;

Clock::time_point at(double seconds) {
  return Clock::time_point{} +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
}

StepDiagnostics state(double time, std::uint64_t step) {
  StepDiagnostics d;
  d.time = time;
  d.step = step;
  return d;
}

/// The ETA of a line in seconds, or -1 when it has none.
long eta_seconds(const std::string& line) {
  long h = 0, m = 0, s = 0;
  const auto where = line.find("ETA ");
  if (where == std::string::npos ||
      std::sscanf(line.c_str() + where, "ETA %ld:%ld:%ld", &h, &m, &s) != 3)
    return -1;
  return 3600 * h + 60 * m + s;
}

TEST(Progress, FirstCallRecordsAndLinesComeOncePerInterval) {
  ProgressReporter r(10.0, 1.0);
  EXPECT_EQ(r.update(state(0.0, 0), at(0.0), false), "");
  EXPECT_EQ(r.update(state(0.01, 1), at(0.5), false), "");  // within the interval
  const std::string line = r.update(state(0.02, 2), at(1.0), false);
  EXPECT_NE(line.find("t = 0.0200 / 10.0000  step 2  2 steps/s  ETA 0:08:19"), std::string::npos)
      << line;
  // A forced first line has no rate yet.
  ProgressReporter forced(10.0, 1.0);
  EXPECT_NE(forced.update(state(0.0, 0), at(0.0), true).find("ETA --:--:--"), std::string::npos);
}

TEST(Progress, RateAndEtaComeFromTheLastMinuteNotTheLastInterval) {
  ProgressReporter r(10.0, 1.0);
  r.update(state(0.0, 0), at(0.0), false);
  // A step of 0.1 every 5 s of wall time: 0.02 per second.
  std::string line;
  for (int k = 1; k <= 20; ++k) line = r.update(state(0.1 * k, k), at(5.0 * k), false);
  EXPECT_EQ(eta_seconds(line), 400) << line;  // (10 - 2) / 0.02
  EXPECT_NE(line.find("0.2 steps/s"), std::string::npos) << line;
  // A step cut to 0.001 to land on an output time. Over its own interval the rate would be
  // 0.0002 per second and the ETA 11 hours; over the last minute (from the line at 45 s, 60 s
  // before) it is (2.001 - 0.9) / 60 per second.
  line = r.update(state(2.001, 21), at(105.0), false);
  EXPECT_EQ(eta_seconds(line), std::lround((10.0 - 2.001) / ((2.001 - 0.9) / 60.0))) << line;
  EXPECT_NE(line.find("0.2 steps/s"), std::string::npos) << line;  // (21 - 9) / 60
  // A checkpoint that takes 30 s: the next line's rate still counts the minute before it.
  line = r.update(state(2.101, 22), at(135.0), false);
  EXPECT_EQ(eta_seconds(line), std::lround((10.0 - 2.101) / ((2.101 - 1.5) / 60.0))) << line;
}

}  // namespace
}  // namespace sphles::control
