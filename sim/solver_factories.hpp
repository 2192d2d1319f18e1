// How a run gets its solver: one seam for every place that builds solvers, so that a run in
// this process, a run under mpirun (par::Driver) and a run in a service's MPI job
// (launch::job_solvers) are built and continued the same way (control::RunOptions).
#pragma once

#include <functional>
#include <memory>

#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::sim {

struct SolverFactories {
  /// A new solver for `scene` starting from all its particles.
  std::function<std::unique_ptr<Simulation>(const Scene&, ParticleArrays)> make;
  /// A solver continuing a saved state of all particles (bitwise the next step).
  std::function<std::unique_ptr<Simulation>(const Scene&, SolverState)> restore;
};

}  // namespace sphles::sim
