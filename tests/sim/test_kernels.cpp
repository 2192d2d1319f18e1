// SPDX-License-Identifier: GPL-3.0-or-later
// Kernels of SPEC §3: normalisation, gradient and compact support, every kernel in 2D and 3D.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "scene/json_reader.hpp"
#include "sim/kernels.hpp"

namespace sphles::sim {
namespace {

template <class Shape, int Dim>
struct Case {
  using shape = Shape;
  static constexpr int dim = Dim;
};

template <class C>
class KernelTest : public ::testing::Test {};

/// Every registered kernel (sim::KernelRegistry) in 2D and 3D: a kernel added to the registry is
/// tested without touching this file.
template <class... Shapes>
::testing::Types<Case<Shapes, 2>..., Case<Shapes, 3>...> all_cases(KernelShapeList<Shapes...>);
using AllKernels = decltype(all_cases(KernelRegistry{}));
TYPED_TEST_SUITE(KernelTest, AllKernels);

// Names round-trip for every registered kernel, and an unknown name lists the valid ones.
template <class Shape>
void check_name() {
  EXPECT_EQ(kKernelNames.find(Shape::name), Shape::type);
  EXPECT_EQ(kernel_name(Shape::type), Shape::name);
}
template <class... Shapes>
void check_names(KernelShapeList<Shapes...>) {
  (check_name<Shapes>(), ...);
}
TEST(KernelRegistry, NamesRoundTripAndUnknownNamesListTheValidOnes) {
  check_names(KernelRegistry{});
  try {
    parse_name(kKernelNames, "gaussian", "kernel.type");
    FAIL() << "an unknown kernel was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "kernel.type");
    EXPECT_NE(std::string(e.what()).find("must be one of wendland_c2, wendland_c4, wendland_c6, "
                                         "quintic_spline, got 'gaussian'"),
              std::string::npos)
        << e.what();
  }
}

/// Composite Simpson rule on [a, b] with n (even) intervals.
template <class F>
double simpson(F&& f, double a, double b, int n) {
  const double h = (b - a) / n;
  double s = f(a) + f(b);
  for (int k = 1; k < n; ++k) s += (k % 2 ? 4.0 : 2.0) * f(a + k * h);
  return s * h / 3.0;
}

TYPED_TEST(KernelTest, IntegratesToOne) {
  constexpr int dim = TypeParam::dim;
  for (const double support : {0.37, 1.0, 2.5}) {
    const Kernel<typename TypeParam::shape, dim> kernel(support);
    const auto shell = [&](double r) {
      const double measure = dim == 3 ? 4.0 * std::numbers::pi * r * r : 2.0 * std::numbers::pi * r;
      return measure * kernel.value(r);
    };
    // Integrate piecewise over thirds of the support so that the quintic spline's breakpoints
    // (s = 1, 2) are interval ends and Simpson's rule is exact to round-off on each piece.
    double integral = 0.0;
    for (int piece = 0; piece < 3; ++piece)
      integral += simpson(shell, piece * support / 3.0, (piece + 1) * support / 3.0, 600);
    EXPECT_NEAR(integral, 1.0, 1e-6) << "support radius " << support;
  }
}

TYPED_TEST(KernelTest, GradientMatchesFiniteDifference) {
  constexpr int dim = TypeParam::dim;
  const double support = 1.3;
  const Kernel<typename TypeParam::shape, dim> kernel(support);
  for (int k = 1; k < 100; ++k) {
    const double r = support * k / 100.0;
    const double h = 1e-6 * support;
    const double finite_difference = (kernel.value(r + h) - kernel.value(r - h)) / (2.0 * h);
    const double analytic = kernel.gradient_over_r(r) * r;
    const double scale = std::abs(kernel.gradient_over_r(0.5 * support)) * support;
    EXPECT_NEAR(analytic, finite_difference, 1e-7 * scale) << "r/H = " << r / support;
  }
}

// Ŵ(k) by the radial quadrature against the kernel summed over a fine lattice,
// Σ_j Δl^n W(|x_j|) cos(k·x_j), along an axis and a diagonal (the transform depends on |k| only).
TYPED_TEST(KernelTest, TransferMatchesTheLatticeSumInEveryDirection) {
  constexpr int dim = TypeParam::dim;
  using Shape = typename TypeParam::shape;
  const double support = 0.9;
  const Kernel<Shape, dim> kernel(support);
  const int n = dim == 3 ? 24 : 60;  // lattice points per support radius
  const double dl = support / n;
  EXPECT_NEAR(kernel_transfer(Shape::type, dim, support, 0.0), 1.0, 1e-12);
  for (const double kh : {0.5, 1.5, std::numbers::pi, 5.0}) {
    const double k = kh / support;
    const double on_axis = kernel_transfer(Shape::type, dim, support, k);
    double axis_sum = 0.0, diagonal_sum = 0.0;
    const double diagonal = k / std::sqrt(static_cast<double>(dim));
    for (int i = -n; i <= n; ++i)
      for (int j = -n; j <= n; ++j)
        for (int l = (dim == 3 ? -n : 0); l <= (dim == 3 ? n : 0); ++l) {
          const double r = dl * std::sqrt(static_cast<double>(i * i + j * j + l * l));
          const double w = kernel.value(r) * std::pow(dl, dim);
          axis_sum += w * std::cos(k * dl * i);
          diagonal_sum += w * std::cos(diagonal * dl * (i + j + l));
        }
    EXPECT_NEAR(on_axis, axis_sum, 2e-5) << "k H = " << kh;
    EXPECT_NEAR(on_axis, diagonal_sum, 2e-5) << "k H = " << kh;
  }
  // The filter damps: below one and falling over the resolved range.
  EXPECT_LT(kernel_transfer(Shape::type, dim, support, 2.0 / support),
            kernel_transfer(Shape::type, dim, support, 1.0 / support));
  EXPECT_THROW(kernel_transfer(Shape::type, 4, support, 1.0), std::invalid_argument);
  EXPECT_THROW(kernel_transfer(Shape::type, dim, 0.0, 1.0), std::invalid_argument);
}

TYPED_TEST(KernelTest, CompactSupportAndShape) {
  constexpr int dim = TypeParam::dim;
  const double support = 0.8;
  const Kernel<typename TypeParam::shape, dim> kernel(support);
  EXPECT_EQ(kernel.value(support), 0.0);
  EXPECT_EQ(kernel.value(1.5 * support), 0.0);
  EXPECT_EQ(kernel.gradient_over_r(support), 0.0);
  EXPECT_EQ(kernel.gradient_over_r(2.0 * support), 0.0);
  EXPECT_GT(kernel.value(0.999 * support), 0.0);
  // Finite gradient factor at r = 0 (the self pair contributes exactly zero force).
  EXPECT_TRUE(std::isfinite(kernel.gradient_over_r(0.0)));
  // Positive and monotonically decreasing inside the support.
  double previous = kernel.value(0.0);
  for (int k = 1; k < 200; ++k) {
    const double w = kernel.value(support * k / 200.0);
    EXPECT_GT(w, 0.0);
    EXPECT_LT(w, previous);
    EXPECT_LE(kernel.gradient_over_r(support * k / 200.0), 0.0);
    previous = w;
  }
}

TEST(KernelNames, RoundTripAndError) {
  for (const auto type : {KernelType::WendlandC2, KernelType::WendlandC4, KernelType::WendlandC6,
                          KernelType::QuinticSpline})
    EXPECT_EQ(kKernelNames.find(kernel_name(type)), type);
  EXPECT_EQ(kKernelNames.find("cubic"), std::nullopt);
  try {
    parse_name(kKernelNames, "cubic", "kernel.type");
    FAIL() << "expected an exception";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("got 'cubic'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("wendland_c4"), std::string::npos);
  }
}

TEST(KernelDispatch, PicksShapeAndDimension) {
  const double w = with_kernel(KernelType::WendlandC2, 2, 1.0, [](const auto& k) {
    EXPECT_EQ(std::decay_t<decltype(k)>::dimension, 2);
    return k.value(0.0);
  });
  EXPECT_DOUBLE_EQ(w, 7.0 / std::numbers::pi);
  EXPECT_THROW(with_kernel(KernelType::WendlandC2, 4, 1.0, [](const auto&) { return 0.0; }),
               std::invalid_argument);
}

}  // namespace
}  // namespace sphles::sim
