// SPDX-License-Identifier: GPL-3.0-or-later
// The seam between the solver and the other processes of a distributed run (docs/scaling.md).
// sim/ knows no MPI: par/ implements this interface over MPI ranks, and a one-process run uses
// LocalExchange, which does nothing.
//
// In a distributed run the solver's ParticleArrays hold the particles this process owns at
// [0, owned) and, behind them, halo copies of the particles other processes own within the
// neighbour-list radius of its part of the box. The passes compute owned particles only (the
// neighbour list lists the owned ones); the exchange refreshes the copies wherever a pass reads
// a neighbour's value that an earlier step or pass changed, and reduces what the solver needs
// over all processes (the time step's maxima, the rebuild decision, the diagnostics' sums).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "sim/particles.hpp"
#include "sim/reduction.hpp"

namespace sphles::sim {

class Exchange {
 public:
  virtual ~Exchange() = default;

  /// Whether other processes hold part of the particles.
  virtual bool distributed() const = 0;

  /// At a neighbour-list rebuild, with `p` holding owned particles only: sends the particles that
  /// left this process' part of the box to the process that owns them now, with their values in
  /// `carried` (per-particle arrays kept alongside p), and appends those received. Positions end
  /// wrapped into the box. Collective.
  virtual void migrate(ParticleArrays& p, std::span<std::vector<double>* const> carried) = 0;

  /// Appends the halo behind the owned particles of `p` (which migrate just placed): copies at
  /// their own positions in [0, L), every field of ParticleArrays::double_fields() and the ids.
  /// The plan holds until the next build. Collective.
  virtual void build_halo(ParticleArrays& p) = 0;

  /// Overwrites the halo entries of each array of `fields` with the owners' current values. An
  /// array holds w values per particle (w = its size / particles, particle-major); positions may
  /// be among the fields. Collective.
  virtual void refresh(std::span<std::vector<double>* const> fields) const = 0;

  /// Reductions over all processes. Collective.
  virtual double max(double local) const = 0;
  virtual bool any(bool local) const = 0;
  virtual std::uint64_t sum(std::uint64_t local) const = 0;
  /// The exact sums of every process combined: the same bits for any split (ExactSum).
  virtual void sum(std::span<ExactSum> partial) const = 0;
};

/// One process holding every particle: no halo, reductions are the local values.
class LocalExchange final : public Exchange {
 public:
  bool distributed() const override { return false; }
  void migrate(ParticleArrays&, std::span<std::vector<double>* const>) override {}
  void build_halo(ParticleArrays&) override {}
  void refresh(std::span<std::vector<double>* const>) const override {}
  double max(double local) const override { return local; }
  bool any(bool local) const override { return local; }
  std::uint64_t sum(std::uint64_t local) const override { return local; }
  void sum(std::span<ExactSum>) const override {}
};

}  // namespace sphles::sim
