// SPDX-License-Identifier: GPL-3.0-or-later
// The units of every column of the CSV files in a run directory, written beside them as
// units.csv: the headers keep their bare names (scripts, numpy's names=True and the service look
// columns up by them), and a reader that wants the units finds them in one file of the run.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace sphles::analysis {

/// Which time series the run directory holds: a particle run's (sphles run, serve) or a
/// spectral reference's (sphles reference).
enum class RunKind { Particles, Reference };

struct ColumnUnit {
  std::string_view file;    // relative to the run directory; * matches a time, E_t*.csv
  std::string_view column;  // as in the file's header
  std::string_view unit;    // SI in ASCII ("m^2/s^3"); "1" a pure number; "-" text
};

/// Every column of the CSV files a run of `kind` may write, file by file, with the case's own
/// time-series columns (sim::case_diagnostic_names) among the time series'.
std::vector<ColumnUnit> column_units(RunKind kind, const std::vector<std::string>& case_columns);

/// Writes RUN/units.csv ("file,column,unit", one row per column_units entry) atomically.
void write_units_file(const std::filesystem::path& run_directory, RunKind kind,
                      const std::vector<std::string>& case_columns);

}  // namespace sphles::analysis
