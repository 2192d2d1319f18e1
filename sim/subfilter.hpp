// Explicit sub-filter models of SPEC §4 (appendix A.1.4): SMAG, SIGMA and SMAG-MCG.
//
// Pointwise formulas (eddy viscosity from a velocity gradient) are small free functions; the
// gradient pass (A.20) and the two force forms (A.18) and (A.23) are neighbour passes in gather
// form, so results do not depend on the thread count. The implicit model (no explicit term) runs
// none of this.
#pragma once

#include <array>
#include <cmath>
#include <string_view>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics.hpp"

namespace sphles::sim {

enum class SubfilterModel { Implicit, Smagorinsky, Sigma, SmagorinskyMcg };

/// Scene names: "implicit", "smag", "sigma", "smag_mcg".
std::string_view subfilter_model_name(SubfilterModel model);
SubfilterModel subfilter_model_from_name(std::string_view name);  // throws invalid_argument

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

/// Eddy viscosity of the configured model (0 for the implicit model).
double eddy_viscosity(const SubfilterConfig& config, double kernel_diameter,
                      const VelocityGradient& gradient);

/// J_i = Σ_j (v_j - v_i) ⊗ ∇W_ij V_j (A.20) for every particle; needs volumes (density_pass).
template <int Dim, class KernelT>
void velocity_gradient_pass(const KernelT& kernel, const PeriodicBox& box,
                            const NeighbourList& neighbours, const VelocityView& velocity,
                            const ParticleArrays& p, std::vector<VelocityGradient>& gradient) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  gradient.resize(p.size());
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    VelocityGradient j_sum{};
    for_each_pair_in_support<Dim>(
        support2, box, neighbours, p, i, [&](std::uint32_t j, const double* dx, double r2) {
          const double scale = kernel.gradient_over_r(std::sqrt(r2)) * p.volume[j];
          for (int a = 0; a < Dim; ++a) {
            const double dv = velocity.v[a][j] - velocity.v[a][i];
            for (int b = 0; b < Dim; ++b) j_sum[a][b] += dv * scale * dx[b];  // (A.20)
          }
        });
    gradient[i] = j_sum;
  }
}

/// Adds F^sfs/ρ_i of (A.18), F^sfs_i = -Σ_j (τ_i + τ_j) ∇W_ij V_j, to the acceleration, with
/// τ_i = -2 ν_t,i ρ_i D_i (A.19).
template <int Dim, class KernelT>
void subfilter_divergence_pass(const KernelT& kernel, const PeriodicBox& box,
                               const NeighbourList& neighbours,
                               const std::vector<VelocityGradient>& gradient,
                               const std::vector<double>& eddy_viscosity, ParticleArrays& p) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const std::size_t count = p.size();
  // τ_i (A.19), symmetric.
  std::vector<std::array<std::array<double, Dim>, Dim>> tau(count);
  for (std::size_t i = 0; i < count; ++i)
    for (int a = 0; a < Dim; ++a)
      for (int b = 0; b < Dim; ++b)
        tau[i][a][b] = -eddy_viscosity[i] * p.density[i] * (gradient[i][a][b] + gradient[i][b][a]);
  const auto n = static_cast<std::ptrdiff_t>(count);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double force[Dim] = {};
    for_each_pair_in_support<Dim>(
        support2, box, neighbours, p, i, [&](std::uint32_t j, const double* dx, double r2) {
          const double scale = kernel.gradient_over_r(std::sqrt(r2)) * p.volume[j];
          for (int a = 0; a < Dim; ++a) {
            double sum = 0.0;
            for (int b = 0; b < Dim; ++b) sum += (tau[i][a][b] + tau[j][a][b]) * dx[b];
            force[a] -= sum * scale;  // (A.18)
          }
        });
    for (int a = 0; a < Dim; ++a) p.acceleration[a][i] += force[a] / p.density[i];
  }
}

/// Adds F^sfs/ρ_i of (A.23) (SMAG-MCG, central pair forces, conserves angular momentum):
/// F^sfs_i = 2(n+2) Σ_j [ρ_i ρ_j (ν_t,i + ν_t,j)/(ρ_i + ρ_j)] [(v_ij·x_ij)/|x_ij|²] ∇W_ij V_j.
template <int Dim, class KernelT>
void subfilter_mcg_pass(const KernelT& kernel, const PeriodicBox& box,
                        const NeighbourList& neighbours, const VelocityView& velocity,
                        const std::vector<double>& eddy_viscosity, ParticleArrays& p) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const double factor = 2.0 * (Dim + 2);
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double force[Dim] = {};
    const double rho_i = p.density[i];
    for_each_pair_in_support<Dim>(
        support2, box, neighbours, p, i, [&](std::uint32_t j, const double* dx, double r2) {
          double v_dot_x = 0.0;
          for (int d = 0; d < Dim; ++d) v_dot_x += (velocity.v[d][i] - velocity.v[d][j]) * dx[d];
          const double rho_j = p.density[j];
          const double mu_pair =
              rho_i * rho_j * (eddy_viscosity[i] + eddy_viscosity[j]) / (rho_i + rho_j);  // (A.23)
          const double scale =
              factor * mu_pair * v_dot_x / r2 * p.volume[j] * kernel.gradient_over_r(std::sqrt(r2));
          for (int d = 0; d < Dim; ++d) force[d] += scale * dx[d];
        });
    for (int d = 0; d < Dim; ++d) p.acceleration[d][i] += force[d] / rho_i;
  }
}

}  // namespace sphles::sim
