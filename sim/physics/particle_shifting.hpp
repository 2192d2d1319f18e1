// SPDX-License-Identifier: GPL-3.0-or-later
// Particle shifting with the consistent ALE correction of the δ⁺-SPH model: Sun, Colagrossi,
// Marrone & Zhang, "The δplus-SPH model", CMAME 315 (2017) 25-49 (the shifting law with its
// anti-clustering term), and Sun, Colagrossi, Marrone, Antuono & Zhang, "A consistent approach to
// particle shifting in the δ⁺-SPH model", CMAME 348 (2019) 912-934 (the shifting velocity and
// the ALE terms it brings into the equations); as in the δ-LES-SPH of Antuono et al. 2021
// (docs/models.md, "Particle shifting").
//
// Particles move with v + δv, the shifting velocity (Sun et al. 2019)
//   δv_i = -Ma c_0 (2h) Σ_j [1 + R (W_ij / W(Δx))^n] ∇W_ij V_j,   |δv_i| ≤ limit,
// a function of the positions only. In sphles' symbols: 2h (the papers' kernel support, Wendland
// C2 with support 2h) is the kernel's support radius D_K/2, Δx the particle spacing Δl, c_0 the
// sound speed c_s, and Ma c_0 the reference velocity U = Ma c_s (scheme.shifting_mach).
//
// The ALE terms. Density stays by summation (density_pass, SPEC (A.1)-(A.2), constant masses): the
// density of a particle follows its volume along the shifted path, dρ_i/dt = -ρ_i ∇·(v + δv),
// so the continuity ALE term -ρ ∇·δv is implicit in the positions; the mass flux ∇·(ρ δv) the
// papers add to their continuity equation is not there (a particle keeps its mass). The velocity
// obeys dv/dt = Dv/Dt + δv·∇v along the shifted path whatever the density does; the papers write
// ρ δv·∇v conservatively as ∇·(ρ v ⊗ δv) - v ∇·(ρ δv). Two discrete forms (scheme.ale_correction):
//  - Conservative (default): the first term alone, in Sun et al. 2019's symmetric sum
//    Σ_j (ρ_i v_i ⊗ δv_i + ρ_j v_j ⊗ δv_j)·∇W_ij V_j. Its pair terms of M_i a_i are
//    antisymmetric, so Σ M a = 0 to round-off; it is the momentum equation one derives from the
//    summation continuity ρ d(v)/dt = d(ρv)/dt - v dρ/dt, but not Galilean invariant (a uniform U
//    adds (U/ρ) ∇·(ρ δv)).
//  - Full: both terms, (1/ρ_i) Σ_j ρ_j (v_j - v_i)(δv_j·∇W_ij) V_j = δv·∇v: Galilean invariant,
//    but -v ∇·(ρ δv) has no antisymmetric pair form (its integral over a periodic box is not
//    zero), so Σ M v is not conserved.
// Pressure (A.9) and viscous term (A.14) are the thesis model's (ThesisMomentum). The ALE term
// at x^{n+1} takes δv^n, the shift the particles drifted with, so the scheme forms the force, the
// ALE correction and δv^{n+1} in one pass after the density (sim/scheme.hpp). The terms are
// evaluators of the pair loop (sim/pair_loop.hpp), in gather form, so results do not depend on
// the thread count.
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

/// R of the anti-clustering term 1 + R (W_ij/W(Δx))^n (Sun et al. 2017, §3; Sun et al. 2019).
inline constexpr double kShiftingClusteringAmplitude = 0.2;
/// n of the anti-clustering term (Sun et al. 2017, §3; Sun et al. 2019).
inline constexpr int kShiftingClusteringExponent = 4;
/// The limiter on the shifting velocity: |δv_i| ≤ kShiftingSpeedLimit · Ma c_0 (Sun et al. 2019
/// limit the shift to half the reference velocity).
inline constexpr double kShiftingSpeedLimit = 0.5;

/// The scheme's constants for one run (SchemeFields::shifting), formed once from the
/// configuration.
struct ShiftingParameters {
  double coefficient = 0.0;       // Ma c_0 (2h) = U · support radius [m²/s]
  double reference_kernel = 1.0;  // W(Δx), the kernel at one particle spacing
  double speed_limit = 0.0;       // the limiter's bound on |δv| [m/s]
  AleCorrection ale = AleCorrection::Conservative;
};

/// Ma c_0 (2h), W(Δx) and the limiter from the reference velocity U = Ma c_0 [m/s], the kernel's
/// support radius (2h) and W at one particle spacing.
inline ShiftingParameters shifting_parameters(double reference_velocity, double support_radius,
                                              double kernel_at_spacing,
                                              AleCorrection ale = AleCorrection::Conservative) {
  return {.coefficient = reference_velocity * support_radius,
          .reference_kernel = kernel_at_spacing,
          .speed_limit = kShiftingSpeedLimit * reference_velocity,
          .ale = ale};
}

/// The pair factor 1 + R (W_ij / W(Δx))^n of the shifting velocity (Sun et al. 2017, 2019);
/// symmetric in i and j (it depends on r_ij only).
inline double shifting_pair_factor(double kernel_value, double reference_kernel) {
  const double ratio = kernel_value / reference_kernel;
  double power = 1.0;
  for (int k = 0; k < kShiftingClusteringExponent; ++k) power *= ratio;
  return 1.0 + kShiftingClusteringAmplitude * power;
}

