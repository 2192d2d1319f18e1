// SPDX-License-Identifier: GPL-3.0-or-later
// Vorticity three ways: by second-order central differences on the periodic grid (SPEC §5, the
// thesis' estimate), per particle as the curl of the (A.20) velocity gradient (SPEC §4), and per
// particle as the curl of a local cubic fit to the velocities (local_fit.hpp).
#pragma once

#include <array>
#include <memory>
#include <span>
#include <vector>

#include "analysis/grid.hpp"
#include "analysis/local_fit.hpp"
#include "analysis/snapshot.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/physics/subfilter_stress.hpp"
#include "sim/reduction.hpp"
#include "sim/subfilter.hpp"

namespace sphles::analysis {

/// ω = ∇ × u. 3D: components 0, 1, 2 = ω_x, ω_y, ω_z. 2D: component 2 holds ω_z, components 0
/// and 1 are empty.
VectorField vorticity(const VectorField& velocity);

/// |ω|² at every node.
std::vector<double> squared_magnitude(const VectorField& field);

/// Arithmetic mean of the values (⟨ω²⟩ for the dissipation ε_v = ν ⟨ω²⟩ of (4.6)).
double mean_value(const std::vector<double>& values);

/// ω = ∇ × v from a velocity gradient J_ab = ∂v_a/∂x_b:
/// (J_zy - J_yz, J_xz - J_zx, J_yx - J_xy). A 2D gradient (zero third row and column) gives
/// (0, 0, ω_z).
inline std::array<double, 3> curl(const sim::VelocityGradient& j) {
  return {j[2][1] - j[1][2], j[0][2] - j[2][0], j[1][0] - j[0][1]};
}

/// Vorticity of every particle, ω_i = ∇ × v from J_i = Σ_j (v_j - v_i) ⊗ ∇W_ij V_j (A.20):
/// the vorticity of the kernel-filtered velocity. Same layout as the grid vorticity, indexed by
/// particle: 3D components 0, 1, 2; 2D component 2 (ω_z) only.
struct ParticleVorticity {
  int dimension = 3;
  std::array<std::vector<double>, 3> component;

  std::size_t size() const { return component[2].size(); }
  /// |ω_i|² of every particle.
  std::vector<double> squared_magnitude() const;
};

/// From a neighbour list whose radius covers the kernel support; needs the particles' volumes
/// (A.1). The gradient is sim::velocity_gradient_pass, the solver's own (gather form, so the
/// result does not depend on the thread count).
ParticleVorticity particle_vorticity(const Snapshot& snapshot,
                                     const sim::NeighbourList& neighbours);

/// Vorticity of every particle from the local cubic least-squares fit of the velocities within
/// fit.radius (local_fit.hpp, the "mls" estimate): the vorticity of the particle velocity field
/// itself, not of its kernel-filtered version. `grid` gives the periodic box.
ParticleVorticity fitted_particle_vorticity(const Snapshot& snapshot, const Grid& grid,
                                            const FitSettings& fit);
/// The same for the first `centres` of `particles` (a rank's own particles; the fits also see
/// its halo behind them): the same bits as for those particles in the whole set.
ParticleVorticity fitted_particle_vorticity(const sim::ParticleArrays& particles, const Grid& grid,
                                            const FitSettings& fit, std::size_t centres);

/// |ω|² at the given grid nodes (all when empty) from the local quadratic fit of the particle
/// vorticity's components (the "mls" estimate's grid values; fitted_sample): omega holds one
/// value per particle of `particles`.
std::vector<double> fitted_vorticity_squared(const Grid& grid, const sim::ParticleArrays& particles,
                                             const FitSettings& fit, const ParticleVorticity& omega,
                                             std::span<const std::size_t> nodes);

/// Σ_i V_i f_i and Σ_i V_i over the first values.size() particles, summed exactly
/// (sim::ExactSum): the same bits in any order and over any split of the particles.
std::array<sim::ExactSum, 2> volume_weighted_sums(const sim::ParticleArrays& particles,
                                                  const std::vector<double>& values);

/// Σ_i V_i f_i / Σ_i V_i over the particles (volume_weighted_sums): the volume average of a
/// per-particle field (A.1 volumes).
double volume_weighted_mean(const sim::ParticleArrays& particles,
                            const std::vector<double>& values);

/// The snapshot's neighbour list, or a list of radius H built for its positions when it has
/// none (shared by the per-particle passes of one analysis).
std::shared_ptr<const sim::NeighbourList> snapshot_neighbours(const Snapshot& snapshot);

}  // namespace sphles::analysis
