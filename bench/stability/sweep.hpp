// SPDX-License-Identifier: GPL-3.0-or-later
// Stability sweep (docs/stability.md): small scenes built in code, each run to a time budget with
// health checks at a step cadence and classified stable / noisy / paired / blown_up
// (sim/health.hpp).
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/document.hpp"
#include "sim/health.hpp"

namespace sphles::stability {

/// One configuration of the sweep: a scene document (parsed by scene::parse_scene, so every key is
/// validated as in a scene file) and the acoustic CFL factor, which is set on the solver
/// configuration directly because the scene limits it to (0, 2].
struct RunSpec {
  std::string group;  // mach, p_ref, cfl, kernel, viscosity, forcing, long
  std::string label;  // the swept value, e.g. "c_s=2"
  nlohmann::json scene;
  /// C_ac of docs/numerics.md. The viscous and force factors are scaled by the same ratio to
  /// their defaults, so that the acoustic limit stays the one that binds.
  double cfl = 0.4;
};

struct RunOptions {
  int check_every = 20;  // steps between health checks (and one at the end)
  /// A run that needs more than this many times the steps its initial time step implies has a
  /// collapsing time step (accelerations running away faster than the energy): blown up.
  double step_budget_factor = 20.0;
  double wall_limit_seconds = 600.0;  // per run; a run stopped by it keeps its classification
  std::string packing_cache_dir;      // empty: the default cache
  bool trace = false;                 // print every check to stderr
  /// The library defaults, except that the runaway test is judged against the flow's own
  /// energy scale (reference_mach = 0): the initial energy of a decaying Taylor-Green vortex, and
  /// for the Kolmogorov flow the larger of that and the laminar energy of the forcing, which
  /// run_one sets as reference_energy.
  sim::HealthThresholds thresholds = sweep_thresholds();

  static sim::HealthThresholds sweep_thresholds() {
    sim::HealthThresholds t;
    t.blow_up.reference_mach = 0.0;
    return t;
  }
};

struct RunResult {
  RunSpec spec;
  // Parameters, read back from the parsed scene.
  std::string case_name;
  int particles_per_side = 0;
  std::string kernel;
  double diameter_over_spacing = 0.0;
  double sound_speed = 0.0;
  double reference_pressure = 0.0;
  double dynamic_viscosity = 0.0;
  double forcing_amplitude = 0.0;  // kolmogorov2d only, else 0
  double end_time = 0.0;
  // Outcome.
  sim::Classification classification = sim::Classification::Stable;
  std::string reason;
  double time_reached = 0.0;
  std::uint64_t steps = 0;
  double max_density_deviation = 0.0;  // maximum over the checks
  double max_rms_density_deviation = 0.0;
  double max_paired_fraction = 0.0;
  double min_neighbour_distance = 0.0;  // minimum over the checks, units of Δl
  double initial_energy = 0.0;
  double final_energy = 0.0;
  /// Final e_v over the flow's expected energy: the analytic decay e_v(0) exp(-4νt) for tgv2d,
  /// the laminar spin-up from rest for kolmogorov2d (0 for tgv3d).
  double energy_ratio = 0.0;
  double wall_seconds = 0.0;
};

/// The configurations of the sweep; `quick` gives a subset of a few minutes.
std::vector<RunSpec> make_sweep(bool quick);

/// Runs one configuration (on the calling thread's OpenMP settings) and classifies it.
RunResult run_one(const RunSpec& spec, const RunOptions& options);

void write_csv_header(std::ostream& out);
void write_csv_row(std::ostream& out, const RunResult& result);

}  // namespace sphles::stability
