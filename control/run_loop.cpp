// The solver thread of a run (control/run.hpp): set-up or restart, the run loop with its
// cadences (sim::Cadence), the consumers (analysis pipeline, renderer), checkpoints, and the end.
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <limits>

#include "analysis/pipeline.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/writer.hpp"
#include "control/live_changes.hpp"
#include "control/render_sink.hpp"
#include "control/run_impl.hpp"
#include "io/checkpoint.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/run_log.hpp"

namespace sphles::control {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

void Run::Impl::execute() {
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
    try {
      const auto files = io::list_checkpoints(directory / "checkpoints");
      why += files.empty()
                 ? "; no checkpoint was written"
                 : "; last valid checkpoint: checkpoints/" + files.front().filename().string();
    } catch (const std::exception& listing) {
      why += std::string("; the checkpoints cannot be listed: ") + listing.what();
    }
    set_state(lock, RunState::Failed, why);
  }
}

void Run::Impl::solve(std::unique_ptr<sim::Simulation>& simulation, std::string& packing,
                      bool resumed) {
  RunSpec current;
  {
    std::lock_guard lock(mutex);
    current = spec;
  }
  const std::filesystem::path checkpoint_dir = directory / "checkpoints";
  const std::filesystem::path frames_dir = directory / "frames";
  const auto restore_solver = [this](const sim::Scene& scene, sim::SolverState state) {
    return options.solvers.restore
               ? options.solvers.restore(scene, std::move(state))
               : sim::restore_simulation(sim::make_solver_config(scene), std::move(state));
  };
  // Temporaries of a write that a crash interrupted are never valid checkpoints: remove them.
  if (std::filesystem::exists(checkpoint_dir))
    for (const auto& entry : std::filesystem::directory_iterator(checkpoint_dir))
      if (entry.path().filename().string().find(".h5.tmp.") != std::string::npos)
        std::filesystem::remove(entry.path());

  std::optional<io::Checkpoint> checkpoint;
  set_phase(resumed ? "restoring" : current.run.scene.packing.enabled ? "packing" : "setting up");
  if (resumed) {
    std::filesystem::path file;
    if (start_checkpoint) {
      file = *start_checkpoint;
    } else if (!io::list_checkpoints(checkpoint_dir).empty()) {
      std::vector<std::string> rejected;
      file = io::newest_valid_checkpoint(checkpoint_dir, &rejected);
      for (const std::string& why : rejected) log->warn("skipped: {}", why);
    }
    if (file.empty())
      throw std::runtime_error(
          "cannot continue: no checkpoint in checkpoints/ (a run that has stepped never starts "
          "again from t = 0)");
    {
      checkpoint = io::read_checkpoint(file);
      log->progress("restart: {} at t = {:.17g}, step {}", file.string(), checkpoint->state.time,
                    checkpoint->state.step);
    }
  }
  const sim::Scene& scene0 = current.run.scene;
  log->progress("sphles run: {} ({}), {} particles, kernel {}, D_K/dl = {:g}, {} threads -> {}",
                scene0.name, sim::case_name(scene0.case_type), scene0.num_particles(),
                sim::kernel_name(scene0.kernel), scene0.kernel_diameter_over_spacing,
                omp_get_max_threads(), directory.string());
  if (checkpoint) {
    packing = checkpoint->metadata.packing;
    simulation = restore_solver(scene0, std::move(checkpoint->state));
    truncate_timeseries_after(directory / "timeseries.csv", simulation->time());
    RenderSink::truncate_index_after(frames_dir, simulation->time());
  } else {
    std::error_code ignored;
    std::filesystem::remove(directory / "timeseries.csv", ignored);
    std::filesystem::remove(frames_dir / "index.csv", ignored);
    const auto setup_start = Clock::now();
    sim::SetupOptions setup_options;
    setup_options.packing_cache_dir = options.packing_cache_dir;
    setup_options.cancelled = [this] {
      std::lock_guard lock(mutex);
      return stop_requested;
    };
    sim::RunSetup setup = sim::setup_run(scene0, setup_options);
    const double setup_seconds = std::chrono::duration<double>(Clock::now() - setup_start).count();
    char text[512];
    std::snprintf(text, sizeof text,
                  "%s; iterations %d; residual %.6g -> %.6g; from cache %s; cache file %s",
                  scene0.packing.enabled ? "Colagrossi packing" : "lattice (packing disabled)",
                  setup.packing.iterations, setup.packing.initial_residual,
                  setup.packing.final_residual, setup.packing.from_cache ? "yes" : "no",
                  setup.packing.cache_file.empty() ? "-" : setup.packing.cache_file.c_str());
    packing = text;
    if (scene0.packing.enabled)
      log->progress("packing: {}, {} iterations, residual {:.3g} -> {:.3g} ({:.1f} s){}{}",
                    setup.packing.from_cache  ? "from cache"
                    : setup.packing.converged ? "converged"
                                              : "NOT converged (max_iterations reached)",
                    setup.packing.iterations, setup.packing.initial_residual,
                    setup.packing.final_residual, setup_seconds,
                    setup.packing.cache_file.empty() ? "" : ", cache ", setup.packing.cache_file);
    set_phase("setting up");  // the solver (and any MPI job) from the packed particles
    simulation = options.solvers.make
                     ? options.solvers.make(scene0, std::move(setup.particles))
                     : sim::make_simulation(setup.solver, std::move(setup.particles));
  }
  set_phase("stepping");

  // Every output goes to the run directory: if it is deleted or replaced while the run goes on,
  // further writes would vanish into unlinked files, so the run fails instead, saying why.
  const auto identity = directory_identity(directory);
  auto last_directory_check = Clock::now();
  const auto check_directory = [&] {
    if (std::chrono::duration<double>(Clock::now() - last_directory_check).count() <
        options.directory_check_seconds)
      return;
    last_directory_check = Clock::now();
    if (directory_identity(directory) != identity)
      throw std::runtime_error("the run directory '" + directory.string() +
                               "' was deleted or replaced while the run was running; its "
                               "outputs could no longer be written");
  };
  analysis::TimeSeriesWriter timeseries(directory / "timeseries.csv",
                                        sim::case_diagnostic_names(scene0), checkpoint.has_value());
  analysis::DissipationEstimator dissipation(current.run.analysis.dissipation_window);
  // A resumed run refills the trailing window from its time series, so that ε(t) continues as
  // in an uninterrupted run.
  if (checkpoint) seed_dissipation(directory / "timeseries.csv", simulation->time(), dissipation);
  // -de_v/dt of the last row written: travels with each analysis snapshot (SPEC §5, the first of
  // the three dissipation estimates of stats/snapshots.csv).
  double latest_dissipation = std::numeric_limits<double>::quiet_NaN();
  std::vector<MetricsSample> batch;
  auto last_flush = Clock::now();
  const auto flush_metrics = [&] {
    if (batch.empty()) return;
    {
      std::lock_guard lock(mutex);
      latest = batch.back();
    }
    for_each_observer([&](RunObserver& o) { o.on_metrics(batch); });
    batch.clear();
    last_flush = Clock::now();
  };
  const auto record = [&](const sim::StepDiagnostics& d) {
    // Summed where the particles live (a distributed run gathers nothing for them).
    const std::vector<double> values = sim::case_diagnostic_names(current.run.scene).empty()
                                           ? std::vector<double>{}
                                           : simulation->case_diagnostics(current.run.scene);
    const double epsilon = dissipation.add(d.time, d.kinetic_energy);
    latest_dissipation = epsilon;
    timeseries.write(d, epsilon, values);
    MetricsSample m{d.time,      d.step, d.dt, d.kinetic_energy, epsilon, d.max_density_deviation,
                    d.max_speed, {}};
    const std::vector<std::string> names = sim::case_diagnostic_names(current.run.scene);
    for (std::size_t k = 0; k < names.size() && k < values.size(); ++k)
      m.case_values.emplace_back(names[k], values[k]);
    batch.push_back(std::move(m));
  };
  if (!checkpoint) record(simulation->diagnostics());

  // Checkpoints at multiples of checkpoint.every and/or every checkpoint.every_seconds of wall
  // time, the newest checkpoint.keep kept; always one when the run is stopped (to resume it).
  auto last_checkpoint_wall = Clock::now();
  std::uint64_t last_checkpoint_step = std::numeric_limits<std::uint64_t>::max();
  const auto save_checkpoint = [&] {
    if (simulation->step_count() == last_checkpoint_step) return;
    std::filesystem::create_directories(checkpoint_dir);
    const io::CheckpointMetadata metadata{run_spec_to_json(current).dump(), SPHLES_VERSION,
                                          packing};
    const auto file = checkpoint_dir / io::checkpoint_file_name(simulation->step_count());
    io::write_checkpoint(file, simulation->state(), metadata,
                         {.gzip_level = current.run.scene.checkpoint.compression});
    io::write_checkpoint_xdmf(file, simulation->state());
    const auto files = io::list_checkpoints(checkpoint_dir);
    for (std::size_t k = static_cast<std::size_t>(current.run.scene.checkpoint.keep);
         k < files.size(); ++k) {
      std::filesystem::remove(files[k]);
      std::filesystem::remove(io::checkpoint_xdmf_path(files[k]));
    }
    last_checkpoint_wall = Clock::now();
    last_checkpoint_step = simulation->step_count();
    // run.json follows the checkpoints: after a crash it says where a resume continues.
    std::lock_guard lock(mutex);
    time = simulation->time();
    step = simulation->step_count();
    last_checkpoint = io::checkpoint_file_name(simulation->step_count());
    try_write_run_file_locked();
  };

  // Consumers on their own threads, created when the scene first needs them.
  // Destroyed in reverse order: the pipeline (which feeds the renderer) stops first.
  std::unique_ptr<analysis::RunDirectoryWriter> writer;
  std::unique_ptr<RenderSink> renderer;
  std::atomic<RenderSink*> render_target{nullptr};  // read by the analysis thread
  std::unique_ptr<analysis::AnalysisPipeline> pipeline;
  const auto on_image = [this](const RenderedImage& image) {
    ImageEvent event{image.field, image.time, image.step, image.file, image.png, Clock::now()};
    {
      std::lock_guard lock(mutex);
      latest_images[image.field] = event;
    }
    for_each_observer([&](RunObserver& o) { o.on_image(event); });
  };
  const auto ensure_consumers = [&] {
    if (current.render.enabled() && !renderer) {
      renderer = std::make_unique<RenderSink>(current.render, current.run.scene.name, frames_dir,
                                              on_image, [this] { return wants_images(); });
      render_target = renderer.get();
    }
    if (current.run.analysis.enabled() && !pipeline) {
      writer = std::make_unique<analysis::RunDirectoryWriter>(
          directory, io::SnapshotMetadata{run_spec_to_json(current).dump(), SPHLES_VERSION});
      pipeline = std::make_unique<analysis::AnalysisPipeline>(
          current.run.analysis,
          std::vector<analysis::FrameSink>{
              [this, w = writer.get(), &render_target](const analysis::AnalysisFrame& frame) {
                w->write(frame);
                auto shared = std::make_shared<const analysis::AnalysisFrame>(frame);
                {
                  std::lock_guard lock(mutex);
                  latest_frame = shared;
                }
                if (RenderSink* target = render_target.load()) target->post(shared);
                for_each_observer([&](RunObserver& o) { o.on_analysis(shared); });
              }});
    }
  };
  ensure_consumers();
  if (pipeline && !checkpoint)
    pipeline->publish(analysis::make_snapshot(*simulation, latest_dissipation));

  // Time-series rows (every step when output.timeseries_every is 0), analysis snapshots and
  // checkpoints at their cadences in simulated time; steps are cut short to land on them.
  const auto cadence = [&](double every) { return sim::Cadence(every, simulation->time()); };
  sim::Cadence rows = cadence(current.run.scene.output.timeseries_every);
  sim::Cadence snapshots = cadence(pipeline ? current.run.analysis.every : 0.0);
  sim::Cadence checkpoints = cadence(current.run.scene.checkpoint.every);
  auto progress = std::make_unique<sim::ProgressReporter>(
      current.run.scene.end_time, current.run.scene.output.progress_every_seconds);
  progress->update(simulation->diagnostics());
  auto rate_wall = Clock::now();
  std::uint64_t rate_step = simulation->step_count();
  const auto publish_progress = [&](bool force) {
    const auto now = Clock::now();
    const double span = std::chrono::duration<double>(now - rate_wall).count();
    std::lock_guard lock(mutex);
    time = simulation->time();
    step = simulation->step_count();
    if (span >= 1.0 || force) {
      if (span > 0.0 && step > rate_step)
        steps_per_second = static_cast<double>(step - rate_step) / span;
      rate_wall = now;
      rate_step = step;
    }
    if (pipeline) {
      const analysis::PipelineCounters c = pipeline->counters();
      analysis_published = c.published;
      analysis_dropped = c.dropped;
    }
    if (renderer) {
      const RenderCounters c = renderer->counters();
      frames_rendered = c.frames_rendered;
      frames_skipped = c.frames_skipped;
    }
  };

  bool stopped = false;
  std::string stopped_reason;
  for (;;) {
    if (attention.load(std::memory_order_relaxed)) {
      std::unique_lock lock(mutex);
      if (pending) {
        const ChangeScope scope = scope_of(pending_fields);
        spec = std::move(*pending);
        pending.reset();
        pending_fields.clear();
        ++revision;
        end_time = spec.run.scene.end_time;
        current = spec;
        lock.unlock();
        if (scope.solver) simulation = restore_solver(current.run.scene, simulation->state());
        if (scope.analysis && pipeline) pipeline->set_config(current.run.analysis);
        if (scope.render && renderer) renderer->set_config(current.render);
        ensure_consumers();
        rows = cadence(current.run.scene.output.timeseries_every);
        snapshots = cadence(pipeline ? current.run.analysis.every : 0.0);
        checkpoints = cadence(current.run.scene.checkpoint.every);
        progress = std::make_unique<sim::ProgressReporter>(
            current.run.scene.end_time, current.run.scene.output.progress_every_seconds);
        lock.lock();
      }
      if (state == RunState::Paused && !stop_requested) {
        lock.unlock();
        flush_metrics();
        lock.lock();
        const auto paused_at = Clock::now();
        holding = true;
        changed.wait(lock, [&] { return state != RunState::Paused || stop_requested || pending; });
        holding = false;
        rate_wall += Clock::now() - paused_at;
      }
      if (stop_requested) {
        stopped = true;
        stopped_reason = stop_reason;
      }
      attention = pending.has_value() || state == RunState::Paused || stop_requested;
      if (pending && !stopped) continue;
    }
    if (stopped) break;
    const double end = current.run.scene.end_time;
    if (sim::reached_end(simulation->time(), end)) break;

    const double t = simulation->time();
    const double max_dt =
        checkpoints.limit_step(t, snapshots.limit_step(t, rows.limit_step(t, end - t)));
    const auto step_start = Clock::now();
    simulation->step(max_dt);
    const sim::StepDiagnostics& d = simulation->diagnostics();
    if (const bool row = rows.take(d.time); row || !rows.active()) record(d);
    if (snapshots.take(d.time))
      pipeline->publish(analysis::make_snapshot(*simulation, latest_dissipation));
    bool checkpoint_due = checkpoints.take(d.time);
    const double every_seconds = current.run.scene.checkpoint.every_seconds;
    if (every_seconds > 0.0 &&
        std::chrono::duration<double>(Clock::now() - last_checkpoint_wall).count() >= every_seconds)
      checkpoint_due = true;
    if (checkpoint_due) save_checkpoint();
    {
      std::lock_guard lock(mutex);
      wall_seconds += std::chrono::duration<double>(Clock::now() - step_start).count();
    }
    publish_progress(false);
    check_directory();
    if (std::chrono::duration<double>(Clock::now() - last_flush).count() >=
        options.metrics_batch_seconds)
      flush_metrics();
    if (const std::string line = progress->update(d); !line.empty()) log->progress("{}", line);
  }

  log->progress("{}", progress->update(simulation->diagnostics(), true));
  flush_metrics();
  // Every run ends with a checkpoint, stopped or finished, so that it can be continued (raise
  // time.end) and never has to start again from t = 0.
  save_checkpoint();
  if (pipeline) {
    pipeline->close(/*drain=*/!stopped);
    const analysis::PipelineCounters c = pipeline->counters();
    log->progress("analysis: {} snapshots published, {} analysed, {} dropped, {:.1f} s busy",
                  c.published, c.analysed, c.dropped, c.busy_seconds);
  }
  if (renderer) renderer->close(/*drain=*/!stopped);
  publish_progress(true);
  if (pipeline && !pipeline->error().empty())
    throw std::runtime_error("analysis failed: " + pipeline->error());
  if (writer && !writer->last_error().empty())
    throw std::runtime_error("writing analysis products failed: " + writer->last_error());
  if (renderer && !renderer->error().empty())
    throw std::runtime_error("rendering failed: " + renderer->error());
  json written = outputs_json(directory);
  log->progress("{}", outputs_summary(written));
  std::unique_lock lock(mutex);
  outputs = std::move(written);
  if (stopped) {
    set_state(lock, RunState::Stopped, stopped_reason);
  } else {
    log->progress("sphles run: finished, outputs in {}", directory.string());
    set_state(lock, RunState::Finished);
  }
}

}  // namespace sphles::control
