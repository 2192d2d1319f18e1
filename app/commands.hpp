// SPDX-License-Identifier: GPL-3.0-or-later
// Subcommands of the sphles program, declared with CLI11 (Debian libcli11-dev): each adds its
// subcommand, options and help text to the program's command line, and a callback that runs it
// and sets the process exit code. `sphles COMMAND --help` prints a command's own help (rc 0).
#pragma once

#include <signal.h>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "analysis/config.hpp"
#include "control/resources.hpp"
#include "control/run.hpp"
#include "logging/logging.hpp"

namespace sphles::app {

/// Exit codes: 0 success, 1 runtime failure (I/O, blow-up), 2 bad command line or scene.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

/// sphles run SCENE.json|PRESET [--set key=value ...] [--out DIR] [--threads N] [--overwrite]
///   [--packing-cache DIR] | --restart CHECKPOINT|RUN_DIR [--set ...] [--out DIR]
void add_run_command(CLI::App& app, int& exit_code);

/// sphles reference SCENE|PRESET [--set ...] [--out DIR] | --restart DIR: the spectral
/// reference of the scene's case (spectral/reference_run.hpp).
void add_reference_command(CLI::App& app, int& exit_code);

/// sphles compare RUN REF [--from T] [--to T] [--json]: a run's resolved-scale errors against
/// a reference run (analysis/resolved_scales.hpp).
void add_compare_command(CLI::App& app, int& exit_code);

/// sphles movie RUN [--field F] [--fps N] [--quality Q] [--out FILE]: a run's saved frames as
/// a WebM video (render/movie.hpp).
void add_movie_command(CLI::App& app, int& exit_code);

/// sphles inspect FILE: validates a checkpoint or snapshot and prints its contents.
void add_inspect_command(CLI::App& app, int& exit_code);

/// sphles presets: lists the presets.
void add_presets_command(CLI::App& app, int& exit_code);

/// sphles schema [scene|patch|openapi|asyncapi]: the scene's JSON Schema
/// (control/scene_schema.hpp), the schema of a scene patch, the service's OpenAPI document or the
/// run stream's AsyncAPI document.
void add_schema_command(CLI::App& app, int& exit_code);

/// sphles calibrate SCENE.json|PRESET --target-urms U [...]: the Kolmogorov forcing amplitude.
void add_calibrate_command(CLI::App& app, int& exit_code);

/// sphles estimate SCENE.json|PRESET [--set key=value ...] [--json]: memory, disk and steps a
/// run would need (control/resources.hpp), without running it.
void add_estimate_command(CLI::App& app, int& exit_code);

/// What estimate prints for a spec (JSON with `as_json`); with `with_time` also the measured time
/// per step and to the end (control/step_time.hpp), unless the run cannot fit in memory; with
/// `ranks` > 1 also what each rank holds. Returns check_machine_memory's refusal, if any.
std::optional<std::string> print_estimate(const control::RunSpec& spec, bool as_json,
                                          bool with_time, int ranks = 1,
                                          const std::filesystem::path& packing_cache = {});

/// The reason a run's estimated peak memory exceeds this machine's, or nothing.
std::optional<std::string> check_machine_memory(const control::ResourceEstimate& estimate);

/// sphles serve [...]: the HTTP/WebSocket service and dashboard.
void add_serve_command(CLI::App& app, int& exit_code);

/// sphles worker --connect HOST:PORT --token TOKEN [--threads N]: a rank of the MPI job the
/// service launches for a run with ranks > 1 (launch/job.hpp); not meant to be run by hand
/// (hidden from the help).
void add_worker_command(CLI::App& app, int& exit_code);

/// sphles docs man|bash-completion: the manual page and the bash completion, generated from
/// the commands' declarations (hidden; the build writes both, app/CMakeLists.txt).
void add_docs_command(CLI::App& app, int& exit_code);

/// A repeatable option taking one value per occurrence (`--set a=1 --set b=2`), collected in
/// order; CLI11's vectors would otherwise swallow the arguments that follow.
inline CLI::Option* repeatable(CLI::Option* option) {
  return option->expected(1)->allow_extra_args(false)->take_all();
}

/// SIGINT, SIGTERM and SIGUSR1: the signals that stop a run (or a reference run) after its step
/// with a checkpoint (run_command.cpp says why SIGUSR1).
sigset_t stop_signals();

/// Ranks of the MPI job this process was started in by mpirun or mpiexec, 1 when it was started
/// alone (run_command.cpp).
int launched_ranks();

/// --threads N (1 to 1024) of the commands that run a solver.
inline CLI::Option* add_threads_option(CLI::App& command, int& threads, const std::string& what) {
  return command.add_option("--threads", threads, what)->type_name("N")->check(CLI::Range(1, 1024));
}

/// --log-level LEVEL of the commands that log (logging/logging.hpp): trace, debug, info (the
/// default), warn, error or off; the command calls logging::configure with it.
inline CLI::Option* add_log_level_option(CLI::App& command, std::string& level) {
  level = "info";
  return command
      .add_option("--log-level", level,
                  "least severe messages shown on stderr (trace, debug, info, warn, error, off); "
                  "run.log records info and above whatever this says, and debug or trace too "
                  "when asked")
      ->type_name("LEVEL")
      ->check(CLI::IsMember(logging::level_names()))
      ->capture_default_str();
}

/// The scene document of a scene file, or of a preset name when no such file exists, with --set
/// overrides applied (not yet validated). Throws sim::SceneError.
nlohmann::json load_scene_document(const std::string& scene_or_preset,
                                   const std::vector<std::string>& overrides);

/// A scene file, or a preset name when no such file exists, with --set overrides applied.
/// Throws sim::SceneError.
analysis::RunConfig load_run_config(const std::string& scene_or_preset,
                                    const std::vector<std::string>& overrides);

}  // namespace sphles::app
