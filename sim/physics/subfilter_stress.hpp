// SPDX-License-Identifier: GPL-3.0-or-later
// The explicit sub-filter models' evaluators and passes ((A.18)-(A.23)): the velocity gradient
// (A.20), the divergence form (A.18) and the central form of SMAG-MCG (A.23), each an evaluator
// of the pair loop (sim/pair_loop.hpp); the models themselves are in sim/subfilter.hpp.
#pragma once

#include <array>
#include <cmath>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/subfilter.hpp"

namespace sphles::sim {

/// The velocity gradient J_i = Σ_j (v_j - v_i) ⊗ ∇W_ij V_j (A.20) as an evaluator of the pair
/// loop: output a·Dim + b is J_ab.
template <int Dim, class KernelT>
struct VelocityGradientSum {
  static constexpr int outputs = Dim * Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    double v[Dim];
  };

  VelocityGradientSum(const KernelT& kernel, const VelocityView& velocity, const ParticleArrays& p,
                      std::vector<VelocityGradient>& gradient)
      : kernel_(kernel), volume_(p.volume.data()), gradient_(gradient.data()) {
    for (int d = 0; d < Dim; ++d) v_[d] = velocity.v[d];
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) o.v[d] = v_[d][i];
    return o;
  }
  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    const double scale = kernel_.gradient_over_r(q.r) * volume_[q.j];
    for (int a = 0; a < Dim; ++a) {
      const double dv = v_[a][q.j] - o.v[a];
      for (int b = 0; b < Dim; ++b) out[a * Dim + b] = dv * scale * q.dx[b];  // (A.20)
    }
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    VelocityGradient j{};
    for (int a = 0; a < Dim; ++a)
      for (int b = 0; b < Dim; ++b) j[a][b] = sum[a * Dim + b];
    gradient_[i] = j;
  }

 private:
  KernelT kernel_;
  const double* v_[Dim];
  const double* volume_;
  VelocityGradient* gradient_;
};

/// J_i = Σ_j (v_j - v_i) ⊗ ∇W_ij V_j (A.20) for every particle; needs volumes (density_pass).
/// `pairs`: a Verlet list, or the InteractionList of the density pass at these positions.
template <int Dim, class KernelT, class List>
void velocity_gradient_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                            const VelocityView& velocity, const ParticleArrays& p,
                            std::vector<VelocityGradient>& gradient) {
  gradient.resize(p.size());
  pair_pass<Dim>(VelocityGradientSum<Dim, KernelT>(kernel, velocity, p, gradient),
                 PeriodicGeometry<Dim>(box, p), pairs, kernel.support_radius(), 0,
                 pairs.num_particles());
}

/// F^sfs/ρ_i of (A.18), F^sfs_i = -Σ_j (τ_i + τ_j) ∇W_ij V_j, as an evaluator of the pair loop
/// (finish adds it to the acceleration); τ_i (A.19) per particle, row-major Dim × Dim.
template <int Dim, class KernelT>
struct SubfilterDivergence {
  static constexpr int outputs = Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    std::size_t i;
  };

  SubfilterDivergence(const KernelT& kernel, const std::vector<double>& tau, ParticleArrays& p)
      : kernel_(kernel), tau_(tau.data()), volume_(p.volume.data()), density_(p.density.data()) {
    for (int d = 0; d < Dim; ++d) a_[d] = p.acceleration[d].data();
  }

  Own own(std::size_t i) const { return {i}; }
  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    const double scale = kernel_.gradient_over_r(q.r) * volume_[q.j];
    const double* tau_i = tau_ + o.i * Dim * Dim;
    const double* tau_j = tau_ + std::size_t{q.j} * Dim * Dim;
    for (int a = 0; a < Dim; ++a) {
      double sum = 0.0;
      for (int b = 0; b < Dim; ++b) sum += (tau_i[a * Dim + b] + tau_j[a * Dim + b]) * q.dx[b];
      out[a] = -sum * scale;  // (A.18)
    }
  }
  void finish(std::size_t i, const Own&, const double (&force)[outputs]) const {
    for (int a = 0; a < Dim; ++a) a_[a][i] += force[a] / density_[i];
  }

 private:
  KernelT kernel_;
  const double* tau_;
  const double* volume_;
  const double* density_;
  double* a_[Dim];
};

