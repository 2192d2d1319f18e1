// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/scene_warnings.hpp"

#include <cmath>
#include <numbers>

#include "sim/format.hpp"

namespace sphles::sim {

namespace {

/// The wavenumber the case is about [1/m]: the initial Taylor-Green vortices' |k| (√dim modes of
/// the box's fundamental, SPEC §6.1-6.2) or the Kolmogorov forcing's k_y (SPEC §6.3); and what
/// it is, for the message.
struct CaseScale {
  double wavenumber;
  const char* what;
};

CaseScale case_scale(const Scene& s) {
  const double fundamental = 2.0 * std::numbers::pi / s.box_length();
  switch (s.case_type) {
    case CaseType::TaylorGreen3D:
      return {std::sqrt(3.0) * fundamental, "the initial vortices' wavenumber"};
    case CaseType::TaylorGreen2D:
      return {std::sqrt(2.0) * fundamental, "the initial vortices' wavenumber"};
    case CaseType::Kolmogorov2D:
      return {s.forcing_wavenumber(), "the forcing's wavenumber k_y"};
  }
  return {fundamental, "the box's wavenumber"};
}

}  // namespace

std::vector<SceneWarning> scene_warnings(const Scene& s) {
  std::vector<SceneWarning> warnings;
  // The particles resolve wavenumbers up to k_SPH = k_kern / 2 = π / D_K (SPEC §9).
  const CaseScale scale = case_scale(s);
  const double resolved = std::numbers::pi / s.kernel_diameter();
  if (scale.wavenumber > resolved * (1.0 + 1e-12)) {
    const double needed = std::ceil(s.kernel_diameter_over_spacing * s.box_length() *
                                        scale.wavenumber / std::numbers::pi -
                                    1e-9);
    warnings.push_back(
        {"particles_per_side",
         "the kernel (D_K = " + format_number(s.kernel_diameter()) +
             " m) resolves wavenumbers up to k_SPH = pi/D_K = " + format_number(resolved) +
             " 1/m (SPEC 9), below " + scale.what + " " + format_number(scale.wavenumber) +
             " 1/m: the flow the case is about is not resolved and the answer is kernel-scale "
             "noise; 'particles_per_side' >= " +
             format_number(needed) +
             " resolves it at D_K = " + format_number(s.kernel_diameter_over_spacing) + " dl"});
  }
  // The Taylor-Green cases start at their fastest (the initial amplitude plus the uniform
  // velocity); a Kolmogorov flow's speed is not known before it runs (its laminar profile, which
  // sets no bound, is unstable).
  const TimeStepEstimate initial = estimate_initial_time_step(s);
  const double speed = initial.max_speed;
  const double mach = speed / s.fluid.sound_speed;
  if (s.case_type != CaseType::Kolmogorov2D && mach > kMaxMachNumber)
    warnings.push_back({"fluid.sound_speed",
                        "the Mach number v/c_s = " + format_number(mach) + " exceeds " +
                            format_number(kMaxMachNumber) +
                            ": density fluctuations of order Ma^2 make the flow compressible; "
                            "'fluid.sound_speed' >= " +
                            format_number(speed / kMaxMachNumber) + " m/s keeps it below"});
  const TimeStepLimits& limits = initial.limits;
  if (limits.fixed == 0.0 && limits.binding() == "viscous")
    warnings.push_back(
        {"fluid.dynamic_viscosity",
         "the viscous limit sets the time step (" + format_number(limits.viscous) +
             " s, the acoustic one allows " + format_number(limits.acoustic) +
             " s): the viscosity damps what the particles resolve, and the run takes " +
             format_number(limits.acoustic / limits.viscous) +
             " times the steps; more particles or less viscosity"});
  return warnings;
}

}  // namespace sphles::sim
