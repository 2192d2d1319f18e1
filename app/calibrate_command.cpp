// SPDX-License-Identifier: GPL-3.0-or-later
// sphles calibrate: secant iterations on the Kolmogorov forcing amplitude χ so that the
// time-averaged u_rms reaches a target (SPEC §6.3: ⟨u_rms⟩ = 0.11 m/s, thesis χ = 1.8 m/s²).
#include <omp.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "app/commands.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::app {

namespace {

struct CalibrateOptions {
  std::string scene_file;
  std::vector<std::string> overrides;
  double target = 0.0;
  double end_time = -1.0, average_from = -1.0, initial = 0.0;  // not given: -1, -1, 0
  int tries = 8;
  double tolerance = 0.01;
  int threads = 0;
};

/// Refusals CLI11 does not express.
void check_options(const CalibrateOptions& o) {
  if (!(o.target > 0.0)) throw std::invalid_argument("--target-urms must be > 0");
  if (!(o.tolerance > 0.0)) throw std::invalid_argument("--tolerance must be > 0");
}

/// Time-averaged u_rms over [average_from, end] of one run with forcing amplitude χ.
double mean_urms(sim::Scene scene, double chi, double average_from) {
  scene.forcing.amplitude = chi;
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  double weighted = 0.0, duration = 0.0;
  while (!sim::reached_end(simulation->time(), scene.end_time)) {
    const double before = simulation->time();
    simulation->step(scene.end_time - before);
    const double dt = simulation->time() - before;
    if (simulation->time() > average_from) {
      const double u_rms = simulation->case_diagnostics(scene)[2];
      weighted += u_rms * dt;
      duration += dt;
    }
  }
  if (!(duration > 0.0)) throw std::invalid_argument("--average-from is not before the end time");
  return weighted / duration;
}

}  // namespace

int calibrate_command(const CalibrateOptions& o) {
  sim::Scene scene;
  try {
    check_options(o);
    scene = load_run_config(o.scene_file, o.overrides).scene;
    if (scene.case_type != sim::CaseType::Kolmogorov2D)
      throw std::invalid_argument("calibrate needs a kolmogorov2d scene, got case '" +
                                  std::string(sim::case_name(scene.case_type)) + "'");
    if (o.end_time >= 0.0) scene.end_time = o.end_time;
    if (!(scene.end_time > 0.0)) throw std::invalid_argument("--time must be > 0");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles calibrate: %s\n", e.what());
    return kExitUsage;
  }
  if (o.threads > 0) omp_set_num_threads(o.threads);
  const double average_from = o.average_from >= 0.0 ? o.average_from : 0.25 * scene.end_time;
  try {
    std::printf("calibrating chi for <u_rms> = %g m/s over t in [%g, %g] s (%zu particles)\n",
                o.target, average_from, scene.end_time, scene.num_particles());
    double chi0 = o.initial > 0.0 ? o.initial : scene.forcing.amplitude;
    double u0 = mean_urms(scene, chi0, average_from);
    std::printf("try 1: chi = %.6g m/s^2  <u_rms> = %.6g m/s  error = %+.3f %%\n", chi0, u0,
                100.0 * (u0 / o.target - 1.0));
    if (std::abs(u0 / o.target - 1.0) <= o.tolerance) {
      std::printf("converged: chi = %.6g m/s^2\n", chi0);
      return kExitOk;
    }
    // Second try from proportional scaling (exact for the laminar state, u ∝ χ).
    double chi1 = u0 > 0.0 ? chi0 * o.target / u0 : 2.0 * chi0;
    for (int attempt = 2; attempt <= o.tries; ++attempt) {
      const double u1 = mean_urms(scene, chi1, average_from);
      std::printf("try %d: chi = %.6g m/s^2  <u_rms> = %.6g m/s  error = %+.3f %%\n", attempt, chi1,
                  u1, 100.0 * (u1 / o.target - 1.0));
      if (std::abs(u1 / o.target - 1.0) <= o.tolerance) {
        std::printf("converged: chi = %.6g m/s^2\n", chi1);
        return kExitOk;
      }
      const double slope = (u1 - u0) / (chi1 - chi0);
      const double next = std::abs(slope) > 0.0 ? chi1 + (o.target - u1) / slope : 2.0 * chi1;
      chi0 = chi1;
      u0 = u1;
      chi1 = next;
    }
    std::fprintf(stderr, "sphles calibrate: not converged within %d tries\n", o.tries);
    return kExitFailure;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles calibrate: %s\n", e.what());
    return kExitFailure;
  }
}

void add_calibrate_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* calibrate =
      app.add_subcommand("calibrate", "calibrate the Kolmogorov forcing to a target u_rms");
  calibrate->footer(
      "Find the Kolmogorov forcing amplitude chi giving a time-averaged u_rms = U by secant "
      "iterations of whole runs (SPEC 6.3). Exit 0 when converged, 1 when not.");
  calibrate->add_option("scene", o->scene_file, "a kolmogorov2d scene file or preset")
      ->type_name("SCENE.json|PRESET")
      ->required();
  calibrate->add_option("--target-urms", o->target, "the target <u_rms> [m/s]")
      ->type_name("U")
      ->required();
  calibrate->add_option("--time", o->end_time, "end time of each run [s] (default: the scene's)")
      ->type_name("T")
      ->check(CLI::NonNegativeNumber);
  calibrate
      ->add_option("--average-from", o->average_from,
                   "start of the averaging window [s] (default: a quarter of the end time)")
      ->type_name("T0")
      ->check(CLI::NonNegativeNumber);
  calibrate->add_option("--initial", o->initial, "first chi [m/s^2] (default: the scene's)")
      ->type_name("CHI")
      ->check(CLI::PositiveNumber);
  calibrate->add_option("--tries", o->tries, "runs at most")
      ->check(CLI::Range(2, 100))
      ->capture_default_str();
  calibrate->add_option("--tolerance", o->tolerance, "relative error accepted")
      ->capture_default_str();
  repeatable(calibrate->add_option("--set", o->overrides, "change a scene key (repeatable)"))
      ->type_name("KEY=VALUE");
  add_threads_option(*calibrate, o->threads, "OpenMP threads");
  calibrate->callback([o, &exit_code] { exit_code = calibrate_command(*o); });
}

}  // namespace sphles::app
