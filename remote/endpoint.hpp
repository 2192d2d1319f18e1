// SPDX-License-Identifier: GPL-3.0-or-later
// The solver's side of a solver elsewhere: carries out requests (remote/messages.hpp) on the
// solver it holds, made by the factories it was given. The one place a request meets a solver,
// whatever carried it: the other MPI ranks (par::serve_commands) and rank 0 itself
// (par::Driver), and the rank 0 of a service's MPI job (launch::serve_job).
#pragma once

#include <memory>
#include <string>

#include "remote/messages.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/solver_factories.hpp"

namespace sphles::remote {

class Endpoint {
 public:
  explicit Endpoint(sim::SolverFactories solvers);

  /// The reply to `request`; throws what the solver throws. A request that makes a solver
  /// replaces the current one once the new one exists (a failure keeps the current one); one
  /// that needs a solver throws std::logic_error before the first. Finish does nothing here:
  /// the caller's service ends.
  Reply handle(Request request);

  /// The solver, what it can do beyond sim::Simulation (asked once when it is made), and the
  /// factories of the next one; each request's handling (endpoint.cpp) works on this.
  struct Held {
    sim::SolverFactories solvers;
    std::unique_ptr<sim::Simulation> simulation;
    const analysis::DistributedProducts* products = nullptr;  // null: it does not
    const io::DistributedCheckpoints* checkpoints = nullptr;
    // The last scene document parsed and its scene: case diagnostics carry the same scene with
    // every time-series row, which is parsed once, not per row.
    std::string scene_json;
    sim::Scene scene;
  };

 private:
  Held held_;
};

}  // namespace sphles::remote
