// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/units.hpp"

#include <algorithm>
#include <array>
#include <stdexcept>

#include "analysis/writer.hpp"

namespace sphles::analysis {

namespace {

// The files the analysis writer and the renderer write (analysis/writer.cpp,
// control/render_sink.cpp), in their header's order; SPEC §5 for the estimates.
constexpr std::array kAnalysisColumns = {
    ColumnUnit{"spectra/index.csv", "t", "s"},
    ColumnUnit{"spectra/index.csv", "step", "1"},
    ColumnUnit{"spectra/index.csv", "file", "-"},
    ColumnUnit{"spectra/index.csv", "e_v_grid", "m^2/s^2"},
    ColumnUnit{"spectra/index.csv", "dissipation_spectral", "m^2/s^3"},
    ColumnUnit{"spectra/index.csv", "dissipation_spectral_resolved", "m^2/s^3"},
    ColumnUnit{"spectra/index.csv", "k_kernel", "1/m"},
    ColumnUnit{"spectra/index.csv", "k_resolution", "1/m"},
    ColumnUnit{"spectra/index.csv", "delta_k", "1/m"},
    ColumnUnit{"spectra/index.csv", "L_c", "m"},
    ColumnUnit{"spectra/E_t*.csv", "k", "1/m"},
    ColumnUnit{"spectra/E_t*.csv", "E", "m^3/s^2"},
    ColumnUnit{"spectra/E_t*.csv", "k_Lc", "1"},
    ColumnUnit{"spectra/E_t*.csv", "E_over_ev_Lc", "1"},
    ColumnUnit{"slices/index.csv", "t", "s"},
    ColumnUnit{"slices/index.csv", "step", "1"},
    ColumnUnit{"slices/index.csv", "field", "-"},
    ColumnUnit{"slices/index.csv", "units", "-"},
    ColumnUnit{"slices/index.csv", "normal_axis", "-"},
    ColumnUnit{"slices/index.csv", "position", "m"},
    ColumnUnit{"slices/index.csv", "axis_u", "-"},
    ColumnUnit{"slices/index.csv", "axis_v", "-"},
    ColumnUnit{"slices/index.csv", "width", "1"},
    ColumnUnit{"slices/index.csv", "height", "1"},
    ColumnUnit{"slices/index.csv", "spacing", "m"},
    ColumnUnit{"slices/index.csv", "min", "the row's units"},
    ColumnUnit{"slices/index.csv", "max", "the row's units"},
    ColumnUnit{"slices/index.csv", "file", "-"},
    ColumnUnit{"slices/index.csv", "vti", "-"},
    ColumnUnit{"stats/snapshots.csv", "t", "s"},
    ColumnUnit{"stats/snapshots.csv", "step", "1"},
    ColumnUnit{"stats/snapshots.csv", "e_v", "m^2/s^2"},
    ColumnUnit{"stats/snapshots.csv", "e_v_grid", "m^2/s^2"},
    ColumnUnit{"stats/snapshots.csv", "mean_omega2", "1/s^2"},
    ColumnUnit{"stats/snapshots.csv", "dissipation_vorticity", "m^2/s^3"},
    ColumnUnit{"stats/snapshots.csv", "dissipation_spectral", "m^2/s^3"},
    ColumnUnit{"stats/snapshots.csv", "tau_sfs_max", "Pa"},
    ColumnUnit{"stats/snapshots.csv", "tau_sfs_mean", "Pa"},
    ColumnUnit{"stats/snapshots.csv", "analysis_seconds", "s"},
    ColumnUnit{"stats/snapshots.csv", "dropped_snapshots", "1"},
    ColumnUnit{"stats/snapshots.csv", "dissipation_spectral_resolved", "m^2/s^3"},
    ColumnUnit{"stats/snapshots.csv", "dissipation_energy", "m^2/s^3"},
    ColumnUnit{"stats/joint_tau_omega2_t*.csv", "tau_lo", "1"},
    ColumnUnit{"stats/joint_tau_omega2_t*.csv", "tau_hi", "1"},
    ColumnUnit{"stats/joint_tau_omega2_t*.csv", "omega2_lo", "1"},
    ColumnUnit{"stats/joint_tau_omega2_t*.csv", "omega2_hi", "1"},
    ColumnUnit{"stats/joint_tau_omega2_t*.csv", "count", "1"},
    ColumnUnit{"stats/alignment_t*.csv", "gamma_lo", "rad"},
    ColumnUnit{"stats/alignment_t*.csv", "gamma_hi", "rad"},
    ColumnUnit{"stats/alignment_t*.csv", "count", "1"},
    ColumnUnit{"stats/alignment_t*.csv", "fraction", "1"},
    ColumnUnit{"snapshots/index.csv", "t", "s"},
    ColumnUnit{"snapshots/index.csv", "step", "1"},
    ColumnUnit{"snapshots/index.csv", "file", "-"},
    ColumnUnit{"snapshots/index.csv", "particles", "1"},
    ColumnUnit{"snapshots/index.csv", "fields", "-"},
    ColumnUnit{"fields/index.csv", "t", "s"},
    ColumnUnit{"fields/index.csv", "step", "1"},
    ColumnUnit{"fields/index.csv", "file", "-"},
    ColumnUnit{"fields/index.csv", "points_per_side", "1"},
    ColumnUnit{"fields/index.csv", "spacing", "m"},
    ColumnUnit{"fields/index.csv", "arrays", "-"},
    ColumnUnit{"frames/index.csv", "time", "s"},
    ColumnUnit{"frames/index.csv", "step", "1"},
    ColumnUnit{"frames/index.csv", "field", "-"},
    ColumnUnit{"frames/index.csv", "file", "-"},
};

// analysis/timeseries.hpp: the standard columns; (5.3), (5.4).
constexpr std::array kParticleSeries = {
    ColumnUnit{"timeseries.csv", "t", "s"},
    ColumnUnit{"timeseries.csv", "step", "1"},
    ColumnUnit{"timeseries.csv", "dt", "s"},
    ColumnUnit{"timeseries.csv", "e_v", "m^2/s^2"},
    ColumnUnit{"timeseries.csv", "dissipation", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "max_density_deviation", "1"},
    ColumnUnit{"timeseries.csv", "max_speed", "m/s"},
};

// spectral/reference_run.cpp (reference_timeseries_header).
constexpr std::array kReferenceSeries = {
    ColumnUnit{"timeseries.csv", "t", "s"},
    ColumnUnit{"timeseries.csv", "step", "1"},
    ColumnUnit{"timeseries.csv", "dt", "s"},
    ColumnUnit{"timeseries.csv", "E", "m^2/s^2"},
    ColumnUnit{"timeseries.csv", "minus_dE_dt", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "epsilon", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "Z", "1/s^2"},
    ColumnUnit{"timeseries.csv", "injection", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "film_dissipation", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "transfer", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "max_speed", "m/s"},
};

// sim/case_diagnostics.hpp: the Kolmogorov flow's columns (SPEC §6.3, (4.3)).
constexpr std::array kCaseSeries = {
    ColumnUnit{"timeseries.csv", "energy_injection", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "film_dissipation", "m^2/s^3"},
    ColumnUnit{"timeseries.csv", "u_rms", "m/s"},
};

}  // namespace

std::vector<ColumnUnit> column_units(RunKind kind, const std::vector<std::string>& case_columns) {
  std::vector<ColumnUnit> units;
  if (kind == RunKind::Reference) {
    units.assign(kReferenceSeries.begin(), kReferenceSeries.end());
  } else {
    units.assign(kParticleSeries.begin(), kParticleSeries.end());
    for (const std::string& c : case_columns) {
      const auto it = std::find_if(kCaseSeries.begin(), kCaseSeries.end(),
                                   [&](const ColumnUnit& u) { return u.column == c; });
      if (it == kCaseSeries.end())
        throw std::logic_error("analysis::column_units: no unit for the case column " + c);
      units.push_back(*it);
    }
  }
  units.insert(units.end(), kAnalysisColumns.begin(), kAnalysisColumns.end());
  return units;
}

void write_units_file(const std::filesystem::path& run_directory, RunKind kind,
                      const std::vector<std::string>& case_columns) {
  std::string text = "file,column,unit\n";
  for (const ColumnUnit& u : column_units(kind, case_columns)) {
    text += u.file;
    text += ',';
    text += u.column;
    text += ',';
    text += u.unit;
    text += '\n';
  }
  replace_atomically(run_directory / "units.csv", text);
}

}  // namespace sphles::analysis
