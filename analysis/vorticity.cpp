// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/vorticity.hpp"

#include <stdexcept>
#include <string>
#include <type_traits>

#include "sim/reduction.hpp"

namespace sphles::analysis {

namespace {

void check_field(const VectorField& field, const char* what) {
  const Grid& grid = field.grid;
  if (grid.dimension != 2 && grid.dimension != 3)
    throw std::invalid_argument(std::string(what) + ": dimension must be 2 or 3");
  if (grid.points_per_side <= 0 || !(grid.length > 0.0))
    throw std::invalid_argument(std::string(what) + ": empty grid");
  for (int d = 0; d < grid.dimension; ++d)
    if (field.component[d].size() != grid.size())
      throw std::invalid_argument(std::string(what) + ": component size does not match the grid");
}

}  // namespace

VectorField vorticity(const VectorField& velocity) {
  check_field(velocity, "vorticity");
  const Grid& grid = velocity.grid;
  const int m = grid.points_per_side;
  const double inv_2h = 0.5 / grid.spacing();
  const auto& u = velocity.component;
  VectorField omega;
  omega.grid = grid;
  const auto up = [m](int i) { return i + 1 == m ? 0 : i + 1; };
  const auto down = [m](int i) { return i == 0 ? m - 1 : i - 1; };

  if (grid.dimension == 2) {
    // ω_z = ∂v/∂x - ∂u/∂y, central differences (u(x+h) - u(x-h)) / 2h with periodic wrap.
    std::vector<double>& omega_z = omega.component[2];
    omega_z.resize(grid.size());
#pragma omp parallel for schedule(static)
    for (int j = 0; j < m; ++j) {
      for (int i = 0; i < m; ++i) {
        const double dv_dx = (u[1][grid.index(up(i), j)] - u[1][grid.index(down(i), j)]) * inv_2h;
        const double du_dy = (u[0][grid.index(i, up(j))] - u[0][grid.index(i, down(j))]) * inv_2h;
        omega_z[grid.index(i, j)] = dv_dx - du_dy;
      }
    }
    return omega;
  }

  for (auto& c : omega.component) c.resize(grid.size());
#pragma omp parallel for schedule(static)
  for (int k = 0; k < m; ++k) {
    for (int j = 0; j < m; ++j) {
      for (int i = 0; i < m; ++i) {
        const std::size_t xp = grid.index(up(i), j, k), xm = grid.index(down(i), j, k);
        const std::size_t yp = grid.index(i, up(j), k), ym = grid.index(i, down(j), k);
        const std::size_t zp = grid.index(i, j, up(k)), zm = grid.index(i, j, down(k));
        const std::size_t n = grid.index(i, j, k);
        // ω = (∂w/∂y - ∂v/∂z, ∂u/∂z - ∂w/∂x, ∂v/∂x - ∂u/∂y).
        omega.component[0][n] = ((u[2][yp] - u[2][ym]) - (u[1][zp] - u[1][zm])) * inv_2h;
        omega.component[1][n] = ((u[0][zp] - u[0][zm]) - (u[2][xp] - u[2][xm])) * inv_2h;
        omega.component[2][n] = ((u[1][xp] - u[1][xm]) - (u[0][yp] - u[0][ym])) * inv_2h;
      }
    }
  }
  return omega;
}

std::vector<double> squared_magnitude(const VectorField& field) {
  const std::size_t nodes = field.grid.size();
  std::vector<double> result(nodes, 0.0);
  for (const std::vector<double>& c : field.component) {
    if (c.empty()) continue;  // unused components (2D velocity, 2D vorticity)
    if (c.size() != nodes)
      throw std::invalid_argument("squared_magnitude: component size does not match the grid");
    for (std::size_t n = 0; n < nodes; ++n) result[n] += c[n] * c[n];
  }
  return result;
}

std::vector<double> ParticleVorticity::squared_magnitude() const {
  const std::size_t n = size();
  std::vector<double> result(n, 0.0);
  for (const std::vector<double>& c : component) {
    if (c.empty()) continue;  // 2D: ω_x, ω_y
    for (std::size_t i = 0; i < n; ++i) result[i] += c[i] * c[i];
  }
  return result;
}

ParticleVorticity particle_vorticity(const Snapshot& snapshot,
                                     const sim::NeighbourList& neighbours) {
  const sim::ParticleArrays& p = snapshot.particles;
  const int dim = snapshot.dimension();
  if (dim != 2 && dim != 3)
    throw std::invalid_argument("particle vorticity: dimension must be 2 or 3");
  if (p.dimension != dim)
    throw std::invalid_argument("particle vorticity: particle and box dimensions differ");
  if (neighbours.num_particles() != p.size())
    throw std::invalid_argument("particle vorticity: neighbour list does not match the particles");
  if (p.volume.size() != p.size())
    throw std::invalid_argument("particle vorticity: particle volumes missing");

  std::vector<sim::VelocityGradient> gradient;
  sim::with_kernel(snapshot.kernel, dim, snapshot.support_radius, [&](const auto& kernel) {
    constexpr int kDim = std::remove_cvref_t<decltype(kernel)>::dimension;
    sim::velocity_gradient_pass<kDim>(kernel, snapshot.box, neighbours, sim::view_velocity(p), p,
                                      gradient);  // (A.20)
  });
  ParticleVorticity omega;
  omega.dimension = dim;
  const std::size_t n = p.size();
  for (int a = dim == 3 ? 0 : 2; a < 3; ++a) omega.component[a].resize(n);
  const auto signed_n = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t si = 0; si < signed_n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    const std::array<double, 3> w = curl(gradient[i]);
    for (int a = dim == 3 ? 0 : 2; a < 3; ++a) omega.component[a][i] = w[a];
  }
  return omega;
}

