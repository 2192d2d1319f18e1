// SPDX-License-Identifier: GPL-3.0-or-later
// The solver's time-step limits (docs/numerics.md), usable before a solver exists: a scene's
// check of its time resolution and the resource estimate use the same formulas.
#pragma once

#include <limits>
#include <string_view>

#include "sim/physics/fluid.hpp"

namespace sphles::sim {

/// Time-step limits (docs/numerics.md); Δl is the mean particle spacing, H the kernel support.
///   acoustic:     dt <= cfl_acoustic * Δl / (c_s + |v|max)
///   viscous:      dt <= cfl_viscous  * Δl² / ν
///   acceleration: dt <= cfl_force    * sqrt(Δl / |a|max)
/// A positive `fixed` step replaces the limits (the limits are still reported).
struct TimeStepConfig {
  double cfl_acoustic = 0.4;
  double cfl_viscous = 0.125;
  double cfl_force = 0.25;
  double fixed = 0.0;
};

/// The three limits of TimeStepConfig for a state with the given maxima (a limit that does not
/// apply, such as the viscous one for ν = 0, is infinite), and the fixed step if one is set.
struct TimeStepLimits {
  double acoustic = std::numeric_limits<double>::infinity();
  double viscous = std::numeric_limits<double>::infinity();
  double force = std::numeric_limits<double>::infinity();
  double fixed = 0.0;

  /// The step the solver takes: the fixed step when set, else the smallest limit.
  double step() const;
  /// Which of them sets step(): "fixed", "acoustic", "viscous" or "force".
  std::string_view binding() const;
};

/// The solver's own formulas (Simulation::stable_time_step() is
/// time_step_limits(...).step() for its current state), usable before a solver exists.
TimeStepLimits time_step_limits(const TimeStepConfig& config, double particle_spacing,
                                const FluidParameters& fluid, double max_speed,
                                double max_acceleration);

}  // namespace sphles::sim
