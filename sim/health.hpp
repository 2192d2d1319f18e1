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

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"

namespace sphles::sim {

/// Runaway kinetic energy, checked by the solver after every step (Simulation::step throws
/// BlowUpError) and by assess_health.
///
/// Reference energy E_ref = max(e_v at the start, ½ (reference_mach c_s)²); runaway when
/// e_v > energy_factor · E_ref. The acoustic floor makes the test meaningful for flows that start
/// from rest (Kolmogorov forcing): a weakly compressible run is only valid while |v| << c_s, so
/// a mean kinetic energy of energy_factor · ½ c_s² (an rms Mach number of sqrt(energy_factor) ≈
/// 3.2 with the defaults) is far outside the model whatever the forcing. Measured blow-ups
/// (docs/stability.md) grow by many orders of magnitude within a few dozen steps, so a generous
/// factor costs only a few steps of delay and never flags a valid run.
struct BlowUpThresholds {
  double energy_factor = 10.0;  // runaway when e_v > energy_factor · E_ref; must be > 1
  double reference_mach = 1.0;  // acoustic floor of E_ref is ½ (reference_mach c_s)²; >= 0
};

/// Thresholds of the classification (defaults measured in docs/stability.md).
struct HealthThresholds {
  /// Noisy when max_i |ρ_i/ρ_ref - 1| exceeds this. A weakly compressible flow at Mach Ma has
  /// physical density variations of order Ma²/2 (0.5 % at Ma = 0.1); packed, stable runs of the
  /// sweep stay below 1-2 %, while the thesis' failing D_K = 4Δl case reaches 20 %.
  double noisy_max_density_deviation = 0.05;
  /// A particle is paired when its nearest neighbour is closer than this many mean spacings Δl.
  /// On packed and on flowing stable states the nearest neighbour stays above ~0.7 Δl (a square
  /// lattice has exactly 1 Δl); paired particles collapse to a small fraction of Δl.
  double pairing_distance = 0.5;
  /// Paired when more than this fraction of particles is paired (one odd close encounter in a
  /// turbulent run is not the pairing instability).
  double paired_fraction = 0.01;
  BlowUpThresholds blow_up;
};

/// Ordered from best to worst: a run's classification is the worst seen over its checks.
enum class Classification { Stable, Noisy, Paired, BlownUp };

/// "stable", "noisy", "paired", "blown_up".
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

/// Nearest-neighbour distances (minimum image) over a neighbour list whose radius is at least
/// the mean spacing: min_distance is min_i r_nn,i / Δl, paired_count counts particles with
/// r_nn,i < thresholds.pairing_distance Δl, paired_fraction = paired_count / N.
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

/// E_ref = max(initial_energy, ½ (reference_mach · sound_speed)²), see BlowUpThresholds.
double runaway_reference_energy(double initial_energy, double sound_speed,
                                const BlowUpThresholds& thresholds);

/// True when e_v is not finite or exceeds energy_factor · reference_energy.
bool is_energy_runaway(double kinetic_energy, double reference_energy,
                       const BlowUpThresholds& thresholds);

/// Index of the fastest particle (lowest index on ties; non-finite speeds count as fastest).
std::size_t fastest_particle(const ParticleArrays& particles);

/// Everything measured on one state and the verdict. Priority: BlownUp (non-finite or runaway)
/// > Paired > Noisy > Stable; `reason` says which figure crossed which threshold.
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