ParticleVorticity fitted_particle_vorticity(const Snapshot& snapshot, const Grid& grid,
                                            const FitSettings& fit) {
  return fitted_particle_vorticity(snapshot.particles, grid, fit, snapshot.size());
}

ParticleVorticity fitted_particle_vorticity(const sim::ParticleArrays& p, const Grid& grid,
                                            const FitSettings& fit, std::size_t centres) {
  const int dim = grid.dimension;
  const std::vector<sim::VelocityGradient> gradient =
      fitted_velocity_gradient(grid, p, fit, centres);
  ParticleVorticity omega;
  omega.dimension = dim;
  const std::size_t n = gradient.size();
  for (int a = dim == 3 ? 0 : 2; a < 3; ++a) omega.component[a].resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::array<double, 3> w = curl(gradient[i]);
    for (int a = dim == 3 ? 0 : 2; a < 3; ++a) omega.component[a][i] = w[a];
  }
  return omega;
}

std::array<sim::ExactSum, 2> volume_weighted_sums(const sim::ParticleArrays& particles,
                                                  const std::vector<double>& values) {
  if (values.size() > particles.size() || particles.volume.size() != particles.size())
    throw std::invalid_argument("volume-weighted mean: one value and one volume per particle");
  return sim::exact_sums<2>(values.size(), [&](std::size_t i, std::array<double, 2>& t) {
    t[0] = particles.volume[i] * values[i];
    t[1] = particles.volume[i];
  });
}

double volume_weighted_mean(const sim::ParticleArrays& particles,
                            const std::vector<double>& values) {
  if (values.size() != particles.size())
    throw std::invalid_argument("volume-weighted mean: one value and one volume per particle");
  if (values.empty()) return 0.0;
  const std::array<sim::ExactSum, 2> sums = volume_weighted_sums(particles, values);
  return sums[0].value() / sums[1].value();
}

std::shared_ptr<const sim::NeighbourList> snapshot_neighbours(const Snapshot& snapshot) {
  if (snapshot.neighbours && snapshot.neighbours->num_particles() == snapshot.size())
    return snapshot.neighbours;
  sim::VerletNeighbourSearch search(snapshot.box, snapshot.support_radius, 0.0);
  search.build(sim::view_positions(snapshot.particles));
  return search.shared_list();
}

std::vector<double> fitted_vorticity_squared(const Grid& grid, const sim::ParticleArrays& particles,
                                             const FitSettings& fit, const ParticleVorticity& omega,
                                             std::span<const std::size_t> nodes) {
  std::vector<std::span<const double>> components;
  for (const std::vector<double>& c : omega.component)
    if (!c.empty()) components.emplace_back(c);
  const std::vector<std::vector<double>> sampled =
      fitted_sample(grid, particles, fit, components, nodes);
  std::vector<double> squared(sampled.front().size(), 0.0);
  for (const std::vector<double>& c : sampled)
    for (std::size_t n = 0; n < squared.size(); ++n) squared[n] += c[n] * c[n];
  return squared;
}

double mean_value(const std::vector<double>& values) {
  if (values.empty()) return 0.0;
  return sim::deterministic_sum(values.size(), [&](std::size_t n) { return values[n]; }) /
         static_cast<double>(values.size());
}

}  // namespace sphles::analysis
