// SPDX-License-Identifier: GPL-3.0-or-later
// The terms of the incompressible Navier-Stokes equations in Fourier space (SPEC §9; Canuto,
// Hussaini, Quarteroni & Zang 2007, ch. 3), as small functions over one mode.
//
// With u(x) = Σ_k û(k) e^{ik·x}, the rotational form ∂u/∂t = u × ω - ∇(p + ½|u|²) + ν∇²u - μu + f
// becomes, after projection onto divergence-free fields,
//   dû/dt = L(k) û + P(k)[(u × ω)^(k)] + f̂(k),   L(k) = -(ν|k|² + μ),   P(k) = I - k kᵀ/|k|²,
// whose nonlinear part is evaluated on the grid (pseudo-spectrally) and dealiased by the 2/3 rule
// (Orszag 1971).
#pragma once

#include <array>
#include <cmath>
#include <complex>

namespace sphles::spectral {

using Complex = std::complex<double>;
using ComplexVector = std::array<Complex, 3>;

/// Signed integer wavenumber of FFT index i on an n-point axis: 0 .. n/2, then -n/2+1 .. -1.
inline int signed_wavenumber(int i, int n) {
  return i <= n / 2 ? i : i - n;
}

/// Largest |m| kept by the 2/3 rule on n points: a product of two fields with |m| <= K has modes
/// up to 2K, which alias to 2K - n; they miss every kept mode when 2K - n < -K, i.e. 3K < n.
inline int dealiased_max_wavenumber(int n) {
  return (n - 1) / 3;
}

/// Whether the mode (mx, my, mz) survives the 2/3 rule's cubic truncation.
inline bool kept_mode(int mx, int my, int mz, int kmax) {
  return std::abs(mx) <= kmax && std::abs(my) <= kmax && std::abs(mz) <= kmax;
}

/// P(k) v = v - k (k·v)/|k|²: the divergence-free part (the pressure's job); the mean (k = 0)
/// carries no pressure gradient and is returned unchanged.
inline ComplexVector project(const std::array<double, 3>& k, const ComplexVector& v) {
  const double k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
  if (k2 == 0.0) return v;
  const Complex kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2];
  return {v[0] - k[0] * kv / k2, v[1] - k[1] * kv / k2, v[2] - k[2] * kv / k2};
}

/// ω̂ = i k × û.
inline ComplexVector curl(const std::array<double, 3>& k, const ComplexVector& u) {
  const Complex i(0.0, 1.0);
  return {i * (k[1] * u[2] - k[2] * u[1]), i * (k[2] * u[0] - k[0] * u[2]),
          i * (k[0] * u[1] - k[1] * u[0])};
}

/// u × ω at one grid point.
inline std::array<double, 3> cross(const std::array<double, 3>& u, const std::array<double, 3>& w) {
  return {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
}

/// The linear rate L(k) = -(ν|k|² + μ) of the viscous term and the linear friction.
inline double linear_rate(double k2, double viscosity, double friction) {
  return -(viscosity * k2 + friction);
}

/// Weight of a stored mode in sums over the whole spectrum of a real field: the r2c layout keeps
/// kx >= 0 only, so a mode 0 < kx < n/2 stands for itself and its conjugate.
inline double conjugate_weight(int ix, int n) {
  return ix == 0 || 2 * ix == n ? 1.0 : 2.0;
}

/// The stages of the fourth-order Runge-Kutta method in integrating-factor (Lawson) form for
/// dû/dt = L û + N(û): with e = exp(L h/2), the linear term is integrated exactly and RK4 applies
/// to N (Lawson 1967; Canuto et al. 2007, §4.4).
///   û₁ = e (û + h/2 a),  û₂ = e û + h/2 b,  û₃ = e² û + h e c,
///   û(t + h) = e² û + h/6 (e² a + 2e (b + c) + d),  a, b, c, d = N(û), N(û₁), N(û₂), N(û₃).
struct LawsonRk4 {
  static Complex stage1(double e, double h, Complex u, Complex a) { return e * (u + 0.5 * h * a); }
  static Complex stage2(double e, double h, Complex u, Complex b) { return e * u + 0.5 * h * b; }
  static Complex stage3(double e, double h, Complex u, Complex c) { return e * e * u + h * e * c; }
  /// The weighted sum e² a + 2e (b + c) + d, accumulated as the stages come: first e² a, then
  /// + 2e b, + 2e c, + d.
  static Complex final_step(double e, double h, Complex u, Complex sum) {
    return e * e * u + h / 6.0 * sum;
  }
};

}  // namespace sphles::spectral
