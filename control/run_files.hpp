// SPDX-License-Identifier: GPL-3.0-or-later
// The files of a run directory that run control reads and writes itself (docs/analysis.md,
// "Run directory"): atomic text writes (run.json, scene.json), the time series a restart
// continues, the directory's identity, and the summary of what it holds.
#pragma once

#include <sys/stat.h>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "analysis/timeseries.hpp"
#include "control/run_types.hpp"

namespace sphles::control {

/// The whole content of a text file; empty if it cannot be read.
std::string read_text(const std::filesystem::path& path);

/// Writes `text` to a temporary beside `path`, then renames it over `path`.
void write_text_atomically(const std::filesystem::path& path, const std::string& text);

/// Feeds the (t, e_v) rows of a time series inside the estimator's window before `time`.
void seed_dissipation(const std::filesystem::path& path, double time,
                      analysis::DissipationEstimator& estimator);

/// A file written under a temporary name and renamed into place when complete (NAME.tmp,
/// NAME.tmp.PID, NAME.tmp.PID.N): never a valid output while it has that name.
bool is_temporary_file(const std::string& name);

/// Removes the temporaries that interrupted writes (a crash, SIGKILL, a full disk between the
/// write and its rename) left in `dir` and its subdirectories. Only where nothing writes.
void remove_interrupted_writes(const std::filesystem::path& dir);

/// Moves a run directory to `trash`, replacing what is there; false when the directory is gone
/// already (deleted by hand), which leaves nothing to move. Throws on failure.
bool move_to_trash(const std::filesystem::path& dir, const std::filesystem::path& trash);

/// What a failed run says of the checkpoints it leaves: "; last valid checkpoint: checkpoints/
/// NAME" (the newest that reads whole), or that none was written or none is valid.
std::string checkpoints_left(const std::filesystem::path& checkpoint_dir);

/// Device and inode of a directory; nullopt if it does not exist.
std::optional<std::pair<dev_t, ino_t>> directory_identity(const std::filesystem::path& path);

/// What the run directory holds, from its indexes (so every session of a restarted run counts):
/// for each kind of output, how many and at which times, and the index listing the files
/// (run.json "outputs", docs/analysis.md).
nlohmann::json outputs_json(const std::filesystem::path& dir);

/// One line: "written: 3 spectra, 3 snapshots, slices omega2 3 tau_sfs 3, ...".
std::string outputs_summary(const nlohmann::json& outputs);

/// The last whole row of a time series (timeseries.csv), its case columns in `case_values`;
/// nullopt when it has none. Reads the header and the file's end only (a series may be large).
std::optional<MetricsSample> last_metrics(const std::filesystem::path& path);

/// The newest saved image of each field (frames/index.csv's last row per field), its PNG not yet
/// read (`png` null, `file` its name under frames/): what a reopened run shows until it renders
/// again. Rows whose file is gone are skipped.
std::map<std::string, ImageEvent> saved_images(const std::filesystem::path& dir);

/// The current UTC time as "2026-12-03T12:00:00Z".
std::string utc_now();

}  // namespace sphles::control
