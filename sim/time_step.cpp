// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/time_step.hpp"

#include <algorithm>
#include <cmath>

namespace sphles::sim {

TimeStepLimits time_step_limits(const TimeStepConfig& ts, double spacing,
                                const FluidParameters& fluid, double max_speed,
                                double max_acceleration) {
  TimeStepLimits limits;
  limits.fixed = ts.fixed;
  limits.acoustic = ts.cfl_acoustic * spacing / (fluid.sound_speed + max_speed);
  const double nu = fluid.kinematic_viscosity();
  if (nu > 0.0) limits.viscous = ts.cfl_viscous * spacing * spacing / nu;
  if (max_acceleration > 0.0) limits.force = ts.cfl_force * std::sqrt(spacing / max_acceleration);
  return limits;
}

double TimeStepLimits::step() const {
  if (fixed > 0.0) return fixed;
  return std::min(acoustic, std::min(viscous, force));
}

std::string_view TimeStepLimits::binding() const {
  if (fixed > 0.0) return "fixed";
  if (acoustic <= viscous && acoustic <= force) return "acoustic";
  return viscous <= force ? "viscous" : "force";
}

}  // namespace sphles::sim
