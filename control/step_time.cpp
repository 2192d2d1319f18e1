// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/step_time.hpp"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include "analysis/products.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/writer.hpp"
#include "render/frame_images.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/packing.hpp"
#include "sim/solver.hpp"

namespace sphles::control {

namespace {
constexpr std::size_t kCalibrationSide2d = 64;
constexpr std::size_t kCalibrationSide3d = 24;
constexpr int kWarmUpSteps = 1;
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}
}  // namespace

std::size_t calibration_side(const RunSpec& spec) {
  const sim::Scene& scene = spec.scene;
  const std::size_t small = scene.dimension() == 2 ? kCalibrationSide2d : kCalibrationSide3d;
  return std::min(static_cast<std::size_t>(scene.particles_per_side), small);
}

namespace {

/// The packing of the run's lattice on this machine: none when it is cached, else the packing
/// of the same lattice at the calibration size, not cached, scaled by `scale`.
double packing_seconds(const RunSpec& spec, nlohmann::json small_document, double scale,
                       const std::filesystem::path& cache_dir) {
  const sim::Scene& scene = spec.scene;
  if (!scene.packing.enabled) return 0.0;
  sim::SetupOptions options;
  options.packing_cache_dir = cache_dir;
  const sim::PackingCacheFile cached = sim::packing_cache_file(scene, options);
  std::error_code ignored;
  if (!cached.path.empty() && std::filesystem::exists(cached.path, ignored)) return 0.0;
  small_document["packing"] = run_spec_to_json(spec)["packing"];
  small_document["packing"]["cache"] = false;
  const RunSpec small = parse_run_spec(small_document);
  const auto start = Clock::now();
  sim::setup_run(small.scene);
  return seconds_since(start) * scale;
}

}  // namespace

StepTimeEstimate estimate_step_time(const RunSpec& spec, const ResourceEstimate& resources,
                                    int steps, const std::filesystem::path& packing_cache_dir) {
  StepTimeEstimate e;
  e.calibration_side = calibration_side(spec);
  e.calibration_steps = std::max(steps, 1);
  e.threads = omp_get_max_threads();
  // The same document at the calibration size, without packing, analysis or rendering.
  nlohmann::json document = run_spec_to_json(spec);
  document["particles_per_side"] = e.calibration_side;
  document["packing"]["enabled"] = false;
  document.erase("analysis");
  document.erase("render");
  const RunSpec small = parse_run_spec(document);
  const auto setup_start = Clock::now();
  sim::RunSetup setup = sim::setup_run(small.scene);
  e.calibration_particles = static_cast<double>(setup.particles.size());
  const std::unique_ptr<sim::Simulation> simulation =
      sim::make_simulation(setup.solver, std::move(setup.particles));
  for (int k = 0; k < kWarmUpSteps; ++k) simulation->step();
  e.calibration_setup_seconds = seconds_since(setup_start);
  const auto start = Clock::now();
  for (int k = 0; k < e.calibration_steps; ++k) simulation->step();
  e.calibration_seconds = seconds_since(start);
  const double scale = resources.particles / e.calibration_particles;
  e.seconds_per_step = e.calibration_seconds / e.calibration_steps * scale;
  e.solver_seconds = e.seconds_per_step * resources.steps;
  e.packing_seconds = packing_seconds(spec, document, scale, packing_cache_dir);
  e.seconds_to_end = e.packing_seconds + e.solver_seconds;
  if (!spec.analysis.enabled()) return e;
  // The analysis thread runs with one OpenMP thread (AnalysisPipeline's default), as here; the
  // caller's count comes back however this scope ends (the estimating thread serves requests).
  const int threads = omp_get_max_threads();
  struct RestoreThreads {
    int count;
    ~RestoreThreads() { omp_set_num_threads(count); }
  } restore{threads};
  omp_set_num_threads(1);
  analysis::AnalysisConfig config = spec.analysis;
  // As the run loop takes it: the 3D view's points carried along when the view is rendered.
  const render::View3dConfig& view3d = spec.render.view3d;
  analysis::ViewPointsRequest view;
  if (spec.render.enabled() && view3d.enabled)
    view = {static_cast<std::uint64_t>(view3d.max_points), view3d.field};
  const analysis::SnapshotPtr snapshot =
      analysis::make_snapshot(*simulation, config, 0.0, nullptr, view);
  analysis::AnalysisFrame frame = analysis::analyse(snapshot, config);  // plans the FFTs
  auto timed = Clock::now();
  frame = analysis::analyse(snapshot, config);
  {
    // Written as the run writes it (real files, removed again): the particle and grid files of
    // a frame can take as long as computing it.
    std::error_code ignored;
    const std::filesystem::path scratch = std::filesystem::temp_directory_path(ignored) /
                                          ("sphles-estimate-" + std::to_string(::getpid()));
    analysis::RunDirectoryWriter(scratch).write(frame);
    std::filesystem::remove_all(scratch, ignored);
  }
  e.analysis_seconds_per_frame = seconds_since(timed) * scale;
  if (spec.render.enabled()) {
    const std::string case_name(sim::case_name(spec.scene.case_type));
    render::render_frame_images(frame, spec.render, case_name, view3d.enabled);  // set-up
    timed = Clock::now();
    render::render_frame_images(frame, spec.render, case_name, view3d.enabled);
    e.render_seconds_per_frame = seconds_since(timed);
  }
  e.frames = resources.analysis_frames;
  // The slower of the solver and the analysis chain sets the pace; the other one shares the
  // cores with it while it works (all of its time when the solver's threads take every core).
  const double output = e.frames * (e.analysis_seconds_per_frame + e.render_seconds_per_frame);
  const double cores = std::max(1u, std::thread::hardware_concurrency());
  const double shared = std::min(1.0, threads / cores);
  e.seconds_to_end = e.packing_seconds + std::max(e.solver_seconds, output) +
                     std::min(e.solver_seconds, output) * shared;
  return e;
}

nlohmann::json step_time_to_json(const StepTimeEstimate& e) {
  return {{"seconds_per_step", e.seconds_per_step},
          {"solver_seconds", e.solver_seconds},
          {"analysis_seconds_per_frame", e.analysis_seconds_per_frame},
          {"render_seconds_per_frame", e.render_seconds_per_frame},
          {"frames", e.frames},
          {"packing_seconds", e.packing_seconds},
          {"seconds_to_end", e.seconds_to_end},
          {"calibration",
           {{"particles_per_side", e.calibration_side},
            {"particles", e.calibration_particles},
            {"steps", e.calibration_steps},
            {"seconds", e.calibration_seconds},
            {"setup_seconds", e.calibration_setup_seconds},
            {"threads", e.threads}}}};
}

}  // namespace sphles::control
