// SPDX-License-Identifier: GPL-3.0-or-later
// Cadences in simulated time: the points k · every (k = 1, 2, ...) at which a run writes a row,
// publishes an analysis snapshot, saves a checkpoint or samples a benchmark. The step before a
// point is cut short to land on it; the point is due once the time reaches it. One type for the
// run loop (control/run.cpp) and the benchmarks, so that every loop lands on the same points.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace sphles::sim {

class Cadence {
 public:
  /// Points k · every after `time` (every <= 0: none). The points at or before `time` count as
  /// taken, computed the same way in a fresh and in a restarted run, so both take the same steps.
  Cadence(double every, double time)
      : every_(every),
        taken_(every > 0.0 ? static_cast<std::uint64_t>(std::floor(time / every + kSnap)) : 0) {}

  bool active() const { return every_ > 0.0; }
  double every() const { return every_; }

  /// The next point, +inf when inactive.
  double next() const {
    return active() ? static_cast<double>(taken_ + 1) * every_
                    : std::numeric_limits<double>::infinity();
  }

  /// The largest step from `time` that does not pass the next point, at most `max_dt`.
  double limit_step(double time, double max_dt) const {
    return active() ? std::min(max_dt, next() - time) : max_dt;
  }

  /// Whether the next point is reached at `time` (within 1e-12 of the cadence: the step that
  /// landed on it rounds); if so it is taken.
  bool take(double time) {
    if (!active() || time < next() - kReach * every_) return false;
    ++taken_;
    return true;
  }

 private:
  static constexpr double kSnap = 1e-9;    // of `every`: a restart time on a point is on it
  static constexpr double kReach = 1e-12;  // of `every`: a step that landed on a point reached it
  double every_;
  std::uint64_t taken_;
};

/// Whether `time` has reached the end time (within 1e-12 of it, the rounding of the last step
/// that was cut to land on it).
inline bool reached_end(double time, double end_time) {
  return time >= end_time - 1e-12 * end_time;
}

}  // namespace sphles::sim
