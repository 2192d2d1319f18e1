// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/kernels.hpp"

#include <cmath>
#include <numbers>

namespace sphles::sim {

std::string_view kernel_name(KernelType type) {
  return kKernelNames.name(type);
}

namespace {

// Simpson intervals over q ∈ [0, 1]: a multiple of 6 puts the quintic spline's joints at
// q = 1/3 and 2/3 on nodes, and for k H up to 2π (k = 2 k_kern) the error is below 1e-10.
constexpr int kTransferIntervals = 600;

}  // namespace

double kernel_transfer(KernelType type, int dim, double support_radius, double wavenumber) {
  if (dim != 2 && dim != 3) throw std::invalid_argument("kernel dimension must be 2 or 3");
  if (!(support_radius > 0.0)) throw std::invalid_argument("kernel support radius must be > 0");
  const double x = std::abs(wavenumber) * support_radius;
  // ∫ f(q) q^(n-1) g(x q) dq over [0, 1], with g the radial Fourier factor of dimension n; the
  // same integral with g = 1 normalises (the shapes' C_n cancel).
  const auto integral = [&]<class Shape>(bool transformed) {
    const auto integrand = [&](double q) {
      const double radial = dim == 3 ? q * q : q;
      if (!transformed || x == 0.0) return Shape::value(q) * radial;
      const double xq = x * q;
      const double g =
          dim == 3 ? (xq == 0.0 ? 1.0 : std::sin(xq) / xq) : std::cyl_bessel_j(0.0, xq);
      return Shape::value(q) * radial * g;
    };
    const double h = 1.0 / kTransferIntervals;
    double sum = integrand(0.0) + integrand(1.0);
    for (int i = 1; i < kTransferIntervals; ++i) sum += (i % 2 ? 4.0 : 2.0) * integrand(i * h);
    return sum * h / 3.0;
  };
  return visit_kernel_shape(
      type,
      [&]<class Shape>() {
        return integral.template operator()<Shape>(true) /
               integral.template operator()<Shape>(false);
      },
      KernelRegistry{});
}

}  // namespace sphles::sim
