// SPDX-License-Identifier: GPL-3.0-or-later
// Interchangeable SPH schemes: the discretisation of the momentum equation and of the particle
// motion (scene key "scheme", docs/scenes.md; docs/models.md).
//
// A scheme is one struct with
//   static constexpr SchemeType type;          its enum value
//   static constexpr std::string_view name;    its scene name
//   static constexpr bool transport_velocity;  particles move with v + δv (SchemeFields)
//   static double drift_shift(double dt, double source);  (transport_velocity only) δv of the
//       step being taken from SchemeFields::drift_source of the last force evaluation
//   template <int Dim, class KernelT> static void evaluate(kernel, box, list, fluid, velocity,
//                                                          fields, particles, exchange);
// where evaluate is one force evaluation (density, pressure, accelerations) at the current
// positions and the given velocity, of the particles `list` lists. Between two passes, where a
// pass reads neighbours' values an earlier pass of the evaluation wrote, it calls
// exchange.refresh on them (the halo of a distributed run, sim/exchange.hpp; the positions,
// velocities and the transport shift the solver refreshes before the evaluation). Adding a scheme
// is its struct, its enum value and one line in SchemeRegistry below; the solver dispatches once
// per force evaluation (visit_scheme). A scheme's parameters are members of SchemeConfig declared
// in kSchemeParameters (the scene reads and checks them from there); the scheme lists the keys it
// takes in `parameters` and reads their values from SchemeFields::scheme.
#pragma once

#include <array>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <utility>
#include <vector>

#include "sim/exchange.hpp"
#include "sim/name_table.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/particle_shifting.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/physics/transport_velocity.hpp"

namespace sphles::sim {

enum class SchemeType { Thesis, TransportVelocity, ParticleShifting };

/// The scene's "scheme" object.
struct SchemeConfig {
  SchemeType type = SchemeType::Thesis;
  /// The viscous term of the thesis and particle-shifting schemes: (A.14), or its
  /// moment-corrected form (viscous_operator.hpp). The transport-velocity scheme has its own.
  ViscousOperator viscous_operator = ViscousOperator::Thesis;
  /// Particle shifting: Ma of Sun et al. 2019, the reference velocity of the shifting velocity
  /// in units of the sound speed, U = Ma c_s (particle_shifting.hpp). Default: the weakly
  /// compressible c_s = 10 U_max.
  double shifting_mach = 0.1;
  /// Transport velocity and particle shifting: the discrete ALE correction of the momentum
  /// equation (ale_correction.hpp; for the TVF its extra stress).
  AleCorrection ale_correction = AleCorrection::Conservative;
};

/// Scene names of scheme.ale_correction.
inline constexpr NameTable<AleCorrection, 2> kAleCorrectionNames{{{
    {AleCorrection::Conservative, "conservative"},
    {AleCorrection::Full, "full"},
}}};

/// A scheme parameter: its key in the scene's "scheme" object, where SchemeConfig keeps it (for
/// a choice, its names too), and why the schemes that do not take it refuse it (may be empty).
struct SchemeNumber {
  std::string_view key;
  double SchemeConfig::*value;
  std::string_view note = {};
};
template <class Enum, std::size_t N>
struct SchemeChoice {
  std::string_view key;
  Enum SchemeConfig::*value;
  const NameTable<Enum, N>* names;
  std::string_view note = {};
};

/// Every scheme parameter a scene may set: the scene reads, writes and publishes them from here.
/// A scheme lists the keys it takes (its `parameters`); the others refuse a value other than
/// the default.
inline constexpr auto kSchemeParameters =
    std::tuple{SchemeChoice<ViscousOperator, 2>{
                   "viscous_operator", &SchemeConfig::viscous_operator, &kViscousOperatorNames,
                   "the transport-velocity scheme has its own viscous term"},
               SchemeNumber{"shifting_mach", &SchemeConfig::shifting_mach},
               SchemeChoice<AleCorrection, 2>{"ale_correction", &SchemeConfig::ale_correction,
                                              &kAleCorrectionNames}};

/// Per-particle fields a scheme carries between force evaluations, in the particles' order.
/// Empty for a scheme without transport velocity. They are functions of the positions (and
/// the step size), so a restart recomputes them instead of storing them.
struct SchemeFields {
  /// The field of the last force evaluation the drift shift is formed from (Scheme::drift_shift):
  /// TVF ã_i, the background-pressure acceleration (eq. 13); particle shifting δv_i, the
  /// shifting velocity (Sun et al. 2019).
  std::array<std::vector<double>, 3> drift_source;
  /// δv_i = ṽ_i - v_i of the step being taken (TVF (dt/2) ã^n_i, read by its force
  /// evaluation; particle shifting δv^n_i).
  std::array<std::vector<double>, 3> transport_shift;
  /// Particle shifting: Ma c_0 (2h), W(Δx) and the limiter (particle_shifting.hpp); both
  /// transport-velocity schemes: the ALE correction (`ale`).
  ShiftingParameters shifting;
  /// The scene's scheme parameters: an evaluation reads its own from here.
  SchemeConfig scheme;
  /// With ViscousOperator::Corrected: its g_i of the current evaluation
  /// (viscous_correction_pass), a function of the positions.
  std::vector<double> viscous_weights;
  /// The pairs inside the kernel support at the positions of the current evaluation, recorded
  /// by its density pass; every later pass of the evaluation (and the sub-filter model's) loops
  /// over these instead of the Verlet list.
  InteractionList interactions;
};

inline VelocityView view_of(const std::array<std::vector<double>, 3>& arrays, int dimension) {
  VelocityView view;
  for (int d = 0; d < dimension; ++d) view.v[d] = arrays[d].data();
  return view;
}

/// The exchange point after a density pass: V, ρ and p of the neighbours.
inline void refresh_density(const Exchange& exchange, ParticleArrays& p) {
  std::vector<double>* written[] = {&p.volume, &p.density, &p.pressure};
  exchange.refresh(written);
}

/// The thesis model of SPEC §2: pressure (A.9) with p_i + p_j and the viscous term (A.14)
/// (or its corrected form, SchemeFields::viscous_operator); particles move with v.
struct ThesisScheme {
  static constexpr SchemeType type = SchemeType::Thesis;
  static constexpr std::string_view name = "thesis";
  static constexpr bool transport_velocity = false;
  static constexpr std::array<std::string_view, 1> parameters{"viscous_operator"};

