// SPDX-License-Identifier: GPL-3.0-or-later
// When a run writes: the scene document's "checkpoint" and "output" sections. They belong to the
// run loops (control/run_loop.cpp, the spectral reference's spectral/reference_run.cpp), not to
// the solver, so they live beside the document rather than in sim::Scene.
#pragma once

namespace sphles::scene {

/// Checkpoints (docs/checkpoints.md): at a cadence in simulated and/or wall time, keeping the
/// newest `keep` files.
struct CheckpointConfig {
  double every = 0.0;          // simulated time between checkpoints [s]; 0 = none by sim time
  double every_seconds = 0.0;  // wall time between checkpoints [s]; 0 = none by wall time
  int keep = 3;                // newest files kept
  int compression = 0;         // gzip level 0-9 (0 = none)
  bool enabled() const { return every > 0.0 || every_seconds > 0.0; }
};

/// The time series and the progress line.
struct OutputConfig {
  double timeseries_every = 0.0;        // simulated time between rows; 0 writes every step
  double progress_every_seconds = 1.0;  // wall time between progress lines
};

/// Both sections, as a run loop takes them.
struct RunPolicy {
  OutputConfig output;
  CheckpointConfig checkpoint;
};

}  // namespace sphles::scene
