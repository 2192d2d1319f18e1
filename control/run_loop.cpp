// SPDX-License-Identifier: GPL-3.0-or-later
// The solver thread of a run (control/run.hpp): set-up or restart, the run loop with its
// cadences (sim::Cadence), the consumers (analysis pipeline, renderer), checkpoints, and the end.
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <limits>
#include <tuple>

#include "analysis/pipeline.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/units.hpp"
#include "analysis/writer.hpp"
#include "control/live_changes.hpp"
#include "control/progress.hpp"
#include "control/render_sink.hpp"
#include "control/run.hpp"
#include "control/run_files.hpp"
#include "control/run_impl.hpp"
#include "io/checkpoint.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene_warnings.hpp"

namespace sphles::control {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

void RunImpl::execute() {
  if (options.threads > 0) omp_set_num_threads(options.threads);
  std::unique_ptr<sim::Simulation> simulation;
  std::string packing;
  bool resumed = false;
  {
    std::lock_guard lock(mutex);
    resumed = continue_from_checkpoint;
  }
  try {
    solve(simulation, packing, resumed);
  } catch (const sim::SetupCancelled& e) {
    // A stop during the set-up: nothing was stepped, so a later start begins afresh.
    std::unique_lock lock(mutex);
    continue_from_checkpoint = false;
    set_state(lock, RunState::Stopped, stop_reason + " (" + e.what() + ", before the first step)");
  } catch (const std::exception& e) {
    std::unique_lock lock(mutex);
    std::string why = e.what();
    why += checkpoints_left(directory / "checkpoints");
    if (solver_given_up) {
      // The stop ended the job: the run stops where its last checkpoint stands (a set-up given
      // up before the first step leaves none of this start, so a later start begins afresh).
      if (!resumed && step == 0) continue_from_checkpoint = false;
      set_state(lock, RunState::Stopped, stop_reason + " (" + why + ")");
    } else {
      set_state(lock, RunState::Failed, why);
    }
  }
}

namespace {

/// A solver restored from a state: the run's own factory (an MPI job) or one process.
std::unique_ptr<sim::Simulation> restore_solver(const RunOptions& options, const sim::Scene& scene,
                                                sim::SolverState state) {
  return options.solvers.restore
             ? options.solvers.restore(scene, std::move(state))
             : sim::restore_simulation(sim::make_solver_config(scene), std::move(state));
}

/// A resumed run found no checkpoint to continue from.
[[noreturn]] void no_checkpoint_to_continue() {
  throw std::runtime_error(
      "cannot continue: no checkpoint in checkpoints/ (a run that has stepped never starts again "
      "from t = 0)");
}

/// The state a resumed run continues from: the explicit file, else the newest valid checkpoint
/// of the run (the invalid ones and other runs' skipped with a warning).
io::Checkpoint read_resume_checkpoint(const std::optional<std::filesystem::path>& explicit_file,
                                      const std::filesystem::path& checkpoint_dir,
                                      logging::RunLog& log) {
  std::filesystem::path file;
  io::Checkpoint checkpoint;
  if (explicit_file) {
    file = *explicit_file;
    checkpoint = io::read_checkpoint(file);
  } else if (!io::list_checkpoints(checkpoint_dir).empty()) {
    std::vector<std::string> rejected;
    // A file of another run's scene among the run's checkpoints is passed over.
    std::tie(file, checkpoint) = io::read_newest_valid_checkpoint(
        checkpoint_dir, &rejected, checkpoints_of_run(checkpoint_dir.parent_path()));
    for (const std::string& why : rejected) log.warn("skipped: {}", why);
  } else {
    no_checkpoint_to_continue();
  }
  log.progress("restart: {} at t = {:.17g}, step {}", file.string(), checkpoint.state.time,
               checkpoint.state.step);
  return checkpoint;
}

/// A solver that reads its checkpoint where its particles live (a distributed solver's ranks,
/// sim::SolverFactories::restore_file) continued from the explicit file, else from the newest
/// checkpoint its ranks read and validate (the invalid ones skipped with a warning); no process
/// reads the whole file. Sets `packing` from the file.
std::unique_ptr<sim::Simulation> restore_from_file(
    const RunOptions& options, const sim::Scene& scene,
    const std::optional<std::filesystem::path>& explicit_file,
    const std::filesystem::path& checkpoint_dir, logging::RunLog& log, std::string& packing) {
  const std::vector<std::filesystem::path> files =
      explicit_file                             ? std::vector<std::filesystem::path>{*explicit_file}
      : std::filesystem::exists(checkpoint_dir) ? io::list_checkpoints(checkpoint_dir)
                                                : std::vector<std::filesystem::path>{};
  if (files.empty()) no_checkpoint_to_continue();
  for (const std::filesystem::path& file : files) {
    try {
      const io::CheckpointHeader header = io::read_checkpoint_header(file);
      if (!explicit_file) checkpoints_of_run(checkpoint_dir.parent_path())(file, header);
      log.progress("restart: {} at t = {:.17g}, step {} (read by the ranks)", file.string(),
                   header.shape.time, header.step);
      auto simulation = options.solvers.restore_file(scene, file);
      packing = header.metadata.packing;
      return simulation;
    } catch (const io::CheckpointError& e) {
      if (explicit_file) throw;
      log.warn("skipped: {}", e.what());
    }
  }
  throw io::CheckpointError("checkpoint: no valid checkpoint in '" + checkpoint_dir.string() +
                            "' (" + std::to_string(files.size()) + " candidates)");
}

/// The run's loop and everything it feeds while it steps: time-series rows and metrics
/// batches, analysis snapshots (pipeline and writer), rendered frames, checkpoints, progress,
/// the run directory's identity, and live changes between steps. solve() sets the solver up,
/// then run() steps to the end or a stop and finish() closes the outputs.
}  // namespace

class RunImpl::Loop {
 public:
  Loop(RunImpl& run, RunSpec& current, std::unique_ptr<sim::Simulation>& simulation,
       const std::string& packing, bool resumed)
      : run_(run),
        current_(current),
        simulation_(simulation),
        packing_(packing),
        checkpoint_dir_(run.directory / "checkpoints"),
        frames_dir_(run.directory / "frames"),
        identity_(directory_identity(run.directory)),
        timeseries_(run.directory / "timeseries.csv", sim::case_diagnostic_names(current.scene),
                    resumed),
        dissipation_(current.analysis.dissipation_window) {
    received();
    analysis::write_units_file(run.directory, analysis::RunKind::Particles,
                               sim::case_diagnostic_names(current.scene));
    // A resumed run refills the trailing window from its time series, so that ε(t) continues
    // as in an uninterrupted run.
    if (resumed)
      seed_dissipation(run.directory / "timeseries.csv", simulation->time(), dissipation_);
    else
      record(simulation_->diagnostics());
    ensure_consumers();
    if (pipeline_ && !resumed) publish_snapshot();
    reset_cadences();
    progress_->update(simulation_->diagnostics());
    rate_wall_ = Clock::now();
    rate_step_ = simulation_->step_count();
  }

