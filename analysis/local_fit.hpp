// SPDX-License-Identifier: GPL-3.0-or-later
// Local polynomial fits of particle data (weighted least squares, the moving-least-squares
// reconstruction; docs/analysis.md, "gridding").
//
// Around a centre x_c, the polynomial f(x_c + r) ≈ Σ_a c_a ξ^a, ξ = r / R, over the monomials of
// total degree ≤ P minimises Σ_j w_j (f_j - f(x_j))² with the weights w_j = W_R(|r_j|) V_j of
// the particles within R (W_R: the run's kernel shape with support R; V_j: the particle volume
// (A.1)). c_0 is the value at x_c and c_{e_d} / R the derivative along axis d. The fit reproduces
// every polynomial of degree ≤ P exactly, so, unlike an SPH sum or a Shepard average, it does not
// filter a smooth field by the kernel: for a Fourier mode of wavenumber k the error is
// O((kR)^(P+1)), and O((kR)^(P+2)) at a centre whose neighbourhood is symmetric (for the value
// when P is even, for the gradient when P is odd).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "analysis/grid.hpp"
#include "sim/eigen.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"
#include "sim/subfilter.hpp"

namespace sphles::analysis {

/// Degree of the velocity fit whose derivatives give the particle velocity gradient (and ω):
/// cubic, so that the gradient error of a smooth field is O((kR)^4).
inline constexpr int kGradientFitDegree = 3;
/// Degree of the fit that interpolates particle values onto grid nodes: quadratic (value error
/// O((kR)^3), O((kR)^4) where the neighbourhood is symmetric about the node).
inline constexpr int kInterpolationFitDegree = 2;
/// Smallest Cholesky pivot of the normal matrix, relative to its largest diagonal entry, for
/// which a fit is accepted; below it the neighbourhood does not determine the polynomial and
/// the fit falls back to the next lower degree.
inline constexpr double kMinRelativePivot = 1e-12;

/// The monomials ξ_x^a ξ_y^b (ξ_z^c) of total degree ≤ Degree, graded: 1, then ξ_x, ξ_y (, ξ_z),
/// then degree 2, ...; monomial 1 + d is ξ_d.
template <int Dim, int Degree>
struct MonomialBasis {
  static constexpr int size =
      Dim == 2 ? (Degree + 1) * (Degree + 2) / 2 : (Degree + 1) * (Degree + 2) * (Degree + 3) / 6;
  using Values = std::array<double, size>;

  static constexpr std::array<std::array<int, 3>, size> exponents() {
    std::array<std::array<int, 3>, size> e{};
    int k = 0;
    for (int degree = 0; degree <= Degree; ++degree)
      for (int a = degree; a >= 0; --a)
        for (int b = degree - a; b >= 0; --b) {
          const int c = degree - a - b;
          if (Dim == 2 && c != 0) continue;
          e[static_cast<std::size_t>(k++)] = {a, b, c};
        }
    return e;
  }

  static Values evaluate(const std::array<double, 3>& xi) {
    constexpr auto exps = exponents();
    std::array<std::array<double, Degree + 1>, 3> power{};
    for (int d = 0; d < 3; ++d) {
      power[d][0] = 1.0;
      for (int p = 1; p <= Degree; ++p) power[d][p] = power[d][p - 1] * xi[d];
    }
    Values m;
    for (int k = 0; k < size; ++k) {
      const auto& x = exps[static_cast<std::size_t>(k)];
      m[static_cast<std::size_t>(k)] = power[0][x[0]] * power[1][x[1]] * power[2][x[2]];
    }
    return m;
  }
};

/// One neighbour of a fit's centre: ξ = (x_j - x_c) / R, its weight W_R V_j and its index.
struct FitPoint {
  std::array<double, 3> xi;
  double weight;
  std::uint32_t index;
};

/// What a fit gives at its centre: the value and the gradient (per unit length) of each field,
/// and the degree used (lower than asked when the neighbourhood could not determine the fit;
/// -1 when there was no neighbour: the values are NaN).
template <int Fields>
struct FitResult {
  std::array<double, Fields> value;
  std::array<std::array<double, 3>, Fields> gradient;
  int degree = -1;
};

/// Weighted least-squares fits of degree Degree to Fields per-particle fields, with scratch
/// space reused between fits (one fitter per thread).
///
/// The normal equations A c = b, A = Σ_j w_j m(ξ_j) m(ξ_j)ᵀ, b = Σ_j w_j m(ξ_j) f_j, are formed
/// as one matrix product of the √w-scaled monomials. The basis is graded, so the system of every
/// lower degree is the leading block of A and b: when the normal matrix is not safely positive
/// definite (fewer points than monomials, points on a plane, ...) the fit falls back to degree
/// Degree - 1, ..., 0 without summing again. The sums run in the order of `points`; the fixed-size
/// objects of the solve are 64-byte aligned, so that Eigen's vectorised loops split the same way
/// on every thread (their split depends on the address), and the products' blocking depends on
/// the sizes alone: the result does not depend on the thread.
template <int Dim, int Degree, int Fields>
class PolynomialFitter {
 public:
  using Basis = MonomialBasis<Dim, Degree>;
  static constexpr int K = Basis::size;

