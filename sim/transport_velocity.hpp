// The transport-velocity formulation (TVF) of Adami, Hu & Adams, J. Comput. Phys. 241 (2013)
// 292-307, as pair formulas and one neighbour pass (docs/models.md, "Transport-velocity
// formulation"). Equation numbers are the paper's, as PySPH's implementation
// (pysph/sph/wc/transport_velocity.py, integrator_step.py TransportVelocityStep) cites them.
//
// Particles move with the transport velocity ṽ = v + dt/2 ã (eqs. 14-16), where ã is the
// acceleration of the constant background pressure p_b (eq. 13); the momentum equation (eq. 8)
// carries the extra stress A = ρ v ⊗ (ṽ - v) of the difference. The momentum pressure is the
// EOS pressure without the background, p - p_b = c_s² (ρ - ρ_ref): p_b (our
// fluid.reference_pressure) acts only through ã. Density by summation, V_i = 1/Σ_j W_ij,
// ρ_i = M_i/V_i, as in the paper and the thesis model (A.1, A.2): density_pass.
//
// The pass is in gather form like physics.hpp, so results do not depend on the thread count.
// Every pair term of M_i a_i is antisymmetric in i and j (the weights V_i² + V_j², p̃_ij and
// A_i + A_j are symmetric, ∇W_ij and v_ij antisymmetric), so Σ M a = 0 to round-off.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics.hpp"