  /// Steps until the end time or a stop; true when stopped (reason in stopped_reason()).
  bool run() {
    for (;;) {
      if (run_.attention.load(std::memory_order_relaxed) && attend()) continue;
      if (stopped_) return true;
      if (sim::reached_end(simulation_->time(), current_.scene.end_time)) return false;
      step();
    }
  }
  const std::string& stopped_reason() const { return stopped_reason_; }

  /// The end of a run, stopped or finished: the last progress line and metrics, a checkpoint
  /// (every run can be continued and never has to start again from t = 0), the consumers
  /// drained; throws what a consumer failed with. A stopped run drains them too: a restart
  /// continues after the checkpoint's time, so an analysis time or frame already reached and
  /// not yet written would be missing for good (at most the snapshot waiting and the one being
  /// analysed, Delivery::Lossless).
  void finish() {
    run_.log->progress("{}", progress_->update(simulation_->diagnostics(), true));
    flush_metrics();
    save_checkpoint();
    if (pipeline_) {
      pipeline_->close(/*drain=*/true);
      const analysis::PipelineCounters c = pipeline_->counters();
      run_.log->progress("analysis: {} snapshots published, {} analysed, {} dropped, {:.1f} s busy",
                         c.published, c.analysed, c.dropped, c.busy_seconds);
    }
    if (renderer_) renderer_->close(/*drain=*/true);
    publish_progress(true);
    if (pipeline_ && !pipeline_->error().empty())
      throw std::runtime_error("analysis failed: " + pipeline_->error());
    if (writer_ && !writer_->last_error().empty())
      throw std::runtime_error("writing analysis products failed: " + writer_->last_error());
    if (renderer_ && !renderer_->error().empty())
      throw std::runtime_error("rendering failed: " + renderer_->error());
  }

