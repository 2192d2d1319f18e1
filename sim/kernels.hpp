// SPDX-License-Identifier: GPL-3.0-or-later
// Smoothing kernels of SPEC §3 (Dehnen & Aly 2012; Morris 1996).
//
// Every kernel is written as W(r) = C_n / H^n * f(q), q = r / H, with H the support radius
// (H = D_K / 2). A "shape" type provides f(q), f'(q)/q (finite at q = 0, so the gradient of the
// self pair is exactly zero without a branch) and the normalisation C_n. `Kernel<Shape, Dim>`
// binds a shape to a support radius and a dimension.
#pragma once

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "sim/name_table.hpp"

namespace sphles::sim {

enum class KernelType { WendlandC2, WendlandC4, WendlandC6, QuinticSpline };

/// Canonical scene-file names: "wendland_c2", "wendland_c4", "wendland_c6", "quintic_spline".
std::string_view kernel_name(KernelType type);

namespace kernel_shape {

/// Wendland C2: f = (1-q)^4 (1 + 4q); σ_3D = 21/(2π), σ_2D = 7/π (SPEC §3).
struct WendlandC2 {
  static constexpr KernelType type = KernelType::WendlandC2;
  static constexpr std::string_view name = "wendland_c2";
  static double value(double q) {
    const double a = 1.0 - q;
    const double a2 = a * a;
    return q < 1.0 ? a2 * a2 * (1.0 + 4.0 * q) : 0.0;
  }
  // f'(q) = -20 q (1-q)^3
  static double derivative_over_q(double q) {
    const double a = 1.0 - q;
    return q < 1.0 ? -20.0 * a * a * a : 0.0;
  }
  static double normalisation(int dim) {
    return dim == 3 ? 21.0 / (2.0 * std::numbers::pi) : 7.0 / std::numbers::pi;
  }
};

/// Wendland C4: f = (1-q)^6 (1 + 6q + 35/3 q²); σ_3D = 495/(32π), σ_2D = 9/π (SPEC §3).
struct WendlandC4 {
  static constexpr KernelType type = KernelType::WendlandC4;
  static constexpr std::string_view name = "wendland_c4";
  static double value(double q) {
    const double a = 1.0 - q;
    const double a2 = a * a;
    return q < 1.0 ? a2 * a2 * a2 * (1.0 + 6.0 * q + (35.0 / 3.0) * q * q) : 0.0;
  }
  // f'(q) = -(56/3) q (1-q)^5 (1 + 5q)
  static double derivative_over_q(double q) {
    const double a = 1.0 - q;
    const double a2 = a * a;
    return q < 1.0 ? -(56.0 / 3.0) * a2 * a2 * a * (1.0 + 5.0 * q) : 0.0;
  }
  static double normalisation(int dim) {
    return dim == 3 ? 495.0 / (32.0 * std::numbers::pi) : 9.0 / std::numbers::pi;
  }
};

/// Wendland C6: f = (1-q)^8 (1 + 8q + 25q² + 32q³); σ_3D = 1365/(64π), σ_2D = 78/(7π) (SPEC §3).
struct WendlandC6 {
  static constexpr KernelType type = KernelType::WendlandC6;
  static constexpr std::string_view name = "wendland_c6";
  static double value(double q) {
    const double a = 1.0 - q;
    const double a2 = a * a;
    const double a4 = a2 * a2;
    return q < 1.0 ? a4 * a4 * (1.0 + q * (8.0 + q * (25.0 + 32.0 * q))) : 0.0;
  }
  // f'(q) = -22 q (1-q)^7 (1 + 7q + 16q²)
  static double derivative_over_q(double q) {
    const double a = 1.0 - q;
    const double a2 = a * a;
    const double a4 = a2 * a2;
    return q < 1.0 ? -22.0 * a4 * a2 * a * (1.0 + q * (7.0 + 16.0 * q)) : 0.0;
  }
  static double normalisation(int dim) {
    return dim == 3 ? 1365.0 / (64.0 * std::numbers::pi) : 78.0 / (7.0 * std::numbers::pi);
  }
};

/// Quintic spline (Morris 1996) in s = r/h with H = 3h, rewritten in q = s/3:
/// g(s) = (3-s)^5 - 6(2-s)^5 + 15(1-s)^5 (s<1), ... (SPEC §3); σ_3D = 1/(120π h³) becomes
/// C_3 = 27/(120π), σ_2D = 7/(478π h²) becomes C_2 = 63/(478π).
struct QuinticSpline {
  static constexpr KernelType type = KernelType::QuinticSpline;
  static constexpr std::string_view name = "quintic_spline";
  static double value(double q) {
    const double s = 3.0 * q;
    const auto p5 = [](double x) { return x * x * x * x * x; };
    if (s < 1.0) return p5(3.0 - s) - 6.0 * p5(2.0 - s) + 15.0 * p5(1.0 - s);
    if (s < 2.0) return p5(3.0 - s) - 6.0 * p5(2.0 - s);
    if (s < 3.0) return p5(3.0 - s);
    return 0.0;
  }
  // f'(q)/q = 9 g'(s)/s. For s < 1, g'(s)/s = -120 + 120 s² - 50 s³ (expanded, finite at s = 0).
  static double derivative_over_q(double q) {
    const double s = 3.0 * q;
    const auto p4 = [](double x) { return x * x * x * x; };
    if (s < 1.0) return 9.0 * (-120.0 + s * s * (120.0 - 50.0 * s));
    if (s < 2.0) return 9.0 * (-5.0 * (p4(3.0 - s) - 6.0 * p4(2.0 - s))) / s;
    if (s < 3.0) return 9.0 * (-5.0 * p4(3.0 - s)) / s;
    return 0.0;
  }
  static double normalisation(int dim) {
    return dim == 3 ? 27.0 / (120.0 * std::numbers::pi) : 63.0 / (478.0 * std::numbers::pi);
  }
};

}  // namespace kernel_shape

template <class... Shapes>
struct KernelShapeList {};

/// The registry: every kernel shape a scene may name. Adding a kernel is its shape struct (with
/// `type`, `name`, `value`, `derivative_over_q`, `normalisation`), its KernelType value and one
/// entry here; names, parsing and with_kernel follow from this list.
using KernelRegistry = KernelShapeList<kernel_shape::WendlandC2, kernel_shape::WendlandC4,
                                       kernel_shape::WendlandC6, kernel_shape::QuinticSpline>;

/// The kernels' scene names, from the registry.
inline constexpr auto kKernelNames = registry_names<KernelType>(KernelRegistry{});

/// Calls for_shape.template operator()<Shape>() for the registered shape of the given type.
template <class F, class First, class... Rest>
decltype(auto) visit_kernel_shape(KernelType type, F&& for_shape, KernelShapeList<First, Rest...>) {
  if (First::type == type) return for_shape.template operator()<First>();
  if constexpr (sizeof...(Rest) > 0) {
    return visit_kernel_shape(type, std::forward<F>(for_shape), KernelShapeList<Rest...>{});
  } else {
    throw std::invalid_argument("unknown kernel type");
  }
}

/// A kernel shape bound to a support radius H in `Dim` dimensions.
template <class Shape, int Dim>
class Kernel {
 public:
  static_assert(Dim == 2 || Dim == 3, "kernels are defined for 2D and 3D");
  using shape = Shape;
  static constexpr int dimension = Dim;

