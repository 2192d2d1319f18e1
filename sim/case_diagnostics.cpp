// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/case_diagnostics.hpp"

#include <array>
#include <cmath>

namespace sphles::sim {

std::vector<std::string> case_diagnostic_names(const Scene& scene) {
  if (scene.case_type == CaseType::Kolmogorov2D)
    return {"energy_injection", "film_dissipation", "u_rms"};
  return {};
}

std::vector<ExactSum> case_diagnostic_sums(const Scene& scene, const ParticleArrays& p,
                                           std::size_t n) {
  if (scene.case_type != CaseType::Kolmogorov2D) return {};
  const double k = scene.forcing_wavenumber();
  // Σ M, Σ M χ sin(k_y y) v_x, Σ M |v|² (4.3): exact, so the same bits in whatever order and
  // split the particles come (one process, MPI ranks).
  const std::array<ExactSum, 3> sums = exact_sums<3>(n, [&](std::size_t i, auto& term) {
    term[0] = p.mass[i];
    term[1] =
        p.mass[i] * scene.forcing.amplitude * std::sin(k * p.position[1][i]) * p.velocity[0][i];
    term[2] =
        p.mass[i] * (p.velocity[0][i] * p.velocity[0][i] + p.velocity[1][i] * p.velocity[1][i]);
  });
  return {sums.begin(), sums.end()};
}

std::vector<double> case_diagnostics_from_sums(const Scene& scene, std::span<const ExactSum> sums) {
  if (scene.case_type != CaseType::Kolmogorov2D) return {};
  const double mass = sums[0].value(), injection = sums[1].value(), v2 = sums[2].value();
  return {injection / mass, scene.forcing.friction * v2 / mass, std::sqrt(v2 / mass)};  // (4.3)
}

std::vector<double> case_diagnostics(const Scene& scene, const ParticleArrays& p) {
  return case_diagnostics_from_sums(scene, case_diagnostic_sums(scene, p, p.size()));
}

}  // namespace sphles::sim