 private:
  /// One step, cut short to land on the next row, snapshot or checkpoint time, and what falls
  /// due after it.
  void step() {
    const double t = simulation_->time();
    const double end = current_.scene.end_time;
    const double max_dt =
        checkpoints_.limit_step(t, snapshots_.limit_step(t, rows_.limit_step(t, end - t)));
    const auto step_start = Clock::now();
    simulation_->step(max_dt);
    const sim::StepDiagnostics& d = simulation_->diagnostics();
    if (const bool row = rows_.take(d.time); row || !rows_.active()) record(d);
    if (snapshots_.take(d.time)) publish_snapshot();
    bool checkpoint_due = checkpoints_.take(d.time);
    const double every_seconds = current_.policy.checkpoint.every_seconds;
    if (every_seconds > 0.0 && seconds_since(last_checkpoint_wall_) >= every_seconds)
      checkpoint_due = true;
    if (checkpoint_due) save_checkpoint();
    {
      std::lock_guard lock(run_.mutex);
      run_.wall_seconds += seconds_since(step_start);
    }
    publish_progress(false);
    check_directory();
    if (seconds_since(last_flush_) >= run_.options.metrics_batch_seconds) flush_metrics();
    if (const std::string line = progress_->update(d); !line.empty())
      run_.log->progress("{}", line);
  }

  /// What a request left for the solver thread: pending changes (applied, then true: look
  /// again), a pause (waits here), a stop (noted for run()).
  bool attend() {
    std::unique_lock lock(run_.mutex);
    if (run_.pending) {
      const ChangeScope scope = scope_of(run_.pending_fields);
      run_.spec = std::move(*run_.pending);
      run_.pending.reset();
      run_.pending_fields.clear();
      ++run_.revision;
      run_.end_time = run_.spec.scene.end_time;
      current_ = run_.spec;
      lock.unlock();
      apply_changes(scope);
      lock.lock();
    }
    if (run_.state == RunState::Paused && !run_.stop_requested) {
      lock.unlock();
      flush_metrics();
      lock.lock();
      const auto paused_at = Clock::now();
      run_.holding = true;
      run_.changed.wait(lock, [&] {
        return run_.state != RunState::Paused || run_.stop_requested || run_.pending;
      });
      run_.holding = false;
      rate_wall_ += Clock::now() - paused_at;
    }
    if (run_.stop_requested) {
      stopped_ = true;
      stopped_reason_ = run_.stop_reason;
    }
    run_.attention =
        run_.pending.has_value() || run_.state == RunState::Paused || run_.stop_requested;
    return run_.pending && !stopped_;
  }

  /// A change set taken into current_: the solver restored from its state under the new scene
  /// (when a solver key changed), the consumers reconfigured, the cadences restarted.
  void apply_changes(const ChangeScope& scope) {
    if (scope.solver) {
      // A distributed solver continues where its particles live; one process from its state.
      simulation_ = run_.options.solvers.change
                        ? run_.options.solvers.change(*simulation_, current_.scene)
                        : restore_solver(run_.options, current_.scene, simulation_->state());
      received();
    }
    if (scope.analysis && pipeline_) pipeline_->set_config(current_.analysis);
    if (scope.render && renderer_) renderer_->set_config(current_.render);
    ensure_consumers();
    reset_cadences();
  }

  /// Time-series rows (every step when output.timeseries_every is 0), analysis snapshots and
  /// checkpoints at their cadences in simulated time, from now; a new progress reporter.
  void reset_cadences() {
    const auto cadence = [&](double every) { return sim::Cadence(every, simulation_->time()); };
    rows_ = cadence(current_.policy.output.timeseries_every);
    snapshots_ = cadence(pipeline_ ? current_.analysis.every : 0.0);
    checkpoints_ = cadence(current_.policy.checkpoint.every);
    progress_ = std::make_unique<ProgressReporter>(current_.scene.end_time,
                                                   current_.policy.output.progress_every_seconds);
  }

