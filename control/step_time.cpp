// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/step_time.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>

#include "sim/initial_conditions.hpp"
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

StepTimeEstimate estimate_step_time(const RunSpec& spec, const ResourceEstimate& resources,
                                    int steps) {
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
  e.seconds_per_step =
      e.calibration_seconds / e.calibration_steps * resources.particles / e.calibration_particles;
  e.seconds_to_end = e.seconds_per_step * resources.steps;
  return e;
}

nlohmann::json step_time_to_json(const StepTimeEstimate& e) {
  return {{"seconds_per_step", e.seconds_per_step},
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
