// SPDX-License-Identifier: GPL-3.0-or-later
// Run control: the narrow interface through which the command line and the server drive a
// simulation (docs/ARCHITECTURE.md). A Run owns the solver, its time series, checkpoints, the
// analysis pipeline and the renderer, all in one run directory:
//   scene.json  run.json  timeseries.csv  checkpoints/  spectra/  slices/  stats/  frames/
// The solver advances on the run's own thread; analysis and rendering run on theirs and never
// block it. Observers receive metrics, analysis frames and images as they appear.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "control/run_types.hpp"

namespace sphles::io {
struct CheckpointHeader;  // io/checkpoint.hpp
}

namespace sphles::control {

struct RunImpl;  // control/run_impl.hpp

/// One simulation with everything it writes. All methods are thread-safe.
/// Throws std::runtime_error when `directory` holds a run (its scene.json) whose scene differs
/// from `checkpoint_scene` in more than a live change may change: a checkpoint of another run
/// (a 48² file dropped among a 32² run's), which would replace the run's particles and scene.
void check_checkpoint_belongs(const std::filesystem::path& directory,
                              const nlohmann::json& checkpoint_scene);

/// check_checkpoint_belongs as the `accept` of io::newest_valid_checkpoint (io::CheckpointAccept):
/// a checkpoint of another run among the run's is passed over, with the reason.
std::function<void(const std::filesystem::path&, const io::CheckpointHeader&)> checkpoints_of_run(
    std::filesystem::path directory);

class Run {
 public:
  /// A new run in `directory` (created; must not already hold a run). Writes scene.json and
  /// run.json; packing and solver set-up happen when it starts.
  Run(std::string id, RunSpec spec, std::filesystem::path directory, RunOptions options = {});
  /// An existing run directory (after a server restart, or `sphles run --restart`). Its state is
  /// read from run.json (a run that was running when the process died is marked stopped); it
  /// continues from the newest valid checkpoint when started. `checkpoint` picks a file instead.
  static std::unique_ptr<Run> open(std::string id, const std::filesystem::path& directory,
                                   RunOptions options = {},
                                   const std::vector<std::string>& overrides = {},
                                   std::optional<std::filesystem::path> checkpoint = {});
  ~Run();  // stop() and join
  Run(const Run&) = delete;
  Run& operator=(const Run&) = delete;

  const std::string& id() const { return id_; }
  const std::filesystem::path& directory() const { return directory_; }
  int ranks() const;  // RunOptions::ranks
  /// The rank count run.json of `directory` records (1 if it records none or cannot be read).
  static int recorded_ranks(const std::filesystem::path& directory);

  /// created/queued → running; stopped/finished/failed → running, continuing from the newest
  /// checkpoint if the run has stepped (StateError if it has none, or if time.end is reached).
  /// Returns at once; the solver thread does the set-up.
  void start();
  /// Starts the run if it is (still) queued; false if it is not (stopped or deleted meanwhile).
  bool start_if_queued();
  /// created/stopped/finished/failed → queued (the run manager has no free slot); the same
  /// checks as start().
  void mark_queued();
  void pause();   // running → paused (takes effect between steps)
  void resume();  // paused → running
  /// running/paused/queued/created → stopped: the solver thread finishes its step (or abandons
  /// the packing of its initial state), writes a checkpoint and exits. Waits for that at most
  /// RunOptions::stop_grace_seconds; a solver's MPI job that has not answered by then (or is
  /// still being set up) is given up (RunOptions::end_solver_job) and the run stops at its last
  /// checkpoint. Returns whether the run has ended; false: it is still stopping (a local step
  /// longer than the grace period, or a stop already under way, which answers at once).
  /// Transitions are serialised: a second stop after the first finds the run stopped.
  bool stop(const std::string& reason = "stopped by request");
  /// Blocks until the run is finished, stopped or failed (or was never started).
  void wait();
  /// Runs on the calling thread until the end (command line). Returns the final state.
  RunState run_here();
  /// Created/finished/stopped/failed → retired: no transition or change is accepted afterwards
  /// (StateError), so the run directory can be deleted. Throws StateError for an active run
  /// (running, paused, queued). reinstate() undoes it when the deletion could not be done.
  void retire();
  void reinstate();

  /// Applies a JSON merge patch to the scene document. Validated in full first; fields the
  /// solver can change safely (docs/rendering.md, "Live changes") take effect at the next step,
  /// the others throw ChangeError naming the field and the reason. The new document is written
  /// to scene.json before it takes effect: if that fails, nothing changes (the error is thrown).
  /// Returns the changed fields.
  std::vector<std::string> apply_changes(const nlohmann::json& patch);
  /// Dotted names of the fields apply_changes accepts.
  static const std::vector<std::string>& changeable_fields();

  RunStatus status() const;
  RunSpec spec() const;             // the current scene (with changes not yet applied)
  nlohmann::json document() const;  // the same as a document
  std::shared_ptr<const analysis::AnalysisFrame> latest_frame() const;
  std::optional<ImageEvent> latest_image(const std::string& field) const;
  /// Fields whose latest image holds a PNG (what latest_image can serve now), sorted.
  std::vector<std::string> image_fields() const;

  void add_observer(std::shared_ptr<RunObserver> observer);
  void remove_observer(const RunObserver* observer);

 private:
  Run(std::string id, std::filesystem::path directory, RunOptions options,
      std::unique_ptr<RunImpl> impl);
  std::string id_;
  std::filesystem::path directory_;
  std::unique_ptr<RunImpl> impl_;
};

}  // namespace sphles::control
