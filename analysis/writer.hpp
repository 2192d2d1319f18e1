// Writes analysis frames into a run directory (file formats in docs/analysis.md):
//   spectra/E_t{t}.csv + spectra/index.csv      energy spectra
//   slices/{field}_t{t}.npy + slices/index.csv   2D slices (NumPy .npy, float64, C order)
//   stats/snapshots.csv                          one row of scalars per analysed snapshot
//   stats/joint_tau_omega2_t{t}.csv              bivariate histogram (τ*, ω²*)
//   stats/alignment_t{t}.csv                     polar histogram of γ (2D runs)
//   snapshots/particles_t{t}.h5 + index.csv + particles.xdmf   particle data for ParaView
// Every file is written to a temporary name and renamed, so no reader sees half a file.
#pragma once

#include <filesystem>
#include <mutex>
#include <span>
#include <string>

#include "analysis/products.hpp"

namespace sphles::analysis {

/// "{prefix}_t{time with 4 decimals}{extension}", e.g. E_t14.0000.csv.
std::string timed_file_name(const std::string& prefix, double time, const std::string& extension);

/// Writes a 2D float64 array as NumPy .npy (format 1.0) with shape (rows, columns).
void write_npy(const std::filesystem::path& path, std::span<const double> values, std::size_t rows,
               std::size_t columns);

class RunDirectoryWriter {
 public:
  /// Creates the sub-directories; throws std::runtime_error naming the path on failure.
  /// `scene_json` is stored in particle snapshots.
  explicit RunDirectoryWriter(std::filesystem::path directory, std::string scene_json = "{}");

  /// Writes the frame's products. Errors are kept (last_error) rather than thrown, because this
  /// runs on the analysis thread.
  void write(const AnalysisFrame& frame);

  std::string last_error() const;

 private:
  void write_or_throw(const AnalysisFrame& frame);
  std::filesystem::path directory_;
  std::string scene_json_;
  mutable std::mutex mutex_;
  std::string last_error_;
};

}  // namespace sphles::analysis
