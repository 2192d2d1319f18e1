// SPDX-License-Identifier: GPL-3.0-or-later
// Health of a particle state: density noise, particle pairing, non-finite values and runaway
// kinetic energy, and the classification of a run built on them (docs/stability.md).
//
// Free functions over the plain particle arrays and the neighbour list; they read, never write.
// Every threshold is a field of BlowUpThresholds or HealthThresholds with a documented default;
// the functions themselves hold no tuning constants. Sums use deterministic_sum, so every
// figure is the same for any thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "sim/name_table.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"

namespace sphles::sim {

/// Runaway kinetic energy, checked by the solver after every step (Simulation::step throws
/// BlowUpError) and by assess_health.
///
/// Reference energy E_ref = max(e_v at the start, reference_energy, ½ (reference_mach c_s)²);
/// runaway when e_v > energy_factor · E_ref.
/// - The acoustic floor makes the test usable for flows that start from rest (Kolmogorov forcing)
///   without knowing the forcing: a weakly compressible run is only valid while |v| << c_s, and
///   with the defaults a flow that starts slower than Ma = 0.2 is stopped when its rms Mach
///   number sqrt(2 e_v)/c_s passes sqrt(10) · 0.2 ≈ 0.63, far outside the model whatever drives
///   it. The thesis' Kolmogorov flow (c_s = 2 m/s, laminar e_v = 0.13 m²/s², turbulent 0.006)
///   stays 6 to 130 times below that.
/// - reference_energy is for callers that know the flow's energy scale (the laminar energy a
///   forcing implies; the stability sweep sets it and reference_mach = 0, so that a decaying flow
///   is judged against its own initial energy).
/// Measured blow-ups (docs/stability.md) gain orders of magnitude within a fraction of a time
/// unit, so a generous factor delays the stop by a few steps and never flags a valid run.
struct BlowUpThresholds {
  double energy_factor = 10.0;    // runaway when e_v > energy_factor · E_ref; must be > 1
  double reference_mach = 0.2;    // acoustic floor of E_ref is ½ (reference_mach c_s)²; >= 0
  double reference_energy = 0.0;  // [m²/s²] energy scale known to the caller; >= 0
};

/// Thresholds of the classification (defaults measured in docs/stability.md).
struct HealthThresholds {
  /// Noisy when the root mean square of |ρ_i/ρ_ref - 1| over the particles exceeds this. A
  /// weakly compressible flow at Mach Ma has physical density variations of order Ma²/2 (rms
  /// 0.6 % for the 2D Taylor-Green vortex at Ma = 0.1). Measured at 48² (docs/stability.md): every
  /// D_K = 4Δl run, the case the thesis finds collapsing, has rms >= 0.037; every run with
  /// D_K >= 5Δl has rms <= 0.024. The threshold sits in that gap.
  double noisy_rms_density_deviation = 0.03;
  /// Noisy when max_i |ρ_i/ρ_ref - 1| exceeds this: the "density errors up to 20 %" of the
  /// thesis' collapsed D_K = 4Δl case (SPEC §7.2), for noise concentrated on few particles.
  double noisy_max_density_deviation = 0.2;
  /// A particle is paired when its nearest neighbour is closer than pairing_distance Δl and
  /// closer than pairing_ratio times its second-nearest neighbour. The ratio separates pairs from
  /// the kinematic compression of a strained flow: at a stagnation point the spacing along the
  /// compressive axis shrinks as exp(-S t) for every particle of a row, so the nearest and
  /// second-nearest neighbours (one on each side) stay equally close, while in a pair the partner
  /// is much closer than anyone else. Measured (docs/stability.md): packed lattices have
  /// r1/r2 > 0.9; the validated 2D Taylor-Green run (128², D_K = 12Δl) reaches r1 = 0.25 Δl but
  /// no particle with r1 < 0.3 r2; quintic-spline runs at D_K = 8Δl have 8 % such particles.
  double pairing_distance = 0.5;
  double pairing_ratio = 0.3;
  /// Paired when more than this fraction of particles is paired (a few close encounters in a
  /// disordered flow are not the pairing instability).
  double paired_fraction = 0.01;
  BlowUpThresholds blow_up;
};

/// Ordered from best to worst: a run's classification is the worst seen over its checks.
enum class Classification { Stable, Noisy, Paired, BlownUp };

inline constexpr NameTable<Classification, 4> kClassificationNames{{{
    {Classification::Stable, "stable"},
    {Classification::Noisy, "noisy"},
    {Classification::Paired, "paired"},
    {Classification::BlownUp, "blown_up"},
}}};
std::string_view classification_name(Classification c);

/// The worse of two classifications.
Classification worst(Classification a, Classification b);

/// Relative density deviation |ρ_i/ρ_ref - 1|: maximum (and the index where it occurs) and root
/// mean square over particles. Non-finite densities are skipped here (find_non_finite sees them).
struct DensityDeviation {
  double max = 0.0;
  double rms = 0.0;
  std::size_t max_index = 0;
};
DensityDeviation density_deviation(const ParticleArrays& particles, double reference_density);

/// Nearest (r1) and second-nearest (r2) neighbour distances, minimum image, over a neighbour
/// list whose radius exceeds the mean spacing: min_distance = min_i r1_i / Δl; paired_count
/// counts particles with r1 < thresholds.pairing_distance Δl and r1 < thresholds.pairing_ratio r2
/// (see HealthThresholds); paired_fraction = paired_count / N.
struct PairingStatistics {
  double min_distance = 0.0;  // in units of Δl; infinity when no particle has a neighbour
  std::size_t paired_count = 0;
  double paired_fraction = 0.0;
};
PairingStatistics pairing_statistics(const ParticleArrays& particles, const NeighbourList& list,
                                     const PeriodicBox& box, double spacing,
                                     const HealthThresholds& thresholds);

/// The first particle (lowest array index) holding a non-finite value, and which one. Fields are
/// checked in the order position, velocity, acceleration, mass, volume, density, pressure,
/// eddy_viscosity (the last only when allocated).
struct NonFiniteValue {
  std::size_t index = 0;
  std::uint64_t id = 0;
  std::string field;  // e.g. "velocity[1]", "density"
  double value = 0.0;
};
std::optional<NonFiniteValue> find_non_finite(const ParticleArrays& particles);

/// Mean kinetic energy e_v = ½ Σ M v² / Σ M (5.3).
double mean_kinetic_energy(const ParticleArrays& particles);

/// E_ref = max(initial_energy, reference_energy, ½ (reference_mach · sound_speed)²), see
/// BlowUpThresholds.
double runaway_reference_energy(double initial_energy, double sound_speed,
                                const BlowUpThresholds& thresholds);

/// True when e_v is not finite or exceeds energy_factor · reference_energy.
bool is_energy_runaway(double kinetic_energy, double reference_energy,
                       const BlowUpThresholds& thresholds);

/// Index of the fastest particle (lowest index on ties; non-finite speeds count as fastest).
std::size_t fastest_particle(const ParticleArrays& particles);

/// Everything measured on one state and the verdict. Priority: BlownUp (non-finite or runaway)
/// > Paired > Noisy (rms or max density deviation) > Stable; `reason` says which figure crossed
/// which threshold.
struct HealthReport {
  Classification classification = Classification::Stable;
  std::string reason;
  DensityDeviation density;
  PairingStatistics pairing;
  double kinetic_energy = 0.0;
  std::optional<NonFiniteValue> non_finite;
  bool energy_runaway = false;
};

/// Assesses a state. `list` must hold, for every particle, at least all neighbours closer than
/// Δl (any Verlet list of the solver does: its radius is H(1 + skin) > Δl).
HealthReport assess_health(const ParticleArrays& particles, const NeighbourList& list,
                           const PeriodicBox& box, double spacing, double reference_density,
                           double reference_energy, const HealthThresholds& thresholds);

}  // namespace sphles::sim
