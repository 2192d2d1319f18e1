// SPDX-License-Identifier: GPL-3.0-or-later
// How long a run's steps take on this machine, measured before the run: a short calibration run
// of the same scene at a small size (same case, kernel and D_K/Δl, scheme and sub-filter model,
// so the same neighbours per particle and the same work per pair), scaled by the particle count.
#pragma once

#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "control/resources.hpp"
#include "control/run.hpp"

namespace sphles::control {

struct StepTimeEstimate {
  double seconds_per_step = 0.0;  // of the run, at its particle count [s]
  double solver_seconds = 0.0;    // seconds_per_step × the estimate's steps (initial step) [s]
  /// One analysis time's products computed and written at the run's size (the calibration's,
  /// scaled by the particle count) and its rendered images (at the run's image size) [s]; 0
  /// without analysis.
  double analysis_seconds_per_frame = 0.0;
  double render_seconds_per_frame = 0.0;
  double frames = 0.0;  // analysis times to the end (ResourceEstimate::analysis_frames)
  /// Packing the initial lattice: 0 when the packing cache holds it (or packing is off), else
  /// the calibration lattice packed (without the cache) and scaled by the particle count [s].
  double packing_seconds = 0.0;
  /// The run to its end: the solver, and the analysis and rendering of every frame on their own
  /// threads, which hold the solver when they fall behind (lossless outputs, analysis/
  /// pipeline.hpp): the larger of the two [s].
  double seconds_to_end = 0.0;
  std::size_t calibration_side = 0;        // particles per side of the calibration run
  double calibration_particles = 0.0;      // its N^n
  int calibration_steps = 0;               // steps timed (after the warm-up)
  double calibration_seconds = 0.0;        // their wall time [s]
  double calibration_setup_seconds = 0.0;  // building it, warm-up included [s]
  int threads = 0;                         // OpenMP threads it ran on
};

/// Particles per side of the calibration run: the run's own when it is small, else 64 in 2D
/// and 24 in 3D (4096 and 13824 particles; at D_K = 8Δl a few supports across the box).
std::size_t calibration_side(const RunSpec& spec);

/// Times `steps` steps of the run's scene at calibration_side() (no packing, no output; one
/// warm-up step builds the neighbour list first) on the calling thread's OpenMP team, and scales
/// the time per step by particles / calibration particles (the pair loops are linear in N at
/// fixed neighbours; caches make large runs somewhat slower per particle). With analysis, then
/// times the run's analysis products of the calibration state (the second of two, the first
/// makes the FFT plans) and their images, scaled the same way (the grid has 2^dim nodes per
/// particle). A packing the cache in `packing_cache_dir` (empty: the default) does not hold is
/// timed the same way, and comes before everything else.
/// Throws sim::SceneError if the scene cannot be set up.
StepTimeEstimate estimate_step_time(const RunSpec& spec, const ResourceEstimate& resources,
                                    int steps = 10,
                                    const std::filesystem::path& packing_cache_dir = {});

/// {"seconds_per_step", "solver_seconds", "analysis_seconds_per_frame",
///  "render_seconds_per_frame", "frames", "packing_seconds", "seconds_to_end", "calibration":
///  {"particles_per_side", "particles", "steps", "seconds", "setup_seconds", "threads"}}.
nlohmann::json step_time_to_json(const StepTimeEstimate& estimate);

}  // namespace sphles::control
