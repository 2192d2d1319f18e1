// Per-step energy history: e_v (5.3) from the solver, ε = -de_v/dt from a smoothed slope, and
// the timeseries.csv writer.
#pragma once

#include <cstdio>
#include <deque>
#include <filesystem>
#include <utility>

#include "sim/solver.hpp"

namespace sphles::analysis {

/// ε(t) = -de_v/dt as the least-squares slope of e_v over the trailing window [t - w, t].
/// A trailing window lags the true derivative by about w/2 but needs no future values, so it
/// can be reported live; it averages out the acoustic oscillations of a weakly compressible
/// run. NaN until two samples are in the window.
class DissipationEstimator {
 public:
  explicit DissipationEstimator(double window) : window_(window) {}
  double add(double time, double kinetic_energy);
  double window() const { return window_; }

 private:
  double window_;
  std::deque<std::pair<double, double>> samples_;
};

/// timeseries.csv with the stable columns
///   t,step,dt,e_v,dissipation,max_density_deviation,max_speed
/// (SI units); numbers in full precision, "nan" where undefined; rows flushed as written.
class TimeSeriesWriter {
 public:
  static constexpr const char* kHeader =
      "t,step,dt,e_v,dissipation,max_density_deviation,max_speed";

  /// Creates (truncates) the file; throws std::runtime_error naming the path on failure.
  explicit TimeSeriesWriter(const std::filesystem::path& path);
  ~TimeSeriesWriter();
  TimeSeriesWriter(const TimeSeriesWriter&) = delete;
  TimeSeriesWriter& operator=(const TimeSeriesWriter&) = delete;

  void write(const sim::StepDiagnostics& diagnostics, double dissipation);

 private:
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
};

}  // namespace sphles::analysis
