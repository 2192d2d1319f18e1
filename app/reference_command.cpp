// SPDX-License-Identifier: GPL-3.0-or-later
// sphles reference SCENE|PRESET: the spectral reference of a scene's case (docs/reference.md).
#include <omp.h>
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include "app/commands.hpp"
#include "control/reference_jobs.hpp"
#include "control/resources.hpp"
#include "control/run.hpp"
#include "io/checkpoint.hpp"
#include "par/slab_exchange.hpp"
#include "scene/document.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::app {

namespace {

struct ReferenceOptions {
  std::string scene;
  std::vector<std::string> overrides;
  std::string out;
  std::string restart;
  int threads = 0;
  bool overwrite = false;
  bool dry_run = false;
  std::string log_level;
};

std::atomic<bool> g_stop{false};

/// The scene of the run to start, or of the run `--restart DIR` continues, with the overrides.
nlohmann::json reference_scene_document(const ReferenceOptions& options) {
  namespace fs = std::filesystem;
  if (options.restart.empty()) {
    if (options.scene.empty()) throw sim::SceneError("", "SCENE or --restart DIR is required");
    return load_scene_document(options.scene, options.overrides);
  }
  if (!options.scene.empty())
    throw sim::SceneError("", "give either SCENE or --restart DIR, not both");
  const fs::path dir = options.restart;
  if (!fs::exists(dir / "scene.json"))
    throw sim::SceneError(dir.string(),
                          "'" + dir.string() + "' holds no reference run (no scene.json)");
  nlohmann::json document = scene::read_scene_file(dir / "scene.json");
  for (const std::string& a : options.overrides) scene::apply_override(document, a);
  return document;
}

/// What the run needs (printed on rank 0 for --dry-run or when it does not fit); throws when it
/// needs more memory than this machine has. True when the run is to go ahead.
bool reference_fits(const ReferenceOptions& options, const control::RunSpec& spec, int ranks,
                    bool root) {
  const sim::Scene& scene = spec.scene;
  const spectral::ReferenceConfig& config = spec.reference;
  const spectral::ReferenceEstimate e = spectral::estimate_reference(scene, config, ranks);
  // Every rank of this machine's job together (mpirun on one node).
  const double machine = static_cast<double>(control::machine_memory_bytes());
  const bool fits = machine <= 0.0 || e.memory_bytes * ranks <= machine;
  if (root && (options.dry_run || !fits))
    std::printf(
        "reference grid       %d^%d points, modes |m| <= %d per axis\n"
        "memory at the peak   %s%s (machine %s)%s\n"
        "checkpoint           %s each\n"
        "time steps           about %.0f to t = %g (CFL %g at the initial speed)\n",
        config.points_per_side, scene.dimension(), e.max_wavenumber,
        control::format_bytes(e.memory_bytes).c_str(),
        ranks > 1 ? (" per rank, " + std::to_string(ranks) + " ranks").c_str() : "",
        control::format_bytes(machine).c_str(), fits ? "" : ": does NOT fit",
        control::format_bytes(e.checkpoint_bytes).c_str(), e.steps, scene.end_time, config.cfl);
  if (!fits)
    throw sim::SceneError(
        "reference.points_per_side",
        "'reference.points_per_side' = " + std::to_string(config.points_per_side) +
            " needs about " + control::format_bytes(e.memory_bytes) +
            ", more than this machine's " + control::format_bytes(machine));
  return !options.dry_run;
}

/// The directory of a new run (--out, or reference-NAME), refused when it holds a run unless
/// --overwrite, which empties it of the earlier run's outputs (on rank 0).
std::filesystem::path new_reference_directory(const ReferenceOptions& options,
                                              const sim::Scene& scene, bool root) {
  namespace fs = std::filesystem;
  const fs::path dir =
      options.out.empty()
          ? fs::path("reference-" + (scene.name.empty() ? std::string("run") : scene.name))
          : fs::path(options.out);
  if ((fs::exists(dir / "run.json") || fs::exists(dir / "checkpoints")) && !options.overwrite)
    throw sim::SceneError(
        dir.string(), "'" + dir.string() + "' already holds a run: continue it with --restart " +
                          dir.string() + ", choose another --out, or pass --overwrite");
  if (options.overwrite && root)
    for (const char* outputs : {"checkpoints", "spectra", "slices", "stats", "frames"})
      fs::remove_all(dir / outputs);
  return dir;
}

/// Runs the reference in `dir`; SIGINT, SIGTERM, SIGUSR1 stop it after the step with a
/// checkpoint (as `sphles run`). The exit code.
int run_reference_until_stopped(const control::RunSpec& spec, const nlohmann::json& document,
                                const std::filesystem::path& dir, bool restart, bool mpi, int ranks,
                                bool root) {
  const sigset_t signals = stop_signals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::atomic<bool> done{false};
  std::thread waiter([&signals, &done, root] {
    int s = 0;
    if (sigwait(&signals, &s) == 0 && !done.load()) {
      if (root) std::fprintf(stderr, "sphles reference: signal %d, stopping after this step\n", s);
      g_stop = true;
    }
  });
  int rc = kExitOk;
  try {
    spectral::ReferenceRunOptions run_options;
    run_options.directory = dir;
    run_options.restart = restart;
    run_options.stop_requested = [] { return g_stop.load(); };
    run_options.echo_progress = root;
    std::unique_ptr<par::MpiSlabExchange> exchange;
    if (mpi) {
      exchange =
          std::make_unique<par::MpiSlabExchange>(MPI_COMM_WORLD, spec.reference.points_per_side);
      run_options.exchange = exchange.get();
      if (root) std::fprintf(stderr, "sphles reference: the grid spans %d MPI ranks\n", ranks);
    }
    // Rank 0 renders the frames; the other ranks step their slabs.
    const spectral::ReferenceRunResult r =
        root ? control::run_rendered_reference(spec, document, run_options)
             : spectral::run_reference(spec.scene, spec.analysis, spec.policy, spec.reference,
                                       document, run_options);
    if (r.stopped) {
      if (root)
        std::fprintf(stderr, "sphles reference: stopped at t = %.6g; continue with --restart %s\n",
                     r.time, dir.c_str());
      rc = kExitFailure;
    } else if (root) {
      std::printf("sphles reference: t = %g after %llu steps, %zu spectra in %s\n", r.time,
                  static_cast<unsigned long long>(r.steps), r.frames, dir.c_str());
    }
  } catch (const sim::SceneError& e) {
    if (root) std::fprintf(stderr, "sphles reference: %s\n", e.what());
    rc = kExitUsage;
  } catch (const std::exception& e) {
    if (root) std::fprintf(stderr, "sphles reference: %s\n", e.what());
    rc = kExitFailure;
  }
  done = true;
  pthread_kill(waiter.native_handle(), SIGINT);
  waiter.join();
  return rc;
}

/// The reference on this process; under mpirun (`mpi`) on every rank of MPI_COMM_WORLD, a 3D
/// grid shared among them (par::MpiSlabExchange), rank 0 printing and writing.
int reference_command(const ReferenceOptions& options, bool mpi) {
  int rank = 0, ranks = 1;
  if (mpi) {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  }
  const bool root = rank == 0;
  logging::configure(logging::ConsoleStyle::plain,
                     root ? logging::parse_level(options.log_level) : logging::Level::off);
  if (options.threads > 0) omp_set_num_threads(options.threads);
  nlohmann::json document;
  std::filesystem::path dir = options.restart;
  control::RunSpec spec;
  try {
    spec = control::parse_run_spec(reference_scene_document(options));
    document = control::run_spec_to_json(spec);
    // A 2D reference runs on rank 0 alone. The other ranks leave before looking at the run
    // directory, which rank 0 may already be writing.
    if (spec.scene.dimension() == 2) {
      if (!root) return kExitOk;
      ranks = 1;
    }
    if (!reference_fits(options, spec, ranks, root)) return kExitOk;  // --dry-run
    if (options.restart.empty()) dir = new_reference_directory(options, spec.scene, root);
  } catch (const std::exception& e) {
    if (root) std::fprintf(stderr, "sphles reference: %s\n", e.what());
    return kExitUsage;
  }
  if (mpi && spec.scene.dimension() == 2) {
    std::fprintf(stderr, "sphles reference: a 2D reference runs on rank 0 alone\n");
    mpi = false;
  }
  return run_reference_until_stopped(spec, document, dir, !options.restart.empty(), mpi, ranks,
                                     root);
}

}  // namespace

