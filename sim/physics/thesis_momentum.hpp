// SPDX-License-Identifier: GPL-3.0-or-later
// The thesis model's momentum equation as an evaluator of the pair loop (sim/pair_loop.hpp).
#pragma once

#include <cmath>
#include <cstddef>

#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/fluid.hpp"
#include "sim/physics/viscous_operator.hpp"

namespace sphles::sim {

/// a_i = (F^p_i + F^visc_i) / ρ_i of (3.25): the pressure term (A.9), -(p_i + p_j) ∇W_ij V_j,
/// and the viscous term (A.14), 2(n+2) η (v_ij·x_ij)/|x_ij|² ∇W_ij V_j, at the given velocities.
/// With Corrected, each viscous pair is weighted by pair_weight of the particles' directional
/// coefficients g_i (viscous_operator.hpp, ViscousOperator::Corrected). Every pair term of
/// V_i F_ij is antisymmetric in i and j, so Σ M a = 0 to round-off.
template <int Dim, class KernelT, bool Corrected>
struct ThesisMomentum {
  static constexpr int outputs = Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    double v[Dim];
    double p;
    const double* g;  // g_i (Corrected)
  };

  ThesisMomentum(const KernelT& kernel, const FluidParameters& fluid, const VelocityView& velocity,
                 ParticleArrays& p, const double* viscous_weights)
      : kernel_(kernel),
        viscous_factor_(2.0 * (Dim + 2) * fluid.dynamic_viscosity),  // 2(n+2)η (A.14)
        pressure_(p.pressure.data()),
        volume_(p.volume.data()),
        density_(p.density.data()),
        weights_(viscous_weights) {
    for (int d = 0; d < Dim; ++d) {
      v_[d] = velocity.v[d];
      a_[d] = p.acceleration[d].data();
    }
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) o.v[d] = v_[d][i];
    o.p = pressure_[i];
    o.g = Corrected ? weights_ + i * QuarticBasis<Dim>::size : nullptr;
    return o;
  }

  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    double v_dot_x = 0.0;
    for (int d = 0; d < Dim; ++d) v_dot_x += (o.v[d] - v_[d][q.j]) * q.dx[d];
    double viscous = viscous_pair_coefficient(viscous_factor_, v_dot_x, q.r2);
    if constexpr (Corrected) {
      const double inv_r = 1.0 / q.r;
      double e[Dim];
      for (int d = 0; d < Dim; ++d) e[d] = q.dx[d] * inv_r;
      viscous *= pair_weight<Dim>(o.g, weights_ + std::size_t{q.j} * QuarticBasis<Dim>::size,
                                  QuarticBasis<Dim>::monomials(e));
    }
    const double coefficient = pressure_pair_coefficient(o.p, pressure_[q.j]) + viscous;
    const double scale = coefficient * volume_[q.j] * kernel_.gradient_over_r(q.r);
    for (int d = 0; d < Dim; ++d) out[d] = scale * q.dx[d];  // ∇W_ij = (1/r)(dW/dr) x_ij
  }

  void finish(std::size_t i, const Own&, const double (&force)[outputs]) const {
    const double inv_density = 1.0 / density_[i];
    for (int d = 0; d < Dim; ++d) a_[d][i] = force[d] * inv_density;
  }

 private:
  KernelT kernel_;
  double viscous_factor_;
  const double* v_[Dim];
  double* a_[Dim];
  const double* pressure_;
  const double* volume_;
  const double* density_;
  const double* weights_;
};

}  // namespace sphles::sim
