// SPDX-License-Identifier: GPL-3.0-or-later
// Kinetic-energy spectrum by FFTW with shell binning (SPEC §5; Durran et al. 2017).
//
// With û(k) = M^-n Σ_x u(x) e^{-i k·x} on an M^n grid of side L, Δk = 2π/L and shell
// p = nint(|k| / Δk), E(k_p) = Σ_{k in shell p} ½ |û(k)|² / Δk for p = 0 .. p_max (all shells,
// including the corners of the cube). Then Σ_p E(k_p) Δk = ½ ⟨|u|²⟩ exactly (discrete Parseval).
#pragma once

#include <limits>
#include <mutex>
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

/// The shell sums energy_spectrum bins an r2c transform into, apart so that a transform split
/// over processes (par/, FFTW's MPI interface) bins its part of the modes the same way and adds
/// the processes' sums. The transform is FFTW's r2c of an M^n grid, x fastest, i.e. of FFTW's
/// row-major array [z][y][x] (3D) or [y][x] (2D), whose output holds M/2 + 1 x modes.
struct ShellSums {
  int dimension = 3;
  int points_per_side = 0;
  /// Shell p = nint(|k| / Δk) of every integer |k|² / Δk² up to the corner of the cube.
  std::vector<int> shell_of;
  /// Σ over each shell's modes of w |FFTW output|², w = 2 for 0 < k_x < M/2 (the conjugate
  /// partner is not stored), else 1; and the same times |k|² / Δk².
  std::vector<double> modulus2;
  std::vector<double> k2_modulus2;
};

/// Empty sums for the r2c transforms of an M^n grid (dimension 2 or 3).
ShellSums empty_shell_sums(int dimension, int points_per_side);

/// Adds `planes` consecutive planes of an r2c output to the sums: complex values as
/// (re, im) pairs, a plane being one z (3D: M × (M/2 + 1) values) or one y (2D: M/2 + 1 values)
/// of the whole transform, the first of them plane `first_plane`.
void add_transform_planes(ShellSums& sums, const double* interleaved, int first_plane, int planes);

/// E(k_p) and the |k|²-weighted sums from the sums of every mode of the transforms of the
/// velocity components on a grid of side `length` (û = M^-n FFTW output, SPEC §5).
EnergySpectrum spectrum_from_shell_sums(const ShellSums& sums, double length);

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
