// SPDX-License-Identifier: GPL-3.0-or-later
// A spectral reference run of a scene's case (`sphles reference`, docs/reference.md): the same
// flow as the particle run (box, viscosity, initial field, Kolmogorov forcing and friction),
// solved by NavierStokesSolver, written into a run directory like a particle run's:
//   scene.json, run.json, run.log, timeseries.csv (reference_timeseries_header),
//   spectra/ and slices/ (analysis::RunDirectoryWriter: the same shells, normalisation and
//   formats as a particle run's), checkpoints/ref_{step}.h5 (restart bitwise).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "analysis/config.hpp"
#include "analysis/products.hpp"
#include "scene/run_policy.hpp"
#include "sim/scene.hpp"
#include "spectral/navier_stokes.hpp"

namespace sphles::spectral {

/// The scene's "reference" section (scene schema).
struct ReferenceConfig {
  int points_per_side = 128;
  double cfl = 0.5;
  double every = 0.0;  // between spectra and slices; 0 = analysis.every, else time.end / 80
};

/// Reads the "reference" section of a scene document (absent: defaults); throws sim::SceneError
/// naming the field.
ReferenceConfig parse_reference_config(const nlohmann::json& document);
nlohmann::json reference_config_to_json(const ReferenceConfig& config);

/// The scene's flow for the spectral solver. Throws sim::SceneError for a scene whose model has
/// no incompressible counterpart (none today: every case is periodic).
FlowParameters flow_of(const sim::Scene& scene);

/// The scene's initial velocity (SPEC §6: the particle run's field, from the same functions) on
/// the n^d grid nodes (x, y, z) L/n, component c at x + n (y + n (z - first_plane)), for the z
/// planes [first_plane, first_plane + planes) (3D; a 2D grid is whole).
std::array<std::vector<double>, 3> initial_velocity_grid(const sim::Scene& scene, int n,
                                                         int first_plane = 0, int planes = -1);

/// The time between spectra and slices the configuration means for the scene.
double reference_output_every(const ReferenceConfig& config, const sim::Scene& scene,
                              const analysis::AnalysisConfig& analysis);

/// The columns of timeseries.csv: t, step, dt, E, minus_dE_dt (exact, from the discrete
/// system), epsilon (2νZ), Z, injection (⟨f·u⟩), film_dissipation (2μE), transfer
/// (nonlinear, zero up to round-off), max_speed.
std::string reference_timeseries_header();

/// The analysis frame of the solver's state (spectrum and ω² slice as a particle run's
/// analysis writes them), its budget included.
analysis::AnalysisFrame reference_frame(NavierStokesSolver& solver, const sim::Scene& scene,
                                        const analysis::AnalysisConfig& analysis);

/// What a reference run needs, without running it.
struct ReferenceEstimate {
  /// Peak resident memory of the process that needs most (rank 0, which holds the whole state
  /// at a checkpoint), the program's own footprint included.
  double memory_bytes = 0.0;
  double checkpoint_bytes = 0.0;  // one checkpoint file
  double steps = 0.0;             // time steps to time.end at the initial CFL step
  int max_wavenumber = 0;         // largest |m| kept (2/3 rule)
};
/// `ranks`: the MPI ranks a 3D grid is shared among.
ReferenceEstimate estimate_reference(const sim::Scene& scene, const ReferenceConfig& config,
                                     int ranks = 1);

struct ReferenceRunOptions {
  std::filesystem::path directory;
  /// The ranks a 3D reference is shared among under mpirun (RealFft), every rank calling
  /// run_reference alike; rank 0 writes the run directory and calls the callbacks below. Null:
  /// one process.
  SlabExchange* exchange = nullptr;
  /// Continue from the newest valid checkpoint in directory/checkpoints (the scene must match
  /// the one it was written with, apart from time.end and the output cadences).
  bool restart = false;
  bool echo_progress = true;
  std::function<bool()> stop_requested;  // checked after every step
  /// Called with the time and step count at the start (after a restart's restore) and after
  /// every step (a service's progress).
  std::function<void(double time, std::uint64_t step)> on_step;
  /// Called with each analysis frame written (for rendering).
  std::function<void(std::shared_ptr<const analysis::AnalysisFrame>)> on_frame;
};

struct ReferenceRunResult {
  double time = 0.0;
  std::uint64_t steps = 0;
  bool stopped = false;  // stop_requested said so before the end
  std::size_t frames = 0;
};

/// Runs the reference from t = 0 (or the checkpoint) to time.end. `scene_document` is the
/// complete scene (written as scene.json, stored in checkpoints). Throws std::runtime_error on
/// I/O failure or a non-finite state, sim::SceneError on a bad configuration.
ReferenceRunResult run_reference(const sim::Scene& scene, const analysis::AnalysisConfig& analysis,
                                 const scene::RunPolicy& policy, const ReferenceConfig& config,
                                 const nlohmann::json& scene_document,
                                 const ReferenceRunOptions& options);

}  // namespace sphles::spectral
