// SPDX-License-Identifier: GPL-3.0-or-later
// A distributed run driven from rank 0 (`mpirun -n N sphles run SCENE.json`, docs/scaling.md).
//
// Rank 0 runs the program as one process would (control::Run: outputs, analysis, checkpoints)
// with a sim::Simulation that is the distributed solver seen whole: each step() is one step of
// the solver on every rank, and particles() and state() gather the ranks' particles to rank 0 in
// id order when asked (at outputs, analysis snapshots and checkpoints; cached per step). The
// other ranks serve rank 0's commands (serve_commands) until the Driver on rank 0 is destroyed.
// Rank 0 holds every particle at such gathers, so this suits runs whose state fits one node's
// memory; analysis where the particles live is still to come (docs/scaling.md).
#pragma once

#include <mpi.h>

#include <filesystem>
#include <functional>
#include <memory>

#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/solver_factories.hpp"

namespace sphles::par {

/// Rank 0's end of the ranks' requests: makes distributed solvers; ends the other ranks' service
/// when destroyed.
class Driver {
 public:
  /// `comm`: the ranks of the run, rank 0 being this process.
  explicit Driver(MPI_Comm comm);
  ~Driver();
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  int ranks() const;
  /// The factories a run takes (control::RunOptions::solvers): solvers over all ranks whose
  /// requests (remote/messages.hpp) rank 0 sends to the other ranks and carries out its own part
  /// of. make() scatters the particles to the ranks of their sub-boxes; set_up() has the ranks
  /// make theirs (par::set_up_share: the lattice of each sub-box, relaxed with the other ranks'
  /// or read from the packing cache, bitwise make(scene, sim::setup_run(scene,
  /// options).particles) without any rank holding every particle); restore() continues a state
  /// of every particle bitwise on this rank count whatever count wrote it; restore_file() has
  /// every rank read a block of the checkpoint and send it to the ranks that own it; change()
  /// continues each rank's own particles (no gather). The solvers refer to this Driver, which
  /// must outlive them.
  sim::SolverFactories factories();

 private:
  class RankZero;
  MPI_Comm comm_;
  std::shared_ptr<RankZero> rank_zero_;
};

/// The other ranks: carries out rank 0's requests until its Driver ends. A solver error (a
/// blow-up, a decomposition too fine for the scene) ends the command on every rank alike; rank 0
/// reports it and this rank waits for the next command. Returns when told to stop.
void serve_commands(MPI_Comm comm);

/// A program's MPI life under mpirun: initialises MPI (funneled threads), runs `rank_zero` with a
/// Driver over MPI_COMM_WORLD on rank 0 while the other ranks serve it, finalises MPI, and
/// returns rank_zero's exit code on rank 0 (0 elsewhere).
int drive_from_rank_zero(const std::function<int(Driver&)>& rank_zero);

}  // namespace sphles::par
