// sphles calibrate: secant iterations on the Kolmogorov forcing amplitude χ so that the
// time-averaged u_rms reaches a target (SPEC §6.3: ⟨u_rms⟩ = 0.11 m/s, thesis χ = 1.8 m/s²).
#include <omp.h>

#include <cmath>
#include <cstdio>
#include <optional>
#include <stdexcept>

#include "app/commands.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::app {

namespace {

struct CalibrateOptions {
  std::string scene_file;
  std::vector<std::string> overrides;
  double target = 0.0;
  std::optional<double> end_time, average_from, initial;
  int tries = 8;
  double tolerance = 0.01;
  int threads = 0;
};

double parse_number(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !std::isfinite(value))
    throw std::invalid_argument(option + " must be a number, got '" + text + "'");
  return value;
}

CalibrateOptions parse_options(const std::vector<std::string>& args) {
  CalibrateOptions o;
  bool have_target = false;
  for (std::size_t k = 0; k < args.size(); ++k) {
    const std::string& a = args[k];
    const auto value = [&]() -> const std::string& {
      if (k + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
      return args[++k];
    };
    if (a == "--target-urms") {
      o.target = parse_number(a, value());
      have_target = true;
    } else if (a == "--time") {
      o.end_time = parse_number(a, value());
    } else if (a == "--average-from") {
      o.average_from = parse_number(a, value());
    } else if (a == "--initial") {
      o.initial = parse_number(a, value());
    } else if (a == "--tries") {
      o.tries = static_cast<int>(parse_number(a, value()));
    } else if (a == "--tolerance") {
      o.tolerance = parse_number(a, value());
    } else if (a == "--threads") {
      o.threads = static_cast<int>(parse_number(a, value()));
    } else if (a == "--set") {
      o.overrides.push_back(value());
    } else if (!a.empty() && a[0] == '-') {
      throw std::invalid_argument("unknown option '" + a + "'");
    } else if (o.scene_file.empty()) {
      o.scene_file = a;
    } else {
      throw std::invalid_argument("unexpected argument '" + a + "'");
    }
  }
  if (o.scene_file.empty()) throw std::invalid_argument("missing SCENE.json or preset");
  if (!have_target || !(o.target > 0.0))
    throw std::invalid_argument("--target-urms must be given and > 0");
  if (o.tries < 2 || o.tries > 100) throw std::invalid_argument("--tries must be in [2, 100]");
  if (!(o.tolerance > 0.0)) throw std::invalid_argument("--tolerance must be > 0");
  if (o.threads < 0 || o.threads > 1024) throw std::invalid_argument("--threads must be >= 1");
  return o;
}

/// Time-averaged u_rms over [average_from, end] of one run with forcing amplitude χ.
double mean_urms(sim::Scene scene, double chi, double average_from) {
  scene.forcing.amplitude = chi;
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  double weighted = 0.0, duration = 0.0;
  while (simulation->time() < scene.end_time - 1e-12 * scene.end_time) {
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

int calibrate_command(const std::vector<std::string>& args) {
  CalibrateOptions o;
  sim::Scene scene;
  try {
    o = parse_options(args);
    scene = load_run_config(o.scene_file, o.overrides).scene;
    if (scene.case_type != sim::CaseType::Kolmogorov2D)
      throw std::invalid_argument("calibrate needs a kolmogorov2d scene, got case '" +
                                  std::string(sim::case_name(scene.case_type)) + "'");
    if (o.end_time) scene.end_time = *o.end_time;
    if (!(scene.end_time > 0.0)) throw std::invalid_argument("--time must be > 0");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles calibrate: %s\n", e.what());
    return kExitUsage;
  }
  if (o.threads > 0) omp_set_num_threads(o.threads);
  const double average_from = o.average_from.value_or(0.25 * scene.end_time);
  try {
    std::printf("calibrating chi for <u_rms> = %g m/s over t in [%g, %g] s (%zu particles)\n",
                o.target, average_from, scene.end_time, scene.num_particles());
    double chi0 = o.initial.value_or(scene.forcing.amplitude);
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

}  // namespace sphles::app
