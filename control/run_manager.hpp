// SPDX-License-Identifier: GPL-3.0-or-later
// The runs of one data directory: creation from presets or scenes, a bounded number running at
// once (the rest queue), and recovery of the runs a previous process left behind; beside them
// the spectral references computed for their flows (control/reference_jobs.hpp).
//   {data}/runs/{id}/         one run directory each (see control/run.hpp)
//   {data}/references/{id}/   one reference job each
#pragma once

#include <condition_variable>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "control/data_lock.hpp"
#include "control/reference_jobs.hpp"
#include "control/run.hpp"
#include "scene/document.hpp"

namespace sphles::control {

struct ResourceEstimate;  // control/resources.hpp

struct ManagerOptions {
  std::filesystem::path data_directory = "sphles-data";
  int max_running = 1;  // runs stepping at once; further starts queue
  int max_queued = 16;  // runs waiting for a slot; a start beyond is refused (CapacityError)
  int max_runs = 256;   // runs in the data directory; creating more is refused (CapacityError)
  /// Memory the active runs may use together, by their resource estimates (control/resources.hpp)
  /// [B]: a run whose estimate exceeds it is refused (AdmissionError), one that fits alone but
  /// not beside the active runs queues. 0: default_memory_limit_bytes() (--max-memory).
  double max_memory_bytes = 0.0;
  RunOptions run_options;
  /// Puts the solver of a run with ranks > 1 into an MPI job: sets `options`' solver factories
  /// for a run in `run_directory` (the serve command: launch::job_solvers with its launcher).
  /// Empty: such runs are refused, and runs a previous server ran on MPI continue in this
  /// process (bitwise the same results).
  std::function<void(RunOptions& options, int ranks, const std::filesystem::path& run_directory)>
      distribute;
  /// Memory one MPI rank of a run may use where the launcher places it [B] (--rank-memory).
  /// 0: the ranks run on this machine, so a run with ranks takes the sum of its ranks' estimates
  /// (control::RankEstimate) of max_memory_bytes, beside the server's own share of it (analysis,
  /// rendering). > 0 (a cluster's launcher): such a run is refused when one rank's estimate
  /// exceeds this, and takes only the server's share of max_memory_bytes.
  double rank_memory_bytes = 0.0;
  int max_ranks = 1024;  // ranks one run may ask for
};

/// What a client asks for when creating a run: a preset or a full scene (exactly one), then a
/// JSON merge patch and/or dotted key=value overrides (scene::apply_override syntax).
struct CreateRequest {
  std::optional<std::string> preset;
  std::optional<nlohmann::json> scene;
  nlohmann::json patch = nlohmann::json::object();
  std::vector<std::string> overrides;
  std::optional<std::string> name;  // replaces the scene's name
  bool start = true;
  int ranks = 1;  // MPI ranks of the solver (ManagerOptions::distribute); 1: in the server
};

/// A scene document without "analysis" and "render" sections gets the live defaults: all
/// products (energy, spectrum, vorticity, ω² and |τ_SFS| slices at x = π, sfs_stats) at 60
/// frames over the run (fewer when its time steps are longer), and rendered images of both
/// slices. Others are returned unchanged.
nlohmann::json with_live_defaults(nlohmann::json document);

/// Parses a create request body: {"preset"|"scene", "patch", "overrides", "name", "start"}.
/// Throws sim::SceneError naming the field for unknown keys and wrong types.
CreateRequest parse_create_request(const nlohmann::json& body);

/// The server is at a configured capacity (runs, queue): try again later (HTTP 429).
class CapacityError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class RunManager {
 public:
  /// Creates the data directory if needed and opens every run directory found in it (runs that
  /// were active when the previous process ended are listed as stopped and can be resumed).
  explicit RunManager(ManagerOptions options);
  ~RunManager();  // shutdown()
  RunManager(const RunManager&) = delete;
  RunManager& operator=(const RunManager&) = delete;

  /// Validates the request in full (throws sim::SceneError naming the field, nothing created),
  /// then creates the run directory and starts or queues the run if request.start.
  std::shared_ptr<Run> create(const CreateRequest& request);

  /// The newest stopped run whose scene document is the one `request` would create (with its
  /// live defaults), or null: what `sphles serve --start-run` continues instead of starting the
  /// same scene again at t = 0. Throws sim::SceneError for an invalid request.
  std::shared_ptr<Run> find_stopped_like(const CreateRequest& request) const;

  /// All runs, oldest first.
  std::vector<std::shared_ptr<Run>> list() const;
  /// Throws UnknownRunError.
  std::shared_ptr<Run> get(const std::string& id) const;

