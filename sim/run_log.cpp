#include "sim/run_log.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace sphles::sim {

ProgressReporter::ProgressReporter(double end_time, double interval_seconds)
    : end_time_(end_time), interval_(interval_seconds) {}

std::string ProgressReporter::update(const StepDiagnostics& d, bool force) {
  const auto now = Clock::now();
  if (!started_) {
    started_ = true;
    last_wall_ = now;
    last_time_ = d.time;
    last_step_ = d.step;
    if (!force) return {};
  }
  const double elapsed = std::chrono::duration<double>(now - last_wall_).count();
  if (!force && elapsed < interval_) return {};
  const double steps_per_second =
      elapsed > 0.0 ? static_cast<double>(d.step - last_step_) / elapsed : 0.0;
  const double sim_rate = elapsed > 0.0 ? (d.time - last_time_) / elapsed : 0.0;
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
                "t = %.4f / %.4f  step %llu  %.1f steps/s  ETA %s  e_v = %.6g  "
                "max|drho|/rho = %.3g  max|v| = %.4g",
                d.time, end_time_, static_cast<unsigned long long>(d.step), steps_per_second,
                eta.c_str(), d.kinetic_energy, d.max_density_deviation, d.max_speed);
  last_wall_ = now;
  last_time_ = d.time;
  last_step_ = d.step;
  return line;
}

}  // namespace sphles::sim