void add_reference_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<ReferenceOptions>();
  CLI::App* cmd =
      app.add_subcommand("reference", "compute the spectral (DNS) reference of a scene's case");
  cmd->footer(
      "An incompressible pseudo-spectral Navier-Stokes solver of the scene's periodic case "
      "(2/3-rule dealiasing, RK4 with an integrating factor, CFL-adaptive step) at "
      "reference.points_per_side points per side. Writes timeseries.csv (E, -dE/dt, 2nuZ, Z, "
      "injection), spectra/ (the same shells as a particle run's), slices/, frames/ and "
      "checkpoints/ into --out (docs/reference.md). Under mpirun or mpiexec a 3D grid is shared "
      "among the ranks in slabs, bitwise as one process; rank 0 writes the run directory.");
  cmd->add_option("scene", options->scene, "scene file or preset name")
      ->type_name("SCENE.json|PRESET");
  repeatable(cmd->add_option("--set", options->overrides,
                             "override a scene key, e.g. reference.points_per_side=256")
                 ->type_name("KEY=VALUE"));
  cmd->add_option("--out", options->out, "run directory (default reference-NAME)")
      ->type_name("DIR");
  cmd->add_option("--restart", options->restart, "continue the reference run in DIR")
      ->type_name("DIR");
  cmd->add_flag("--overwrite", options->overwrite, "replace the run already in --out");
  cmd->add_flag("--dry-run", options->dry_run,
                "print the memory, checkpoint size and steps the run needs, and stop");
  add_threads_option(*cmd, options->threads, "OpenMP threads");
  add_log_level_option(*cmd, options->log_level);
  cmd->callback([options, &exit_code] {
    if (launched_ranks() <= 1) {
      exit_code = reference_command(*options, false);
      return;
    }
    // mpirun sends the stop signals to every rank: blocked before MPI starts its threads, they
    // reach the waiter of each rank, and rank 0's word stops them all (run_reference).
    const sigset_t signals = stop_signals();
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
    exit_code = reference_command(*options, true);
    MPI_Finalize();
  });
}

}  // namespace sphles::app
