// SPDX-License-Identifier: GPL-3.0-or-later
// The fluid of SPEC §2 and the pair coefficients of the thesis model's momentum equation: pure
// functions over plain data, shared by the evaluators of sim/physics/.
#pragma once

#include "sim/particles.hpp"

namespace sphles::sim {

/// Barotropic fluid with constant dynamic viscosity (SPEC §2).
struct FluidParameters {
  double reference_density = 1.0;    // ρ_ref [kg/m^n]
  double sound_speed = 5.0;          // c_s [m/s]
  double reference_pressure = 6.25;  // p_ref [Pa]
  double dynamic_viscosity = 1e-4;   // η [Pa s]

  double kinematic_viscosity() const { return dynamic_viscosity / reference_density; }
};

/// Equation of state p = p_ref + c_s² (ρ - ρ_ref) (SPEC §2).
inline double equation_of_state(double density, const FluidParameters& fluid) {
  return fluid.reference_pressure +
         fluid.sound_speed * fluid.sound_speed * (density - fluid.reference_density);
}

/// Pressure pair coefficient of (A.9): the pair adds -(p_i + p_j) ∇W_ij V_j to F^p_i.
inline double pressure_pair_coefficient(double pressure_i, double pressure_j) {
  return -(pressure_i + pressure_j);
}

/// Viscous pair coefficient of (A.14): the pair adds 2(n+2) η (v_ij·x_ij)/|x_ij|² ∇W_ij V_j.
/// `viscous_factor` is 2(n+2) η.
inline double viscous_pair_coefficient(double viscous_factor, double v_dot_x, double r2) {
  return viscous_factor * v_dot_x / r2;
}

/// Read-only velocity components, so that forces can be evaluated at a predicted velocity.
struct VelocityView {
  const double* v[3] = {nullptr, nullptr, nullptr};
};

inline VelocityView view_velocity(const ParticleArrays& p) {
  VelocityView view;
  for (int d = 0; d < p.dimension; ++d) view.v[d] = p.velocity[d].data();
  return view;
}

}  // namespace sphles::sim