  /// State transitions with queueing; throw UnknownRunError or StateError (CapacityError when a
  /// start would queue and the queue is full). Slots are counted and taken atomically, so
  /// concurrent starts never run more than max_running runs.
  void start(const std::string& id);  // created/stopped → running or queued
  void pause(const std::string& id);
  void resume(const std::string& id);  // paused → running; stopped → running or queued
  /// Whether the run has ended (Run::stop); false: it is still stopping.
  bool stop(const std::string& id);
  /// Deletes a run that is not active (created, finished, stopped, failed) with its directory;
  /// throws UnknownRunError or StateError (active runs must be stopped first). The directory is
  /// first moved to {data}/trash/ in one rename, so an interrupted delete never leaves a partial
  /// run that a restart would list; leftovers in trash/ are removed on start.
  void remove(const std::string& id);

  /// What a create request would need and take, creating nothing (POST /api/estimate): the
  /// resource estimate (resource_estimate_to_json), "admitted" and, if not, "refusal" {"field",
  /// "message"} as create would refuse it; for an admitted run "time" (step_time_to_json), a
  /// short calibration of its scene on this machine with the runs' threads (the solver in one
  /// process, also for ranks > 1). Throws sim::SceneError naming the field.
  nlohmann::json estimate(const CreateRequest& request) const;

  /// Stops every active run (each writes a checkpoint and is marked stopped) and the scheduler.
  /// Idempotent.
  void shutdown();

  const ManagerOptions& options() const { return options_; }

  /// The reference jobs of the data directory, admitted against max_memory_bytes; shutdown()
  /// stops them too.
  ReferenceJobs& references() { return *references_; }

  /// The built-in presets: [{"name", "case", "dimension", "particles_per_side", "kernel",
  /// "subfilter_model", "description", "scene": {...}}].
  static nlohmann::json presets();

  /// The scene files (*.json) of `directory` (the source tree's scenes/), by file name, in the
  /// presets' shape plus "file" (the file's name); a file that is no valid scene is left out
  /// and named in "skipped": {"scenes": [...], "skipped": [{"file", "error"}]}.
  static nlohmann::json scene_files(const std::filesystem::path& directory);

 private:
  class SlotObserver;
  /// The scheduler's wake-up, shared with the runs' observer so that a run's thread that reports
  /// its end after the manager is gone still touches only live memory.
  struct Wakeup {
    std::mutex mutex;
    std::condition_variable condition;
    bool wake = false, stop = false;
    void notify();  // from a run's thread: never blocks on a run
  };
  /// The scene document of a create request, validated (throws sim::SceneError naming the
  /// field): preset or scene, patch, overrides, name, live defaults.
  static RunSpec spec_of(const CreateRequest& request);
  /// Throws AdmissionError if the run's estimated memory exceeds the limits (one rank's against
  /// rank_memory_bytes, this machine's share against max_memory_bytes), or its checkpoints the
  /// free disk of the data directory; returns the memory it takes of this machine [B].
  double admit(const RunSpec& spec, int ranks) const;
  /// The same for an estimate at hand (estimate_resources with the run's ranks).
  double admit(const ResourceEstimate& estimate) const;
  /// The run's estimated memory on this machine (what admit returns; 0 for a document that no
  /// longer parses).
  double memory_here(const Run& run) const;
  /// Whether a run (`run`, or a new one when null) needing `memory` may start now: a free slot,
  /// and memory beside the active runs. Caller holds schedule_mutex_.
  bool fits_now(const Run* run, double memory) const;
  void refuse_if_queue_full() const;                   // throws CapacityError
  void start_locked(const std::shared_ptr<Run>& run);  // caller holds schedule_mutex_
  void start_queued();  // starts the oldest queued runs that fit; holds schedule_mutex_
  /// The options of a run in `directory` whose solver spans `ranks` MPI ranks.
  RunOptions run_options_for(int ranks, const std::filesystem::path& directory) const;
  /// Why this server cannot run `request.ranks` ranks (no launcher, above --max-ranks), if so.
  std::optional<std::string> ranks_refusal(const CreateRequest& request) const;
  void schedule_loop();  // the scheduler thread

  ManagerOptions options_;
  std::optional<DataDirectoryLock> lock_;  // taken first, released last
  std::shared_ptr<Wakeup> wakeup_ = std::make_shared<Wakeup>();
  std::shared_ptr<SlotObserver> slot_observer_;
  // Lock order: schedule_mutex_, then mutex_, then a run's own locks. A run's threads take
  // neither: they only signal the scheduler (wakeup_), so no run waits for another.
  std::mutex schedule_mutex_;  // serialises start decisions: slots are counted and taken at once
  mutable std::mutex mutex_;   // guards runs_, queue_, next_number_, shut_down_
  std::vector<std::shared_ptr<Run>> runs_;
  std::vector<std::string> queue_;  // ids waiting for a slot, oldest first
  std::uint64_t next_number_ = 1;
  bool shut_down_ = false;
  std::unique_ptr<ReferenceJobs> references_;
  std::thread scheduler_;  // starts queued runs when a slot frees (last member: starts last)
};

}  // namespace sphles::control
