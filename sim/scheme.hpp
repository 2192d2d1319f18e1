// Interchangeable SPH schemes: the discretisation of the momentum equation and of the particle
// motion (scene key "scheme", docs/scenes.md; docs/models.md).
//
// A scheme is one struct with
//   static constexpr SchemeType type;          its enum value
//   static constexpr std::string_view name;    its scene name
//   static constexpr bool transport_velocity;  particles move with v + (dt/2) ã (SchemeFields)
//   template <int Dim, class KernelT> static void evaluate(kernel, box, list, fluid, velocity,
//                                                          fields, particles);
// where evaluate is one force evaluation (density, pressure, accelerations) at the current
// positions and the given velocity. Adding a scheme is its struct, its enum value and one line
// in SchemeRegistry below; the solver dispatches once per force evaluation (visit_scheme).
#pragma once

#include <array>
#include <stdexcept>
#include <string_view>
#include <utility>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics.hpp"
#include "sim/transport_velocity.hpp"

namespace sphles::sim {

enum class SchemeType { Thesis, TransportVelocity };

/// The scene's "scheme" object.
struct SchemeConfig {
  SchemeType type = SchemeType::Thesis;
  /// The thesis scheme's viscous term: (A.14), or its moment-corrected form
  /// (viscous_operator.hpp). The transport-velocity scheme has its own.
  ViscousOperator viscous_operator = ViscousOperator::Thesis;
};

/// Per-particle fields a scheme carries between force evaluations, in the particles' order.
/// Empty for a scheme without transport velocity. They are functions of the positions (and
/// the step size), so a restart recomputes them instead of storing them.
struct SchemeFields {
  /// ã_i of the last force evaluation (TVF: the background-pressure acceleration, eq. 13).
  std::array<std::vector<double>, 3> background_acceleration;
  /// δv_i = ṽ_i - v_i = (dt/2) ã^n_i of the step being taken, read by the force evaluation.
  std::array<std::vector<double>, 3> transport_shift;
  /// The thesis scheme with ViscousOperator::Corrected: the operator, and its g_i of the
  /// current evaluation (viscous_correction_pass), a function of the positions.
  ViscousOperator viscous_operator = ViscousOperator::Thesis;
  std::vector<double> viscous_weights;
};

inline VelocityView view_of(const std::array<std::vector<double>, 3>& arrays, int dimension) {
  VelocityView view;
  for (int d = 0; d < dimension; ++d) view.v[d] = arrays[d].data();
  return view;
}

/// The thesis model of SPEC §2: pressure (A.9) with p_i + p_j and the viscous term (A.14)
/// (or its corrected form, SchemeFields::viscous_operator); particles move with v.
struct ThesisScheme {
  static constexpr SchemeType type = SchemeType::Thesis;
  static constexpr std::string_view name = "thesis";
  static constexpr bool transport_velocity = false;

  template <int Dim, class KernelT>
  static void evaluate(const KernelT& kernel, const PeriodicBox& box,
                       const NeighbourList& neighbours, const FluidParameters& fluid,
                       const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p) {
    density_pass<Dim>(kernel, box, neighbours, fluid, p);
    const double* weights = nullptr;
    if (fields.viscous_operator == ViscousOperator::Corrected) {
      viscous_correction_pass<Dim>(kernel, box, neighbours, p, fields.viscous_weights);
      weights = fields.viscous_weights.data();
    }
    force_pass<Dim>(kernel, box, neighbours, fluid, velocity, p, weights);
  }
};

/// The transport-velocity formulation of Adami, Hu & Adams 2013 (transport_velocity.hpp).
struct TransportVelocityScheme {
  static constexpr SchemeType type = SchemeType::TransportVelocity;
  static constexpr std::string_view name = "transport_velocity";
  static constexpr bool transport_velocity = true;

  template <int Dim, class KernelT>
  static void evaluate(const KernelT& kernel, const PeriodicBox& box,
                       const NeighbourList& neighbours, const FluidParameters& fluid,
                       const VelocityView& velocity, SchemeFields& fields, ParticleArrays& p) {
    density_pass<Dim>(kernel, box, neighbours, fluid, p);
    transport_velocity_force_pass<Dim>(kernel, box, neighbours, fluid, velocity,
                                       view_of(fields.transport_shift, Dim),
                                       fields.background_acceleration, p);
  }
};

template <class... Schemes>
struct SchemeList {};

/// The registry: every scheme the scene may name, the default first.
using SchemeRegistry = SchemeList<ThesisScheme, TransportVelocityScheme>;

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

/// Scene names: "thesis", "transport_velocity".
std::string_view scheme_name(SchemeType type);
SchemeType scheme_from_name(std::string_view name);  // throws invalid_argument listing the names
bool scheme_uses_transport_velocity(SchemeType type);

}  // namespace sphles::sim
