// SPDX-License-Identifier: GPL-3.0-or-later
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
// The pass is an evaluator of the pair loop (sim/pair_loop.hpp), in gather form, so results do
// not depend on the thread count.
// Every pair term of M_i a_i is antisymmetric in i and j (the weights V_i² + V_j², p̃_ij and
// A_i + A_j are symmetric, ∇W_ij and v_ij antisymmetric), so Σ M a = 0 to round-off.
// A holds v itself, so eq. (8) is not Galilean invariant: a uniform U adds U ∇·(ρ δv). With
// scheme.ale_correction = full the extra stress is the full ALE term of Sun et al. 2019,
// ∇·(ρ v ⊗ δv) - v ∇·(ρ δv) = ρ δv·∇v (ale_correction.hpp): Galilean invariant, but no longer
// antisymmetric, so Σ M v drifts.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/ale_correction.hpp"
#include "sim/physics/thesis_passes.hpp"

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
/// δv = ṽ - v (Conservative; symmetric in i and j), or half the full ALE term
/// ½ ρ_j (v_j,a - v_i,a)(δv_j·∇W_ij) (Full). `shift_dot_gradient_*` are δv · ∇W_ij.
template <AleCorrection Ale = AleCorrection::Conservative>
inline double transport_velocity_stress_term(double density_i, double velocity_i,
                                             double shift_dot_gradient_i, double density_j,
                                             double velocity_j, double shift_dot_gradient_j) {
  return 0.5 * ale_term<Ale>(density_i, velocity_i, shift_dot_gradient_i, density_j, velocity_j,
                             shift_dot_gradient_j);
}

/// Acceleration of the background pressure, eq. (13): ã_i = -(p_b / M_i) Σ_j (V_i² + V_j²)
/// ∇W_ij, from the pair sum S_i = Σ_j (V_i² + V_j²) ∇W_ij.
inline double transport_velocity_background_acceleration(double background_pressure, double mass,
                                                         double pair_sum) {
  return -background_pressure / mass * pair_sum;
}

/// The TVF's pair terms as an evaluator of the pair loop (sim/pair_loop.hpp): outputs 0..Dim-1
/// are Σ_j (V_i² + V_j²) [-p̃_ij ∇W_ij + ½ (A_i + A_j)·∇W_ij + η̃_ij (1/r)(∂W/∂r) v_ij] (eq. 8),
/// outputs Dim..2Dim-1 the pair sum S_i = Σ_j (V_i² + V_j²) ∇W_ij of eq. (13). `Ale` chooses the
/// extra stress (transport_velocity_stress_term).
template <int Dim, class KernelT, AleCorrection Ale = AleCorrection::Conservative>
struct TransportVelocityMomentum {
  static constexpr int outputs = 2 * Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    double v[Dim];
    double dv[Dim];
    double density;
    double pressure;
    double volume;
  };

  TransportVelocityMomentum(const KernelT& kernel, const FluidParameters& fluid,
                            const VelocityView& velocity, const VelocityView& shift,
                            std::array<std::vector<double>, 3>& background, ParticleArrays& p)
      : kernel_(kernel),
        fluid_(fluid),
        eta_(transport_velocity_averaged_viscosity(fluid.dynamic_viscosity,
                                                   fluid.dynamic_viscosity)),  // eq. (6)
        volume_(p.volume.data()),
        density_(p.density.data()),
        mass_(p.mass.data()) {
    for (int d = 0; d < Dim; ++d) {
      v_[d] = velocity.v[d];
      dv_[d] = shift.v[d];
      a_[d] = p.acceleration[d].data();
      a_background_[d] = background[d].data();
    }
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) {
      o.v[d] = v_[d][i];
      o.dv[d] = dv_[d][i];
    }
    o.density = density_[i];
    o.pressure = transport_velocity_momentum_pressure(o.density, fluid_);
    o.volume = volume_[i];
    return o;
  }

  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    const std::uint32_t j = q.j;
    const double g = kernel_.gradient_over_r(q.r);  // ∇W_ij = g x_ij
    const double rho_j = density_[j];
    const double weight = transport_velocity_pair_weight(o.volume, volume_[j]);
    const double pressure = transport_velocity_pressure_coefficient(
        weight,
        transport_velocity_averaged_pressure(o.density, rho_j, o.pressure,
                                             transport_velocity_momentum_pressure(rho_j, fluid_)));
    const double viscous = transport_velocity_viscous_coefficient(weight, eta_, g);
    double shift_i = 0.0, shift_j = 0.0;  // δv · ∇W_ij
    for (int d = 0; d < Dim; ++d) {
      shift_i += o.dv[d] * g * q.dx[d];
      shift_j += dv_[d][j] * g * q.dx[d];
    }
    for (int d = 0; d < Dim; ++d) {
      const double gradient = g * q.dx[d];
      const double stress =
          transport_velocity_stress_term<Ale>(o.density, o.v[d], shift_i, rho_j, v_[d][j], shift_j);
      out[d] = pressure * gradient + weight * stress + viscous * (o.v[d] - v_[d][j]);
      out[Dim + d] = weight * gradient;
    }
  }

  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    const double inv_mass = 1.0 / mass_[i];
    for (int d = 0; d < Dim; ++d) {
      a_[d][i] = sum[d] * inv_mass;  // eq. (8)
      a_background_[d][i] = transport_velocity_background_acceleration(
          fluid_.reference_pressure, mass_[i], sum[Dim + d]);  // eq. (13)
    }
  }

 private:
  KernelT kernel_;
  FluidParameters fluid_;
  double eta_;
  const double* v_[Dim];
  const double* dv_[Dim];
  double* a_[Dim];
  double* a_background_[Dim];
  const double* volume_;
  const double* density_;
  const double* mass_;
};

/// One TVF force evaluation: the acceleration (1/M_i) Σ_j (V_i² + V_j²) [-p̃_ij ∇W_ij +
/// ½ (A_i + A_j)·∇W_ij + η̃_ij (1/r)(∂W/∂r) v_ij] of eq. (8) (with the extra stress chosen by
/// `ale`) at the given velocities and transport shifts δv = ṽ - v (overwrites p.acceleration),
/// and the background acceleration ã of eq. (13) (overwrites `background`, whose arrays must have
/// p.size() entries for each dimension). Requires density_pass on the same positions; `pairs` is
/// the Verlet list or the InteractionList of that density pass.
template <int Dim, class KernelT, class List>
void transport_velocity_force_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                                   const FluidParameters& fluid, const VelocityView& velocity,
                                   const VelocityView& shift,
                                   std::array<std::vector<double>, 3>& background,
                                   ParticleArrays& p,
                                   AleCorrection ale = AleCorrection::Conservative) {
  const PeriodicGeometry<Dim> geometry(box, p);
  if (ale == AleCorrection::Full)
    pair_pass<Dim>(TransportVelocityMomentum<Dim, KernelT, AleCorrection::Full>(
                       kernel, fluid, velocity, shift, background, p),
                   geometry, pairs, kernel.support_radius(), 0, pairs.num_particles());
  else
    pair_pass<Dim>(TransportVelocityMomentum<Dim, KernelT, AleCorrection::Conservative>(
                       kernel, fluid, velocity, shift, background, p),
                   geometry, pairs, kernel.support_radius(), 0, pairs.num_particles());
}

}  // namespace sphles::sim