  template <int Dim, class KernelT>
  static void evaluate(const KernelT& kernel, const PeriodicBox& box,
                       const NeighbourList& neighbours, const FluidParameters& fluid,
                       const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p,
                       const Exchange& exchange) {
    density_pass<Dim>(kernel, box, neighbours, fluid, p, &fields.interactions);
    refresh_density(exchange, p);
    forces<Dim>(kernel, box, fluid, velocity, fields, p, exchange);
  }

  /// Pressure (A.9) and viscous term (A.14 or its corrected form) after density_pass, over the
  /// pairs it recorded.
  template <int Dim, class KernelT>
  static void forces(const KernelT& kernel, const PeriodicBox& box, const FluidParameters& fluid,
                     const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p,
                     const Exchange& exchange) {
    const double* weights = viscous_weights<Dim>(kernel, box, fields, p, exchange);
    force_pass<Dim>(kernel, box, fields.interactions, fluid, velocity, p, weights);
  }

  /// With ViscousOperator::Corrected, the g_i of the current positions (viscous_correction_pass,
  /// after density_pass; the halo's too); else nullptr.
  template <int Dim, class KernelT>
  static const double* viscous_weights(const KernelT& kernel, const PeriodicBox& box,
                                       SchemeFields& fields, ParticleArrays& p,
                                       const Exchange& exchange) {
    if (fields.scheme.viscous_operator != ViscousOperator::Corrected) return nullptr;
    viscous_correction_pass<Dim>(kernel, box, fields.interactions, p, fields.viscous_weights);
    std::vector<double>* written[] = {&fields.viscous_weights};  // g_j of the force pass
    exchange.refresh(written);
    return fields.viscous_weights.data();
  }
};

/// The transport-velocity formulation of Adami, Hu & Adams 2013 (transport_velocity.hpp).
struct TransportVelocityScheme {
  static constexpr SchemeType type = SchemeType::TransportVelocity;
  static constexpr std::string_view name = "transport_velocity";
  static constexpr bool transport_velocity = true;
  static constexpr std::array<std::string_view, 1> parameters{"ale_correction"};

  /// ṽ - v = (dt/2) ã^n (eqs. 14-16).
  static double drift_shift(double dt, double background_acceleration) {
    return 0.5 * dt * background_acceleration;
  }

