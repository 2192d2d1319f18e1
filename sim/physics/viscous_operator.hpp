// SPDX-License-Identifier: GPL-3.0-or-later
// The discrete viscous operator of the momentum equation and its corrected form
// (docs/models.md, "Viscous operator").
//
// (A.14) F^visc_i = 2(n+2) η Σ_j [(v_ij·x_ij)/|x_ij|²] ∇W_ij V_j reproduces η(∇²v + 2∇∇·v) when
// the weighted fourth moment of the neighbour directions
//     Q_i = Σ_j w_ij e_ij⊗e_ij⊗e_ij⊗e_ij,   w_ij = |x_ij|² (W'/r)(r_ij) V_j,   e_ij = x_ij/|x_ij|,
// equals its continuous, isotropic value -n ⟨e⊗e⊗e⊗e⟩ (the Taylor expansion of v_ij to second
// order). On a packed arrangement it does not: the arrangement keeps the anisotropy of the
// lattice it was relaxed from, and the TGV modes decay at 0.95 to 1.16 times ν depending on
// D_K/Δl, at any N (tests/sim/test_consistent_start.cpp).
//
// ViscousOperator::Corrected weighs every pair by g_ij = ½(g_i(e_ij) + g_j(e_ij)), where g_i is
// the quartic polynomial of the direction (all monomials e^a e^b e^c e^d: 5 in 2D, 15 in 3D, the
// spherical harmonics of degree 0, 2 and 4) that makes particle i's weighted fourth moment
// exact: Σ_j w_ij g_i(e_ij) μ_m(e_ij) = -n ⟨μ_m⟩ for every monomial μ_m. This is the moment
// condition of the renormalised SPH Laplacians (Schwaiger 2008; Fatehi & Manzari 2011) imposed
// through a scalar pair weight: the pair force stays central and symmetric in i and j, so linear
// and angular momentum are conserved to round-off, and g_ij is clamped to [0, 2]: no pair adds
// energy (the dissipative sign of (A.14)), and none is weighted enough to limit the step. On a
// uniform arrangement g_i ≡ 1 and (A.14) is unchanged.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <string_view>
#include <vector>

#include "sim/eigen.hpp"
#include "sim/name_table.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"

namespace sphles::sim {

enum class ViscousOperator { Thesis, Corrected };

/// Scene names: "thesis", "corrected".
std::string_view viscous_operator_name(ViscousOperator op);
inline constexpr NameTable<ViscousOperator, 2> kViscousOperatorNames{{{
    {ViscousOperator::Thesis, "thesis"},
    {ViscousOperator::Corrected, "corrected"},
}}};

/// The monomials e_x^a e_y^b (e_z^c) of degree 4 in the direction e.
template <int Dim>
struct QuarticBasis {
  static constexpr int size = Dim == 2 ? 5 : 15;
  static constexpr std::array<std::array<int, 3>, size> exponents() {
    std::array<std::array<int, 3>, size> e{};
    int k = 0;
    for (int a = 4; a >= 0; --a)
      for (int b = 4 - a; b >= 0; --b) {
        const int c = 4 - a - b;
        if (Dim == 2 && c != 0) continue;
        e[static_cast<std::size_t>(k++)] = {a, b, c};
      }
    return e;
  }
  using Values = std::array<double, size>;

  static Values monomials(const double* e) {
    constexpr auto exps = exponents();
    std::array<std::array<double, 5>, 3> power{};
    for (int d = 0; d < 3; ++d) {
      power[d][0] = 1.0;
      const double x = d < Dim ? e[d] : 0.0;
      for (int p = 1; p < 5; ++p) power[d][p] = power[d][p - 1] * x;
    }
    Values m;
    for (int k = 0; k < size; ++k) {
      const auto& x = exps[static_cast<std::size_t>(k)];
      m[static_cast<std::size_t>(k)] = power[0][x[0]] * power[1][x[1]] * power[2][x[2]];
    }
    return m;
  }

  /// ⟨μ⟩ over the unit sphere (circle in 2D): (a-1)!!(b-1)!!(c-1)!! / (n(n+2)) for even
  /// exponents, 0 otherwise.
  static Values sphere_means() {
    constexpr auto exps = exponents();
    const auto double_factorial_odd = [](int even) { return even == 4 ? 3.0 : 1.0; };  // (k-1)!!
    Values m{};
    for (int k = 0; k < size; ++k) {
      const auto& x = exps[static_cast<std::size_t>(k)];
      if (x[0] % 2 || x[1] % 2 || x[2] % 2) continue;
      m[static_cast<std::size_t>(k)] = double_factorial_odd(x[0]) * double_factorial_odd(x[1]) *
                                       double_factorial_odd(x[2]) / (Dim * (Dim + 2));
    }
    return m;
  }

