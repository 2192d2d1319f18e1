// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/local_fit.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "analysis/cell_list.hpp"

namespace sphles::analysis {

namespace {

void check_fit(const Grid& grid, const sim::ParticleArrays& particles, const FitSettings& fit,
               const char* what) {
  check_particles(grid, particles, what);
  if (particles.volume.size() != particles.size())
    throw std::invalid_argument(std::string(what) + ": particle volumes missing");
  if (!(fit.radius > 0.0) || !(2.0 * fit.radius <= grid.length))
    throw std::invalid_argument(std::string(what) +
                                ": fit radius must be > 0 and at most half the box length");
}

/// The particles within R of `point` as fit points (ξ = offset / R, weight W_R(r) V_j), in the
/// fixed order of for_each_particle_within.
template <int Dim, class KernelT>
void gather_fit_points(const KernelT& weight, const CellList& cells,
                       const std::vector<int>& offsets, const std::array<double, 3>& point,
                       double length, const sim::ParticleArrays& particles,
                       std::vector<FitPoint>& points) {
  const double radius = weight.support_radius();
  const double inv_radius = 1.0 / radius;
  points.clear();
  for_each_particle_within<Dim>(
      cells, offsets, point, radius, length,
      [&](std::uint32_t j, const std::array<double, 3>& offset, double r2) {
        FitPoint p;
        for (int d = 0; d < 3; ++d) p.xi[static_cast<std::size_t>(d)] = offset[d] * inv_radius;
        p.weight = weight.value(std::sqrt(r2)) * particles.volume[j];
        p.index = j;
        points.push_back(p);
      });
}

template <int Dim, class KernelT>
void gradient_fill(const KernelT& weight, const CellList& cells, const Grid& grid,
                   const sim::ParticleArrays& particles,
                   std::vector<sim::VelocityGradient>& gradient) {
  const std::vector<int> offsets = gather_offsets(cells);
  const auto n = static_cast<std::ptrdiff_t>(gradient.size());
  const auto velocity = [&](std::uint32_t j, int f) { return particles.velocity[f][j]; };
#pragma omp parallel
  {
    std::vector<FitPoint> points;
    PolynomialFitter<Dim, kGradientFitDegree, Dim> fitter;
#pragma omp for schedule(dynamic, 256)
    for (std::ptrdiff_t si = 0; si < n; ++si) {
      const auto i = static_cast<std::size_t>(si);
      std::array<double, 3> x{0.0, 0.0, 0.0};
      for (int d = 0; d < Dim; ++d) x[d] = particles.position[d][i];
      gather_fit_points<Dim>(weight, cells, offsets, x, grid.length, particles, points);
      const FitResult<Dim> fit = fitter.fit(points, weight.support_radius(), velocity);
      sim::VelocityGradient& j = gradient[i];
      j = {};
      for (int a = 0; a < Dim; ++a)
        for (int b = 0; b < Dim; ++b) j[a][b] = fit.gradient[a][b];
    }
  }
}

template <int Dim, int Fields, class KernelT>
void sample_fill(const KernelT& weight, const CellList& cells, const Grid& grid,
                 const sim::ParticleArrays& particles,
                 std::span<const std::span<const double>> fields,
                 std::span<const std::size_t> nodes, std::vector<std::vector<double>>& out) {
  const std::vector<int> offsets = gather_offsets(cells);
  const std::size_t count = nodes.empty() ? grid.size() : nodes.size();
  const auto signed_count = static_cast<std::ptrdiff_t>(count);
  const auto m = static_cast<std::size_t>(grid.points_per_side);
  const double h = grid.spacing();
  const auto value = [&](std::uint32_t j, int f) { return fields[f][j]; };
#pragma omp parallel
  {
    std::vector<FitPoint> points;
    PolynomialFitter<Dim, kInterpolationFitDegree, Fields> fitter;
#pragma omp for schedule(dynamic, 256)
    for (std::ptrdiff_t sk = 0; sk < signed_count; ++sk) {
      const auto k = static_cast<std::size_t>(sk);
      const std::size_t node = nodes.empty() ? k : nodes[k];
      const std::array<double, 3> x{static_cast<double>(node % m) * h,
                                    static_cast<double>((node / m) % m) * h,
                                    Dim == 3 ? static_cast<double>(node / (m * m)) * h : 0.0};
      gather_fit_points<Dim>(weight, cells, offsets, x, grid.length, particles, points);
      const FitResult<Fields> fit = fitter.fit(points, weight.support_radius(), value);
      for (int f = 0; f < Fields; ++f) out[f][k] = fit.value[f];
    }
  }
}

}  // namespace

std::vector<sim::VelocityGradient> fitted_velocity_gradient(const Grid& grid,
                                                            const sim::ParticleArrays& particles,
                                                            const FitSettings& fit,
                                                            std::size_t centres) {
  check_fit(grid, particles, fit, "fitted velocity gradient");
  for (int d = 0; d < grid.dimension; ++d)
    if (particles.velocity[d].size() != particles.size())
      throw std::invalid_argument(
          "fitted velocity gradient: velocity arrays do not match the particles");
  const CellList cells = build_gather_cell_list(grid, particles, fit.radius);
  std::vector<sim::VelocityGradient> gradient(std::min(centres, particles.size()));
  sim::with_kernel(fit.weight, grid.dimension, fit.radius, [&](const auto& weight) {
    constexpr int kDim = std::remove_cvref_t<decltype(weight)>::dimension;
    gradient_fill<kDim>(weight, cells, grid, particles, gradient);
  });
  return gradient;
}

std::vector<std::vector<double>> fitted_sample(const Grid& grid,
                                               const sim::ParticleArrays& particles,
                                               const FitSettings& fit,
                                               std::span<const std::span<const double>> fields,
                                               std::span<const std::size_t> nodes) {
  check_fit(grid, particles, fit, "fitted sample");
  if (fields.empty() || fields.size() > 3)
    throw std::invalid_argument("fitted sample: between 1 and 3 fields");
  for (const std::span<const double> f : fields)
    if (f.size() != particles.size())
      throw std::invalid_argument("fitted sample: a field does not have one value per particle");
  for (const std::size_t node : nodes)
    if (node >= grid.size()) throw std::invalid_argument("fitted sample: node outside the grid");
  const CellList cells = build_gather_cell_list(grid, particles, fit.radius);
  const std::size_t count = nodes.empty() ? grid.size() : nodes.size();
  std::vector<std::vector<double>> out(fields.size(), std::vector<double>(count));
  sim::with_kernel(fit.weight, grid.dimension, fit.radius, [&](const auto& weight) {
    constexpr int kDim = std::remove_cvref_t<decltype(weight)>::dimension;
    switch (fields.size()) {
      case 1:
        sample_fill<kDim, 1>(weight, cells, grid, particles, fields, nodes, out);
        break;
      case 2:
        sample_fill<kDim, 2>(weight, cells, grid, particles, fields, nodes, out);
        break;
      default:
        sample_fill<kDim, 3>(weight, cells, grid, particles, fields, nodes, out);
    }
  });
  return out;
}

}  // namespace sphles::analysis
