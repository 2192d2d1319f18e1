// SPDX-License-Identifier: GPL-3.0-or-later
// Spectral references computed by the service (POST /api/references, docs/reference.md "From
// the service"): the `sphles reference` run of a run's flow, one job each, in its own directory
//   {data}/references/{id}/   a reference run directory (spectral/reference_run.hpp), job.json
// Jobs run one after another on one worker thread (the others queue); the solver uses OpenMP's
// default threads. A job that was queued or running when the previous process ended is listed
// as stopped, and resuming it continues from its newest checkpoint.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "control/run.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::control {

/// spectral::run_reference with its ω² frames rendered into `options.directory`/frames, as
/// `sphles reference` writes them. Throws as run_reference, std::runtime_error when rendering
/// failed.
spectral::ReferenceRunResult run_rendered_reference(const RunSpec& spec,
                                                    const nlohmann::json& document,
                                                    const spectral::ReferenceRunOptions& options);

/// queued → running → done | stopped | failed; stopped or failed → queued again (resume).
enum class JobState { Queued, Running, Done, Stopped, Failed };
std::string_view job_state_name(JobState state);
/// What a job in `state` accepts: "stop" (queued or running), "resume" (stopped or failed) and
/// "delete" (neither queued nor running). ReferenceJobs refuses the others by the same rule.
std::vector<std::string_view> job_actions(JobState state);

/// What a client asks for: the reference of run `run`'s flow, its grid and CFL number (the
/// run's scene's reference section when not given), or only its estimate (`dry_run`).
struct ReferenceRequest {
  std::string run;
  std::optional<int> points_per_side;
  std::optional<double> cfl;
  bool dry_run = false;
};

/// Parses a request body {"run", "points_per_side", "cfl", "dry_run"}. Throws sim::SceneError
/// naming the key: unknown keys, wrong types, and values outside the scene schema's bounds of
/// reference.points_per_side and reference.cfl (quoted in the message).
ReferenceRequest parse_reference_request(const nlohmann::json& body);

/// A reference to compute: the run's scene document with the request's reference section,
/// validated, and what it needs.
struct ReferencePlan {
  nlohmann::json document;
  RunSpec spec;
  spectral::ReferenceEstimate estimate;
};

/// {"memory_bytes", "checkpoint_bytes", "steps", "max_wavenumber"}.
nlohmann::json reference_estimate_json(const spectral::ReferenceEstimate& estimate);

/// One job as clients see it.
struct ReferenceJobStatus {
  std::string id;   // also its directory's name under {data}/references/
  std::string run;  // the run it was asked for
  JobState state = JobState::Queued;
  std::string error;  // why it failed
  double time = 0.0, end_time = 0.0;
  std::uint64_t step = 0;
  int points_per_side = 0;
  double cfl = 0.0;
  spectral::ReferenceEstimate estimate;
  std::filesystem::path directory;
};

class ReferenceJobs {
 public:
  /// Opens the jobs in {data_directory}/references/ (creating it) and starts the worker.
  /// `max_memory_bytes` is what one job may need (the server's --max-memory).
  ReferenceJobs(std::filesystem::path data_directory, double max_memory_bytes);
  ~ReferenceJobs();  // shutdown()
  ReferenceJobs(const ReferenceJobs&) = delete;
  ReferenceJobs& operator=(const ReferenceJobs&) = delete;

  /// The reference of `scene_document`'s flow with the request's grid and CFL number. Throws
  /// sim::SceneError naming the field.
  static ReferencePlan plan(nlohmann::json scene_document, const ReferenceRequest& request);

  /// {"points_per_side", "cfl", "max_wavenumber", "memory_bytes", "memory_limit_bytes",
  /// "checkpoint_bytes", "steps", "end_time", "admitted", "refusal": {"field", "message"} when
  /// not admitted}: what POST /api/references with "dry_run" answers.
  nlohmann::json estimate(const ReferencePlan& plan) const;

  /// Queues a job computing `plan` for run `run`; throws AdmissionError (field
  /// "points_per_side") when its memory exceeds the limit, StateError after shutdown.
  ReferenceJobStatus submit(const std::string& run, const ReferencePlan& plan);

  std::vector<ReferenceJobStatus> list() const;  // oldest first
  /// Throws UnknownRunError.
  ReferenceJobStatus get(const std::string& id) const;
  /// Directories of the done jobs: reference runs for the resolved scales.
  std::vector<std::filesystem::path> done_directories() const;

  /// queued → stopped; running → stopped after its step and checkpoint (returns once written).
  /// Throws UnknownRunError, StateError for a job that is done, stopped or failed.
  void stop(const std::string& id);
  /// stopped or failed → queued: continues from the newest checkpoint when there is one, else
  /// from t = 0. Throws UnknownRunError, StateError otherwise.
  void resume(const std::string& id);
  /// Deletes a job that is done, stopped or failed with its directory. Throws UnknownRunError,
  /// StateError for a queued or running job.
  void remove(const std::string& id);

  /// Stops the running job (after its step, with a checkpoint) and the worker. Idempotent.
  void shutdown();

 private:
  struct Job;
  std::shared_ptr<Job> find(const std::string& id) const;  // caller holds mutex_
  ReferenceJobStatus status_of(const Job& job) const;      // caller holds mutex_
  void write_record(const Job& job) const;                 // job.json; caller holds mutex_
  void open_existing();
  void work();             // the worker thread
  bool compute(Job& job);  // true: stopped before its end

  std::filesystem::path data_directory_;
  std::filesystem::path directory_;  // {data}/references
  double max_memory_bytes_;
  mutable std::mutex mutex_;  // guards everything below but the worker
  std::condition_variable changed_;
  std::vector<std::shared_ptr<Job>> jobs_;
  std::deque<std::string> queue_;
  std::atomic<bool> stop_running_{false};  // asks the running job to stop after its step
  std::uint64_t next_number_ = 1;
  bool shut_down_ = false;
  std::thread worker_;  // last member: starts last
};

}  // namespace sphles::control
