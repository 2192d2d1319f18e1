// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/subfilter.hpp"

#include "sim/eigen.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace sphles::sim {

std::string_view subfilter_model_name(SubfilterModel model) {
  return kSubfilterModelNames.name(model);
}

double smagorinsky_viscosity(const VelocityGradient& j, double scale) {
  double dd = 0.0;  // D:D with D = (J + Jᵀ)/2
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const double d = 0.5 * (j[a][b] + j[b][a]);
      dd += d * d;
    }
  return scale * std::sqrt(2.0 * dd);  // (A.21)
}

double sigma_viscosity(const VelocityGradient& j, double scale) {
  // 64-byte aligned, so that Eigen's address-dependent loop splitting is the same on every
  // thread's stack (thread-count determinism; see directional_weight in viscous_operator.hpp).
  alignas(64) Eigen::Matrix3d g;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) g(a, b) = j[a][b];
  alignas(64) const Eigen::Matrix3d gram = g.transpose() * g;
  // Singular values of J are the square roots of the eigenvalues of JᵀJ (ascending here).
  alignas(64) const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(gram,
                                                                          Eigen::EigenvaluesOnly);
  const Eigen::Vector3d lambda = solver.eigenvalues();
  const double s3 = std::sqrt(std::max(lambda(0), 0.0));
  const double s2 = std::sqrt(std::max(lambda(1), 0.0));
  const double s1 = std::sqrt(std::max(lambda(2), 0.0));
  if (!(s1 > 0.0)) return 0.0;
  const double d_sigma = s3 * (s1 - s2) * (s2 - s3) / (s1 * s1);  // (A.22)
  return scale * std::max(d_sigma, 0.0);
}

double eddy_viscosity(const SubfilterConfig& c, double kernel_diameter,
                      const VelocityGradient& gradient) {
  const double width = c.filter_width > 0.0 ? c.filter_width : kernel_diameter;
  return visit_subfilter_model(
      c.model, [&](auto model) { return decltype(model)::eddy_viscosity(c, width, gradient); });
}

}  // namespace sphles::sim
