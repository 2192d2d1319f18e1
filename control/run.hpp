// SPDX-License-Identifier: GPL-3.0-or-later
// Run control: the narrow interface through which the command line and the server drive a
// simulation (docs/ARCHITECTURE.md). A Run owns the solver, its time series, checkpoints, the
// analysis pipeline and the renderer, all in one run directory:
//   scene.json  run.json  timeseries.csv  checkpoints/  spectra/  slices/  stats/  frames/
// The solver advances on the run's own thread; analysis and rendering run on theirs and never
// block it. Observers receive metrics, analysis frames and images as they appear.
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
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "sim/solver_factories.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::control {

/// A scene document parsed in full: solver, analysis and render sections.
struct RunSpec {
  sim::Scene scene;                   // the solver's sections (scene/document.hpp)
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
};

/// A run name as a single path component: letters, digits, '-', '_' and '.' (others become '-'),
/// no leading '.', at most kMaxDirectoryName characters, "run" if nothing is left. Names from
/// scenes and clients become directory names only through this.
inline constexpr std::size_t kMaxDirectoryName = 40;
std::string directory_name(const std::string& name);

/// One simulation with everything it writes. All methods are thread-safe.
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
  /// the packing of its initial state), writes a checkpoint and exits. Blocks until it has.
  /// Transitions are serialised: a second stop waits for the first, then finds the run stopped.
  void stop(const std::string& reason = "stopped by request");
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
  struct Impl;
  Run(std::string id, std::filesystem::path directory, RunOptions options,
      std::unique_ptr<Impl> impl);
  std::string id_;
  std::filesystem::path directory_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sphles::control
