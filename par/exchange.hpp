// SPDX-License-Identifier: GPL-3.0-or-later
// The solver's exchange over MPI ranks (sim::Exchange, sim/exchange.hpp): migration and a
// Wrapped halo of width = the neighbour-list radius at each list rebuild, halo refreshes along
// the same plan, and reductions over the ranks of a Decomposition (exact sums by
// par::allreduce), so a run's particle states and diagnostics are bitwise those of one process.
#pragma once

#include <memory>
#include <optional>

#include "par/decomposition.hpp"
#include "par/halo.hpp"
#include "sim/exchange.hpp"

namespace sphles::par {

/// What an MpiExchange did on this rank since it was made (for benchmarks and logs).
struct ExchangeStats {
  double migrate_seconds = 0.0;     // migration (MPI_Wtime)
  double halo_build_seconds = 0.0;  // halo builds
  double refresh_seconds = 0.0;     // halo refreshes
  double reduce_seconds = 0.0;      // global maxima, sums and the rebuild decision
  std::size_t migrated = 0;         // particles sent by migration
  std::size_t halo_builds = 0;
  std::size_t build_bytes = 0;    // sent by halo builds
  std::size_t refresh_bytes = 0;  // sent by halo refreshes
  std::size_t halo_copies = 0;    // copies in the current halo
  double seconds() const {
    return migrate_seconds + halo_build_seconds + refresh_seconds + reduce_seconds;
  }
};

class MpiExchange final : public sim::Exchange {
 public:
  /// `decomposition` must outlive this exchange; its halo width must be at least the solver's
  /// neighbour-list radius (sim::VerletNeighbourSearch::list_radius()).
  explicit MpiExchange(const Decomposition& decomposition) : d_(decomposition) {}

  bool distributed() const override { return true; }
  void migrate(sim::ParticleArrays& p, std::span<std::vector<double>* const> carried) override;
  void build_halo(sim::ParticleArrays& p) override;
  void refresh(std::span<std::vector<double>* const> fields) const override;
  double max(double local) const override;
  bool any(bool local) const override;
  std::uint64_t sum(std::uint64_t local) const override;
  void sum(std::span<sim::ExactSum> partial) const override;

  /// The halo of the last build (none before the first).
  const Halo* halo() const { return halo_ ? &*halo_ : nullptr; }
  const ExchangeStats& stats() const { return stats_; }

 private:
  const Decomposition& d_;
  std::optional<Halo> halo_;
  mutable ExchangeStats stats_;
};

}  // namespace sphles::par