  template <int Dim, class KernelT>
  static void evaluate(const KernelT& kernel, const PeriodicBox& box,
                       const NeighbourList& neighbours, const FluidParameters& fluid,
                       const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p,
                       const Exchange& exchange) {
    density_pass<Dim>(kernel, box, neighbours, fluid, p, &fields.interactions);
    refresh_density(exchange, p);
    transport_velocity_force_pass<Dim>(kernel, box, fields.interactions, fluid, velocity,
                                       view_of(fields.transport_shift, Dim), fields.drift_source, p,
                                       fields.shifting.ale);
  }
};

/// Particle shifting with the consistent ALE correction of the δ⁺-SPH model (Sun et al. 2017,
/// 2019; particle_shifting.hpp): the thesis pressure (A.9) and viscous term (A.14, or its
/// corrected form) plus (1/ρ) ∇·(ρ v ⊗ δv); particles move with v + δv, δv the shifting
/// velocity at the positions of the step's start. After the density pass, one pass forms the
/// force, the ALE correction and the shifting velocity of the next step.
struct ParticleShiftingScheme {
  static constexpr SchemeType type = SchemeType::ParticleShifting;
  static constexpr std::string_view name = "particle_shifting";
  static constexpr bool transport_velocity = true;
  static constexpr std::array<std::string_view, 3> parameters{"viscous_operator", "shifting_mach",
                                                              "ale_correction"};

  /// δv^n, computed at the positions x^n (a velocity: independent of dt).
  static double drift_shift(double /*dt*/, double shifting_velocity) { return shifting_velocity; }

  template <int Dim, class KernelT>
  static void evaluate(const KernelT& kernel, const PeriodicBox& box,
                       const NeighbourList& neighbours, const FluidParameters& fluid,
                       const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p,
                       const Exchange& exchange) {
    density_pass<Dim>(kernel, box, neighbours, fluid, p, &fields.interactions);
    refresh_density(exchange, p);
    const double* weights = ThesisScheme::viscous_weights<Dim>(kernel, box, fields, p, exchange);
    // The ALE correction takes the shift the particles drifted with to these positions, δv^n
    // (transport_shift, in the halo too), as the TVF's A term does (numerics.md): the pass then
    // needs no value of a neighbour it computes itself.
    const VelocityView shift = view_of(fields.transport_shift, Dim);
    const auto pass = [&](auto momentum) {
      if (fields.shifting.ale == AleCorrection::Full)
        fused_pass<Dim, AleCorrection::Full>(momentum, kernel, box, velocity, shift, fields, p);
      else
        fused_pass<Dim, AleCorrection::Conservative>(momentum, kernel, box, velocity, shift, fields,
                                                     p);
    };
    if (weights)
      pass(ThesisMomentum<Dim, KernelT, true>(kernel, fluid, velocity, p, weights));
    else
      pass(ThesisMomentum<Dim, KernelT, false>(kernel, fluid, velocity, p, nullptr));
  }

 private:
  template <int Dim, AleCorrection Ale, class Momentum, class KernelT>
  static void fused_pass(const Momentum& momentum, const KernelT& kernel, const PeriodicBox& box,
                         const VelocityView& velocity, const VelocityView& shift,
                         SchemeFields& fields, ParticleArrays& p) {
    const InteractionList& pairs = fields.interactions;
    const Fused<Momentum, ShiftingAle<Dim, Ale, KernelT>, ShiftingVelocity<Dim, KernelT>> fused(
        momentum, ShiftingAle<Dim, Ale, KernelT>(kernel, velocity, shift, p),
        ShiftingVelocity<Dim, KernelT>(kernel, fields.shifting, p, fields.drift_source));
    pair_pass<Dim>(fused, PeriodicGeometry<Dim>(box, p), pairs, kernel.support_radius(), 0,
                   pairs.num_particles());
  }
};

template <class... Schemes>
struct SchemeList {};

/// The registry: every scheme the scene may name, the default first.
using SchemeRegistry = SchemeList<ThesisScheme, TransportVelocityScheme, ParticleShiftingScheme>;

/// The schemes' scene names, from the registry.
inline constexpr auto kSchemeNames = registry_names<SchemeType>(SchemeRegistry{});

/// Calls f(S{}) with the registered scheme S of the given type.
template <class F, class... Schemes>
void visit_scheme(SchemeType type, SchemeList<Schemes...>, F&& f) {
  const bool found = ((Schemes::type == type ? (f(Schemes{}), true) : false) || ...);
  if (!found) throw std::invalid_argument("unregistered scheme type");
}
template <class F>
void visit_scheme(SchemeType type, F&& f) {
  visit_scheme(type, SchemeRegistry{}, std::forward<F>(f));
}

/// Scene names: "thesis", "transport_velocity", "particle_shifting".
std::string_view scheme_name(SchemeType type);
bool scheme_uses_transport_velocity(SchemeType type);
/// Whether the scheme of `type` takes the parameter `key` (its `parameters`).
bool scheme_takes(SchemeType type, std::string_view key);
/// The registered schemes that take the parameter `key`, as "thesis and particle_shifting".
std::string schemes_taking(std::string_view key);

/// Scene names of scheme.ale_correction: "conservative", "full".
std::string_view ale_correction_name(AleCorrection ale);

}  // namespace sphles::sim