  /// Every output goes to the run directory: if it is deleted or replaced while the run goes
  /// on, further writes would vanish into unlinked files, so the run fails instead, saying why.
  void check_directory() {
    if (seconds_since(last_directory_check_) < run_.options.directory_check_seconds) return;
    last_directory_check_ = Clock::now();
    if (directory_identity(run_.directory) != identity_)
      throw std::runtime_error("the run directory '" + run_.directory.string() +
                               "' was deleted or replaced while the run was running; its "
                               "outputs could no longer be written");
  }

  void flush_metrics() {
    if (batch_.empty()) return;
    {
      std::lock_guard lock(run_.mutex);
      run_.latest = batch_.back();
    }
    run_.for_each_observer([&](RunObserver& o) { o.on_metrics(batch_); });
    batch_.clear();
    last_flush_ = Clock::now();
  }

  /// A time-series row and a metrics sample of the step.
  /// The analysis snapshot of now for the products the pipeline is configured for; a
  /// distributed solver computes the energy, spectrum and, when it serves every product, the
  /// particle products on its ranks (make_snapshot).
  void publish_snapshot() {
    // A distributed solver's ranks write the particle file themselves and send the renderer's
    // 3D particle view only its points.
    const render::View3dConfig& view3d = current_.render.view3d;
    analysis::ViewPointsRequest view;
    if (current_.render.enabled() && view3d.enabled)
      view = {static_cast<std::uint64_t>(view3d.max_points), view3d.field};
    const analysis::ParticleFileTarget target = writer_->particle_target();
    analysis::SnapshotPtr snapshot = analysis::make_snapshot(
        *simulation_, pipeline_->config(), latest_dissipation_, &target, view, ranks_products_);
    const char* ranks = snapshot->velocity_spectrum && snapshot->ranks
                            ? "spectrum and particle products"
                        : snapshot->velocity_spectrum ? "spectrum"
                        : snapshot->ranks             ? "particle products"
                                                      : nullptr;
    if (ranks)
      run_.log->debug("analysis at t = {}: {} computed on the ranks, {}", snapshot->time, ranks,
                      snapshot->has_particles ? "particles gathered for the other products"
                                              : "no particles gathered");
    pipeline_->publish(std::move(snapshot));
  }

  void record(const sim::StepDiagnostics& d) {
    // Summed where the particles live (a distributed run gathers nothing for them).
    const std::vector<std::string> names = sim::case_diagnostic_names(current_.scene);
    const std::vector<double> values =
        names.empty() ? std::vector<double>{} : simulation_->case_diagnostics(current_.scene);
    const double epsilon = dissipation_.add(d.time, d.kinetic_energy);
    latest_dissipation_ = epsilon;
    timeseries_.write(d, epsilon, values);
    MetricsSample m{d.time,      d.step, d.dt, d.kinetic_energy, epsilon, d.max_density_deviation,
                    d.max_speed, {}};
    for (std::size_t k = 0; k < names.size() && k < values.size(); ++k)
      m.case_values.emplace_back(names[k], values[k]);
    batch_.push_back(std::move(m));
  }

  /// A checkpoint of the current step (none twice), the newest checkpoint.keep kept; run.json
  /// follows, so that after a crash it says where a resume continues.
  void save_checkpoint() {
    if (simulation_->step_count() == last_checkpoint_step_) return;
    std::filesystem::create_directories(checkpoint_dir_);
    const io::CheckpointMetadata metadata{run_spec_to_json(current_).dump(), SPHLES_VERSION,
                                          packing_};
    const auto file = checkpoint_dir_ / io::checkpoint_file_name(simulation_->step_count());
    const io::CheckpointWriteOptions options{.gzip_level = current_.policy.checkpoint.compression};
    if (ranks_checkpoints_) {
      // A distributed solver's ranks write their own particles; none is gathered.
      ranks_checkpoints_->write_checkpoint(file, metadata, options);
      run_.log->debug("checkpoint {} written by the ranks, no particles gathered",
                      file.filename().string());
    } else {
      const sim::SolverState state = simulation_->state();
      io::write_checkpoint(file, state, metadata, options);
      io::write_checkpoint_xdmf(file, state);
    }
    const auto files = io::list_checkpoints(checkpoint_dir_);
    for (std::size_t k = static_cast<std::size_t>(current_.policy.checkpoint.keep);
         k < files.size(); ++k) {
      std::filesystem::remove(files[k]);
      std::filesystem::remove(io::checkpoint_xdmf_path(files[k]));
    }
    last_checkpoint_wall_ = Clock::now();
    last_checkpoint_step_ = simulation_->step_count();
    std::lock_guard lock(run_.mutex);
    run_.time = simulation_->time();
    run_.step = simulation_->step_count();
    run_.last_checkpoint = io::checkpoint_file_name(simulation_->step_count());
    run_.try_write_run_file_locked();
  }

