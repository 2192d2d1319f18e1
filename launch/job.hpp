// SPDX-License-Identifier: GPL-3.0-or-later
// A run's solver in an MPI job of its own (docs/scaling.md, "From the service"): the service starts
// `LAUNCHER sphles worker --connect ...` (default launcher `mpirun -n {ranks}`; `srun -n {ranks}`
// under Slurm), the job's rank 0 connects back over TCP, and the run drives the job's distributed
// solver (par::Driver) through a sim::Simulation like any other. Everything else of the run
// (analysis, rendering, checkpoints, live changes, pause, stop) stays in the service.
//
// One job per run while it is active: the first solver made launches it, a live change or a
// restart made while a solver of the job exists reuses it, and the job ends when the run's last
// solver goes (stop, end, failure). A job that ends unasked (a rank killed or out of memory:
// mpirun then ends every rank) fails the step or request in progress with a SimulationError
// naming the launcher's exit status and the last lines of the job's log. A job that stops
// answering (a rank frozen, a batch queue that never starts it) is given up by the service
// (JobSolvers::end_job) when a stop's grace period has passed.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/solver_factories.hpp"

namespace sphles::launch {

struct LaunchOptions {
  /// The command before the worker's, with {ranks} replaced by the rank count; run by /bin/sh.
  std::string launcher = "mpirun -n {ranks}";
  std::filesystem::path executable;  // the sphles program the ranks run
  int ranks = 2;
  int threads = 0;  // OpenMP threads per rank; 0 = the ranks' default
  /// The job's standard output and error (appended).
  std::filesystem::path log_file;
  /// Address the service listens on for the job's rank 0, which must reach it: on a cluster,
  /// an address of the service's node the compute nodes can reach. 0.0.0.0 (or ::) listens on
  /// every interface and tells rank 0 this host's name (gethostname) to connect to.
  std::string listen_address = "127.0.0.1";
  double connect_timeout_seconds = 120.0;  // from the launch to rank 0's connection
  double finish_timeout_seconds = 30.0;    // from Finish to the job's exit, then it is killed
};

/// Throws std::invalid_argument naming the field if the options cannot launch anything.
void validate(const LaunchOptions& options);

/// The shell command that starts the job (without the connection arguments).
std::string launch_command(const LaunchOptions& options);

struct JobSolvers {
  /// Solver factories for control::RunOptions::solvers that put the solver into a job launched
  /// with `options`; they share the job.
  sim::SolverFactories solvers;
  /// Gives up on the job (control::RunOptions::end_solver_job): the call waiting on it, or the
  /// launch waiting for its rank 0, fails within a poll (0.2 s) with a sim::SimulationError
  /// saying `why`, and the job's process group is ended (SIGTERM, SIGKILL 5 s later). A job
  /// launched afterwards is not affected. Thread-safe; nothing happens when no job runs.
  std::function<void(const std::string& why)> end_job;
};

JobSolvers job_solvers(LaunchOptions options);

/// The job's side, on rank 0 (app/worker_command.cpp): connects to the service, proves the
/// token, and carries out requests with the given solver factories until told to finish or the
/// service goes away. Returns normally in both cases.
/// `ranks`: the job's rank count, which rank 0 reports to the service.
void serve_job(const std::string& host, unsigned short port, const std::string& token,
               const sim::SolverFactories& solvers, int ranks);

}  // namespace sphles::launch