  /// Field f of point p is values(p.index, f).
  template <class Values>
  FitResult<Fields> fit(std::span<const FitPoint> points, double radius, const Values& values) {
    const auto n = static_cast<Eigen::Index>(points.size());
    scaled_basis_.resize(K, n);
    scaled_values_.resize(n, Fields);
    for (Eigen::Index k = 0; k < n; ++k) {
      const FitPoint& p = points[static_cast<std::size_t>(k)];
      const double root = std::sqrt(p.weight);
      const typename Basis::Values m = Basis::evaluate(p.xi);
      for (int a = 0; a < K; ++a) scaled_basis_(a, k) = root * m[static_cast<std::size_t>(a)];
      for (int f = 0; f < Fields; ++f) scaled_values_(k, f) = root * values(p.index, f);
    }
    alignas(64) Eigen::Matrix<double, K, K> normal;
    alignas(64) Eigen::Matrix<double, K, Fields> rhs;
    normal.noalias() = scaled_basis_ * scaled_basis_.transpose();
    rhs.noalias() = scaled_basis_ * scaled_values_;
    return solve<Degree>(normal, rhs, static_cast<int>(n), radius);
  }

 private:
  /// The fit of degree D from the leading blocks of the degree-Degree system.
  template <int D>
  static FitResult<Fields> solve(const Eigen::Matrix<double, K, K>& normal,
                                 const Eigen::Matrix<double, K, Fields>& rhs, int points,
                                 double radius) {
    constexpr int Kd = MonomialBasis<Dim, D>::size;
    if (points >= Kd) {
      alignas(64) const Eigen::Matrix<double, Kd, Kd> a = normal.template topLeftCorner<Kd, Kd>();
      alignas(64) const Eigen::Matrix<double, Kd, Fields> b = rhs.template topRows<Kd>();
      alignas(64) const Eigen::LLT<Eigen::Matrix<double, Kd, Kd>> llt(a);
      if (llt.info() == Eigen::Success && llt.matrixLLT().diagonal().array().square().minCoeff() >
                                              kMinRelativePivot * a.diagonal().maxCoeff()) {
        alignas(64) const Eigen::Matrix<double, Kd, Fields> c = llt.solve(b);
        if (c.allFinite()) {
          FitResult<Fields> result;
          result.degree = D;
          for (int f = 0; f < Fields; ++f) {
            result.value[static_cast<std::size_t>(f)] = c(0, f);
            for (int d = 0; d < 3; ++d)
              result.gradient[static_cast<std::size_t>(f)][static_cast<std::size_t>(d)] =
                  D >= 1 && d < Dim ? c(1 + d, f) / radius : 0.0;
          }
          return result;
        }
      }
    }
    if constexpr (D > 0) {
      return solve<D - 1>(normal, rhs, points, radius);
    } else {
      FitResult<Fields> none;
      none.value.fill(std::nan(""));
      for (auto& g : none.gradient) g.fill(std::nan(""));
      return none;
    }
  }

  Eigen::Matrix<double, K, Eigen::Dynamic> scaled_basis_;        // √w_j m(ξ_j), one column each
  Eigen::Matrix<double, Eigen::Dynamic, Fields> scaled_values_;  // √w_j f_j, one row each
};

/// One fit with its own scratch space (PolynomialFitter::fit).
template <int Dim, int Degree, int Fields, class Values>
FitResult<Fields> fit_polynomial(std::span<const FitPoint> points, double radius,
                                 const Values& values) {
  return PolynomialFitter<Dim, Degree, Fields>().fit(points, radius, values);
}

/// The weight function and radius of the analysis fits.
struct FitSettings {
  sim::KernelType weight = sim::KernelType::WendlandC4;  // the run's kernel shape
  double radius = 0.0;                                   // R [m]
};

/// ∂v_a/∂x_b at every particle (J[a][b], as sim::VelocityGradient) from the local fit of degree
/// kGradientFitDegree to the velocities of the particles within R, the particle itself included.
/// `grid` gives the periodic box (its length and dimension). Needs the particles' volumes.
/// With `centres` < the particle count, only the first `centres` particles are fitted (a rank's
/// own particles, whose halo follows them: par/) and the result holds that many. Independent of
/// the thread count and of the particles' order (the fits gather in id order, cell_list.hpp).
std::vector<sim::VelocityGradient> fitted_velocity_gradient(
    const Grid& grid, const sim::ParticleArrays& particles, const FitSettings& fit,
    std::size_t centres = std::numeric_limits<std::size_t>::max());

/// Per-particle fields (at most 3) at grid nodes from the local fit of degree
/// kInterpolationFitDegree: out[f][k] is field f at node nodes[k], or at node k when `nodes` is
/// empty (the whole grid). Needs the particles' volumes. Independent of the thread count and of
/// the particles' order.
std::vector<std::vector<double>> fitted_sample(const Grid& grid,
                                               const sim::ParticleArrays& particles,
                                               const FitSettings& fit,
                                               std::span<const std::span<const double>> fields,
                                               std::span<const std::size_t> nodes = {});

}  // namespace sphles::analysis
