// The discrete SPH-LES model of SPEC §2 as pair formulas and two neighbour passes.
//
// Pair formulas are small free functions; the passes loop over a neighbour list in gather form
// (each particle sums over its own neighbours in list order), which makes the result independent
// of the thread count. Pair terms V_i F_ij are antisymmetric in i and j (∇W_ji = -∇W_ij exactly,
// coefficients symmetric), so linear momentum is conserved to round-off.
#pragma once

#include <cmath>
#include <cstddef>
#include <string_view>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/viscous_operator.hpp"

namespace sphles::sim {

/// Calls visit(j, dx, r2) for every neighbour j of particle i with 0 < |x_ij|² < support², in
/// list order (dx = x_i - x_j under the minimum image). The pair loop of the sub-filter and
/// particle-shifting passes.
template <int Dim, class Visit>
inline void for_each_pair_in_support(double support2, const PeriodicBox& box,
                                     const NeighbourList& neighbours, const ParticleArrays& p,
                                     std::size_t i, Visit&& visit) {
  for (const std::uint32_t j : neighbours.of(i)) {
    double dx[Dim];
    double r2 = 0.0;
    for (int d = 0; d < Dim; ++d) {
      dx[d] =
          minimum_image(p.position[d][i] - p.position[d][j], box.length[d], 0.5 * box.length[d]);
      r2 += dx[d] * dx[d];
    }
    if (r2 < support2 && r2 > 0.0) visit(j, dx, r2);
  }
}

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

/// Volume (A.1), density (A.2) and pressure (EOS) of every particle from a neighbour list whose
/// radius is at least the kernel support. The self term W(0) is included.
template <int Dim, class KernelT>
void density_pass(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& neighbours,
                  const FluidParameters& fluid, ParticleArrays& p) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const double self_weight = kernel.value(0.0);
  double length[Dim], half_length[Dim];
  const double* x[Dim];
  for (int d = 0; d < Dim; ++d) {
    length[d] = box.length[d];
    half_length[d] = 0.5 * box.length[d];
    x[d] = p.position[d].data();
  }
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double xi[Dim];
    for (int d = 0; d < Dim; ++d) xi[d] = x[d][i];
    double weight_sum = self_weight;
    for (const std::uint32_t j : neighbours.of(i)) {
      double r2 = 0.0;
      for (int d = 0; d < Dim; ++d) {
        const double dx = minimum_image(xi[d] - x[d][j], length[d], half_length[d]);
        r2 += dx * dx;
      }
      if (r2 < support2) weight_sum += kernel.value(std::sqrt(r2));
    }
    const double volume = 1.0 / weight_sum;  // (A.1)
    p.volume[i] = volume;
    p.density[i] = p.mass[i] / volume;                       // (A.2)
    p.pressure[i] = equation_of_state(p.density[i], fluid);  // EOS
  }
}

template <int Dim, bool Corrected, class KernelT>
void force_pass_impl(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& neighbours,
                     const FluidParameters& fluid, const VelocityView& velocity, ParticleArrays& p,
                     const double* viscous_weights);

/// Acceleration (F^p + F^visc)/ρ_i of (3.25) with (A.9) and (A.14), evaluated at the given
/// velocities; overwrites p.acceleration. Requires density_pass on the same positions. With
/// non-null `viscous_weights` (the g_i of viscous_correction_pass) each viscous pair is scaled
/// by pair_weight (ViscousOperator::Corrected, viscous_operator.hpp).
template <int Dim, class KernelT>
void force_pass(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& neighbours,
                const FluidParameters& fluid, const VelocityView& velocity, ParticleArrays& p,
                const double* viscous_weights = nullptr) {
  if (viscous_weights)
    force_pass_impl<Dim, true>(kernel, box, neighbours, fluid, velocity, p, viscous_weights);
  else
    force_pass_impl<Dim, false>(kernel, box, neighbours, fluid, velocity, p, nullptr);
}

template <int Dim, bool Corrected, class KernelT>
void force_pass_impl(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& neighbours,
                     const FluidParameters& fluid, const VelocityView& velocity, ParticleArrays& p,
                     const double* viscous_weights) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const double viscous_factor = 2.0 * (Dim + 2) * fluid.dynamic_viscosity;  // 2(n+2)η (A.14)
  double length[Dim], half_length[Dim];
  const double* x[Dim];
  const double* v[Dim];
  double* a[Dim];
  for (int d = 0; d < Dim; ++d) {
    length[d] = box.length[d];
    half_length[d] = 0.5 * box.length[d];
    x[d] = p.position[d].data();
    v[d] = velocity.v[d];
    a[d] = p.acceleration[d].data();
  }
  const double* pressure = p.pressure.data();
  const double* volume = p.volume.data();
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double xi[Dim], vi[Dim], force[Dim];
    for (int d = 0; d < Dim; ++d) {
      xi[d] = x[d][i];
      vi[d] = v[d][i];
      force[d] = 0.0;
    }
    const double pi = pressure[i];
    for (const std::uint32_t j : neighbours.of(i)) {
      double dx[Dim];
      double r2 = 0.0;
      double v_dot_x = 0.0;
      for (int d = 0; d < Dim; ++d) {
        dx[d] = minimum_image(xi[d] - x[d][j], length[d], half_length[d]);
        r2 += dx[d] * dx[d];
        v_dot_x += (vi[d] - v[d][j]) * dx[d];
      }
      if (!(r2 < support2 && r2 > 0.0)) continue;
      double viscous = viscous_pair_coefficient(viscous_factor, v_dot_x, r2);
      if constexpr (Corrected) {
        constexpr int K = QuarticBasis<Dim>::size;
        const double inv_r = 1.0 / std::sqrt(r2);
        double e[Dim];
        for (int d = 0; d < Dim; ++d) e[d] = dx[d] * inv_r;
        viscous *= pair_weight<Dim>(viscous_weights + i * K, viscous_weights + std::size_t{j} * K,
                                    QuarticBasis<Dim>::monomials(e));
      }
      const double coefficient = pressure_pair_coefficient(pi, pressure[j]) + viscous;
      const double scale = coefficient * volume[j] * kernel.gradient_over_r(std::sqrt(r2));
      for (int d = 0; d < Dim; ++d) force[d] += scale * dx[d];  // ∇W_ij = (1/r)(dW/dr) x_ij
    }
    const double inv_density = 1.0 / p.density[i];
    for (int d = 0; d < Dim; ++d) a[d][i] = force[d] * inv_density;
  }
}

}  // namespace sphles::sim
