// SPDX-License-Identifier: GPL-3.0-or-later
// Summation density as an evaluator of the pair loop (sim/pair_loop.hpp).
#pragma once

#include <cstddef>

#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"
#include "sim/physics/fluid.hpp"

namespace sphles::sim {

/// V_i = 1 / Σ_j W_ij (SPEC (A.1), the self term W(0) included), ρ_i = M_i / V_i (A.2) and the
/// EOS pressure p_i = p_ref + c_s² (ρ_i - ρ_ref) (SPEC §2). Pairs at r = 0 count: a particle
/// on top of another adds W(0) to its volume sum.
template <int Dim, class KernelT>
struct SummationDensity {
  static constexpr int outputs = 1;
  static constexpr bool coincident_pairs = true;
  struct Own {};

  SummationDensity(const KernelT& kernel, const FluidParameters& fluid, ParticleArrays& p)
      : kernel_(kernel),
        fluid_(fluid),
        self_weight_(kernel.value(0.0)),
        mass_(p.mass.data()),
        volume_(p.volume.data()),
        density_(p.density.data()),
        pressure_(p.pressure.data()) {}

  Own own(std::size_t) const { return {}; }
  void pair(const Own&, const Pair<Dim>& q, double (&out)[outputs]) const {
    out[0] = kernel_.value(q.r);  // W_ij
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    const double volume = 1.0 / (self_weight_ + sum[0]);  // (A.1)
    volume_[i] = volume;
    density_[i] = mass_[i] / volume;                        // (A.2)
    pressure_[i] = equation_of_state(density_[i], fluid_);  // EOS
  }

 private:
  KernelT kernel_;
  FluidParameters fluid_;
  double self_weight_;
  const double* mass_;
  double* volume_;
  double* density_;
  double* pressure_;
};

}  // namespace sphles::sim
