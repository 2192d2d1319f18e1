// SPDX-License-Identifier: GPL-3.0-or-later
// Implicit sub-filter stress per particle (3.27), its norm (4.7) and principal axes (4.8).
#pragma once

#include <array>
#include <vector>

#include "analysis/snapshot.hpp"
#include "sim/neighbour_search.hpp"

namespace sphles::analysis {

/// Symmetric tensor components in the order xx, yy, zz, xy, xz, yz (2D: xx, yy, xy used; the
/// others are zero).
enum StressComponent { kXX = 0, kYY = 1, kZZ = 2, kXY = 3, kXZ = 4, kYZ = 5 };

struct SubfilterStressField {
  int dimension = 3;
  std::vector<std::array<double, 6>> tensor;  // τ_SFS,i = Σ_j (v_j - v_i)(v_j - v_i)ᵀ W_ij M_j [Pa]
  std::vector<double> norm;                   // Frobenius norm (4.7) [Pa]
  /// Principal stresses, descending (τ_I ≥ τ_II (≥ τ_III)); unused entries zero.
  std::vector<std::array<double, 3>> principal;
  /// Unit principal directions; direction[i][a] is the direction of principal[i][a] (t_I, t_II,
  /// ...), each with its first non-zero component made positive.
  std::vector<std::array<std::array<double, 3>, 3>> direction;
};

/// τ_SFS (3.27) of the first `centres` particles (a rank's own ones, its halo behind them: par/)
/// in the periodic `box`, with the kernel `kernel` of support H (j = i contributes nothing).
/// Principal axes from Eigen's self-adjoint eigen-solver. The neighbours come from the
/// analysis' cell list (cell_list.hpp: cells of side >= H/2 over the cubic box, a cell's
/// members in id order), so each particle sums its neighbours in an order set by positions and
/// ids alone: the same bits for any order of the particles and on the ranks of a distributed
/// run as in one process.
SubfilterStressField implicit_subfilter_stress(const sim::ParticleArrays& particles,
                                               const sim::PeriodicBox& box, sim::KernelType kernel,
                                               double support_radius, std::size_t centres);

/// Of every particle of the snapshot.
SubfilterStressField implicit_subfilter_stress(const Snapshot& snapshot);

}  // namespace sphles::analysis
