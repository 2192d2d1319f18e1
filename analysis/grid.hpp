// Cartesian grid over the periodic box and nearest-particle sampling (SPEC §5, "Gridding").
//
// Node (i, j, k) sits at (i h, j h, k h), h = L / M, i, j, k in [0, M); storage is x fastest:
// index = i + M (j + M k). A 2D grid has k = 0 only. M = 2 N^(1/n) gives spacing Δl / 2.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "sim/particles.hpp"

namespace sphles::analysis {

struct Grid {
  int dimension = 3;
  int points_per_side = 0;  // M
  double length = 0.0;      // L [m]

  double spacing() const { return length / points_per_side; }
  std::size_t size() const {
    std::size_t n = 1;
    for (int d = 0; d < dimension; ++d) n *= static_cast<std::size_t>(points_per_side);
    return n;
  }
  std::size_t index(int i, int j, int k = 0) const {
    const auto m = static_cast<std::size_t>(points_per_side);
    return static_cast<std::size_t>(i) +
           m * (static_cast<std::size_t>(j) + m * static_cast<std::size_t>(k));
  }
};

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

/// Velocity of the nearest particle at every node; with remove_mean, the spatial mean over the
/// nodes is subtracted from each component (SPEC §5).
VectorField sample_velocity(const NearestParticleMap& map, const sim::ParticleArrays& particles,
                            bool remove_mean);

/// Any per-particle scalar sampled the same way.
std::vector<double> sample_scalar(const NearestParticleMap& map,
                                  std::span<const double> per_particle);

/// Grid node nearest to each particle (for per-particle values of grid fields such as ω²).
std::vector<std::size_t> nearest_node(const Grid& grid, const sim::ParticleArrays& particles);

}  // namespace sphles::analysis
