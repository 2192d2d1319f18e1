// SPDX-License-Identifier: GPL-3.0-or-later
// Periodic cell-list neighbour search producing a Verlet list with a skin.
//
// The search borrows positions and owns no particle data (CompactNSearch style): it returns a
// cell-major sort order that the caller applies to every field in one place
// (ParticleArrays::reorder), then builds a list of all j != i with
// |x_i - x_j| < cutoff + skin under the minimum-image convention. Lists are rebuilt when some
// particle has moved more than skin/2 since the last build, so the list stays complete for the
// cutoff in between. Each particle's list is built independently in a fixed order: the result is
// identical for any thread count. The candidates of the particles of one cell are gathered once
// and tested in single precision; near the list radius the double-precision minimum-image test
// decides, so the lists are those of a double-precision test (docs/performance.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include "sim/particles.hpp"

namespace sphles::sim {

/// Neighbour list: the neighbours of i are indices[start[i] .. start[i] + count[i]). A particle's
/// entries are contiguous; between the segments of particles built by different threads there
/// may be unused entries (each thread writes its particles straight into a region of `indices`).
struct NeighbourList {
  std::vector<std::size_t> start;
  std::vector<std::uint32_t> count;
  std::vector<std::uint32_t> indices;
  /// Σ count: the entries in use.
  std::size_t entries = 0;

  std::size_t num_particles() const { return count.size(); }
  std::size_t num_entries() const { return entries; }
  std::span<const std::uint32_t> of(std::size_t i) const {
    return {indices.data() + start[i], count[i]};
  }
};

struct PositionsView {
  int dimension = 3;
  std::size_t size = 0;
  const double* x[3] = {nullptr, nullptr, nullptr};
};

inline PositionsView view_positions(const ParticleArrays& p) {
  PositionsView v;
  v.dimension = p.dimension;
  v.size = p.size();
  for (int d = 0; d < p.dimension; ++d) v.x[d] = p.position[d].data();
  return v;
}

/// The indices 0..n-1 sorted by their keys (unique), for VerletNeighbourSearch::build's cell
/// order: O(n) when the keys are a permutation of 0..n-1 (the ids of one process), else a sort.
std::vector<std::uint32_t> order_by_key(std::span<const std::uint64_t> keys);

class VerletNeighbourSearch {
 public:
  /// Cells per list radius: 2 scans (5/2)^n list-radius volumes instead of 3^n.
  static constexpr int kCellsPerRadius = 2;
  /// A build's region for a range of particles holds this many times the entries per particle
  /// expected (from the last build) times the range's particles: the list's indices are about
  /// this many times its entries (control/resources.cpp).
  static constexpr double kRegionMargin = 1.1;

  /// cutoff: interaction radius (kernel support H); skin: extra list radius. The skin is reduced
  /// automatically when the box is too small for minimum-image lists of radius cutoff + skin.
  /// Throws std::invalid_argument if the box is shorter than 2 * cutoff in any direction.
  VerletNeighbourSearch(const PeriodicBox& box, double cutoff, double skin);

  double cutoff() const { return cutoff_; }
  double skin() const { return skin_; }
  double list_radius() const { return cutoff_ + skin_; }
  std::array<int, 3> cells_per_side() const { return cells_; }

  /// Cell-major order (stable within a cell) for memory locality. Positions must lie in the box.
  std::vector<std::uint32_t> locality_order(const PositionsView& positions) const;

  /// Builds the list for the given positions and remembers them for needs_rebuild(). Each
  /// particle's neighbours come cell by cell in a fixed stencil order and, within a cell, in
  /// index order, or in the order of `cell_order` (a permutation of the indices) when given: with
  /// the indices sorted by a global key (the particle id), the list of a particle names the same
  /// neighbours in the same order whatever other particles the arrays hold and in whatever
  /// order, which makes the sums of a particle distributed over ranks (par/) bitwise those of
  /// one process. Only the first `listed` particles get a list (a distributed run lists its
  /// owned particles, not the halo copies behind them); all are candidates.
  void build(const PositionsView& positions, std::span<const std::uint32_t> cell_order = {},
             std::size_t listed = std::numeric_limits<std::size_t>::max());

  /// True when the list was never built, the particle count changed, or one of the first
  /// `checked` particles moved more than skin/2 (minimum image) since the last build.
  bool needs_rebuild(const PositionsView& positions,
                     std::size_t checked = std::numeric_limits<std::size_t>::max()) const;

  const NeighbourList& list() const { return list_ ? *list_ : kEmptyList; }
  /// The current list for readers that outlive this build (analysis snapshots). It stays valid
  /// for the positions it was shared with; a later build never modifies a shared list.
  std::shared_ptr<const NeighbourList> shared_list() const { return list_; }
  std::size_t num_builds() const { return num_builds_; }
  /// Positions the current list was built from (what a checkpoint needs to rebuild the very
  /// same list), and the build counter, restorable on restart.
  const std::array<std::vector<double>, 3>& reference_positions() const {
    return reference_positions_;
  }
  void set_num_builds(std::size_t count) { num_builds_ = count; }

 private:
  template <int Dim>
  void build_impl(const PositionsView& positions, std::span<const std::uint32_t> cell_order,
                  std::size_t listed);
  /// A build's binning into scratch_ (neighbour_search_cells.cpp): each particle's cell, the
  /// particles cell by cell (within a cell in the order of `cell_order` when given, else by index)
  /// and where each cell begins, the positions in that order and each particle's place in it.
  template <int Dim>
  void bin_particles(const PositionsView& positions, std::span<const std::uint32_t> cell_order);
  /// The list to build into, with room for the rows of `listed` particles.
  NeighbourList& list_to_build(std::size_t listed);
  void cell_of(const PositionsView& positions, std::vector<std::uint32_t>& cell) const;
  std::size_t num_cells() const {
    return static_cast<std::size_t>(cells_[0]) * static_cast<std::size_t>(cells_[1]) *
           static_cast<std::size_t>(cells_[2]);
  }

  PeriodicBox box_;
  double cutoff_;
  double skin_;
  std::array<int, 3> cells_{1, 1, 1};
  std::array<double, 3> inv_cell_size_{0.0, 0.0, 0.0};
  std::shared_ptr<NeighbourList> list_;
  static inline const NeighbourList kEmptyList{};
  std::array<std::vector<double>, 3> reference_positions_;
  std::size_t num_builds_ = 0;
  /// A list a reader held at the last build, kept to build into once the reader lets it go
  /// (a fresh list of this size is mapped and zeroed page by page, which is slow on this VM).
  std::shared_ptr<NeighbourList> spare_;
  /// Entries per listed particle of the last build: sizes the regions of the next one.
  double entries_per_particle_ = 0.0;
  /// The other per-particle scratch of build(), kept for the same reason.
  struct BuildScratch {
    std::vector<std::uint32_t> cell, cell_members, rank, visit_order;
    std::vector<std::size_t> cell_start;
    std::array<std::vector<double>, 3> sorted;
  } scratch_;
};

}  // namespace sphles::sim