  /// The coefficients of g ≡ (e·e)² = 1: the fallback when the moment system is singular.
  static Values unit() {
    constexpr auto exps = exponents();
    Values g{};
    for (int k = 0; k < size; ++k) {
      const auto& x = exps[static_cast<std::size_t>(k)];
      // (Σ e_d²)² = Σ e_d⁴ + 2 Σ_{d<d'} e_d² e_d'²
      if (x[0] == 4 || x[1] == 4 || x[2] == 4)
        g[static_cast<std::size_t>(k)] = 1.0;
      else if (x[0] % 2 == 0 && x[1] % 2 == 0 && x[2] % 2 == 0)
        g[static_cast<std::size_t>(k)] = 2.0;
    }
    return g;
  }
};

/// Accumulated moment system of one particle: A_mk = Σ_j w_ij μ_m(e_ij) μ_k(e_ij).
template <int Dim>
using MomentMatrix = Eigen::Matrix<double, QuarticBasis<Dim>::size, QuarticBasis<Dim>::size>;

/// g_i of the corrected operator from its moment matrix: solves A G = -n ⟨μ⟩ (A is negative
/// definite when the neighbours span all directions; otherwise g ≡ 1).
template <int Dim>
typename QuarticBasis<Dim>::Values directional_weight(const MomentMatrix<Dim>& moments) {
  using Basis = QuarticBasis<Dim>;
  constexpr int K = Basis::size;
  const typename Basis::Values means = Basis::sphere_means();
  // Every object of the solve is 64-byte aligned: Eigen splits its loops over blocks of these
  // small matrices into a scalar head and a vector body by the runtime address, so on an AVX-512
  // machine two threads' stacks (aligned differently mod 64) summed in different orders and the
  // weights differed with the thread count in the last bit.
  alignas(64) Eigen::Matrix<double, K, 1> rhs;
  for (int k = 0; k < K; ++k) rhs(k) = Dim * means[static_cast<std::size_t>(k)];  // -(-n⟨μ⟩)
  alignas(64) const MomentMatrix<Dim> negated = -moments;
  alignas(64) const Eigen::LLT<MomentMatrix<Dim>> llt(negated);
  if (llt.info() != Eigen::Success) return Basis::unit();
  alignas(64) const Eigen::Matrix<double, K, 1> g = llt.solve(rhs);
  typename Basis::Values out;
  for (int k = 0; k < K; ++k) {
    if (!std::isfinite(g(k))) return Basis::unit();
    out[static_cast<std::size_t>(k)] = g(k);
  }
  return out;
}

/// Bound of a corrected pair weight. Where a particle's neighbours do not span all directions
/// evenly (a free surface, a strongly strained arrangement) the moment system is ill-conditioned
/// and g_i can reach large values in some directions; an unbounded weight then makes the
/// explicit step unstable (a rotating cluster with ν = 0.1 blew up within 6 steps).
inline constexpr double kMaxViscousPairWeight = 2.0;

/// g_ij = ½(g_i(e) + g_j(e)) clamped to [0, kMaxViscousPairWeight], for the pair direction e,
/// given both particles' coefficients and the direction's monomials.
template <int Dim>
inline double pair_weight(const double* g_i, const double* g_j,
                          const typename QuarticBasis<Dim>::Values& monomials) {
  double sum = 0.0;
  for (int k = 0; k < QuarticBasis<Dim>::size; ++k)
    sum += (g_i[k] + g_j[k]) * monomials[static_cast<std::size_t>(k)];
  return std::clamp(0.5 * sum, 0.0, kMaxViscousPairWeight);
}

/// The moment system A_mk = Σ_j w_ij μ_m(e_ij) μ_k(e_ij), w_ij = x_ij·∇W_ij V_j, as an
/// evaluator of the pair loop (outputs: the upper triangle, row by row); finish solves it for
/// g_i (directional_weight).
template <int Dim, class KernelT>
struct ViscousMoments {
  using Basis = QuarticBasis<Dim>;
  static constexpr int K = Basis::size;
  static constexpr int outputs = K * (K + 1) / 2;
  static constexpr bool coincident_pairs = false;
  struct Own {};

  ViscousMoments(const KernelT& kernel, const ParticleArrays& p, std::vector<double>& coefficients)
      : kernel_(kernel), volume_(p.volume.data()), coefficients_(coefficients.data()) {}

  Own own(std::size_t) const { return {}; }
  void pair(const Own&, const Pair<Dim>& q, double (&out)[outputs]) const {
    double e[Dim];
    for (int d = 0; d < Dim; ++d) e[d] = q.dx[d] / q.r;
    const double w = q.r2 * kernel_.gradient_over_r(q.r) * volume_[q.j];  // x_ij·∇W_ij V_j
    const typename Basis::Values mu = Basis::monomials(e);
    int slot = 0;
    for (int a = 0; a < K; ++a)
      for (int b = a; b < K; ++b)
        out[slot++] = w * mu[static_cast<std::size_t>(a)] * mu[static_cast<std::size_t>(b)];
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    alignas(64) MomentMatrix<Dim> moments;
    int slot = 0;
    for (int a = 0; a < K; ++a)
      for (int b = a; b < K; ++b) moments(a, b) = moments(b, a) = sum[slot++];
    const typename Basis::Values g = directional_weight<Dim>(moments);
    for (int k = 0; k < K; ++k) coefficients_[i * K + static_cast<std::size_t>(k)] = g[k];
  }

 private:
  KernelT kernel_;
  const double* volume_;
  double* coefficients_;
};

/// g_i of every particle (QuarticBasis<Dim>::size coefficients per particle, particle-major);
/// requires the volumes V_j of density_pass on the same positions. `pairs`: a Verlet list, or
/// the InteractionList of that density pass.
template <int Dim, class KernelT, class List>
void viscous_correction_pass(const KernelT& kernel, const PeriodicBox& box, const List& pairs,
                             const ParticleArrays& p, std::vector<double>& coefficients) {
  coefficients.resize(p.size() * QuarticBasis<Dim>::size);
  pair_pass<Dim>(ViscousMoments<Dim, KernelT>(kernel, p, coefficients),
                 PeriodicGeometry<Dim>(box, p), pairs, kernel.support_radius(), 0,
                 pairs.num_particles());
}

}  // namespace sphles::sim
