// SPDX-License-Identifier: GPL-3.0-or-later
// Run time against error (docs/accuracy.md): a matrix of small scenes, each run on the calling
// thread's OpenMP settings with its error measured against a reference while the solver steps
// (2D Taylor-Green: analytic solution, SPEC §6.2; 3D Taylor-Green at Re = 1600 and 5000: first
// the resolved energy against the `sphles reference` run of the flow (SPEC §9), then e_v against
// the DNS; Kolmogorov flow: its own energy budget, SPEC (4.3)).
#pragma once

#include <cstdint>
#include <iosfwd>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace sphles::accuracy {

inline constexpr double kMisfitEndTime = 12.0;  // the 3D comparison window t ∈ [0, 12]
// The shells' window: the nine analysis times around the Taylor-Green dissipation peak, where a
// shell at one time swings with the phase of the roll-up (accuracy.md, "How the errors are
// measured").
inline constexpr double kShellWindowStart = 7.5, kShellWindowEnd = 9.5;

/// Studies: "tgv2d_re100", "tgv2d_re1000", "tgv3d_re5000", "peers", "kolmogorov".
struct RunSpec {
  std::string study;
  std::string config;  // everything but the resolution, e.g. "wendland_c4 D_K/dl=8"
  std::string label;   // config and resolution, e.g. "wendland_c4 D_K/dl=8 N=64"
  nlohmann::json scene;
  double sample_interval = 0.1;  // simulated time between recorded samples [s]
};

/// One recorded sample of a run. Fields a study does not use stay 0.
struct Sample {
  double time = 0.0;                 // [s]
  double kinetic_energy = 0.0;       // e_v of (5.3), the solver's diagnostic [m²/s²]
  double reference_energy = 0.0;     // tgv2d: analytic e_v(t); tgv3d: DNS E(t) interpolated
  double velocity_error = 0.0;       // tgv2d: relative L2 error of the particle velocities
  double speed_l1_error = 0.0;       // tgv2d: PySPH's L1 error of |v|
  double dissipation = 0.0;          // tgv3d: -de_v/dt by centred differences of the samples
  double energy_injection = 0.0;     // kolmogorov: ⟨χ sin(k_y y) v_x⟩ [m²/s³]
  double viscous_dissipation = 0.0;  // kolmogorov: ν⟨ω²⟩ on the Δl/2 grid (4.6) [m²/s³]
  double film_dissipation = 0.0;     // kolmogorov: μ⟨|v|²⟩ [m²/s³]
  double u_rms = 0.0;                // kolmogorov: sqrt(⟨|v|²⟩) [m/s]
  /// tgv3d at the spectrum times: E_res (k <= k_SPH, SPEC §9) of the run and of the reference
  /// run; NaN at the other samples.
  double resolved_energy = std::numeric_limits<double>::quiet_NaN();
  double reference_resolved_energy = std::numeric_limits<double>::quiet_NaN();
};

struct RunResult {
  RunSpec spec;
  std::string case_name;
  int particles_per_side = 0;
  std::size_t particles = 0;
  std::string kernel;
  double diameter_over_spacing = 0.0;
  std::string subfilter;
  double dynamic_viscosity = 0.0;
  double end_time = 0.0;
  std::string status = "completed";  // completed, blown_up, wall_limit
  double time_reached = 0.0;
  std::uint64_t steps = 0;
  /// Solver steps only (packing, set-up and the error measurement excluded): wall seconds and
  /// process CPU seconds (user + system) spent inside Simulation::step.
  double wall_seconds = 0.0;
  double cpu_seconds = 0.0;
  double total_wall_seconds = 0.0;  // everything, including set-up and measurement
  // tgv2d
  double energy_error = 0.0;        // relative L2 of e_v(t) over the samples
  double velocity_error_end = 0.0;  // relative L2 velocity error at end_time
  double velocity_error_rms = 0.0;  // RMS over the samples of the relative L2 velocity error
  double energy_error_end = 0.0;    // e_v(end) / e_v,exact(end) - 1 (signed)
  double speed_l1_error_end = 0.0;  // PySPH's L1 error of |v| at end_time
  // tgv3d, the primary error (SPEC §9): against the `sphles reference` run of the flow, at the
  // spectrum times in [0, 12]; NaN without a reference run (its name then empty)
  std::string resolved_reference;
  double resolved_misfit = std::numeric_limits<double>::quiet_NaN();     // L2 of E_res
  double resolved_max_error = std::numeric_limits<double>::quiet_NaN();  // max |E_res/E_res,ref-1|
  std::string shell_ratios_t8, shell_ratios_t9;  // "k:E(k)/E_ref(k)" for k <= k_kern, by spaces
  std::string shell_ratios_window;  // each shell's energy over the window over the reference's
  double resolved_flux_peak_time = std::numeric_limits<double>::quiet_NaN();  // -dE_res/dt
  double reference_resolved_flux_peak_time = std::numeric_limits<double>::quiet_NaN();
  // tgv3d (t in [0, 12] on the DNS time grid); NaN without a DNS at the run's Re
  double energy_misfit = 0.0;       // relative L2 of e_v against the DNS E
  double dissipation_misfit = 0.0;  // relative L2 of -de_v/dt against the DNS -dE/dt
  double peak_dissipation = 0.0;    // maximum of -de_v/dt over the samples
  double peak_time = 0.0;
  double final_energy = 0.0;  // e_v at end_time
  // kolmogorov: time averages over the second half of the run
  double mean_u_rms = 0.0;
  double mean_energy_injection = 0.0;
  double mean_viscous_dissipation = 0.0;
  double mean_film_dissipation = 0.0;
  double mean_energy_change = 0.0;  // (e_v(end) - e_v(start)) / window
  /// (ε_inj - ε_v - ε_film - de_v/dt) / ε_inj: the share of the injected power that the resolved
  /// budget does not account for (numerical dissipation of the scheme).
  double budget_imbalance = 0.0;
  std::vector<Sample> history;
};

/// The configurations of `study` ("2d", "3d", "peers" or "kolmogorov"); `quick` gives a few-minute
/// subset.
std::vector<RunSpec> make_matrix(const std::string& study, bool quick);

/// The same configuration at another resolution (the label's N is replaced).
RunSpec with_resolution(const RunSpec& spec, int particles_per_side);

struct RunOptions {
  double wall_limit_seconds = 1800.0;  // per run
  /// The reference data (data/reference/): the 3D Taylor-Green DNS curves and the `sphles
  /// reference` runs whose spectra judge the resolved scales.
  std::string reference_dir;
  double spectrum_interval = 0.25;  // tgv3d: simulated time between spectra [s]
  bool trace = false;               // print every sample to stderr
};

RunResult run_one(const RunSpec& spec, const RunOptions& options);

void write_summary_header(std::ostream& out);
void write_summary_row(std::ostream& out, const RunResult& result);
void write_history_header(std::ostream& out);
void write_history_rows(std::ostream& out, const RunResult& result);

}  // namespace sphles::accuracy
