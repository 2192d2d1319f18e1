// The per-run time series file (timeseries.csv) and the progress line of a run.
#pragma once

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>

#include "sim/solver.hpp"

namespace sphles::sim {

/// timeseries.csv with the stable columns
///   t,step,dt,e_v,max_density_deviation,max_speed
/// (SI units; e_v of (5.3)); numbers in full precision. Rows are flushed as written.
class TimeSeriesWriter {
 public:
  static constexpr const char* kHeader = "t,step,dt,e_v,max_density_deviation,max_speed";

  /// Creates (truncates) the file; throws std::runtime_error naming the path on failure.
  explicit TimeSeriesWriter(const std::filesystem::path& path);
  ~TimeSeriesWriter();
  TimeSeriesWriter(const TimeSeriesWriter&) = delete;
  TimeSeriesWriter& operator=(const TimeSeriesWriter&) = delete;

  void write(const StepDiagnostics& diagnostics);

 private:
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
};

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