  /// The renderer and the analysis pipeline (with its writer), each created when the scene
  /// first needs it, on threads of their own.
  void ensure_consumers() {
    if (current_.render.enabled() && !renderer_) {
      renderer_ = std::make_unique<RenderSink>(
          current_.render, current_.scene.name, frames_dir_,
          [this](const RenderedImage& image) { on_image(image); },
          [this] { return run_.wants_images(); });
      render_target_ = renderer_.get();
    }
    if (current_.analysis.enabled() && !pipeline_) {
      writer_ = std::make_unique<analysis::RunDirectoryWriter>(
          run_.directory, io::SnapshotMetadata{run_spec_to_json(current_).dump(), SPHLES_VERSION});
      pipeline_ = std::make_unique<analysis::AnalysisPipeline>(
          current_.analysis,
          std::vector<analysis::FrameSink>{
              [this](const analysis::AnalysisFrame& frame) { on_frame(frame); }});
    }
  }

  /// On the analysis thread: a frame analysed, written, rendered and sent to the observers.
  void on_frame(const analysis::AnalysisFrame& frame) {
    writer_->write(frame);
    auto shared = std::make_shared<const analysis::AnalysisFrame>(frame);
    {
      std::lock_guard lock(run_.mutex);
      run_.latest_frame = shared;
    }
    if (RenderSink* target = render_target_.load()) target->post(shared);
    run_.for_each_observer([&](RunObserver& o) { o.on_analysis(shared); });
  }

  /// On the render thread: a frame rendered.
  void on_image(const RenderedImage& image) {
    ImageEvent event{image.field, image.time, image.step, image.file, image.png, Clock::now()};
    {
      std::lock_guard lock(run_.mutex);
      run_.latest_images[image.field] = event;
    }
    run_.for_each_observer([&](RunObserver& o) { o.on_image(event); });
  }

  /// The run's time, step, rate (over at least 1 s of stepping, or now when forced) and the
  /// consumers' counters, for the status.
  void publish_progress(bool force) {
    const auto now = Clock::now();
    const double span = std::chrono::duration<double>(now - rate_wall_).count();
    std::lock_guard lock(run_.mutex);
    run_.time = simulation_->time();
    run_.step = simulation_->step_count();
    if (span >= 1.0 || force) {
      if (span > 0.0 && run_.step > rate_step_)
        run_.steps_per_second = static_cast<double>(run_.step - rate_step_) / span;
      rate_wall_ = now;
      rate_step_ = run_.step;
    }
    if (pipeline_) {
      const analysis::PipelineCounters c = pipeline_->counters();
      run_.analysis_published = c.published;
      run_.analysis_dropped = c.dropped;
    }
    if (renderer_) {
      const RenderCounters c = renderer_->counters();
      run_.frames_rendered = c.frames_rendered;
      run_.frames_skipped = c.frames_skipped;
    }
  }

  static double seconds_since(Clock::time_point then) {
    return std::chrono::duration<double>(Clock::now() - then).count();
  }

