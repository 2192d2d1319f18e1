// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/frame_reader.hpp"

#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/snapshot.hpp"
#include "analysis/writer.hpp"

namespace sphles::analysis {

namespace fs = std::filesystem;

namespace {

using Row = std::map<std::string, std::string>;

std::uint64_t count_cell(const Row& row, const std::string& column, const fs::path& file) {
  const double value = index_number(row, column, file);
  if (!(value >= 0.0) || value != std::floor(value))
    throw std::runtime_error("'" + file.string() + "': '" + column + "' is not a count");
  return static_cast<std::uint64_t>(value);
}

/// A histogram's bin count from its bins' width (the bounds are b/bins and (b + 1)/bins).
int bins_of(double lo, double hi, const fs::path& file) {
  const double bins = std::round(1.0 / (hi - lo));
  if (!(bins >= 1.0 && bins <= 1e6))
    throw std::runtime_error("'" + file.string() + "': bin bounds " + std::to_string(lo) + ", " +
                             std::to_string(hi) + " are not a regular histogram's");
  return static_cast<int>(bins);
}

/// The spectrum product of the frame at the index row `row` (spectra/index.csv).
SpectrumProduct read_spectrum(const fs::path& directory, const Row& row) {
  const fs::path index = directory / "spectra" / "index.csv";
  SpectrumProduct s;
  s.kinetic_energy_grid = index_number(row, "e_v_grid", index);
  s.dissipation = index_number(row, "dissipation_spectral", index);
  s.dissipation_resolved = index_number(row, "dissipation_spectral_resolved", index);
  s.kernel_wavenumber = index_number(row, "k_kernel", index);
  s.resolution_wavenumber = index_number(row, "k_resolution", index);
  s.spectrum.delta_k = index_number(row, "delta_k", index);
  s.length_scale = index_number(row, "L_c", index);
  const fs::path file = directory / "spectra" / row.at("file");
  if (!fs::exists(file)) throw std::runtime_error("'" + file.string() + "' is missing");
  for (const Row& shell : read_index(file)) {
    s.spectrum.wavenumber.push_back(index_number(shell, "k", file));
    s.spectrum.energy.push_back(index_number(shell, "E", file));
  }
  return s;
}

/// The sub-filter statistics of the frame at `time`: the joint histogram (only its non-empty
/// bins are on disk), the polar one in 2D, and the norms of the frame's summary row.
SubfilterStatisticsProduct read_statistics(const fs::path& directory, double time, double threshold,
                                           const Row& summary, const fs::path& summary_file) {
  SubfilterStatisticsProduct s;
  s.max_norm = index_number(summary, "tau_sfs_max", summary_file);
  s.mean_norm = index_number(summary, "tau_sfs_mean", summary_file);
  const fs::path joint = directory / "stats" / timed_file_name("joint_tau_omega2", time, ".csv");
  const std::vector<Row> bins = read_index(joint);
  // Every particle falls into a bin (analysis/statistics.cpp): at least one row.
  if (bins.empty()) throw std::runtime_error("'" + joint.string() + "' is missing or empty");
  Histogram2D& h = s.joint;
  h.bins_x = bins_of(index_number(bins[0], "tau_lo", joint), index_number(bins[0], "tau_hi", joint),
                     joint);
  h.bins_y = bins_of(index_number(bins[0], "omega2_lo", joint),
                     index_number(bins[0], "omega2_hi", joint), joint);
  h.counts.assign(static_cast<std::size_t>(h.bins_x) * static_cast<std::size_t>(h.bins_y), 0);
  for (const Row& bin : bins) {
    const auto bx =
        static_cast<std::size_t>(std::lround(index_number(bin, "tau_lo", joint) * h.bins_x));
    const auto by =
        static_cast<std::size_t>(std::lround(index_number(bin, "omega2_lo", joint) * h.bins_y));
    if (bx >= static_cast<std::size_t>(h.bins_x) || by >= static_cast<std::size_t>(h.bins_y))
      throw std::runtime_error("'" + joint.string() + "': a bin lies outside [0, 1]²");
    const std::uint64_t count = count_cell(bin, "count", joint);
    h.counts[bx + static_cast<std::size_t>(h.bins_x) * by] = count;
    h.total += count;
  }
  const fs::path polar = directory / "stats" / timed_file_name("alignment", time, ".csv");
  if (fs::exists(polar)) {
    AngleHistogram a;
    a.threshold = threshold;
    for (const Row& bin : read_index(polar)) {
      a.counts.push_back(count_cell(bin, "count", polar));
      a.total += a.counts.back();
    }
    a.bins = static_cast<int>(a.counts.size());
    s.alignment = std::move(a);
  }
  return s;
}

}  // namespace

std::optional<AnalysisFrame> read_latest_frame(const fs::path& directory,
                                               const AnalysisConfig& config) {
  const fs::path summary_file = directory / "stats" / "snapshots.csv";
  const std::vector<Row> rows = read_index(summary_file);
  // The last row may be one being appended (or cut short by a crash): the newest whole row.
  auto it = rows.rbegin();
  while (it != rows.rend() && !it->contains("dissipation_energy")) ++it;
  if (it == rows.rend()) return std::nullopt;
  const Row& summary = *it;
  AnalysisFrame frame;
  frame.time = index_number(summary, "t", summary_file);
  frame.step = count_cell(summary, "step", summary_file);
  frame.kinetic_energy = index_number(summary, "e_v", summary_file);
  frame.energy_dissipation = index_number(summary, "dissipation_energy", summary_file);
  frame.total_seconds = index_number(summary, "analysis_seconds", summary_file);
  frame.dropped_snapshots = count_cell(summary, "dropped_snapshots", summary_file);
  const double grid_energy = index_number(summary, "e_v_grid", summary_file);
  if (!std::isnan(grid_energy)) frame.grid_kinetic_energy = grid_energy;
  const double mean_omega2 = index_number(summary, "mean_omega2", summary_file);
  if (!std::isnan(mean_omega2))
    frame.vorticity =
        VorticityProduct{config.gridding.vorticity, mean_omega2,
                         index_number(summary, "dissipation_vorticity", summary_file)};
  if (!std::isnan(index_number(summary, "dissipation_spectral", summary_file))) {
    // The frame's spectrum: its row in spectra/index.csv (the same time, written the same way).
    for (const Row& row : read_index(directory / "spectra" / "index.csv"))
      if (row.contains("L_c") && row.at("t") == summary.at("t"))
        frame.spectrum = read_spectrum(directory, row);
    if (!frame.spectrum)
      throw std::runtime_error("'" + (directory / "spectra" / "index.csv").string() +
                               "' lists no spectrum at t = " + summary.at("t"));
  }
  if (!std::isnan(index_number(summary, "tau_sfs_max", summary_file)))
    frame.subfilter =
        read_statistics(directory, frame.time, config.angle_threshold, summary, summary_file);
  return frame;
}

}  // namespace sphles::analysis
