// SPDX-License-Identifier: GPL-3.0-or-later
// The state of a control::Run shared by its state machine (control/run.cpp) and its solver
// thread (control/run_loop.cpp); private to run control.
#pragma once

#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "control/run_files.hpp"
#include "control/run_types.hpp"
#include "logging/logging.hpp"
#include "sim/solver.hpp"

#ifndef SPHLES_VERSION
#define SPHLES_VERSION "unknown"
#endif

namespace sphles::control {

struct RunImpl {
  using json = nlohmann::json;
  std::string id;
  std::filesystem::path directory;
  RunOptions options;

  // Serialises the transitions that spawn or join the solver thread (start, stop, mark_queued,
  // retire, destruction), so that exactly one caller ever joins it and a second request finds
  // the state the first one left. Taken before `mutex`, never by the solver thread.
  std::mutex transition_mutex;

  // Serialises live changes (Run::apply_changes) and retire: held while a change is parsed,
  // validated, admitted and written to scene.json, so that `mutex` is held only to swap it in.
  // Taken after transition_mutex and before `mutex`, never by the solver thread.
  std::mutex change_mutex;

  mutable std::mutex mutex;  // guards everything below up to "solver thread only"
  std::condition_variable changed;
  RunSpec spec;
  std::uint64_t revision = 0;      // number of change sets applied to spec
  std::optional<RunSpec> pending;  // changes the solver thread has not applied yet
  std::vector<std::string> pending_fields;
  RunState state = RunState::Created;
  std::string reason;
  bool holding = false;
  std::string created;
  bool stop_requested = false;
  std::string stop_reason;
  /// A stop gave up on the solver's MPI job (RunOptions::end_solver_job): the failure that
  /// follows is the stop's, not the run's.
  bool solver_given_up = false;
  /// After a solver's job is given up: how long it may take to end (a poll, then SIGTERM and
  /// SIGKILL 5 s apart, launch/job.cpp) [s].
  static constexpr double kJobEndSeconds = 15.0;
  std::optional<std::filesystem::path> start_checkpoint;  // explicit restart file
  bool continue_from_checkpoint = false;
  bool retired = false;  // being deleted: every transition and change is refused
  void refuse_if_retired() const {
    if (retired) throw StateError("run " + id + " has been deleted");
  }
  std::unique_ptr<logging::RunLog> log;  // run.log (and the console)
  std::thread thread;
  std::string last_checkpoint;  // file name under checkpoints/ of the newest one written
  json outputs;                 // what the run directory holds, set when the run ends
  double time = 0.0, end_time = 0.0;
  std::uint64_t step = 0;
  double wall_seconds = 0.0, steps_per_second = 0.0;
  std::string phase;  // RunStatus::phase while the solver thread runs
  void set_phase(const char* p) {
    std::lock_guard lock(mutex);
    phase = p;
  }
  std::optional<MetricsSample> latest;
  std::shared_ptr<const analysis::AnalysisFrame> latest_frame;
  std::map<std::string, ImageEvent> latest_images;
  std::uint64_t analysis_published = 0, analysis_dropped = 0, frames_rendered = 0,
                frames_skipped = 0;
  std::atomic<bool> attention{false};  // a request waits for the solver thread

  mutable std::mutex observer_mutex;
  std::shared_ptr<const std::vector<std::shared_ptr<RunObserver>>> observers =
      std::make_shared<const std::vector<std::shared_ptr<RunObserver>>>();

  std::shared_ptr<const std::vector<std::shared_ptr<RunObserver>>> observer_list() const {
    std::lock_guard lock(observer_mutex);
    return observers;
  }
  /// Calls f on every observer. The list is held by a local so that it outlives the loop (a
  /// range-for over `*observer_list()` would destroy the temporary before the body runs).
  template <class F>
  void for_each_observer(F&& f) const {
    const auto list = observer_list();
    for (const auto& o : *list) f(*o);
  }
  bool wants_images() const {
    const auto list = observer_list();
    for (const auto& o : *list)
      if (o->wants_images()) return true;
    return false;
  }

  void write_run_file_locked() const {
    json j = {{"schema", "sphles-run"},
              {"code_version", SPHLES_VERSION},
              {"id", id},
              {"name", spec.scene.name},
              {"state", run_state_name(state)},
              {"reason", reason},
              {"created", created},
              {"updated", utc_now()},
              {"time", time},
              {"step", step},
              {"checkpoint", last_checkpoint},
              {"ranks", options.ranks},
              {"wall_seconds", wall_seconds}};
    if (!outputs.is_null()) j["outputs"] = outputs;
    write_text_atomically(directory / "run.json", j.dump(2) + "\n");
  }
  /// run.json, where a failure to write it must not change what happens (the state in memory is
  /// right; the file catches up at the next write).
  void try_write_run_file_locked() const {
    try {
      write_run_file_locked();
    } catch (const std::exception& e) {
      log->warn("{}", e.what());
    }
  }
  void write_scene_file_locked() const {
    write_text_atomically(directory / "scene.json", run_spec_to_json(spec).dump(2) + "\n");
  }

  /// Sets the state (caller holds the lock), persists it, and tells observers after unlocking.
  void set_state(std::unique_lock<std::mutex>& lock, RunState s, std::string why = {}) {
    const RunState before = state;
    state = s;
    reason = std::move(why);
    if (s == RunState::Failed)
      log->error("state: {} -> failed: {}", run_state_name(before), reason);
    else if (reason.empty())
      log->info("state: {} -> {}", run_state_name(before), run_state_name(s));
    else
      log->info("state: {} -> {} ({})", run_state_name(before), run_state_name(s), reason);
    try_write_run_file_locked();
    const std::string r = reason;
    const std::vector<std::string_view> verbs = actions_locked();
    changed.notify_all();
    lock.unlock();
    for_each_observer([&](RunObserver& o) { o.on_state(s, r, verbs); });
    lock.lock();
  }

  // Transitions; the caller holds transition_mutex (and not `mutex`).
  void prepare_start_locked();  // checks a start or queueing is allowed; caller holds `mutex`
  /// Why a start (or queueing) is refused now, nullopt if it is allowed; sets *continues to
  /// whether it would continue from a checkpoint. Caller holds `mutex`.
  std::optional<std::string> start_refusal(bool* continues) const;
  /// The transitions the run accepts now (RunStatus::actions); caller holds `mutex`.
  std::vector<std::string_view> actions_locked() const;
  void start_locked();
  bool stop_locked(const std::string& why);
  void join_solver();

  class Loop;  // the run loop and the outputs it feeds (control/run_loop.cpp)
  void execute();
  void solve(std::unique_ptr<sim::Simulation>& simulation, std::string& packing_provenance,
             bool resumed);
  std::unique_ptr<sim::Simulation> set_up(const sim::Scene& scene, std::string& packing_provenance);
};

}  // namespace sphles::control
