// SPDX-License-Identifier: GPL-3.0-or-later
// Explicit sub-filter models of SPEC §4 (appendix A.1.4): SMAG, SIGMA and SMAG-MCG.
//
// Pointwise formulas (eddy viscosity from a velocity gradient) are small free functions; the
// gradient pass (A.20) and the two force forms (A.18) and (A.23) are evaluators of the pair loop
// (sim/pair_loop.hpp), in gather form, so results do not depend on the thread count. The implicit
// model (no explicit term) runs none of this.
#pragma once

#include <array>
#include <cmath>
#include <stdexcept>
#include <string_view>
#include <utility>
#include <vector>

#include "sim/name_table.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics.hpp"

namespace sphles::sim {

enum class SubfilterModel { Implicit, Smagorinsky, Sigma, SmagorinskyMcg };

/// Scene names and parsing come from SubfilterRegistry below ("implicit", "smag", "sigma",
/// "smag_mcg").
std::string_view subfilter_model_name(SubfilterModel model);

struct SubfilterConfig {
  SubfilterModel model = SubfilterModel::Implicit;
  double smagorinsky_constant = 0.15;  // C_S (A.21)
  double sigma_constant = 1.35;        // C_σ (A.22)
  double filter_width = 0.0;           // Δ [m]; 0 means D_K
};

/// 3x3 velocity gradient J_ab = ∂v_a/∂x_b (2D uses the upper-left 2x2 block, rest zero).
using VelocityGradient = std::array<std::array<double, 3>, 3>;

/// SMAG (A.21): ν_t = (C_S Δ)² sqrt(2 D:D), D = (J + Jᵀ)/2. `scale` is (C_S Δ)².
double smagorinsky_viscosity(const VelocityGradient& gradient, double scale);

/// SIGMA (A.22, Nicoud et al. 2011): σ1 ≥ σ2 ≥ σ3 singular values of J,
/// ν_t = (C_σ Δ)² σ3 (σ1 - σ2)(σ2 - σ3) / σ1². `scale` is (C_σ Δ)². Zero for solid rotation,
/// pure shear and any two-dimensional gradient (σ3 = 0).
double sigma_viscosity(const VelocityGradient& gradient, double scale);

/// How an explicit model's stress enters the momentum equation.
enum class SubfilterForce {
  None,        // the implicit model: no explicit term
  Divergence,  // (A.18): -Σ_j (τ_i + τ_j) ∇W_ij V_j with τ = -2 ν_t ρ D (A.19)
  Central,     // (A.23): central pair forces (SMAG-MCG), angular momentum conserved
};

/// The models, one struct each: its enum value, scene name, force form and eddy viscosity ν_t
/// from the velocity gradient and the filter width Δ.
namespace subfilter_model {

struct Implicit {
  static constexpr SubfilterModel type = SubfilterModel::Implicit;
  static constexpr std::string_view name = "implicit";
  static constexpr SubfilterForce force = SubfilterForce::None;
  static double eddy_viscosity(const SubfilterConfig&, double, const VelocityGradient&) {
    return 0.0;
  }
};

struct Smagorinsky {
  static constexpr SubfilterModel type = SubfilterModel::Smagorinsky;
  static constexpr std::string_view name = "smag";
  static constexpr SubfilterForce force = SubfilterForce::Divergence;
  static double eddy_viscosity(const SubfilterConfig& c, double width,
                               const VelocityGradient& gradient) {
    const double cs_delta = c.smagorinsky_constant * width;
    return smagorinsky_viscosity(gradient, cs_delta * cs_delta);  // (A.21)
  }
};

struct Sigma {
  static constexpr SubfilterModel type = SubfilterModel::Sigma;
  static constexpr std::string_view name = "sigma";
  static constexpr SubfilterForce force = SubfilterForce::Divergence;
  static double eddy_viscosity(const SubfilterConfig& c, double width,
                               const VelocityGradient& gradient) {
    const double c_delta = c.sigma_constant * width;
    return sigma_viscosity(gradient, c_delta * c_delta);  // (A.22)
  }
};

/// SMAG's eddy viscosity with the central pair force of (A.23).
struct SmagorinskyMcg {
  static constexpr SubfilterModel type = SubfilterModel::SmagorinskyMcg;
  static constexpr std::string_view name = "smag_mcg";
  static constexpr SubfilterForce force = SubfilterForce::Central;
  static double eddy_viscosity(const SubfilterConfig& c, double width,
                               const VelocityGradient& gradient) {
    return Smagorinsky::eddy_viscosity(c, width, gradient);
  }
};

}  // namespace subfilter_model

template <class... Models>
struct SubfilterModelList {};

/// The registry: every sub-filter model a scene may name. Adding a model is its struct above,
/// its enum value and one entry here; names, parsing, ν_t and the solver's force dispatch follow.
using SubfilterRegistry =
    SubfilterModelList<subfilter_model::Implicit, subfilter_model::Smagorinsky,
                       subfilter_model::Sigma, subfilter_model::SmagorinskyMcg>;

/// The registered models' types, in registry order (typed tests and listings iterate these).
template <class... Models>
constexpr std::array<SubfilterModel, sizeof...(Models)> subfilter_model_types(
    SubfilterModelList<Models...>) {
  return {Models::type...};
}
inline constexpr auto kSubfilterModels = subfilter_model_types(SubfilterRegistry{});
/// The models' scene names, from the registry.
inline constexpr auto kSubfilterModelNames = registry_names<SubfilterModel>(SubfilterRegistry{});

/// Calls f(Model{}) with the registered model of the given type.
template <class F, class First, class... Rest>
decltype(auto) visit_subfilter_model(SubfilterModel type, F&& f,
                                     SubfilterModelList<First, Rest...>) {
  if (First::type == type) return f(First{});
  if constexpr (sizeof...(Rest) > 0) {
    return visit_subfilter_model(type, std::forward<F>(f), SubfilterModelList<Rest...>{});
  } else {
    throw std::invalid_argument("unregistered sub-filter model");
  }
}
template <class F>
decltype(auto) visit_subfilter_model(SubfilterModel type, F&& f) {
  return visit_subfilter_model(type, std::forward<F>(f), SubfilterRegistry{});
}

/// Eddy viscosity of the configured model (0 for the implicit model); the filter width Δ is
/// config.filter_width, or the kernel diameter when that is 0.
double eddy_viscosity(const SubfilterConfig& config, double kernel_diameter,
                      const VelocityGradient& gradient);

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
