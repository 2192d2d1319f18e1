// SPDX-License-Identifier: GPL-3.0-or-later
// The ALE correction of the momentum equation for particles that move with v + δv instead of v
// (the transport-velocity formulation, transport_velocity.hpp, and particle shifting,
// particle_shifting.hpp; docs/models.md). Along the shifted path dv/dt = Dv/Dt + δv·∇v; Sun et
// al. 2019 (CMAME 348) write ρ δv·∇v as ∇·(ρ v ⊗ δv) - v ∇·(ρ δv), and Adami, Hu & Adams 2013
// (J. Comput. Phys. 241, eq. 8) keep the first term alone as the extra stress A = ρ v ⊗ δv.
// Pair terms below are per component a, with `shift_dot_gradient_*` = δv·∇W_ij.
#pragma once

namespace sphles::sim {

/// The discrete ALE correction (scene key scheme.ale_correction).
enum class AleCorrection {
  /// ∇·(ρ v ⊗ δv) alone: antisymmetric pair terms, Σ M a = 0 to round-off; not Galilean
  /// invariant (a uniform U adds U ∇·(ρ δv)).
  Conservative,
  /// ∇·(ρ v ⊗ δv) - v ∇·(ρ δv) = ρ δv·∇v: Galilean invariant; the -v_i ∇·(ρ δv)_i term is not
  /// antisymmetric (its integral over a periodic box is not zero), so Σ M v drifts.
  Full,
};

/// Pair term of ∇·(ρ v ⊗ δv) in Sun et al. 2019's symmetric form (Adami et al.'s A_i + A_j):
/// ρ_i v_i,a (δv_i·∇W_ij) + ρ_j v_j,a (δv_j·∇W_ij). Symmetric in i and j; times the
/// antisymmetric ∇W_ij it makes the pair term of M_i a_i antisymmetric.
inline double ale_conservative_term(double density_i, double velocity_i,
                                    double shift_dot_gradient_i, double density_j,
                                    double velocity_j, double shift_dot_gradient_j) {
  return density_i * velocity_i * shift_dot_gradient_i +
         density_j * velocity_j * shift_dot_gradient_j;
}

/// Pair term of the full correction ∇·(ρ v ⊗ δv) - v_i ∇·(ρ δv): the conservative term less
/// v_i,a (ρ_i δv_i·∇W_ij + ρ_j δv_j·∇W_ij), i.e. ρ_j (v_j,a - v_i,a)(δv_j·∇W_ij): unchanged by a
/// uniform velocity added to v_i and v_j.
inline double ale_full_term(double density_i, double velocity_i, double shift_dot_gradient_i,
                            double density_j, double velocity_j, double shift_dot_gradient_j) {
  return ale_conservative_term(density_i, velocity_i, shift_dot_gradient_i, density_j, velocity_j,
                               shift_dot_gradient_j) -
         velocity_i * (density_i * shift_dot_gradient_i + density_j * shift_dot_gradient_j);
}

/// The pair term of the chosen form.
template <AleCorrection Ale>
inline double ale_term(double density_i, double velocity_i, double shift_dot_gradient_i,
                       double density_j, double velocity_j, double shift_dot_gradient_j) {
  if constexpr (Ale == AleCorrection::Full)
    return ale_full_term(density_i, velocity_i, shift_dot_gradient_i, density_j, velocity_j,
                         shift_dot_gradient_j);
  else
    return ale_conservative_term(density_i, velocity_i, shift_dot_gradient_i, density_j, velocity_j,
                                 shift_dot_gradient_j);
}

}  // namespace sphles::sim
