// Kinetic-energy spectrum by FFTW with shell binning (SPEC §5; Durran et al. 2017).
//
// With û(k) = M^-n Σ_x u(x) e^{-i k·x} on an M^n grid of side L, Δk = 2π/L and shell
// p = nint(|k| / Δk), E(k_p) = Σ_{k in shell p} ½ |û(k)|² / Δk for p = 0 .. p_max (all shells,
// including the corners of the cube). Then Σ_p E(k_p) Δk = ½ ⟨|u|²⟩ exactly (discrete Parseval).
#pragma once

#include <limits>
#include <vector>

#include "analysis/grid.hpp"

namespace sphles::analysis {

struct EnergySpectrum {
  double delta_k = 0.0;            // Δk = 2π/L [1/m]
  std::vector<double> wavenumber;  // k_p = p Δk [1/m]
  std::vector<double> energy;      // E(k_p) [m³/s²] (3D), per shell width
  /// Σ_shell |k|² ½|û(k)|² / Δk with each mode's exact |k| (not the shell centre k_p), so that
  /// 2ν Σ_p k2_energy_p Δk = ν ⟨|∇u|²⟩ exactly for the gridded field.
  std::vector<double> k2_energy;
};

/// Spectrum of the (mean-removed) field; uses FFTW r2c with FFTW_ESTIMATE plans (deterministic).
/// Thread-safe: plan creation is serialised internally.
/// The mean is not removed here (sample_velocity(..., true) does that): a mean flow shows up as
/// E(k_0) Δk = ½|ū|², so that Parseval holds for any field.
EnergySpectrum energy_spectrum(const VectorField& velocity);

/// Σ_p E(k_p) Δk.
double spectrum_energy(const EnergySpectrum& spectrum);

/// ε = 2ν ∫ k² E(k) dk (4.6), summed over the shells with k_p <= max_wavenumber using every
/// mode's exact |k|² (binning with k_p² instead would bias a low mode, e.g. by 4/3 for the TGV
/// modes |k| = √3 in shell 2).
double spectral_dissipation(const EnergySpectrum& spectrum, double kinematic_viscosity,
                            double max_wavenumber = std::numeric_limits<double>::infinity());

/// ½ ⟨|u|²⟩ over the grid nodes.
double grid_kinetic_energy(const VectorField& velocity);

}  // namespace sphles::analysis