/// Adds F^sfs/ρ_i of (A.18), F^sfs_i = -Σ_j (τ_i + τ_j) ∇W_ij V_j, to the acceleration, with
/// τ_i = -2 ν_t,i ρ_i D_i (A.19). `pairs` as for velocity_gradient_pass.
template <int Dim, class KernelT, class List>
void subfilter_divergence_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                               const std::vector<VelocityGradient>& gradient,
                               const std::vector<double>& eddy_viscosity, ParticleArrays& p) {
  const std::size_t count = p.size();
  // τ_i (A.19), symmetric.
  std::vector<double> tau(count * Dim * Dim);
  for (std::size_t i = 0; i < count; ++i)
    for (int a = 0; a < Dim; ++a)
      for (int b = 0; b < Dim; ++b)
        tau[(i * Dim + a) * Dim + b] =
            -eddy_viscosity[i] * p.density[i] * (gradient[i][a][b] + gradient[i][b][a]);
  pair_pass<Dim>(SubfilterDivergence<Dim, KernelT>(kernel, tau, p), PeriodicGeometry<Dim>(box, p),
                 pairs, kernel.support_radius(), 0, pairs.num_particles());
}

/// F^sfs/ρ_i of (A.23) (SMAG-MCG) as an evaluator of the pair loop (finish adds it to the
/// acceleration): 2(n+2) Σ_j [ρ_i ρ_j (ν_t,i + ν_t,j)/(ρ_i + ρ_j)] [(v_ij·x_ij)/|x_ij|²] ∇W_ij V_j.
template <int Dim, class KernelT>
struct SubfilterMcg {
  static constexpr int outputs = Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    double v[Dim];
    double density;
    double nu_t;
  };

  SubfilterMcg(const KernelT& kernel, const VelocityView& velocity,
               const std::vector<double>& eddy_viscosity, ParticleArrays& p)
      : kernel_(kernel),
        nu_t_(eddy_viscosity.data()),
        volume_(p.volume.data()),
        density_(p.density.data()) {
    for (int d = 0; d < Dim; ++d) {
      v_[d] = velocity.v[d];
      a_[d] = p.acceleration[d].data();
    }
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) o.v[d] = v_[d][i];
    o.density = density_[i];
    o.nu_t = nu_t_[i];
    return o;
  }
  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    const std::uint32_t j = q.j;
    double v_dot_x = 0.0;
    for (int d = 0; d < Dim; ++d) v_dot_x += (o.v[d] - v_[d][j]) * q.dx[d];
    const double rho_j = density_[j];
    const double mu_pair = o.density * rho_j * (o.nu_t + nu_t_[j]) / (o.density + rho_j);  // (A.23)
    const double scale =
        kFactor * mu_pair * v_dot_x / q.r2 * volume_[j] * kernel_.gradient_over_r(q.r);
    for (int d = 0; d < Dim; ++d) out[d] = scale * q.dx[d];
  }
  void finish(std::size_t i, const Own& o, const double (&force)[outputs]) const {
    for (int d = 0; d < Dim; ++d) a_[d][i] += force[d] / o.density;
  }

 private:
  static constexpr double kFactor = 2.0 * (Dim + 2);  // 2(n+2) of (A.23)
  KernelT kernel_;
  const double* v_[Dim];
  double* a_[Dim];
  const double* nu_t_;
  const double* volume_;
  const double* density_;
};

/// Adds F^sfs/ρ_i of (A.23) (SMAG-MCG, central pair forces, conserves angular momentum):
/// F^sfs_i = 2(n+2) Σ_j [ρ_i ρ_j (ν_t,i + ν_t,j)/(ρ_i + ρ_j)] [(v_ij·x_ij)/|x_ij|²] ∇W_ij V_j.
/// `pairs` as for velocity_gradient_pass.
template <int Dim, class KernelT, class List>
void subfilter_mcg_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                        const VelocityView& velocity, const std::vector<double>& eddy_viscosity,
                        ParticleArrays& p) {
  pair_pass<Dim>(SubfilterMcg<Dim, KernelT>(kernel, velocity, eddy_viscosity, p),
                 PeriodicGeometry<Dim>(box, p), pairs, kernel.support_radius(), 0,
                 pairs.num_particles());
}

}  // namespace sphles::sim
