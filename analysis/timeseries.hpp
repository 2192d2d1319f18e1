// SPDX-License-Identifier: GPL-3.0-or-later
// Per-step energy history: e_v (5.3) from the solver, ε = -de_v/dt from a smoothed slope, and
// the timeseries.csv writer.
#pragma once

#include <cstdio>
#include <deque>
#include <filesystem>
#include <span>
#include <string>
#include <utility>
#include <vector>

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
/// followed by the case's own columns (sim::case_diagnostic_names, e.g. the Kolmogorov energy
/// budget) (SI units); numbers in full precision, "nan" where undefined; rows flushed as written.
class TimeSeriesWriter {
 public:
  static constexpr const char* kHeader =
      "t,step,dt,e_v,dissipation,max_density_deviation,max_speed";

  /// Creates (truncates) the file; throws std::runtime_error naming the path on failure.
  /// With `append`, an existing file is continued (no header); otherwise it is truncated.
  TimeSeriesWriter(const std::filesystem::path& path,
                   const std::vector<std::string>& extra_columns = {}, bool append = false);
  ~TimeSeriesWriter();
  TimeSeriesWriter(const TimeSeriesWriter&) = delete;
  TimeSeriesWriter& operator=(const TimeSeriesWriter&) = delete;

  void write(const sim::StepDiagnostics& diagnostics, double dissipation,
             std::span<const double> extra = {});

 private:
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
  std::size_t extra_columns_ = 0;
};

}  // namespace sphles::analysis
