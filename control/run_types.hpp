// SPDX-License-Identifier: GPL-3.0-or-later
// What a run is made of and reports, apart from the Run itself (control/run.hpp): its spec and
// options, its states and errors, the status, metrics and images it publishes and the observer
// that receives them. Live changes (control/live_changes.hpp) and the run's private state
// (control/run_impl.hpp) build on these without the Run.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "analysis/config.hpp"
#include "analysis/products.hpp"
#include "render/config.hpp"
#include "scene/run_policy.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/solver_factories.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::control {

/// A scene document parsed in full: solver, analysis and render sections.
struct RunSpec {
  sim::Scene scene;                   // the solver's sections (scene/document.hpp)
  scene::RunPolicy policy;            // "output", "checkpoint": when the run writes
  analysis::AnalysisConfig analysis;  // "analysis"
  render::RenderConfig render;
  spectral::ReferenceConfig reference;  // the case's spectral reference (sphles reference)
};

/// Throws sim::SceneError naming the field.
RunSpec parse_run_spec(const nlohmann::json& document);
nlohmann::json run_spec_to_json(const RunSpec& spec);

/// created → (queued →) running ⇄ paused → finished | stopped | failed; stopped → running again
/// resumes from the newest checkpoint (also after a server restart).
enum class RunState { Created, Queued, Running, Paused, Finished, Stopped, Failed };
std::string_view run_state_name(RunState state);
/// The state of a name run_state_name gives; throws std::runtime_error naming run.json otherwise.
RunState run_state_from_name(const std::string& name);
bool is_terminal(RunState state);  // finished, stopped, failed

/// A state change the current state does not allow (HTTP 409).
class StateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A run or reference job id that does not exist (HTTP 404).
class UnknownRunError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A parameter change that is malformed or not allowed while the run exists (HTTP 400/422).
class ChangeError : public std::runtime_error {
 public:
  ChangeError(std::string field, const std::string& reason)
      : std::runtime_error("'" + field + "' " + reason), field_(std::move(field)) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

/// A run that asks for more than the server allows (memory, disk), with the estimate (HTTP 422).
class AdmissionError : public std::runtime_error {
 public:
  AdmissionError(std::string field, const std::string& reason)
      : std::runtime_error(reason), field_(std::move(field)) {}
  const std::string& field() const { return field_; }  // the scene key that drives it

