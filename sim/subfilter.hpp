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
#include "sim/physics/thesis_passes.hpp"

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

/// A model's own constant: its key in the scene's "subfilter" object and where SubfilterConfig
/// keeps it. The scene reads and writes every registered model's constants from these.
struct SubfilterConstant {
  std::string_view key;
  double SubfilterConfig::*value;
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

/// The models, one struct each: its enum value, scene name, force form, its own constants and
/// eddy viscosity ν_t from the velocity gradient and the filter width Δ.
namespace subfilter_model {

struct Implicit {
  static constexpr SubfilterModel type = SubfilterModel::Implicit;
  static constexpr std::string_view name = "implicit";
  static constexpr SubfilterForce force = SubfilterForce::None;
  static constexpr std::array<SubfilterConstant, 0> constants{};
  static double eddy_viscosity(const SubfilterConfig&, double, const VelocityGradient&) {
    return 0.0;
  }
};

struct Smagorinsky {
  static constexpr SubfilterModel type = SubfilterModel::Smagorinsky;
  static constexpr std::string_view name = "smag";
  static constexpr SubfilterForce force = SubfilterForce::Divergence;
  static constexpr std::array<SubfilterConstant, 1> constants{
      {{"smagorinsky_constant", &SubfilterConfig::smagorinsky_constant}}};
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
  static constexpr std::array<SubfilterConstant, 1> constants{
      {{"sigma_constant", &SubfilterConfig::sigma_constant}}};
  static double eddy_viscosity(const SubfilterConfig& c, double width,
                               const VelocityGradient& gradient) {
    const double c_delta = c.sigma_constant * width;
    return sigma_viscosity(gradient, c_delta * c_delta);  // (A.22)
  }
};

/// SMAG's eddy viscosity with the central pair force of (A.23), and SMAG's C_S.
struct SmagorinskyMcg {
  static constexpr SubfilterModel type = SubfilterModel::SmagorinskyMcg;
  static constexpr std::string_view name = "smag_mcg";
  static constexpr SubfilterForce force = SubfilterForce::Central;
  static constexpr std::array<SubfilterConstant, 0> constants{};
  static double eddy_viscosity(const SubfilterConfig& c, double width,
                               const VelocityGradient& gradient) {
    return Smagorinsky::eddy_viscosity(c, width, gradient);
  }
};

}  // namespace subfilter_model

template <class... Models>
struct SubfilterModelList {};

/// The registry: every sub-filter model a scene may name. Adding a model is its struct above,
/// its enum value, its constants in SubfilterConfig and one entry here; names, parsing of the
/// name and the constants, ν_t and the solver's force dispatch follow.
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

/// Calls f(constant) for every registered model's own constants, in registry order.
template <class F, class... Models>
void for_each_subfilter_constant(F&& f, SubfilterModelList<Models...>) {
  (..., [&] {
    for (const SubfilterConstant& constant : Models::constants) f(constant);
  }());
}
template <class F>
void for_each_subfilter_constant(F&& f) {
  for_each_subfilter_constant(std::forward<F>(f), SubfilterRegistry{});
}

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

}  // namespace sphles::sim
