// SPDX-License-Identifier: GPL-3.0-or-later
// Particle state as a structure of arrays (SPEC §2 symbols in comments).
//
// Layout is ready for a later domain decomposition: indices [0, size()) are the particles this
// process owns. A halo of copies owned by other ranks would be appended behind them; physics loops
// run over owned particles and read neighbours from either range.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace sphles::sim {

/// Periodic box [0, L_0) x [0, L_1) (x [0, L_2)) in metres.
struct PeriodicBox {
  int dimension = 3;
  std::array<double, 3> length{0.0, 0.0, 0.0};

  double volume() const {
    double v = 1.0;
    for (int d = 0; d < dimension; ++d) v *= length[d];
    return v;
  }
  double min_length() const {
    double m = length[0];
    for (int d = 1; d < dimension; ++d) m = m < length[d] ? m : length[d];
    return m;
  }
};

/// Maps a coordinate into [0, L). Assumes |x| < 2L (particles move far less than a box per step).
inline double wrap_periodic(double x, double length) {
  if (x >= length) {
    x -= length;
  } else if (x < 0.0) {
    x += length;
    if (x >= length) x = 0.0;  // x was a tiny negative number that rounded to L
  }
  return x;
}

/// Minimum-image difference. Exactly antisymmetric: min_image(-d) == -min_image(d) bit for bit,
/// which keeps pairwise forces antisymmetric and momentum conserved to round-off.
/// Written as two selects (the second cannot fire after the first: dx - L > -L/2 when dx > L/2),
/// which the vectoriser turns into blends; branches kept some loops scalar.
inline double minimum_image(double dx, double length, double half_length) {
  dx = dx > half_length ? dx - length : dx;
  return dx < -half_length ? dx + length : dx;
}

struct ParticleArrays {
  int dimension = 3;
  std::array<std::vector<double>, 3> position;      // x_i [m]; components >= dimension unused
  std::array<std::vector<double>, 3> velocity;      // v_i [m/s]
  std::array<std::vector<double>, 3> acceleration;  // dv_i/dt [m/s²] at the current state
  std::vector<double> mass;                         // M_i [kg] (per unit depth in 2D)
  std::vector<double> volume;                       // V_i = 1/Σ_j W_ij (A.1) [m^n]
  std::vector<double> density;                      // ρ_i = M_i/V_i (A.2) [kg/m^n]
  std::vector<double> pressure;                     // p_i from the EOS [Pa]
  std::vector<double> eddy_viscosity;               // ν_t [m²/s] of an explicit model, else empty
  std::vector<std::uint64_t> id;                    // stable identity across reorderings

  std::size_t size() const { return mass.size(); }

  /// Allocates every array for n particles (values zero, ids 0..n-1).
  void resize(std::size_t n);

  /// Applies a permutation to every per-particle array: new[k] = old[order[k]].
  /// The single place where particles are reordered.
  void reorder(std::span<const std::uint32_t> order);

  /// Keeps the first n particles (n <= size()), every array, their values unchanged: drops the
  /// halo copies a distributed run keeps behind its owned particles (sim/exchange.hpp).
  void truncate(std::size_t n);

  /// Every per-particle array of doubles that holds values, positions first: x, v and a for
  /// each dimension, M, V, ρ, p, and ν_t when present. For code that moves whole particles
  /// (reorder; the halo exchange and migration between MPI ranks, par/). `id` is the one
  /// per-particle array that is not in it.
  std::vector<std::vector<double>*> double_fields();
  std::vector<const std::vector<double>*> double_fields() const;
};

}  // namespace sphles::sim
