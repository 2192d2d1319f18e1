// SPDX-License-Identifier: GPL-3.0-or-later
// Cartesian grid over the periodic box: nearest-particle sampling (SPEC §5, "Gridding") and
// kernel-weighted (Shepard) interpolation with the run's kernel.
//
// Node (i, j, k) sits at (i h, j h, k h), h = L / M, i, j, k in [0, M); storage is x fastest:
// index = i + M (j + M k). A 2D grid has k = 0 only. M = 2 N^(1/n) gives spacing Δl / 2.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "analysis/grid_shape.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::analysis {

/// Three components (2D fields use components 0 and 1) of a vector field on a grid.
struct VectorField {
  Grid grid;
  std::array<std::vector<double>, 3> component;
};

/// For every node, the index of the nearest particle (minimum image); ties go to the smaller
/// particle id, so the map does not depend on particle order or thread count.
/// Squared distances within a relative 1e-12 of the smallest count as ties, so that lattices and
/// other equidistant sets are decided by id rather than by round-off (whose last bits depend on
/// the compiler's use of fused multiply-adds). Positions must lie in [0, L]; the box is the
/// grid's cube of side L.
struct NearestParticleMap {
  Grid grid;
  std::vector<std::uint32_t> particle;
};

NearestParticleMap nearest_particle_map(const Grid& grid, const sim::ParticleArrays& particles);

/// A block of nodes: [first[d], first[d] + count[d]) along each axis d < dimension (count 1 and
/// first 0 beyond it).
struct NodeBlock {
  std::array<int, 3> first{0, 0, 0};
  std::array<int, 3> count{1, 1, 1};
  std::size_t size() const {
    return static_cast<std::size_t>(count[0]) * static_cast<std::size_t>(count[1]) *
           static_cast<std::size_t>(count[2]);
  }
};

/// The nearest particles of a block's nodes, x fastest, and the largest of the nodes' squared
/// distances to them.
struct NearestInBlock {
  std::vector<std::uint32_t> particle;
  double max_distance2 = 0.0;
};

/// nearest_particle_map for the nodes of `block` only, with a cell list of `cells_per_side` cells
/// per side (nearest_particle_map takes N^(1/n)). For particles that are only those near the
/// block (a rank's own particles and its halo, par/): the answer is the whole set's whenever
/// every particle left out lies further than sqrt(max_distance2) (times a relative 1e-12 for the
/// ties) from every node of the block.
NearestInBlock nearest_particles_in_block(const Grid& grid, const sim::ParticleArrays& particles,
                                          const NodeBlock& block, int cells_per_side);

/// Velocity of the nearest particle at every node; with remove_mean, the spatial mean over the
/// nodes is subtracted from each component (SPEC §5).
VectorField sample_velocity(const NearestParticleMap& map, const sim::ParticleArrays& particles,
                            bool remove_mean);

/// Any per-particle scalar sampled the same way.
std::vector<double> sample_scalar(const NearestParticleMap& map,
                                  std::span<const double> per_particle);

/// Subtracts the spatial mean over the nodes from each used component (SPEC §5: spectra and
/// vorticity of the fluctuation). The mean is a fixed-order sum: independent of thread count.
void remove_spatial_mean(VectorField& field);

/// The kernel of a Shepard interpolation: the run's kernel type and support radius H.
struct InterpolationKernel {
  sim::KernelType type = sim::KernelType::WendlandC4;
  double support_radius = 0.0;  // H [m]
};

/// One node's Shepard value Σ_j f_j W_j V_j / Σ_j W_j V_j from its two sums; NaN when no
/// particle lies inside the kernel support of the node (weight sum zero).
inline double shepard_value(double weighted_sum, double weight_sum) {
  return weight_sum > 0.0 ? weighted_sum / weight_sum : std::numeric_limits<double>::quiet_NaN();
}

/// Kernel-weighted (Shepard) interpolation of per-particle fields onto the nodes:
///   f(x_n) = Σ_j f_j W(x_n - x_j) V_j / Σ_j W(x_n - x_j) V_j   (minimum image),
/// with the particles' volumes V_j (A.1). Reproduces a constant exactly and is smooth where the
/// particles are. Each node gathers its particles in a fixed order (cells, then ascending id),
/// so the result does not depend on the thread count. Every field must hold one value per
/// particle; positions must lie in [0, L].
std::vector<std::vector<double>> shepard_sample(const Grid& grid,
                                                const sim::ParticleArrays& particles,
                                                const InterpolationKernel& kernel,
                                                std::span<const std::span<const double>> fields);

/// The velocity interpolated the same way; with remove_mean, the spatial mean over the nodes is
/// subtracted from each component (as sample_velocity does).
VectorField shepard_velocity(const Grid& grid, const sim::ParticleArrays& particles,
                             const InterpolationKernel& kernel, bool remove_mean);

/// Grid node nearest to each particle (for per-particle values of grid fields such as ω²).
std::vector<std::size_t> nearest_node(const Grid& grid, const sim::ParticleArrays& particles);

}  // namespace sphles::analysis
