// SPDX-License-Identifier: GPL-3.0-or-later
// Reads back the newest analysed frame of a run directory from the files RunDirectoryWriter
// wrote (docs/analysis.md): its scalars, spectrum and sub-filter statistics, so that a process
// that opens a finished or stopped run serves what the run computed before.
#pragma once

#include <filesystem>
#include <optional>

#include "analysis/config.hpp"
#include "analysis/products.hpp"

namespace sphles::analysis {

/// The frame of the last complete row of stats/snapshots.csv (the writer appends it after the
/// frame's other files), with its spectrum (spectra/) and sub-filter statistics (stats/) when the
/// frame has them; nullopt when the directory holds no analysed frame. Every number is the one
/// the analysis computed (the files carry 17 significant digits); what the files do not say
/// (how vorticity was estimated, the polar histogram's threshold) comes from `config`, the
/// run's analysis configuration. Throws std::runtime_error naming a file that does not read.
std::optional<AnalysisFrame> read_latest_frame(const std::filesystem::path& directory,
                                               const AnalysisConfig& config);

}  // namespace sphles::analysis
