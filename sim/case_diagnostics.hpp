// SPDX-License-Identifier: GPL-3.0-or-later
// The scalars a case adds to a run's time series (SPEC §6.3 for the Kolmogorov flow), summed so
// that one process and any split over MPI ranks give the same bits.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "sim/particles.hpp"
#include "sim/reduction.hpp"
#include "sim/scene.hpp"

namespace sphles::sim {

/// Per-step scalars a case adds to the time series, after the standard columns. kolmogorov2d:
/// energy_injection = ⟨χ sin(k_y y) v_x⟩, film_dissipation = μ⟨|v|²⟩, u_rms = sqrt(⟨|v|²⟩)
/// (mass-weighted averages, SPEC (4.3)); the Taylor-Green cases add none.
std::vector<std::string> case_diagnostic_names(const Scene& scene);
std::vector<double> case_diagnostics(const Scene& scene, const ParticleArrays& particles);
/// The same in two halves, for particles spread over processes: the exact sums over particles
/// [0, n) (a process' owned ones), which combine bitwise in any order (ExactSum), and the
/// diagnostics from the sums over every particle.
std::vector<ExactSum> case_diagnostic_sums(const Scene& scene, const ParticleArrays& particles,
                                           std::size_t n);
std::vector<double> case_diagnostics_from_sums(const Scene& scene, std::span<const ExactSum> sums);

}  // namespace sphles::sim
