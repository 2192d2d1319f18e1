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

/// Rank 0's end of the command channel: makes distributed solvers; ends the other ranks' service
/// when destroyed.
class Driver {
 public:
  /// `comm`: the ranks of the run, rank 0 being this process.
  explicit Driver(MPI_Comm comm);
  ~Driver();
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  /// A solver over all ranks for `scene` (sim::make_solver_config) starting from `all`, every
  /// particle of the run (each rank receives those of its sub-box). Replaces the solver the other
  /// ranks held; the Simulation returned must not outlive this Driver.
  std::unique_ptr<sim::Simulation> make(const sim::Scene& scene, sim::ParticleArrays all);
  /// A new run's solver whose particles the ranks make, each its share: the lattice of its
  /// sub-box, relaxed with the other ranks' or read from the packing cache, with the case's
  /// fields (par::set_up_share): bitwise make(scene, sim::setup_run(scene, options).particles),
  /// without any rank holding every particle. `options.cancelled` is polled here (rank 0);
  /// throws sim::SetupCancelled on every rank when it says so. `report` gets the packing's.
  std::unique_ptr<sim::Simulation> set_up(const sim::Scene& scene, const sim::SetupOptions& options,
                                          sim::PackingReport& report);
  /// The same from a state of every particle (a checkpoint, or state() of a solver made here):
  /// continues bitwise on this rank count whatever count wrote it (par::scatter_state sends each
  /// rank its share).
  std::unique_ptr<sim::Simulation> restore(const sim::Scene& scene, sim::SolverState whole);

  /// The same from the checkpoint file `path`, read by every rank, each a block of it, then sent
  /// to the ranks that own them (par::read_share): no rank holds the whole state. Throws
  /// io::CheckpointError (on every rank) for a file read_checkpoint would reject.
  std::unique_ptr<sim::Simulation> restore_file(const sim::Scene& scene,
                                                const std::filesystem::path& path);

  /// A solver for `scene` (a live change) continuing `current`, a solver made here, on the ranks
  /// where its particles are: each rank restores from its own state (no gather), bitwise what
  /// restore(scene, current.state()) gives. Throws std::invalid_argument for another solver.
  std::unique_ptr<sim::Simulation> change(const sim::Simulation& current, const sim::Scene& scene);

  int ranks() const;
  /// make(), set_up(), restore() and the others as the factories a run takes
  /// (control::RunOptions::solvers); they refer to this Driver, which must outlive them.
  sim::SolverFactories factories();

 private:
  MPI_Comm comm_;
};

/// The other ranks: carries out rank 0's commands until its Driver ends. A solver error (a
/// blow-up, a decomposition too fine for the scene) ends the command on every rank alike; rank 0
/// reports it and this rank waits for the next command. Returns when told to stop.
void serve_commands(MPI_Comm comm);

/// A program's MPI life under mpirun: initialises MPI (funneled threads), runs `rank_zero` with a
/// Driver over MPI_COMM_WORLD on rank 0 while the other ranks serve it, finalises MPI, and
/// returns rank_zero's exit code on rank 0 (0 elsewhere).
int drive_from_rank_zero(const std::function<int(Driver&)>& rank_zero);

}  // namespace sphles::par