/// Scale applied to the unlimited δv of magnitude `speed` so that |δv| ≤ `limit` (1 below it).
inline double shifting_limiter_scale(double speed, double limit) {
  return speed > limit ? limit / speed : 1.0;
}

/// The shifting velocity's pair sum Σ_j [1 + R (W_ij/W(Δx))^n] ∇W_ij V_j as an evaluator of the
/// pair loop; finish scales it by -Ma c_0 (2h) and limits it to |δv_i| ≤ speed_limit.
template <int Dim, class KernelT>
struct ShiftingVelocity {
  static constexpr int outputs = Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {};

  ShiftingVelocity(const KernelT& kernel, const ShiftingParameters& parameters,
                   const ParticleArrays& p, std::array<std::vector<double>, 3>& shift)
      : kernel_(kernel), parameters_(parameters), volume_(p.volume.data()) {
    for (int d = 0; d < Dim; ++d) dv_[d] = shift[d].data();
  }

  Own own(std::size_t) const { return {}; }
  void pair(const Own&, const Pair<Dim>& q, double (&out)[outputs]) const {
    const double scale = shifting_pair_factor(kernel_.value(q.r), parameters_.reference_kernel) *
                         kernel_.gradient_over_r(q.r) * volume_[q.j];
    for (int d = 0; d < Dim; ++d) out[d] = scale * q.dx[d];  // ∇W_ij = (1/r)(dW/dr) x_ij
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    double shift[Dim];
    double speed2 = 0.0;
    for (int d = 0; d < Dim; ++d) {
      shift[d] = -parameters_.coefficient * sum[d];
      speed2 += shift[d] * shift[d];
    }
    const double limiter = shifting_limiter_scale(std::sqrt(speed2), parameters_.speed_limit);
    for (int d = 0; d < Dim; ++d) dv_[d][i] = limiter * shift[d];
  }

 private:
  KernelT kernel_;
  ShiftingParameters parameters_;
  const double* volume_;
  double* dv_[Dim];
};

/// The shifting velocity δv_i = -Ma c_0 (2h) Σ_j [1 + R (W_ij/W(Δx))^n] ∇W_ij V_j, limited to
/// |δv_i| ≤ speed_limit (overwrites `shift`, whose arrays must have p.size() entries for each
/// dimension). Requires density_pass on the same positions (V_j); `pairs` is the Verlet list or
/// the InteractionList of that density pass.
template <int Dim, class KernelT, class List>
void shifting_velocity_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                            const ShiftingParameters& parameters, const ParticleArrays& p,
                            std::array<std::vector<double>, 3>& shift) {
  pair_pass<Dim>(ShiftingVelocity<Dim, KernelT>(kernel, parameters, p, shift),
                 PeriodicGeometry<Dim>(box, p), pairs, kernel.support_radius(), 0,
                 pairs.num_particles());
}

/// The ALE correction (1/ρ_i) Σ_j (ρ_i v_i ⊗ δv_i + ρ_j v_j ⊗ δv_j)·∇W_ij V_j (Conservative), or
/// Sun et al. 2019's full form (Full), at the given velocities and shifting velocities, as an
/// evaluator of the pair loop; finish adds it to the acceleration (after the momentum evaluator
/// of the same pass, Fused). Requires density_pass on the same positions.
template <int Dim, AleCorrection Ale, class KernelT>
struct ShiftingAle {
  static constexpr int outputs = Dim;
  static constexpr bool coincident_pairs = false;
  struct Own {
    double v[Dim];
    double dv[Dim];
    double density;
  };

  ShiftingAle(const KernelT& kernel, const VelocityView& velocity, const VelocityView& shift,
              ParticleArrays& p)
      : kernel_(kernel), volume_(p.volume.data()), density_(p.density.data()) {
    for (int d = 0; d < Dim; ++d) {
      v_[d] = velocity.v[d];
      dv_[d] = shift.v[d];
      a_[d] = p.acceleration[d].data();
    }
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) {
      o.v[d] = v_[d][i];
      o.dv[d] = dv_[d][i];
    }
    o.density = density_[i];
    return o;
  }
  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    const std::uint32_t j = q.j;
    const double g = kernel_.gradient_over_r(q.r);  // ∇W_ij = g x_ij
    double shift_i = 0.0, shift_j = 0.0;            // δv · ∇W_ij
    for (int d = 0; d < Dim; ++d) {
      shift_i += o.dv[d] * g * q.dx[d];
      shift_j += dv_[d][j] * g * q.dx[d];
    }
    const double rho_j = density_[j];
    const double vol_j = volume_[j];
    for (int d = 0; d < Dim; ++d)
      out[d] = vol_j * ale_term<Ale>(o.density, o.v[d], shift_i, rho_j, v_[d][j], shift_j);
  }
  void finish(std::size_t i, const Own& o, const double (&sum)[outputs]) const {
    const double inv_density = 1.0 / o.density;
    for (int d = 0; d < Dim; ++d) a_[d][i] += sum[d] * inv_density;
  }

 private:
  KernelT kernel_;
  const double* v_[Dim];
  const double* dv_[Dim];
  double* a_[Dim];
  const double* volume_;
  const double* density_;
};

}  // namespace sphles::sim
