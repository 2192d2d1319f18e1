// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/progress.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace sphles::control {

ProgressReporter::ProgressReporter(double end_time, double interval_seconds)
    : end_time_(end_time), interval_(interval_seconds) {}

std::string ProgressReporter::update(const sim::StepDiagnostics& d, Clock::time_point now,
                                     bool force) {
  const auto seconds_since = [&](const Sample& s) {
    return std::chrono::duration<double>(now - s.wall).count();
  };
  const bool first_call = samples_.empty();
  if (first_call) {
    samples_.push_back({now, d.time, d.step});
    if (!force) return {};
  }
  if (!force && seconds_since(samples_.back()) < interval_) return {};
  // The oldest sample within the window, or the newest one before this line.
  while (samples_.size() > 1 && seconds_since(samples_[1]) >= kRateWindowSeconds)
    samples_.pop_front();
  const Sample& first = samples_.front();
  const double elapsed = seconds_since(first);
  const double steps_per_second =
      elapsed > 0.0 ? static_cast<double>(d.step - first.step) / elapsed : 0.0;
  const double sim_rate = elapsed > 0.0 ? (d.time - first.time) / elapsed : 0.0;
  std::string eta = "--:--:--";
  if (sim_rate > 0.0) {
    const long seconds = std::lround(std::max(0.0, end_time_ - d.time) / sim_rate);
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%ld:%02ld:%02ld", seconds / 3600, (seconds / 60) % 60,
                  seconds % 60);
    eta = buffer;
  }
  char line[256];
  std::snprintf(line, sizeof line,
                "t = %.4f / %.4f  step %llu  %.3g steps/s  ETA %s  e_v = %.6g  "
                "max|drho|/rho = %.3g  max|v| = %.4g",
                d.time, end_time_, static_cast<unsigned long long>(d.step), steps_per_second,
                eta.c_str(), d.kinetic_energy, d.max_density_deviation, d.max_speed);
  if (!first_call) samples_.push_back({now, d.time, d.step});  // the first is stored above
  return line;
}

}  // namespace sphles::control
