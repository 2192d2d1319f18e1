// SPDX-License-Identifier: GPL-3.0-or-later
// How a run gets its solver: one seam for every place that builds solvers, so that a run in
// this process, a run under mpirun (par::Driver) and a run in a service's MPI job
// (launch::job_solvers) are built and continued the same way (control::RunOptions).
#pragma once

#include <filesystem>
#include <functional>
#include <memory>

#include "sim/packing.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::sim {

struct SolverFactories {
  /// A new solver for `scene` starting from all its particles.
  std::function<std::unique_ptr<Simulation>(const Scene&, ParticleArrays)> make;
  /// A solver continuing a saved state of all particles (bitwise the next step).
  std::function<std::unique_ptr<Simulation>(const Scene&, SolverState)> restore;
  /// Optional: a solver continuing the checkpoint file at the path, read where its particles
  /// will live (a distributed solver's ranks, each its part) instead of by the caller. Throws
  /// the file's io::CheckpointError when it is not a valid checkpoint (sim does not know io's
  /// types: the run that calls it does). Empty: the caller reads the file and calls restore.
  std::function<std::unique_ptr<Simulation>(const Scene&, const std::filesystem::path&)>
      restore_file;
  /// Optional: a solver for `scene` (a live change) continuing the state of `current`, a solver
  /// these factories made, where its particles live (a distributed solver's ranks keep theirs)
  /// instead of through current.state(). Bitwise what restore(scene, current.state()) gives.
  /// Empty: the caller does that.
  std::function<std::unique_ptr<Simulation>(const Simulation& current, const Scene&)> change;
  /// Optional: a new run's solver whose particles are made where they will live (a distributed
  /// solver's ranks make, pack and set up each its part) instead of by the caller: bitwise
  /// make(scene, setup_run(scene, options).particles). `report` receives the packing's; throws
  /// SetupCancelled as setup_run does. Empty: the caller calls setup_run and make.
  std::function<std::unique_ptr<Simulation>(const Scene&, const SetupOptions&, PackingReport&)>
      set_up;
};

}  // namespace sphles::sim
