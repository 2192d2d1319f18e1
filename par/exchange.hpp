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
  /// Particles this rank sent by migration since it was made.
  std::size_t migrated() const { return migrated_; }

 private:
  const Decomposition& d_;
  std::optional<Halo> halo_;
  std::size_t migrated_ = 0;
};

}  // namespace sphles::par
