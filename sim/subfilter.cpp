#include "sim/subfilter.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace sphles::sim {

namespace {
constexpr std::array<std::pair<SubfilterModel, std::string_view>, 4> kModelNames{{
    {SubfilterModel::Implicit, "implicit"},
    {SubfilterModel::Smagorinsky, "smag"},
    {SubfilterModel::Sigma, "sigma"},
    {SubfilterModel::SmagorinskyMcg, "smag_mcg"},
}};
}  // namespace

std::string_view subfilter_model_name(SubfilterModel model) {
  for (const auto& [m, name] : kModelNames)
    if (m == model) return name;
  return "unknown";
}

SubfilterModel subfilter_model_from_name(std::string_view name) {
  std::string valid;
  for (const auto& [m, n] : kModelNames) {
    if (n == name) return m;
    valid += (valid.empty() ? "" : ", ") + std::string(n);
  }
  throw std::invalid_argument("unknown sub-filter model '" + std::string(name) +
                              "' (valid: " + valid + ")");
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
  Eigen::Matrix3d g;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) g(a, b) = j[a][b];
  // Singular values of J are the square roots of the eigenvalues of JᵀJ (ascending here).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(g.transpose() * g,
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
  switch (c.model) {
    case SubfilterModel::Implicit:
      return 0.0;
    case SubfilterModel::Smagorinsky:
    case SubfilterModel::SmagorinskyMcg: {
      const double cs_delta = c.smagorinsky_constant * width;
      return smagorinsky_viscosity(gradient, cs_delta * cs_delta);
    }
    case SubfilterModel::Sigma: {
      const double c_delta = c.sigma_constant * width;
      return sigma_viscosity(gradient, c_delta * c_delta);
    }
  }
  return 0.0;
}

}  // namespace sphles::sim
