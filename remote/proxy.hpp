// SPDX-License-Identifier: GPL-3.0-or-later
// A solver elsewhere as the run sees it: a sim::Simulation (with analysis::DistributedProducts
// and io::DistributedCheckpoints) whose every call is a request (remote/messages.hpp) over a
// Transport to an Endpoint holding the real solver. par/ carries requests to the MPI ranks of a
// `mpirun sphles run`, launch/ to the MPI job a service launched for a run.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>

#include "remote/messages.hpp"
#include "sim/solver_factories.hpp"

namespace sphles::remote {

/// Carries requests to the solver's side and brings their replies back. Used by one thread at a
/// time (the run's solver thread).
class Transport {
 public:
  virtual ~Transport();

  /// The reply to `request`; the solver's side's errors are rethrown as their own types
  /// (remote/codec.hpp, encode_error), a transport's own failure as sim::SimulationError.
  virtual Reply call(Request request) = 0;

  /// A new solver made over this transport replaces the one before: solvers made before it are
  /// stale, and using one is a logic error.
  std::uint64_t next_generation() { return ++generation_; }
  void require_current(std::uint64_t generation) const;

 private:
  std::uint64_t generation_ = 0;
};

/// Solver factories for control::RunOptions::solvers whose solvers live across `transport`,
/// asked for the transport once per solver made (it may launch a job). `change` continues the
/// current solver where its particles are, so no state crosses.
sim::SolverFactories remote_solvers(std::function<std::shared_ptr<Transport>()> transport);

}  // namespace sphles::remote