 private:
  std::string field_;
};

/// One row of the time series, as pushed to observers.
struct MetricsSample {
  double time = 0.0;  // [s]
  std::uint64_t step = 0;
  double dt = 0.0;
  double kinetic_energy = 0.0;         // e_v (5.3) [m²/s²]
  double dissipation = 0.0;            // -de_v/dt, trailing-window slope; NaN at first
  double max_density_deviation = 0.0;  // max |ρ/ρ_ref - 1|
  double max_speed = 0.0;              // [m/s]
  std::vector<std::pair<std::string, double>> case_values;  // e.g. u_rms, eps_inj (Kolmogorov)
};

/// A rendered image, PNG-encoded in memory.
struct ImageEvent {
  std::string field;  // "omega2", "tau_sfs", "nu_t", "combined", "view3d"
  double time = 0.0;
  std::uint64_t step = 0;
  std::string file;  // name under frames/ if saved, else empty
  std::shared_ptr<const std::vector<unsigned char>> png;
  std::chrono::steady_clock::time_point created;  // when encoding finished
};

/// Progress and health of a run at one moment.
struct RunStatus {
  RunState state = RunState::Created;
  std::string reason;    // why it stopped or failed; empty otherwise
  bool holding = false;  // paused and the solver thread has finished its step and is waiting
  double time = 0.0;
  double end_time = 0.0;
  std::uint64_t step = 0;
  double wall_seconds = 0.0;      // spent stepping (excludes paused time), over every start
                                  // of the run, also across server restarts (run.json)
  double steps_per_second = 0.0;  // over the last progress interval
  /// What a running or paused run is doing: "packing" (relaxing the initial lattice, which may
  /// take minutes), "restoring" (reading its checkpoint), "setting up" (building the initial
  /// state or launching its MPI job) or "stepping"; "" for a run that is not active.
  std::string phase;
  std::optional<MetricsSample> latest;
  std::uint64_t analysis_published = 0, analysis_dropped = 0, frames_rendered = 0;
  std::uint64_t frames_skipped = 0;  // analysis frames nobody needed an image of
  /// The transitions the run accepts now, by the same rules that refuse the others: a subset
  /// of "start", "pause", "resume", "stop", "delete" (resuming a stopped run is a start and is
  /// listed as "start"), so that a client offers exactly these.
  std::vector<std::string_view> actions;
};

/// Receives a run's products. Called from the solver, analysis or render thread, and on_state
/// also from a thread making a transition (start, stop) while it holds the run's transition
/// lock; must be quick (copy or enqueue) and must not throw or call back into the Run. Never
/// hold a lock an observer takes while calling into a Run.
class RunObserver {
 public:
  virtual ~RunObserver() = default;
  virtual void on_metrics(std::span<const MetricsSample> /*batch*/) {}
  virtual void on_analysis(const std::shared_ptr<const analysis::AnalysisFrame>& /*frame*/) {}
  virtual void on_image(const ImageEvent& /*image*/) {}
  /// `actions`: what the run accepts in its new state (RunStatus::actions).
  virtual void on_state(RunState /*state*/, const std::string& /*reason*/,
                        std::span<const std::string_view> /*actions*/) {}
  /// True if this observer wants images: a run renders frames its scene does not save only
  /// while some observer wants them.
  virtual bool wants_images() const { return false; }
};

struct RunOptions {
  int threads = 0;  // OpenMP threads of the solver; 0 = default
  bool log_progress =
      false;  // progress lines on the console too (command line); run.log has them always
  double metrics_batch_seconds = 0.1;       // observers get metrics at most this often (wall time)
  std::filesystem::path packing_cache_dir;  // empty: sim::default_packing_cache_dir()
  /// How often (wall time) the solver thread checks that its run directory still exists.
  double directory_check_seconds = 1.0;
  /// Called with the document a live change would give and the run's ranks, before it is made;
  /// throws AdmissionError to refuse it (the run manager checks the resource estimate).
  std::function<void(const RunSpec&, int ranks)> admit;
  /// Builds the solver of a fresh start and of a restart or live change; empty members: one
  /// process (sim::make_simulation, sim::restore_simulation). `sphles run` under mpirun sets
  /// them to the distributed solver (par::Driver::factories), the service for runs with ranks
  /// > 1 to an MPI job of their own (launch::job_solvers); Run drives either like any other.
  sim::SolverFactories solvers;
  /// MPI ranks the solver spans, recorded in run.json: 1 for this process; more when the
  /// factories above put the solver into an MPI job (`mpirun sphles run`; the service's runs
  /// created with ranks > 1, launch/job.hpp).
  int ranks = 1;
  /// How long a stop waits for the solver to reach its next step and write the checkpoint
  /// before it gives up on a solver that does not answer (end_solver_job) or, without one,
  /// answers that the run is still stopping [s].
  double stop_grace_seconds = 30.0;
  /// Gives up on the solver's MPI job (launch::JobSolvers::end_job): the call the solver thread
  /// waits on fails within a poll and the job is ended. Empty: the solver is this process.
  std::function<void(const std::string& why)> end_solver_job;
};

/// A run name as a single path component: letters, digits, '-', '_' and '.' (others become '-'),
/// no leading '.', at most kMaxDirectoryName characters, "run" if nothing is left. Names from
/// scenes and clients become directory names only through this.
inline constexpr std::size_t kMaxDirectoryName = 40;
std::string directory_name(const std::string& name);
/// Throws sim::SceneError for field "name" unless `name` is its own directory_name (what the
/// service accepts: a name it would not have to rewrite).
void check_run_name(const std::string& name);

}  // namespace sphles::control