  RunImpl& run_;
  RunSpec& current_;
  std::unique_ptr<sim::Simulation>& simulation_;
  // What the solver does where its particles live (null: nothing), asked once per solver.
  const analysis::DistributedProducts* ranks_products_ = nullptr;
  const io::DistributedCheckpoints* ranks_checkpoints_ = nullptr;
  void received() {
    ranks_products_ = dynamic_cast<const analysis::DistributedProducts*>(simulation_.get());
    ranks_checkpoints_ = dynamic_cast<const io::DistributedCheckpoints*>(simulation_.get());
  }
  const std::string& packing_;
  const std::filesystem::path checkpoint_dir_, frames_dir_;
  const std::optional<std::pair<dev_t, ino_t>> identity_;  // directory_identity at the start
  Clock::time_point last_directory_check_ = Clock::now();
  analysis::TimeSeriesWriter timeseries_;
  analysis::DissipationEstimator dissipation_;
  // -de_v/dt of the last row written: travels with each analysis snapshot (SPEC §5, the first
  // of the three dissipation estimates of stats/snapshots.csv).
  double latest_dissipation_ = std::numeric_limits<double>::quiet_NaN();
  std::vector<MetricsSample> batch_;
  Clock::time_point last_flush_ = Clock::now();
  Clock::time_point last_checkpoint_wall_ = Clock::now();
  std::uint64_t last_checkpoint_step_ = std::numeric_limits<std::uint64_t>::max();
  sim::Cadence rows_{0.0, 0.0}, snapshots_{0.0, 0.0}, checkpoints_{0.0, 0.0};  // reset_cadences
  std::unique_ptr<ProgressReporter> progress_;
  Clock::time_point rate_wall_ = Clock::now();
  std::uint64_t rate_step_ = 0;
  bool stopped_ = false;
  std::string stopped_reason_;
  // Consumers, destroyed in reverse order: the pipeline (which feeds the renderer) stops first.
  std::unique_ptr<analysis::RunDirectoryWriter> writer_;
  std::unique_ptr<RenderSink> renderer_;
  std::atomic<RenderSink*> render_target_{nullptr};  // read by the analysis thread
  std::unique_ptr<analysis::AnalysisPipeline> pipeline_;
};

/// The solver of a new run (packed or lattice particles, the packing's provenance into
/// `packing`), or nothing to do for a resumed one; then the loop, then the end state.
void RunImpl::solve(std::unique_ptr<sim::Simulation>& simulation, std::string& packing,
                    bool resumed) {
  RunSpec current;
  {
    std::lock_guard lock(mutex);
    current = spec;
  }
  const std::filesystem::path checkpoint_dir = directory / "checkpoints";
  // Checkpoint temporaries of an interrupted write are never valid checkpoints; only this loop
  // writes there (the rest of the directory is cleaned when the run is opened, Run::open).
  remove_interrupted_writes(checkpoint_dir);
  const sim::Scene& scene0 = current.scene;
  for (const sim::SceneWarning& w : sim::scene_warnings(scene0))
    log->warn("scene: {} ('{}')", w.message, w.field);
  set_phase(resumed ? "restoring" : scene0.packing.enabled ? "packing" : "setting up");
  // Read here, or by the ranks of a distributed solver (restore_from_file below).
  const bool ranks_read = resumed && static_cast<bool>(options.solvers.restore_file);
  std::optional<io::Checkpoint> checkpoint;
  if (resumed && !ranks_read)
    checkpoint = read_resume_checkpoint(start_checkpoint, checkpoint_dir, *log);
  log->progress("sphles run: {} ({}), {} particles, kernel {}, D_K/dl = {:g}, {} threads -> {}",
                scene0.name, sim::case_name(scene0.case_type), scene0.num_particles(),
                sim::kernel_name(scene0.kernel), scene0.kernel_diameter_over_spacing,
                omp_get_max_threads(), directory.string());
  if (resumed) {
    if (checkpoint) {
      packing = checkpoint->metadata.packing;
      simulation = restore_solver(options, scene0, std::move(checkpoint->state));
    } else {
      simulation =
          restore_from_file(options, scene0, start_checkpoint, checkpoint_dir, *log, packing);
    }
    // Whatever a crash after that checkpoint left of later times is written again.
    analysis::truncate_run_files_after(directory, simulation->time());
  } else {
    simulation = set_up(scene0, packing);
  }
  set_phase("stepping");

  Loop loop(*this, current, simulation, packing, resumed);
  const bool stopped = loop.run();
  loop.finish();
  json written = outputs_json(directory);
  log->progress("{}", outputs_summary(written));
  std::unique_lock lock(mutex);
  outputs = std::move(written);
  if (stopped) {
    set_state(lock, RunState::Stopped, loop.stopped_reason());
  } else {
    log->progress("sphles run: finished, outputs in {}", directory.string());
    set_state(lock, RunState::Finished);
  }
}

}  // namespace sphles::control
