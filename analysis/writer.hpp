// SPDX-License-Identifier: GPL-3.0-or-later
// Writes analysis frames into a run directory (file formats in docs/analysis.md):
//   spectra/E_t{t}.csv + spectra/index.csv      energy spectra
//   slices/{field}_t{t}.npy + .vti + {field}.pvd  2D slices (NumPy .npy, float64, C order;
//                                                VTK image data; ParaView time series)
//   slices/index.csv                             one row per slice file
//   stats/snapshots.csv                          one row of scalars per analysed snapshot
//   stats/joint_tau_omega2_t{t}.csv              bivariate histogram (τ*, ω²*)
//   stats/alignment_t{t}.csv                     polar histogram of γ (2D runs)
//   snapshots/particles_t{t}.h5 + index.csv + particles.xdmf   particle data for ParaView
//   fields/fields_t{t}.vti + index.csv + fields.pvd   the whole analysis grid (VTK image data)
// Every file is written to a temporary name and renamed, so no reader sees half a file.
#pragma once

#include <filesystem>
#include <map>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "analysis/products.hpp"
#include "io/particle_snapshot.hpp"

namespace sphles::analysis {

/// The rows of a CSV index (header name → cell; sphles' indexes quote nothing). A missing file
/// has no rows; a row shorter than the header (being appended) lacks the missing cells.
std::vector<std::map<std::string, std::string>> read_index(const std::filesystem::path& path);

/// The number in `column` of a row read_index gave from `file` (the writer writes "nan" for what
/// a frame lacks). Throws std::runtime_error naming the file and the column when the cell is
/// missing, empty or not wholly a number.
double index_number(const std::map<std::string, std::string>& row, const std::string& column,
                    const std::filesystem::path& file);

/// Writes `content` to `path` through a temporary file (PATH.tmp) renamed over it: no reader sees
/// half a file, and a crash leaves the old file or the new one.
void replace_atomically(const std::filesystem::path& path, const std::string& content);

/// Keeps the header and the rows whose first column (the time) is at most `time` of an
/// existing CSV (an index or timeseries.csv; nothing if it does not exist). A restart from a
/// checkpoint at `time` writes every later row again, and a crash after that checkpoint may
/// have left some of them; a row cut short or without a time is dropped too, and a file
/// without a whole header line is removed.
void truncate_rows_after(const std::filesystem::path& path, double time);

/// truncate_rows_after for every CSV a restart of a run (particle or reference) continues:
/// timeseries.csv, frames/index.csv and the indices RunDirectoryWriter appends to.
void truncate_run_files_after(const std::filesystem::path& run_directory, double time);

/// Writes a 2D float64 array as NumPy .npy (format 1.0) with shape (rows, columns).
void write_npy(const std::filesystem::path& path, std::span<const double> values, std::size_t rows,
               std::size_t columns);

class RunDirectoryWriter {
 public:
  /// Creates the sub-directories; throws std::runtime_error naming the path on failure.
  /// `metadata` (scene JSON, code version) is stored in particle snapshots and images.
  explicit RunDirectoryWriter(std::filesystem::path directory, io::SnapshotMetadata metadata = {});

  /// Writes the frame's products. Errors are kept (last_error) rather than thrown, because this
  /// runs on the analysis thread.
  void write(const AnalysisFrame& frame);

  std::string last_error() const;

  /// Where the ranks of a distributed run write the product "particles" themselves, as this
  /// writer would (analysis::make_snapshot): snapshots/ with this writer's metadata.
  ParticleFileTarget particle_target() const;

 private:
  void write_or_throw(const AnalysisFrame& frame);
  void write_spectrum(const AnalysisFrame& frame, const SpectrumProduct& spectrum);
  void write_slice(const AnalysisFrame& frame, const SliceProduct& slice);
  void write_statistics(const AnalysisFrame& frame, const SubfilterStatisticsProduct& statistics);
  void write_particles(const AnalysisFrame& frame, const ParticlesProduct& particles);
  void write_fields(const AnalysisFrame& frame, const GridFieldsProduct& fields);
  void write_summary(const AnalysisFrame& frame);
  std::filesystem::path directory_;
  io::SnapshotMetadata metadata_;
  mutable std::mutex mutex_;
  std::string last_error_;
};

}  // namespace sphles::analysis