  explicit Kernel(double support_radius)
      : support_radius_(support_radius),
        inv_support_radius_(1.0 / support_radius),
        value_factor_(Shape::normalisation(Dim) / std::pow(support_radius, Dim)),
        gradient_factor_(value_factor_ / (support_radius * support_radius)) {
    if (!(support_radius > 0.0)) throw std::invalid_argument("kernel support radius must be > 0");
  }

  double support_radius() const { return support_radius_; }

  /// W(r).
  double value(double r) const { return value_factor_ * Shape::value(r * inv_support_radius_); }

  /// (1/r) dW/dr, so that ∇_i W_ij = gradient_over_r(r_ij) * x_ij; zero at r = 0.
  double gradient_over_r(double r) const {
    return gradient_factor_ * Shape::derivative_over_q(r * inv_support_radius_);
  }

 private:
  double support_radius_;
  double inv_support_radius_;
  double value_factor_;     // C_n / H^n
  double gradient_factor_;  // C_n / H^(n+2): (1/r) dW/dr = C_n/H^n * f'(q)/(q H²)
};

/// Calls f(Kernel<Shape, Dim>{support_radius}) for the runtime kernel type and dimension, so that
/// templated loops are instantiated once per combination (one factory for all runtime choices).
template <class F>
decltype(auto) with_kernel(KernelType type, int dim, double support_radius, F&& f) {
  const auto for_dim = [&]<class Shape>() -> decltype(auto) {
    if (dim == 2) return f(Kernel<Shape, 2>(support_radius));
    if (dim != 3) throw std::invalid_argument("kernel dimension must be 2 or 3");
    return f(Kernel<Shape, 3>(support_radius));
  };
  return visit_kernel_shape(type, for_dim, KernelRegistry{});
}

/// The kernel's Fourier transform normalised to Ŵ(0) = 1, at wavenumber k for support radius H:
/// the transfer function of the filter an SPH-LES applies to the flow (SPEC §1: the particles
/// carry the kernel-filtered velocity, so their spectrum is Ŵ(k)² E(k) of the flow's). Radial
/// integrals of the shape, 4π ∫ W r² sin(kr)/(kr) dr in 3D and 2π ∫ W r J₀(kr) dr in 2D.
double kernel_transfer(KernelType type, int dim, double support_radius, double wavenumber);

}  // namespace sphles::sim