namespace sphles::sim {

/// Momentum pressure of the TVF: the EOS pressure less the background, c_s² (ρ - ρ_ref).
inline double transport_velocity_momentum_pressure(double density, const FluidParameters& fluid) {
  return fluid.sound_speed * fluid.sound_speed * (density - fluid.reference_density);
}

/// Pair weight of eqs. (8) and (13): V_i² + V_j² (symmetric in i and j bit for bit).
inline double transport_velocity_pair_weight(double volume_i, double volume_j) {
  return volume_i * volume_i + volume_j * volume_j;
}

/// Inter-particle averaged pressure of eq. (7): p̃_ij = (ρ_j p_i + ρ_i p_j) / (ρ_i + ρ_j).
inline double transport_velocity_averaged_pressure(double density_i, double density_j,
                                                   double pressure_i, double pressure_j) {
  return (density_j * pressure_i + density_i * pressure_j) / (density_i + density_j);
}

/// Inter-particle averaged dynamic viscosity of eq. (6): η̃_ij = 2 η_i η_j / (η_i + η_j); zero
/// for an inviscid pair. With the constant η of SPEC §2 it is η.
inline double transport_velocity_averaged_viscosity(double viscosity_i, double viscosity_j) {
  const double sum = viscosity_i + viscosity_j;
  return sum > 0.0 ? 2.0 * viscosity_i * viscosity_j / sum : 0.0;
}

/// Coefficient of v_ij in the viscous term of eq. (8): the pair adds
/// (V_i² + V_j²) η̃_ij (1/r_ij)(∂W/∂r) v_ij to M_i a_i. `gradient_over_r` is (1/r)(∂W/∂r).
inline double transport_velocity_viscous_coefficient(double weight, double averaged_viscosity,
                                                     double gradient_over_r) {
  return weight * averaged_viscosity * gradient_over_r;
}

/// Coefficient of ∇W_ij in the pressure term of eq. (8): -(V_i² + V_j²) p̃_ij.
inline double transport_velocity_pressure_coefficient(double weight, double averaged_pressure) {
  return -weight * averaged_pressure;
}

/// Component a of the extra-stress term of eq. (8), ½ (A_i + A_j) · ∇W_ij with
/// A = ρ v ⊗ (ṽ - v), i.e. ½ (ρ_i v_i,a (δv_i · ∇W_ij) + ρ_j v_j,a (δv_j · ∇W_ij)) with
/// δv = ṽ - v. `shift_dot_gradient_*` are δv · ∇W_ij; the sum is symmetric in i and j.
inline double transport_velocity_stress_term(double density_i, double velocity_i,
                                             double shift_dot_gradient_i, double density_j,
                                             double velocity_j, double shift_dot_gradient_j) {
  return 0.5 * (density_i * velocity_i * shift_dot_gradient_i +
                density_j * velocity_j * shift_dot_gradient_j);
}

/// Acceleration of the background pressure, eq. (13): ã_i = -(p_b / M_i) Σ_j (V_i² + V_j²)
/// ∇W_ij, from the pair sum S_i = Σ_j (V_i² + V_j²) ∇W_ij.
inline double transport_velocity_background_acceleration(double background_pressure, double mass,
                                                         double pair_sum) {
  return -background_pressure / mass * pair_sum;
}

/// One TVF force evaluation: the acceleration (1/M_i) Σ_j (V_i² + V_j²) [-p̃_ij ∇W_ij +
/// ½ (A_i + A_j)·∇W_ij + η̃_ij (1/r)(∂W/∂r) v_ij] of eq. (8) at the given velocities and transport
/// shifts δv = ṽ - v (overwrites p.acceleration), and the background acceleration ã of eq. (13)
/// (overwrites `background`, whose arrays must have p.size() entries for each dimension).
/// Requires density_pass on the same positions.
template <int Dim, class KernelT>
void transport_velocity_force_pass(const KernelT& kernel, const PeriodicBox& box,
                                   const NeighbourList& neighbours, const FluidParameters& fluid,
                                   const VelocityView& velocity, const VelocityView& shift,
                                   std::array<std::vector<double>, 3>& background,
                                   ParticleArrays& p) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const double eta = transport_velocity_averaged_viscosity(fluid.dynamic_viscosity,
                                                           fluid.dynamic_viscosity);  // eq. (6)
  double length[Dim], half_length[Dim];
  const double* x[Dim];
  const double* v[Dim];
  const double* dv[Dim];
  double* a[Dim];
  double* a_background[Dim];
  for (int d = 0; d < Dim; ++d) {
    length[d] = box.length[d];
    half_length[d] = 0.5 * box.length[d];
    x[d] = p.position[d].data();
    v[d] = velocity.v[d];
    dv[d] = shift.v[d];
    a[d] = p.acceleration[d].data();
    a_background[d] = background[d].data();
  }
  const double* volume = p.volume.data();
  const double* density = p.density.data();
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double xi[Dim], vi[Dim], dvi[Dim], force[Dim], background_sum[Dim];
    for (int d = 0; d < Dim; ++d) {
      xi[d] = x[d][i];
      vi[d] = v[d][i];
      dvi[d] = dv[d][i];
      force[d] = 0.0;
      background_sum[d] = 0.0;
    }
    const double rho_i = density[i];
    const double p_i = transport_velocity_momentum_pressure(rho_i, fluid);
    const double vol_i = volume[i];
    for (const std::uint32_t j : neighbours.of(i)) {
      double dx[Dim];
      double r2 = 0.0;
      for (int d = 0; d < Dim; ++d) {
        dx[d] = minimum_image(xi[d] - x[d][j], length[d], half_length[d]);
        r2 += dx[d] * dx[d];
      }
      if (!(r2 < support2 && r2 > 0.0)) continue;
      const double g = kernel.gradient_over_r(std::sqrt(r2));  // ∇W_ij = g x_ij
      const double rho_j = density[j];
      const double weight = transport_velocity_pair_weight(vol_i, volume[j]);
      const double pressure = transport_velocity_pressure_coefficient(
          weight, transport_velocity_averaged_pressure(
                      rho_i, rho_j, p_i, transport_velocity_momentum_pressure(rho_j, fluid)));
      const double viscous = transport_velocity_viscous_coefficient(weight, eta, g);
      double shift_i = 0.0, shift_j = 0.0;  // δv · ∇W_ij
      for (int d = 0; d < Dim; ++d) {
        shift_i += dvi[d] * g * dx[d];
        shift_j += dv[d][j] * g * dx[d];
      }
      for (int d = 0; d < Dim; ++d) {
        const double gradient = g * dx[d];
        const double stress =
            transport_velocity_stress_term(rho_i, vi[d], shift_i, rho_j, v[d][j], shift_j);
        force[d] += pressure * gradient + weight * stress + viscous * (vi[d] - v[d][j]);
        background_sum[d] += weight * gradient;
      }
    }
    const double inv_mass = 1.0 / p.mass[i];
    for (int d = 0; d < Dim; ++d) {
      a[d][i] = force[d] * inv_mass;  // eq. (8)
      a_background[d][i] = transport_velocity_background_acceleration(
          fluid.reference_pressure, p.mass[i], background_sum[d]);  // eq. (13)
    }
  }
}

}  // namespace sphles::sim
