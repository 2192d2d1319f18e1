// SPDX-License-Identifier: GPL-3.0-or-later
// A new run's first solver (RunImpl::set_up): its particles made and packed (or read from the
// packing cache) here or where they will live, with the packing reported in run.log.
#include <chrono>
#include <cstdio>

#include "control/run_impl.hpp"
#include "sim/initial_conditions.hpp"

namespace sphles::control {

using Clock = std::chrono::steady_clock;

/// A new run's particles (packed, from the packing cache, or the lattice) and its solver; a
/// stop during the packing cancels it (sim::SetupCancelled).
std::unique_ptr<sim::Simulation> RunImpl::set_up(const sim::Scene& scene, std::string& packing) {
  std::error_code ignored;
  std::filesystem::remove(directory / "timeseries.csv", ignored);
  std::filesystem::remove(directory / "frames" / "index.csv", ignored);
  const auto setup_start = Clock::now();
  sim::SetupOptions setup_options;
  setup_options.packing_cache_dir = options.packing_cache_dir;
  setup_options.cancelled = [this] {
    std::lock_guard lock(mutex);
    return stop_requested;
  };
  // Made where the particles will live (a distributed solver's ranks), or here.
  std::unique_ptr<sim::Simulation> made;
  sim::RunSetup setup;
  if (options.solvers.set_up)
    made = options.solvers.set_up(scene, setup_options, setup.packing);
  else
    setup = sim::setup_run(scene, setup_options);
  const double setup_seconds = std::chrono::duration<double>(Clock::now() - setup_start).count();
  char text[512];
  std::snprintf(text, sizeof text,
                "%s; iterations %d; residual %.6g -> %.6g; from cache %s; cache file %s",
                scene.packing.enabled ? "Colagrossi packing" : "lattice (packing disabled)",
                setup.packing.iterations, setup.packing.initial_residual,
                setup.packing.final_residual, setup.packing.from_cache ? "yes" : "no",
                setup.packing.cache_file.empty() ? "-" : setup.packing.cache_file.c_str());
  packing = text;
  if (scene.packing.enabled)
    log->progress("packing: {}, {} iterations, residual {:.3g} -> {:.3g} ({:.1f} s){}{}",
                  setup.packing.from_cache  ? "from cache"
                  : setup.packing.converged ? "converged"
                                            : "NOT converged (max_iterations reached)",
                  setup.packing.iterations, setup.packing.initial_residual,
                  setup.packing.final_residual, setup_seconds,
                  setup.packing.cache_file.empty() ? "" : ", cache ", setup.packing.cache_file);
  if (made) {
    log->debug("set-up: particles made, packed and set up by the ranks, none gathered");
    return made;
  }
  set_phase("setting up");  // the solver (and any MPI job) from the packed particles
  return options.solvers.make ? options.solvers.make(scene, std::move(setup.particles))
                              : sim::make_simulation(setup.solver, std::move(setup.particles));
}

}  // namespace sphles::control
