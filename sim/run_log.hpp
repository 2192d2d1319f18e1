// The progress line of a run.
#pragma once

#include <chrono>
#include <string>

#include "sim/solver.hpp"

namespace sphles::sim {

/// Formats "t = 1.200 / 15.000  step 120  41.2 steps/s  ETA 0:05:12  e_v = 0.12312".
/// The rate is measured between consecutive calls of update().
class ProgressReporter {
 public:
  ProgressReporter(double end_time, double interval_seconds);
  /// Returns a line when `interval_seconds` have passed since the last one (or `force`), else "".
  std::string update(const StepDiagnostics& diagnostics, bool force = false);

 private:
  using Clock = std::chrono::steady_clock;
  double end_time_;
  double interval_;
  Clock::time_point last_wall_;
  double last_time_ = 0.0;
  std::uint64_t last_step_ = 0;
  bool started_ = false;
};

}  // namespace sphles::sim
