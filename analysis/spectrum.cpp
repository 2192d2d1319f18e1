// SPDX-License-Identifier: GPL-3.0-or-later
// Energy spectrum by FFTW r2c transforms (SPEC §5).
//
// FFTW usage: one plan per call, made with FFTW_ESTIMATE (no timing measurements, so the same
// grid always gets the same algorithm) on buffers from fftw_alloc_* (always SIMD-aligned, so
// the planner cannot pick different codelets from one call to the next because of alignment).
// FFTW's planner, fftw_destroy_plan and its allocator are not thread-safe: they run under one
// static mutex. Only fftw_execute, which is thread-safe, runs outside the lock, so concurrent
// calls on different threads transform in parallel. The transform itself is single-threaded.
#include "analysis/spectrum.hpp"

#include <fftw3.h>

#include <cmath>
#include <cstddef>
#include <mutex>
#include <numbers>
#include <stdexcept>

#include "analysis/fftw_r2c.hpp"
#include "sim/reduction.hpp"

namespace sphles::analysis {

namespace {

int signed_wavenumber(int q, int m) {
  return 2 * q <= m ? q : q - m;
}

/// An r2c plan of an M^n real array (x fastest, i.e. x is FFTW's last, halved dimension) with
/// its own input and output buffers.
R2cPlan real_to_complex_transform(int dimension, int points_per_side) {
  const auto m = static_cast<std::size_t>(points_per_side);
  std::size_t rows = 1;  // M^(n-1)
  for (int d = 1; d < dimension; ++d) rows *= m;
  return R2cPlan(rows * m, rows * (m / 2 + 1), [&](double* in, fftw_complex* out) {
    const int dims[3] = {points_per_side, points_per_side, points_per_side};
    return fftw_plan_dft_r2c(dimension, dims, in, out, FFTW_ESTIMATE);
  });
}

void check_velocity(const VectorField& velocity) {
  const Grid& grid = velocity.grid;
  if (grid.dimension != 2 && grid.dimension != 3)
    throw std::invalid_argument("energy spectrum: dimension must be 2 or 3");
  if (grid.points_per_side <= 0 || !(grid.length > 0.0))
    throw std::invalid_argument("energy spectrum: empty grid");
  for (int d = 0; d < grid.dimension; ++d)
    if (velocity.component[d].size() != grid.size())
      throw std::invalid_argument("energy spectrum: component size does not match the grid");
}

}  // namespace

ShellSums empty_shell_sums(int dimension, int points_per_side) {
  if (dimension != 2 && dimension != 3)
    throw std::invalid_argument("energy spectrum: dimension must be 2 or 3");
  if (points_per_side <= 0) throw std::invalid_argument("energy spectrum: empty grid");
  ShellSums sums;
  sums.dimension = dimension;
  sums.points_per_side = points_per_side;
  // Shell of every integer |k|² / Δk²: p = nint(|k| / Δk). No |k|/Δk is a half-integer, since
  // (p + ½)² is never an integer, so rounding has no ties.
  const int half = points_per_side / 2;  // largest |k| / Δk per axis
  const int max_q2 = dimension * half * half;
  sums.shell_of.resize(static_cast<std::size_t>(max_q2) + 1);
  for (int q2 = 0; q2 <= max_q2; ++q2)
    sums.shell_of[static_cast<std::size_t>(q2)] =
        static_cast<int>(std::lround(std::sqrt(static_cast<double>(q2))));
  const auto num_shells = static_cast<std::size_t>(sums.shell_of.back()) + 1;  // to the corner
  sums.modulus2.assign(num_shells, 0.0);
  sums.k2_modulus2.assign(num_shells, 0.0);
  return sums;
}

void add_transform_planes(ShellSums& sums, const double* interleaved, int first_plane, int planes) {
  const int m = sums.points_per_side;
  const int kx_count = m / 2 + 1;
  const int rows = sums.dimension == 3 ? m : 1;  // y rows per plane
  std::size_t n = 0;
  for (int plane = first_plane; plane < first_plane + planes; ++plane) {
    // 3D: the plane is z and its rows y; 2D: the plane is y.
    const int k_plane = signed_wavenumber(plane, m);
    for (int qy = 0; qy < rows; ++qy) {
      const int ky = sums.dimension == 3 ? signed_wavenumber(qy, m) : 0;
      for (int kx = 0; kx < kx_count; ++kx, ++n) {
        const double weight = (kx == 0 || 2 * kx == m) ? 1.0 : 2.0;
        const double re = interleaved[2 * n];
        const double im = interleaved[2 * n + 1];
        const double modulus2 = re * re + im * im;
        const int q2 = kx * kx + ky * ky + k_plane * k_plane;
        const auto shell = static_cast<std::size_t>(sums.shell_of[static_cast<std::size_t>(q2)]);
        sums.modulus2[shell] += weight * modulus2;
        sums.k2_modulus2[shell] += weight * modulus2 * q2;
      }
    }
  }
}

EnergySpectrum spectrum_from_shell_sums(const ShellSums& sums, double length) {
  // û = M^-n (FFTW output); E(k_p) = Σ_shell ½ |û|² / Δk (SPEC §5, Durran et al. 2017).
  EnergySpectrum spectrum;
  spectrum.delta_k = 2.0 * std::numbers::pi / length;
  double nodes = 1.0;
  for (int d = 0; d < sums.dimension; ++d) nodes *= sums.points_per_side;
  const double inv_nodes = 1.0 / nodes;
  const double scale = 0.5 * inv_nodes * inv_nodes / spectrum.delta_k;
  const std::size_t shells = sums.modulus2.size();
  spectrum.wavenumber.resize(shells);
  spectrum.energy.resize(shells);
  spectrum.k2_energy.resize(shells);
  const double delta_k2 = spectrum.delta_k * spectrum.delta_k;
  for (std::size_t p = 0; p < shells; ++p) {
    spectrum.wavenumber[p] = static_cast<double>(p) * spectrum.delta_k;
    spectrum.energy[p] = scale * sums.modulus2[p];
    spectrum.k2_energy[p] = scale * delta_k2 * sums.k2_modulus2[p];
  }
  return spectrum;
}

EnergySpectrum energy_spectrum(const VectorField& velocity) {
  check_velocity(velocity);
  const Grid& grid = velocity.grid;
  const int dim = grid.dimension;
  const int m = grid.points_per_side;
  ShellSums sums = empty_shell_sums(dim, m);
  const R2cPlan transform = real_to_complex_transform(dim, m);
  const std::size_t nodes = grid.size();
  const int planes = m;  // z (3D) or y (2D)
  for (int c = 0; c < dim; ++c) {
    const std::vector<double>& u = velocity.component[c];
    double* in = transform.input();
    for (std::size_t n = 0; n < nodes; ++n) in[n] = u[n];
    transform.execute();
    add_transform_planes(sums, reinterpret_cast<const double*>(transform.output()), 0, planes);
  }
  return spectrum_from_shell_sums(sums, grid.length);
}

double spectrum_energy(const EnergySpectrum& spectrum) {
  double sum = 0.0;
  for (double e : spectrum.energy) sum += e;
  return sum * spectrum.delta_k;
}

double spectral_dissipation(const EnergySpectrum& spectrum, double kinematic_viscosity,
                            double max_wavenumber) {
  // ε = 2ν Σ_p (Σ_shell |k|² ½|û|² / Δk) Δk (4.6), exact |k| per mode.
  double sum = 0.0;
  for (std::size_t p = 0; p < spectrum.k2_energy.size(); ++p)
    if (spectrum.wavenumber[p] <= max_wavenumber) sum += spectrum.k2_energy[p];
  return 2.0 * kinematic_viscosity * sum * spectrum.delta_k;
}

double grid_kinetic_energy(const VectorField& velocity) {
  check_velocity(velocity);
  const std::size_t nodes = velocity.grid.size();
  const int dim = velocity.grid.dimension;
  const double sum_u2 = sim::deterministic_sum(nodes, [&](std::size_t n) {
    double u2 = 0.0;
    for (int c = 0; c < dim; ++c) u2 += velocity.component[c][n] * velocity.component[c][n];
    return u2;
  });
  return 0.5 * sum_u2 / static_cast<double>(nodes);
}

}  // namespace sphles::analysis
