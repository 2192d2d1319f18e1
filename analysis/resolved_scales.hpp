// SPDX-License-Identifier: GPL-3.0-or-later
// Resolved-scale errors of a run against a reference (SPEC §9): what an implicit LES is judged
// by. With the kernel wavenumber k_kern = 2π/D_K and the best resolvable scale k_SPH = k_kern/2
// (SPEC §7, finding 4), at equal times:
//   the resolved energy E_res = Σ_{k_p <= k_SPH} E(k_p) Δk, against the reference's;
//   the per-shell ratio E(k_p)/E_ref(k_p) for the shells k_p <= k_kern;
//   the energy above k_kern (particle-scale motion), against the reference's there;
// and over time the resolved energy's misfit and its rate -dE_res/dt (the flux leaving the
// resolved scales).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "analysis/spectrum.hpp"
#include "sim/scene.hpp"

namespace sphles::analysis {

/// One spectrum of a run directory's spectra/ (writer.hpp): shells k_p = p Δk and E(k_p).
struct ShellSpectrum {
  double time = 0.0;
  double delta_k = 1.0;
  double kernel_wavenumber = 0.0;  // the run's k_kern (index column k_kernel)
  std::vector<double> wavenumber, energy;
};

/// A spectrum computed in-process (e.g. by a benchmark) as the shells read_run_spectra gives.
ShellSpectrum shell_spectrum(double time, const EnergySpectrum& spectrum, double kernel_wavenumber);

/// Every spectrum listed in DIR/spectra/index.csv, in time order. Throws std::runtime_error
/// naming the file when one is missing or malformed.
std::vector<ShellSpectrum> read_run_spectra(const std::filesystem::path& run_directory);

/// The reference's spectrum at `time`: the one at that time (within 1e-6 of its spacing), else
/// linear in time between the two around it (the reference writes densely). Empty optional-like
/// result (no shells) when `time` lies outside the reference's times.
ShellSpectrum spectrum_at(const std::vector<ShellSpectrum>& reference, double time);

/// The reference as the run's kernel filters the flow: each shell's E_ref(k) times Ŵ(k)², with Ŵ
/// the transfer function of the scene's kernel at its D_K (sim::kernel_transfer). An SPH-LES
/// carries the kernel-filtered velocity (SPEC §1), so the filtered reference is what a perfect
/// scheme of that kernel would give; the shell ratios against it separate what the scheme
/// loses from what the kernel's filter removes by design.
std::vector<ShellSpectrum> kernel_filtered(std::vector<ShellSpectrum> reference,
                                           const sim::Scene& run_scene);

/// Ŵ(k)² of the scene's kernel at its D_K at each wavenumber: the factor kernel_filtered applies.
std::vector<double> kernel_transfer_squared(const sim::Scene& scene,
                                            const std::vector<double>& wavenumbers);

struct ResolvedScales {
  double time = 0.0;
  double kernel_wavenumber = 0.0;  // k_kern
  double sph_wavenumber = 0.0;     // k_SPH = k_kern / 2
  double resolved_energy = 0.0, reference_resolved_energy = 0.0;
  double energy_above_kernel = 0.0, reference_energy_above_kernel = 0.0;
  double reference_energy = 0.0;    // Σ_k E_ref(k) Δk
  std::vector<double> shell;        // k_p of the shells 0 < k_p <= k_kern
  std::vector<double> shell_ratio;  // E(k_p)/E_ref(k_p); NaN where the reference's shell is empty
  std::vector<double> shell_energy, reference_shell_energy;  // E(k_p) and E_ref(k_p)
};

/// The measures at one time, with the run's k_kern. Throws std::invalid_argument when the two
/// spectra's Δk differ.
ResolvedScales resolved_scales(const ShellSpectrum& run, const ShellSpectrum& reference,
                               double kernel_wavenumber);

struct ResolvedHistory {
  std::vector<ResolvedScales> samples;  // at the run's spectra times the reference covers
  /// sqrt(Σ (E_res - E_res,ref)² / Σ E_res,ref²) over the samples whose reference has resolved
  /// energy (more than 10⁻¹² of its total: a kernel so wide that k_SPH lies below the flow's
  /// scales has none); NaN when none has.
  double l2_misfit = 0.0;
  /// max |E_res / E_res,ref - 1| over the same samples (NaN when none).
  double max_relative_error = 0.0;
  /// -dE_res/dt by centred differences at the interior samples (and its reference's), and the
  /// times of their largest values.
  std::vector<double> flux_time, flux, reference_flux;
  double flux_peak_time = 0.0, reference_flux_peak_time = 0.0;
  double flux_peak = 0.0, reference_flux_peak = 0.0;
  /// Each shell's energy summed over the samples where it has a ratio, over the reference's
  /// (NaN where none has): a single shell at a single time swings with the phase of the
  /// roll-up, the ratio over a window (e.g. t = 7.5 … 9.5 around the Taylor-Green dissipation
  /// peak) measures the energy kept; weighting by energy keeps the early times, when a high
  /// shell holds almost nothing, from dominating a long window.
  std::vector<double> mean_shell, mean_shell_ratio;
};

/// The measures at every time of `run` the reference covers, from t_min to t_max.
ResolvedHistory resolved_history(const std::vector<ShellSpectrum>& run,
                                 const std::vector<ShellSpectrum>& reference, double t_min = 0.0,
                                 double t_max = 1e300);

/// The history as JSON: "samples" (t, k_kernel, k_sph, resolved_energy, reference_resolved_energy,
/// energy_above_kernel, reference_energy_above_kernel, shell, shell_ratio; NaN ratios as null),
/// "resolved_energy_l2_misfit", "resolved_energy_max_relative_error", "flux" {t, run,
/// reference}, "flux_peak" and "reference_flux_peak" {t, value}, "mean_shell_ratio" {shell,
/// ratio} (NaN means as null).
nlohmann::json resolved_history_to_json(const ResolvedHistory& history);

}  // namespace sphles::analysis
