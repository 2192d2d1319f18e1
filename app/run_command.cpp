// SPDX-License-Identifier: GPL-3.0-or-later
#include <omp.h>
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <thread>

#include "app/commands.hpp"
#include "control/run.hpp"
#include "io/checkpoint.hpp"
#include "par/driver.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

/// The signals that stop a run with a checkpoint. SIGUSR1 is there for MPI jobs and batch
/// systems: Open MPI's mpirun forwards it to every rank and does nothing else, whereas on SIGINT
/// or SIGTERM it sends the ranks SIGTERM and, odls_base_sigkill_timeout seconds later (default
/// 1), SIGKILL; Slurm sends it ahead of a time limit with --signal=USR1@SECONDS.
sigset_t stop_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  for (int signal : {SIGINT, SIGTERM, SIGUSR1}) sigaddset(&signals, signal);
  return signals;
}

namespace {

struct RunOptions {
  std::string scene_file;
  std::vector<std::string> overrides;
  std::string out_dir;        // empty: the default
  std::string restart;        // checkpoint file or run directory; empty: none
  std::string packing_cache;  // empty: the default cache directory
  int threads = 0;
  bool overwrite = false;
  bool dry_run = false;
  std::string log_level;
};

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Refusals CLI11 cannot express: exactly one of SCENE.json and --restart.
void check_run_options(const RunOptions& o) {
  if (o.scene_file.empty() && o.restart.empty())
    throw UsageError("missing SCENE.json (or --restart)");
  if (!o.scene_file.empty() && !o.restart.empty())
    throw UsageError(
        "give either SCENE.json or --restart, not both (the scene is in the checkpoint)");
}

}  // namespace

/// Stops the run on SIGINT/SIGTERM/SIGUSR1: it finishes its step, writes a checkpoint and exits.
std::atomic<control::Run*> g_interruptible_run{nullptr};

/// Ranks of the MPI job this process was started in by mpirun or mpiexec (OpenMPI, or an MPI
/// using PMI such as MPICH or Slurm's srun), 1 when it was started alone.
int launched_ranks() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"})
    if (const char* value = std::getenv(name)) {
      const int n = std::atoi(value);
      if (n > 1) return n;
    }
  return 1;
}

/// The checkpoint --restart names: the file, or a run directory's (or checkpoints directory's)
/// newest valid checkpoint of that run; the files passed over are listed on stderr.
std::filesystem::path restart_checkpoint(const RunOptions& options, bool distributed) {
  const std::filesystem::path given = options.restart;
  if (!std::filesystem::is_directory(given)) return given;
  const std::filesystem::path dir =
      std::filesystem::exists(given / "checkpoints") ? given / "checkpoints" : given;
  // A file of another run's scene among the run's checkpoints is passed over.
  const std::filesystem::path run_dir = !options.out_dir.empty()
                                            ? std::filesystem::path(options.out_dir)
                                        : dir == given ? dir.parent_path()
                                                       : given;
  std::vector<std::string> rejected;
  // Under mpirun the ranks read and validate the particles (the factories' restore_file).
  const std::filesystem::path file = io::newest_valid_checkpoint(
      dir, &rejected, distributed ? io::CheckpointCheck::Header : io::CheckpointCheck::Whole,
      control::checkpoints_of_run(run_dir));
  for (const std::string& r : rejected) std::fprintf(stderr, "skipped: %s\n", r.c_str());
  return file;
}

