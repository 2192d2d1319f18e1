// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/timeseries.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace sphles::analysis {

double DissipationEstimator::add(double time, double kinetic_energy) {
  samples_.emplace_back(time, kinetic_energy);
  while (!samples_.empty() && samples_.front().first < time - window_) samples_.pop_front();
  if (samples_.size() < 2) return std::numeric_limits<double>::quiet_NaN();
  // Least-squares slope about the mean time (centred sums keep it well conditioned).
  double t_mean = 0.0, e_mean = 0.0;
  for (const auto& [t, e] : samples_) {
    t_mean += t;
    e_mean += e;
  }
  const double count = static_cast<double>(samples_.size());
  t_mean /= count;
  e_mean /= count;
  double stt = 0.0, ste = 0.0;
  for (const auto& [t, e] : samples_) {
    stt += (t - t_mean) * (t - t_mean);
    ste += (t - t_mean) * (e - e_mean);
  }
  if (!(stt > 0.0)) return std::numeric_limits<double>::quiet_NaN();
  return -ste / stt;  // ε = -de_v/dt (5.4)
}

TimeSeriesWriter::TimeSeriesWriter(const std::filesystem::path& path,
                                   const std::vector<std::string>& extra_columns, bool append)
    : path_(path), extra_columns_(extra_columns.size()) {
  const bool continue_file = append && std::filesystem::exists(path);
  file_ = std::fopen(path.c_str(), continue_file ? "a" : "w");
  if (!file_)
    throw std::runtime_error("cannot create '" + path.string() + "': " + std::strerror(errno));
  if (!continue_file) {
    std::fprintf(file_, "%s", kHeader);
    for (const std::string& column : extra_columns) std::fprintf(file_, ",%s", column.c_str());
    std::fprintf(file_, "\n");
  }
  std::fflush(file_);
}

TimeSeriesWriter::~TimeSeriesWriter() {
  if (file_) std::fclose(file_);
}

void TimeSeriesWriter::write(const sim::StepDiagnostics& d, double dissipation,
                             std::span<const double> extra) {
  if (extra.size() != extra_columns_)
    throw std::invalid_argument("timeseries: " + std::to_string(extra.size()) +
                                " extra values for " + std::to_string(extra_columns_) + " columns");
  std::fprintf(file_, "%.17g,%llu,%.17g,%.17g,%.17g,%.17g,%.17g", d.time,
               static_cast<unsigned long long>(d.step), d.dt, d.kinetic_energy, dissipation,
               d.max_density_deviation, d.max_speed);
  for (const double value : extra) std::fprintf(file_, ",%.17g", value);
  std::fprintf(file_, "\n");
  if (std::fflush(file_) != 0)
    throw std::runtime_error("cannot write '" + path_.string() + "': " + std::strerror(errno));
}

}  // namespace sphles::analysis
