// Subcommands of the sphles program. Each returns the process exit code.
#pragma once

#include <string>
#include <vector>

#include "analysis/config.hpp"

namespace sphles::app {

/// Exit codes: 0 success, 1 runtime failure (I/O, blow-up), 2 bad command line or scene.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

/// sphles run SCENE.json|PRESET [--set key=value ...] [--out DIR] [--threads N] [--overwrite]
///   [--packing-cache DIR] | --restart CHECKPOINT|RUN_DIR [--set ...] [--out DIR]
int run_command(const std::vector<std::string>& args);

/// sphles inspect FILE: validates a checkpoint and prints its contents (exit 2 if invalid).
int inspect_command(const std::vector<std::string>& args);

/// sphles presets: lists the preset names.
int presets_command(const std::vector<std::string>& args);

/// sphles calibrate SCENE.json|PRESET --target-urms U [--time T] [--average-from T0]
///   [--initial CHI] [--tries N] [--tolerance F] [--set key=value ...] [--threads N]
int calibrate_command(const std::vector<std::string>& args);

/// sphles estimate SCENE.json|PRESET [--set key=value ...] [--json]: memory, disk and steps a
/// run would need (control/resources.hpp), without running it.
int estimate_command(const std::vector<std::string>& args);

/// sphles serve [--port 8080] [--bind 127.0.0.1] [--data DIR] [--token TOKEN] [--web DIR]
///   [--max-running N] [--max-queued N] [--max-runs N] [--max-memory SIZE] [--threads N]
///   [--packing-cache DIR] [--launcher CMD] [--job-address IP] [--max-ranks N]
///   [--start-run PRESET|SCENE.json [--set key=value ...]]
int serve_command(const std::vector<std::string>& args);

/// sphles worker --connect HOST:PORT --token TOKEN [--threads N]: a rank of the MPI job the
/// service launches for a run with ranks > 1 (launch/job.hpp); not meant to be run by hand.
int worker_command(const std::vector<std::string>& args);

/// The scene document of a scene file, or of a preset name when no such file exists, with --set
/// overrides applied (not yet validated). Throws sim::SceneError.
nlohmann::json load_scene_document(const std::string& scene_or_preset,
                                   const std::vector<std::string>& overrides);

/// A scene file, or a preset name when no such file exists, with --set overrides applied.
/// Throws sim::SceneError.
analysis::RunConfig load_run_config(const std::string& scene_or_preset,
                                    const std::vector<std::string>& overrides);

}  // namespace sphles::app