/// The run on this process; with a driver, its solver spans the MPI ranks (rank 0 only).
int run_here(const RunOptions& options, par::Driver* driver) {
  std::unique_ptr<control::Run> run;
  control::RunOptions run_options;
  run_options.log_progress = true;
  if (driver) {
    run_options.solvers = driver->factories();
    run_options.ranks = driver->ranks();  // recorded in run.json
    std::fprintf(stderr, "sphles run: the solver spans %d MPI ranks\n", driver->ranks());
  }
  try {
    check_run_options(options);
    run_options.threads = options.threads;
    run_options.packing_cache_dir = options.packing_cache;
    if (!options.restart.empty()) {
      const std::filesystem::path checkpoint_file = restart_checkpoint(options, driver != nullptr);
      const std::filesystem::path out_dir =
          !options.out_dir.empty()
              ? std::filesystem::path(options.out_dir)
              : std::filesystem::absolute(checkpoint_file).parent_path().parent_path();
      std::filesystem::create_directories(out_dir);
      run = control::Run::open(out_dir.filename().string(), out_dir, run_options, options.overrides,
                               checkpoint_file);
    } else {
      nlohmann::json document = load_scene_document(options.scene_file, options.overrides);
      control::RunSpec spec = control::parse_run_spec(document);
      // A run that cannot fit in this machine's memory is refused before anything is written.
      if (const auto too_big = check_machine_memory(control::estimate_resources(spec)))
        throw UsageError(*too_big);
      // The scene's name becomes one path component under runs/, never a path of its own.
      const std::filesystem::path out_dir =
          !options.out_dir.empty()
              ? std::filesystem::path(options.out_dir)
              : std::filesystem::path("runs") / control::directory_name(spec.scene.name);
      // A fresh run never silently replaces the checkpoints of an earlier one.
      if (std::filesystem::exists(out_dir / "run.json") ||
          std::filesystem::exists(out_dir / "checkpoints")) {
        if (!options.overwrite)
          throw UsageError("'" + out_dir.string() +
                           "' already holds a run: continue it with --restart " + out_dir.string() +
                           ", choose another --out, or pass --overwrite");
        for (const char* stale : {"run.json", "checkpoints", "frames"})
          std::filesystem::remove_all(out_dir / stale);
      }
      try {
        run = std::make_unique<control::Run>(out_dir.filename().string(), std::move(spec), out_dir,
                                             run_options);
      } catch (const std::exception& e) {
        // The run directory or its first files cannot be written: an I/O failure (exit 1).
        std::fprintf(stderr, "sphles run: cannot set up the run directory '%s': %s\n",
                     out_dir.c_str(), e.what());
        return kExitFailure;
      }
    }
  } catch (const sim::SceneError& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitUsage;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitUsage;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitUsage;
  }

  g_interruptible_run = run.get();
  std::thread signal_waiter;
  const sigset_t signals = stop_signals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  signal_waiter = std::thread([signals] {
    int signal = 0;
    if (sigwait(&signals, &signal) == 0) {
      if (control::Run* r = g_interruptible_run.load()) {
        std::fprintf(stderr, "sphles run: signal %d, stopping after this step\n", signal);
        try {
          r->stop("interrupted by signal " + std::to_string(signal));
        } catch (const std::exception&) {
        }
      }
    }
  });
  control::RunState final_state = control::RunState::Failed;
  std::optional<std::string> refused;
  try {
    final_state = run->run_here();
  } catch (const control::StateError& e) {
    refused = e.what();  // e.g. a restart of a run that has reached time.end
  }
  g_interruptible_run = nullptr;
  pthread_kill(signal_waiter.native_handle(), SIGINT);  // wake the waiter; the run is done
  signal_waiter.join();
  if (refused) {
    std::fprintf(stderr, "sphles run: %s\n", refused->c_str());
    return kExitUsage;
  }
  const control::RunStatus status = run->status();
  if (final_state == control::RunState::Failed) {
    std::fprintf(stderr, "sphles run: %s\n", status.reason.c_str());
    return kExitFailure;
  }
  if (final_state == control::RunState::Stopped) {
    std::fprintf(stderr, "sphles run: stopped at t = %.6g (%s)\n", status.time,
                 status.reason.c_str());
    return kExitFailure;
  }
  return kExitOk;
}

