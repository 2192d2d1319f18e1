// SPDX-License-Identifier: GPL-3.0-or-later
// The progress line of a run.
#pragma once

#include <chrono>
#include <deque>
#include <string>

#include "sim/solver.hpp"

namespace sphles::control {

/// Formats "t = 1.200 / 15.000  step 120  41.2 steps/s  ETA 0:05:12  e_v = 0.12312".
/// The rate and the ETA are measured over the lines of about the last kRateWindowSeconds of wall
/// time (at least the last two), as the dashboard's ETA is: a single interval would make them
/// jump with every step shortened to land on an output time or slowed by a checkpoint.
class ProgressReporter {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr double kRateWindowSeconds = 60.0;

  ProgressReporter(double end_time, double interval_seconds);
  /// Returns a line when `interval_seconds` have passed since the last one (or `force`), else "".
  std::string update(const sim::StepDiagnostics& diagnostics, bool force = false) {
    return update(diagnostics, Clock::now(), force);
  }
  /// The same at wall time `now` (for tests).
  std::string update(const sim::StepDiagnostics& diagnostics, Clock::time_point now, bool force);

 private:
  struct Sample {
    Clock::time_point wall;
    double time;
    std::uint64_t step;
  };
  double end_time_;
  double interval_;
  std::deque<Sample> samples_;  // the first call's state, then one per line, oldest first
};

}  // namespace sphles::control