/// --dry-run: what the run would need and take on this machine, nothing written.
int dry_run(const RunOptions& options) {
  try {
    if (!options.restart.empty())
      throw UsageError("--dry-run estimates a new run: give SCENE.json, not --restart");
    check_run_options(options);
    if (options.threads > 0) omp_set_num_threads(options.threads);
    const control::RunSpec spec =
        control::parse_run_spec(load_scene_document(options.scene_file, options.overrides));
    if (const auto too_big =
            print_estimate(spec, /*as_json=*/false, /*with_time=*/true, 1, options.packing_cache)) {
      std::fprintf(stderr, "sphles run: %s\n", too_big->c_str());
      return kExitUsage;
    }
    return kExitOk;
  } catch (const sim::SceneError& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
  } catch (const UsageError& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
  }
  return kExitUsage;
}

int run_command(const RunOptions& options) {
  logging::configure(logging::ConsoleStyle::plain, logging::parse_level(options.log_level));
  if (options.dry_run) return dry_run(options);
  if (launched_ranks() <= 1) return run_here(options, nullptr);
  // Under mpirun: rank 0 runs as one process would, with the solver over every rank; the others
  // serve it. mpirun sends the stop signals to every rank: they are blocked on all ranks before
  // MPI starts its threads, so rank 0 alone acts on them (it stops after the step and writes a
  // checkpoint, with every rank) and the others wait for its word.
  const sigset_t signals = stop_signals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  return par::drive_from_rank_zero([&](par::Driver& driver) { return run_here(options, &driver); });
}

void add_run_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<RunOptions>();
  CLI::App* run = app.add_subcommand("run", "run a scene or preset to its end time");
  run->footer(
      "Run a scene (or a preset, see 'sphles presets') to its end time, printing progress and "
      "writing DIR/scene.json, DIR/run.json, DIR/timeseries.csv, checkpoints and the analysis "
      "products the scene asks for (docs/scenes.md). Under mpirun or mpiexec the solver spans "
      "the ranks, bitwise as one process (docs/scaling.md). Exit 0 when the end time is reached, "
      "1 when the run fails or is stopped by a signal (SIGINT, SIGTERM or SIGUSR1: it finishes "
      "the step and writes a checkpoint; under Open MPI's mpirun send SIGUSR1, since on SIGINT "
      "or SIGTERM mpirun kills the ranks 1 s later), 2 for a bad command line or scene.");
  run->add_option("scene", options->scene_file, "scene file (JSON) or preset name")
      ->type_name("SCENE.json|PRESET");
  repeatable(run->add_option("--set", options->overrides,
                             "change a scene key, e.g. --set particles_per_side=48 (repeatable; "
                             "with --restart only what a live change may change)"))
      ->type_name("KEY=VALUE");
  run->add_option("--out", options->out_dir,
                  "run directory (default runs/NAME; with --restart the checkpoint's run)")
      ->type_name("DIR");
  run->add_flag("--dry-run", options->dry_run,
                "print what the run would need (particles, neighbours, memory, disk) and take on "
                "this machine (time per step and to the end, from a short calibration), then "
                "exit without writing anything; exit 2 if it cannot fit in memory");
  run->add_flag("--overwrite", options->overwrite,
                "replace the checkpoints and run record of an earlier run in --out");
  run->add_option("--restart", options->restart,
                  "continue from a checkpoint, or from the newest valid one of a run directory")
      ->type_name("CHECKPOINT.h5|RUN_DIR");
  run->add_option("--packing-cache", options->packing_cache,
                  "directory of the packed initial lattices (default ~/.cache/sphles/packing)")
      ->type_name("DIR")
      ->check([](const std::string& v) {
        return v.empty() ? std::string("must not be empty") : std::string();
      });
  add_threads_option(*run, options->threads, "OpenMP threads (per MPI rank under mpirun)");
  add_log_level_option(*run, options->log_level);
  run->callback([options, &exit_code] { exit_code = run_command(*options); });
}

}  // namespace sphles::app
