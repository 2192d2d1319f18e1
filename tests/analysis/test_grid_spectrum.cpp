// SPDX-License-Identifier: GPL-3.0-or-later
// Gridding, vorticity and energy spectra (SPEC §5) against brute force, analytic fields and
// discrete identities (Parseval, single Fourier modes, a synthetic k^(-5/3) spectrum).
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "analysis/grid.hpp"
#include "analysis/spectrum.hpp"
#include "analysis/vorticity.hpp"
#include "sim/packing.hpp"

namespace sphles::analysis {
namespace {

constexpr double kPi = std::numbers::pi;

Grid make_grid(int dim, int m, double length) {
  return {.dimension = dim, .points_per_side = m, .length = length};
}

using VectorFunction = std::function<std::array<double, 3>(double, double, double)>;

/// Samples f at the nodes (i h, j h, k h); components >= dim stay empty.
VectorField sample_function(const Grid& grid, const VectorFunction& f) {
  VectorField field;
  field.grid = grid;
  for (int d = 0; d < grid.dimension; ++d) field.component[d].resize(grid.size());
  const int m = grid.points_per_side;
  const double h = grid.spacing();
  for (int k = 0; k < (grid.dimension == 3 ? m : 1); ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const std::array<double, 3> value = f(i * h, j * h, k * h);
        for (int d = 0; d < grid.dimension; ++d) field.component[d][grid.index(i, j, k)] = value[d];
      }
  return field;
}

double relative_difference(double a, double b) {
  return std::abs(a - b) / std::abs(b);
}

// ---------------------------------------------------------------------------------------------
// Energy spectrum

TEST(EnergySpectrum, ParsevalHoldsForRandomFields) {
  struct Case {
    int dim;
    int m;
    double length;
  };
  // Even and odd M in 2D and 3D; the fields have a non-zero mean, which lands in shell 0.
  for (const Case c :
       {Case{3, 24, 1.7}, Case{2, 64, 2.0 * kPi}, Case{3, 15, 0.4}, Case{2, 63, 3.0}}) {
    const Grid grid = make_grid(c.dim, c.m, c.length);
    VectorField u;
    u.grid = grid;
    std::mt19937_64 rng(1234 + c.m);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    for (int d = 0; d < c.dim; ++d) {
      u.component[d].resize(grid.size());
      for (double& value : u.component[d]) value = 0.3 + uniform(rng);
    }
    const EnergySpectrum spectrum = energy_spectrum(u);
    const double grid_energy = grid_kinetic_energy(u);
    const double error = relative_difference(spectrum_energy(spectrum), grid_energy);
    std::printf("Parseval %dD M=%d: relative error %.2e\n", c.dim, c.m, error);
    EXPECT_LT(error, 1e-12) << c.dim << "D M=" << c.m;
    // Shells 0 .. nint(sqrt(n) floor(M/2)), the corner of the cube.
    const int corner = static_cast<int>(std::lround(std::sqrt(c.dim) * (c.m / 2)));
    ASSERT_EQ(spectrum.energy.size(), static_cast<std::size_t>(corner + 1));
    EXPECT_DOUBLE_EQ(spectrum.delta_k, 2.0 * kPi / c.length);
    EXPECT_DOUBLE_EQ(spectrum.wavenumber[5], 5.0 * spectrum.delta_k);
    EXPECT_GT(spectrum.energy[0], 0.0);  // the mean 0.3 (plus sampling noise)
  }
}

/// Expects all energy in shell `shell` with value `expected`, every other shell below 1e-12 of it.
void expect_single_shell(const EnergySpectrum& spectrum, int shell, double expected) {
  ASSERT_LT(static_cast<std::size_t>(shell), spectrum.energy.size());
  EXPECT_LT(relative_difference(spectrum.energy[shell], expected), 1e-12);
  for (std::size_t p = 0; p < spectrum.energy.size(); ++p)
    if (static_cast<int>(p) != shell) {
      EXPECT_LT(std::abs(spectrum.energy[p]), 1e-12 * expected) << "shell " << p;
    }
}

TEST(EnergySpectrum, SingleModesLandInTheirShell) {
  // u = A cos(k·x) has û = A/2 at ±k, so Σ_k ½|û|² = 2 · ½ (A/2)² = A²/4 = ½⟨u²⟩ and
  // E(k_p) = A² / (4 Δk) in the shell p = |k|/Δk.
  const double a = 0.7;
  {
    // 2D, even M = 32, L = 2π (Δk = 1): k = (3, 4), |k| = 5, stored with 0 < k_x < M/2
    // (weight 2).
    const Grid grid = make_grid(2, 32, 2.0 * kPi);
    const VectorField u = sample_function(grid, [&](double x, double y, double) {
      return std::array<double, 3>{a * std::cos(3.0 * x + 4.0 * y), 0.0, 0.0};
    });
    SCOPED_TRACE("2D k=(3,4)");
    expect_single_shell(energy_spectrum(u), 5, a * a / 4.0);
  }
  {
    // 2D, k = (0, 7) in the k_x = 0 plane (weight 1, both ±k stored), L = 3.
    const Grid grid = make_grid(2, 32, 3.0);
    const double dk = 2.0 * kPi / 3.0;
    const VectorField u = sample_function(grid, [&](double, double y, double) {
      return std::array<double, 3>{0.0, a * std::sin(7.0 * dk * y), 0.0};
    });
    SCOPED_TRACE("2D k=(0,7)");
    expect_single_shell(energy_spectrum(u), 7, a * a / (4.0 * dk));
  }
  {
    // 3D, odd M = 15, L = 3: k = Δk (1, 2, 2), |k| = 3 Δk; no Nyquist plane for odd M.
    const Grid grid = make_grid(3, 15, 3.0);
    const double dk = 2.0 * kPi / 3.0;
    const VectorField u = sample_function(grid, [&](double x, double y, double z) {
      return std::array<double, 3>{0.0, 0.0, a * std::sin(dk * (x + 2.0 * y + 2.0 * z))};
    });
    SCOPED_TRACE("3D odd M k=(1,2,2)");
    expect_single_shell(energy_spectrum(u), 3, a * a / (4.0 * dk));
  }
  {
    // 3D, M = 8: the Nyquist mode u = A (-1)^i (k_x = M/2, weight 1) is its own partner:
    // û = A, E = ½ A² / Δk in shell M/2 = 4.
    const Grid grid = make_grid(3, 8, 2.0 * kPi);
    VectorField u;
    u.grid = grid;
    for (int d = 0; d < 3; ++d) u.component[d].assign(grid.size(), 0.0);
    for (std::size_t n = 0; n < grid.size(); ++n) u.component[0][n] = (n % 2 == 0) ? a : -a;
    SCOPED_TRACE("3D Nyquist");
    expect_single_shell(energy_spectrum(u), 4, 0.5 * a * a);
  }
}

/// u(x) = Σ_k û(k) e^{i k·x} (inverse of û = M^-n Σ_x u e^{-i k·x}) by separable 1D DFTs.
std::vector<double> inverse_dft(int dim, int m, std::vector<std::complex<double>> values) {
  std::vector<std::complex<double>> twiddle(static_cast<std::size_t>(m));
  for (int q = 0; q < m; ++q) twiddle[q] = std::polar(1.0, 2.0 * kPi * q / m);
  std::vector<std::complex<double>> line(static_cast<std::size_t>(m));
  std::size_t stride = 1;
  for (int axis = 0; axis < dim; ++axis, stride *= static_cast<std::size_t>(m)) {
    for (std::size_t start = 0; start < values.size(); ++start) {
      if ((start / stride) % static_cast<std::size_t>(m) != 0) continue;  // not a line start
      for (int x = 0; x < m; ++x) {
        std::complex<double> sum = 0.0;
        for (int q = 0; q < m; ++q) sum += values[start + q * stride] * twiddle[(q * x) % m];
        line[x] = sum;
      }
      for (int x = 0; x < m; ++x) values[start + x * stride] = line[x];
    }
  }
  std::vector<double> real(values.size());
  for (std::size_t n = 0; n < values.size(); ++n) real[n] = values[n].real();
  return real;
}

TEST(EnergySpectrum, RandomPhaseFieldRecoversMinusFiveThirds) {
  // 3D, M = 64, L = 2π. Each component has |û(k)|² = |k|^(-11/3) with random phases (Hermitian,
  // so u is real): E(k) ≈ 4πk² · 3 · ½ |k|^(-11/3) ∝ k^(-5/3) up to the lattice-point count of
  // each shell.
  const int m = 64;
  const Grid grid = make_grid(3, m, 2.0 * kPi);
  const auto signed_index = [m](int q) { return 2 * q <= m ? q : q - m; };
  const auto wrap = [m](int q) { return (m - q) % m; };
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> phase(0.0, 2.0 * kPi);
  VectorField u;
  u.grid = grid;
  for (int c = 0; c < 3; ++c) {
    std::vector<std::complex<double>> modes(grid.size(), 0.0);
    for (int qz = 0; qz < m; ++qz)
      for (int qy = 0; qy < m; ++qy)
        for (int qx = 0; qx < m; ++qx) {
          const std::size_t n = grid.index(qx, qy, qz);
          const std::size_t partner = grid.index(wrap(qx), wrap(qy), wrap(qz));
          if (n > partner) continue;  // set together with its partner
          const int kx = signed_index(qx), ky = signed_index(qy), kz = signed_index(qz);
          const int k2 = kx * kx + ky * ky + kz * kz;
          if (k2 == 0) continue;  // zero mean
          const double amplitude = std::pow(static_cast<double>(k2), -11.0 / 12.0);
          if (n == partner) {
            modes[n] = phase(rng) < kPi ? amplitude : -amplitude;  // self-conjugate: real
          } else {
            modes[n] = std::polar(amplitude, phase(rng));
            modes[partner] = std::conj(modes[n]);
          }
        }
    u.component[c] = inverse_dft(3, m, std::move(modes));
  }
  const EnergySpectrum spectrum = energy_spectrum(u);
  EXPECT_LT(relative_difference(spectrum_energy(spectrum), grid_kinetic_energy(u)), 1e-12);

  // Least-squares slope of log E against log k over the inner shells 4..28 (complete spheres).
  double sx = 0.0, sy = 0.0, sxx = 0.0, sxy = 0.0;
  int count = 0;
  for (int p = 4; p <= 28; ++p) {
    const double x = std::log(spectrum.wavenumber[p]);
    const double y = std::log(spectrum.energy[p]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
    ++count;
  }
  const double slope = (count * sxy - sx * sy) / (count * sxx - sx * sx);
  std::printf("synthetic spectrum slope over shells 4..28: %.4f (target %.4f)\n", slope,
              -5.0 / 3.0);
  EXPECT_NEAR(slope, -5.0 / 3.0, 0.05);
}

TEST(EnergySpectrum, ConcurrentCallsAgreeBitwise) {
  // Plans are made under the internal lock; execution runs concurrently. Every call must give
  // bit-identical spectra.
  const Grid grid = make_grid(3, 20, 1.0);
  VectorField u;
  u.grid = grid;
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int d = 0; d < 3; ++d) {
    u.component[d].resize(grid.size());
    for (double& value : u.component[d]) value = uniform(rng);
  }
  const EnergySpectrum reference = energy_spectrum(u);
  std::vector<EnergySpectrum> results(4);
  std::vector<std::thread> threads;
  for (EnergySpectrum& result : results)
    threads.emplace_back([&u, &result] {
      for (int repeat = 0; repeat < 5; ++repeat) result = energy_spectrum(u);
    });
  for (std::thread& thread : threads) thread.join();
  for (const EnergySpectrum& result : results) EXPECT_EQ(result.energy, reference.energy);
}

// ---------------------------------------------------------------------------------------------
// Vorticity

std::array<double, 3> taylor_green_velocity(double x, double y, double z) {
  // (5.1) with v0 = 1.
  return {std::sin(x) * std::cos(y) * std::cos(z), -std::cos(x) * std::sin(y) * std::cos(z), 0.0};
}

std::array<double, 3> taylor_green_vorticity(double x, double y, double z) {
  // ω = ∇×u = (-∂v/∂z, ∂u/∂z, ∂v/∂x - ∂u/∂y)
  //   = (-cos x sin y sin z, -sin x cos y sin z, 2 sin x sin y cos z).
  return {-std::cos(x) * std::sin(y) * std::sin(z), -std::sin(x) * std::cos(y) * std::sin(z),
          2.0 * std::sin(x) * std::sin(y) * std::cos(z)};
}

/// max over nodes and used components of |a - b|.
double max_difference(const VectorField& a, const VectorField& b) {
  double result = 0.0;
  for (int d = 0; d < 3; ++d) {
    EXPECT_EQ(a.component[d].size(), b.component[d].size());
    for (std::size_t n = 0; n < a.component[d].size(); ++n)
      result = std::max(result, std::abs(a.component[d][n] - b.component[d][n]));
  }
  return result;
}

TEST(Vorticity, TaylorGreen3DConvergesAtSecondOrder) {
  // Central differences of sin(x) give cos(x) sin(h)/h, so the error is max|ω| (1 - sin h / h)
  // ≈ 2 h²/6: second order.
  std::vector<double> errors;
  for (int m : {16, 32, 64}) {
    const Grid grid = make_grid(3, m, 2.0 * kPi);
    const VectorField omega = vorticity(sample_function(grid, taylor_green_velocity));
    VectorField exact = sample_function(grid, taylor_green_vorticity);
    errors.push_back(max_difference(omega, exact));
    const double h = grid.spacing();
    EXPECT_NEAR(errors.back(), 2.0 * (1.0 - std::sin(h) / h), 1e-12);
  }
  for (std::size_t i = 0; i + 1 < errors.size(); ++i) {
    const double order = std::log2(errors[i] / errors[i + 1]);
    std::printf("3D TGV vorticity: max error %.3e -> %.3e, observed order %.3f\n", errors[i],
                errors[i + 1], order);
    EXPECT_NEAR(order, 2.0, 0.2);
  }
}

TEST(Vorticity, TaylorGreen2DConvergesAtSecondOrder) {
  // u = (sin x cos y, -cos x sin y): ω_z = ∂v/∂x - ∂u/∂y = 2 sin x sin y.
  std::vector<double> errors;
  for (int m : {16, 32, 64}) {
    const Grid grid = make_grid(2, m, 2.0 * kPi);
    const VectorField u = sample_function(grid, [](double x, double y, double) {
      return std::array<double, 3>{std::sin(x) * std::cos(y), -std::cos(x) * std::sin(y), 0.0};
    });
    const VectorField omega = vorticity(u);
    EXPECT_TRUE(omega.component[0].empty());
    EXPECT_TRUE(omega.component[1].empty());
    ASSERT_EQ(omega.component[2].size(), grid.size());
    VectorField exact = sample_function(grid, [](double x, double y, double) {
      return std::array<double, 3>{2.0 * std::sin(x) * std::sin(y), 0.0, 0.0};
    });
    exact.component[2] = std::move(exact.component[0]);  // sample_function fills 0, 1 in 2D
    exact.component[0].clear();
    exact.component[1].clear();
    errors.push_back(max_difference(omega, exact));
  }
  for (std::size_t i = 0; i + 1 < errors.size(); ++i) {
    const double order = std::log2(errors[i] / errors[i + 1]);
    std::printf("2D TGV vorticity: max error %.3e -> %.3e, observed order %.3f\n", errors[i],
                errors[i + 1], order);
    EXPECT_NEAR(order, 2.0, 0.2);
  }
}

// ---------------------------------------------------------------------------------------------
// Dissipation two ways (4.6)

TEST(Dissipation, TaylorGreenSpectralAndVorticityEstimates) {
  // TGV (5.1) on [0, 2π)³: e = ½⟨u² + v²⟩ = 1/8, all in the 8 modes k = (±1, ±1, ±1), |k| = √3.
  // Analytic ⟨ω²⟩ = 1/8 + 1/8 + 4/8 = 3/4 = 2 |k|² e, so ν⟨ω²⟩ = 0.75 ν.
  // The spectrum puts these modes in shell p = nint(√3) = 2, but the dissipation uses each
  // mode's exact |k|² = 3, so 2ν Σ |k|² ½|û|² = ν⟨ω²⟩ to round-off for any M (shell-centre
  // weighting k_p² = 4 would give 4/3 of it, and that value must not come out). Restricted to
  // k_p <= 1 only round-off remains. The grid estimate from vorticity() is
  // ν⟨ω_h²⟩ = 0.75 ν (sin h / h)² (every derivative gains sin h / h), second order in h.
  const double nu = 1e-3;
  const double analytic = nu * 0.75;
  std::vector<double> errors;
  for (int m : {16, 32, 64}) {
    const Grid grid = make_grid(3, m, 2.0 * kPi);
    const VectorField u = sample_function(grid, taylor_green_velocity);
    EXPECT_NEAR(grid_kinetic_energy(u), 0.125, 1e-15);
    EXPECT_NEAR(nu * mean_value(squared_magnitude(sample_function(grid, taylor_green_vorticity))),
                analytic, 1e-15);
    const EnergySpectrum spectrum = energy_spectrum(u);
    const double spectral = spectral_dissipation(spectrum, nu);
    EXPECT_LT(relative_difference(spectral, analytic), 1e-12);
    EXPECT_LT(spectral_dissipation(spectrum, nu, 1.0), 1e-12 * analytic);
    EXPECT_LT(relative_difference(spectral_dissipation(spectrum, nu, 2.0), analytic), 1e-12);
    const double discrete = nu * mean_value(squared_magnitude(vorticity(u)));
    const double h = grid.spacing();
    EXPECT_LT(relative_difference(discrete, analytic * std::pow(std::sin(h) / h, 2)), 1e-12);
    errors.push_back(std::abs(discrete - analytic));
    std::printf("TGV M=%d: spectral %.6e, nu<w^2> analytic %.6e, from vorticity() %.6e\n", m,
                spectral, analytic, discrete);
  }
  for (std::size_t i = 0; i + 1 < errors.size(); ++i) {
    const double order = std::log2(errors[i] / errors[i + 1]);
    std::printf("TGV nu<w_h^2> error order %.3f\n", order);
    EXPECT_NEAR(order, 2.0, 0.2);
  }
}

TEST(Dissipation, ModeOnAShellCentreAgreesExactly) {
  // Solenoidal 2D mode with stream function ψ = (A/5) sin(3x + 4y), |k| = 5 on the shell centre:
  // u = (4A/5) cos(3x + 4y), v = -(3A/5) cos(3x + 4y), ω = 5A sin(3x + 4y),
  // ½⟨|u|²⟩ = A²/4, ν⟨ω²⟩ = 25 ν A²/2 = 2ν |k|² e. The spectral estimate is exact (to round-off);
  // the one from vorticity() converges to it at second order.
  const double nu = 2e-2, a = 1.3;
  const double exact = 12.5 * nu * a * a;
  std::vector<double> errors;
  for (int m : {32, 64, 128}) {
    const Grid grid = make_grid(2, m, 2.0 * kPi);
    const VectorField u = sample_function(grid, [&](double x, double y, double) {
      const double c = std::cos(3.0 * x + 4.0 * y);
      return std::array<double, 3>{0.8 * a * c, -0.6 * a * c, 0.0};
    });
    EXPECT_LT(relative_difference(spectral_dissipation(energy_spectrum(u), nu), exact), 1e-12);
    errors.push_back(std::abs(nu * mean_value(squared_magnitude(vorticity(u))) - exact));
  }
  for (std::size_t i = 0; i + 1 < errors.size(); ++i) {
    const double order = std::log2(errors[i] / errors[i + 1]);
    std::printf("shell-centre mode nu<w_h^2> error %.3e -> %.3e, order %.3f\n", errors[i],
                errors[i + 1], order);
    EXPECT_NEAR(order, 2.0, 0.2);
  }
}

// ---------------------------------------------------------------------------------------------
// Nearest-particle map

/// Nearest particle by brute force: the smallest id among the particles whose squared
/// minimum-image distance is within a factor 1 + 1e-12 of the smallest (grid.hpp's tie rule).
std::uint32_t brute_force_nearest(const sim::ParticleArrays& p, const Grid& grid,
                                  std::array<double, 3> x) {
  std::vector<double> r2(p.size(), 0.0);
  for (std::size_t j = 0; j < p.size(); ++j) {
    for (int d = 0; d < grid.dimension; ++d) {
      const double dx = sim::minimum_image(x[d] - p.position[d][j], grid.length, 0.5 * grid.length);
      r2[j] += dx * dx;
    }
  }
  const double window = *std::min_element(r2.begin(), r2.end()) * (1.0 + 1e-12);
  std::uint32_t best = 0;
  std::uint64_t best_id = std::numeric_limits<std::uint64_t>::max();
  for (std::size_t j = 0; j < p.size(); ++j) {
    if (r2[j] <= window && p.id[j] < best_id) {
      best_id = p.id[j];
      best = static_cast<std::uint32_t>(j);
    }
  }
  return best;
}

std::array<double, 3> node_position(const Grid& grid, std::size_t n) {
  const auto m = static_cast<std::size_t>(grid.points_per_side);
  const double h = grid.spacing();
  return {static_cast<double>(n % m) * h, static_cast<double>((n / m) % m) * h,
          static_cast<double>(n / (m * m)) * h};
}

enum class Layout { kUniform, kClustered };

/// Random particles in [0, L)^dim; uniform ones include particles on and within 1e-9 L of the
/// faces, clustered ones sit in a ball of radius 0.05 L around a point near a corner (the ball
/// wraps across the faces).
sim::ParticleArrays random_particles(int dim, std::size_t count, double length, Layout layout,
                                     std::uint64_t seed) {
  sim::ParticleArrays p;
  p.dimension = dim;
  p.resize(count);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (std::size_t i = 0; i < count; ++i) {
    for (int d = 0; d < dim; ++d) {
      double x = length * uniform(rng);
      if (layout == Layout::kUniform) {
        if (i % 5 == 0) x = (i % 2 ? 0.0 : std::nextafter(length, 0.0));
        if (i % 7 == 0) x = (i % 2 ? 1e-9 : 1.0 - 1e-9) * length;
      } else {
        x = sim::wrap_periodic(0.02 * length + 0.05 * length * (2.0 * uniform(rng) - 1.0), length);
      }
      p.position[d][i] = x;
    }
  }
  return p;
}

/// Checks every node of the map against brute force and that a shuffled copy (ids kept) maps
/// every node to the same particle id.
void expect_map_matches_brute_force(const Grid& grid, const sim::ParticleArrays& particles,
                                    std::uint64_t seed) {
  const NearestParticleMap map = nearest_particle_map(grid, particles);
  ASSERT_EQ(map.particle.size(), grid.size());
  std::size_t mismatches = 0;
  for (std::size_t n = 0; n < grid.size(); ++n) {
    const std::array<double, 3> x = node_position(grid, n);
    const std::uint32_t expected = brute_force_nearest(particles, grid, x);
    if (map.particle[n] == expected) continue;
    if (++mismatches <= 3) {
      ADD_FAILURE() << "node " << n << " at (" << x[0] << ", " << x[1] << ", " << x[2]
                    << "): map gives particle " << map.particle[n] << ", brute force " << expected;
    }
  }
  EXPECT_EQ(mismatches, 0u) << "nodes differing from brute force";

  std::vector<std::uint32_t> order(particles.size());
  std::iota(order.begin(), order.end(), 0u);
  std::mt19937_64 rng(seed);
  std::shuffle(order.begin(), order.end(), rng);
  sim::ParticleArrays shuffled = particles;
  shuffled.reorder(order);
  const NearestParticleMap shuffled_map = nearest_particle_map(grid, shuffled);
  std::size_t id_mismatches = 0;
  for (std::size_t n = 0; n < grid.size(); ++n)
    if (particles.id[map.particle[n]] != shuffled.id[shuffled_map.particle[n]]) ++id_mismatches;
  EXPECT_EQ(id_mismatches, 0u) << "nodes whose particle id changed after shuffling";
}

TEST(NearestParticleMap, EqualsBruteForce3D) {
  {
    SCOPED_TRACE("uniform, faces, M=17");
    expect_map_matches_brute_force(make_grid(3, 17, 1.3),
                                   random_particles(3, 400, 1.3, Layout::kUniform, 1), 11);
  }
  {
    SCOPED_TRACE("uniform, M=24");
    expect_map_matches_brute_force(make_grid(3, 24, 1.0),
                                   random_particles(3, 1000, 1.0, Layout::kUniform, 2), 12);
  }
  {
    SCOPED_TRACE("clustered");
    expect_map_matches_brute_force(make_grid(3, 20, 2.0),
                                   random_particles(3, 343, 2.0, Layout::kClustered, 3), 13);
  }
  for (std::size_t count : {1u, 2u, 5u, 9u, 30u}) {  // one to three cells per side
    SCOPED_TRACE("few particles: " + std::to_string(count));
    expect_map_matches_brute_force(make_grid(3, 9, 1.0),
                                   random_particles(3, count, 1.0, Layout::kUniform, count), 14);
  }
  {
    // Lattice with M = 2 N^(1/3): nodes on the lattice cell corners are equidistant from 8
    // particles, so the ties decide.
    SCOPED_TRACE("lattice ties");
    const sim::PeriodicBox box{.dimension = 3, .length = {1.0, 1.0, 1.0}};
    expect_map_matches_brute_force(make_grid(3, 12, 1.0), sim::make_lattice(box, 6), 15);
  }
}

TEST(NearestParticleMap, EqualsBruteForce2D) {
  {
    SCOPED_TRACE("uniform, faces");
    expect_map_matches_brute_force(make_grid(2, 40, 0.7),
                                   random_particles(2, 500, 0.7, Layout::kUniform, 21), 31);
  }
  {
    SCOPED_TRACE("clustered");
    expect_map_matches_brute_force(make_grid(2, 33, 1.0),
                                   random_particles(2, 200, 1.0, Layout::kClustered, 22), 32);
  }
  for (std::size_t count : {1u, 3u, 7u}) {
    SCOPED_TRACE("few particles: " + std::to_string(count));
    expect_map_matches_brute_force(make_grid(2, 11, 1.0),
                                   random_particles(2, count, 1.0, Layout::kUniform, count), 33);
  }
  {
    SCOPED_TRACE("lattice ties");
    const sim::PeriodicBox box{.dimension = 2, .length = {2.0, 2.0, 0.0}};
    expect_map_matches_brute_force(make_grid(2, 20, 2.0), sim::make_lattice(box, 10), 34);
  }
}

/// A block of nodes (a rank's part of the grid, par/) gets the whole map's particles, with any
/// number of cells, and the largest of its nodes' nearest distances; a block outside the grid is
/// refused naming the axis.
TEST(NearestParticleMap, BlockEqualsTheWholeMapOnItsNodes) {
  for (const int dim : {2, 3}) {
    SCOPED_TRACE("dimension " + std::to_string(dim));
    const Grid grid = make_grid(dim, 18, 1.0);
    const sim::ParticleArrays particles =
        random_particles(dim, dim == 3 ? 300 : 150, 1.0, Layout::kClustered, 41);
    const NearestParticleMap map = nearest_particle_map(grid, particles);
    NodeBlock block;
    block.first = {3, 5, dim == 3 ? 2 : 0};
    block.count = {7, 4, dim == 3 ? 9 : 1};
    for (const int cells : {1, 4, 9}) {
      const NearestInBlock got = nearest_particles_in_block(grid, particles, block, cells);
      ASSERT_EQ(got.particle.size(), block.size());
      double max_r2 = 0.0;
      std::size_t n = 0, mismatches = 0;
      for (int k = 0; k < block.count[2]; ++k)
        for (int j = 0; j < block.count[1]; ++j)
          for (int i = 0; i < block.count[0]; ++i, ++n) {
            const std::size_t node =
                grid.index(block.first[0] + i, block.first[1] + j, block.first[2] + k);
            if (got.particle[n] != map.particle[node]) ++mismatches;
            const std::array<double, 3> x = node_position(grid, node);
            double r2 = 0.0;
            for (int d = 0; d < dim; ++d) {
              const double dx =
                  sim::minimum_image(x[d] - particles.position[d][map.particle[node]], 1.0, 0.5);
              r2 += dx * dx;
            }
            max_r2 = std::max(max_r2, r2);
          }
      EXPECT_EQ(mismatches, 0u) << cells << " cells per side";
      EXPECT_EQ(got.max_distance2, max_r2);
    }
    NodeBlock outside = block;
    outside.first[1] = 15;  // 15 + 4 > 18
    try {
      nearest_particles_in_block(grid, particles, outside, 4);
      ADD_FAILURE() << "a block outside the grid was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("outside the grid (axis 1)"), std::string::npos)
          << e.what();
    }
  }
}

TEST(NearestParticleMap, FastOnTheTargetSize) {
  // 96³ nodes over 48³ perturbed lattice particles, on one thread.
  const sim::PeriodicBox box{.dimension = 3, .length = {1.0, 1.0, 1.0}};
  sim::ParticleArrays p = sim::make_lattice(box, 48);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uniform(-0.3 / 48, 0.3 / 48);
  for (int d = 0; d < 3; ++d)
    for (double& x : p.position[d]) x = sim::wrap_periodic(x + uniform(rng), 1.0);
  const Grid grid = make_grid(3, 96, 1.0);

  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto start = std::chrono::steady_clock::now();
  const NearestParticleMap map = nearest_particle_map(grid, p);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  omp_set_num_threads(threads);
  std::printf("nearest_particle_map 96^3 nodes over 48^3 particles, 1 thread: %.3f s\n", seconds);
  EXPECT_LT(seconds, 2.0);  // target: well under a second; slack for a loaded machine

  std::mt19937_64 pick(8);
  std::uniform_int_distribution<std::size_t> node(0, grid.size() - 1);
  for (int s = 0; s < 300; ++s) {
    const std::size_t n = node(pick);
    ASSERT_EQ(map.particle[n], brute_force_nearest(p, grid, node_position(grid, n))) << n;
  }
  // Same map with all threads.
  EXPECT_EQ(nearest_particle_map(grid, p).particle, map.particle);
}

// ---------------------------------------------------------------------------------------------
// Sampling

TEST(Sampling, RemoveMeanLeavesZeroMeanFluctuations) {
  sim::ParticleArrays p = random_particles(3, 2000, 1.0, Layout::kUniform, 41);
  std::mt19937_64 rng(42);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int d = 0; d < 3; ++d)
    for (double& v : p.velocity[d]) v = 2.0 * (d + 1) + normal(rng);
  const NearestParticleMap map = nearest_particle_map(make_grid(3, 24, 1.0), p);
  const VectorField raw = sample_velocity(map, p, false);
  const VectorField fluctuation = sample_velocity(map, p, true);
  for (int d = 0; d < 3; ++d) {
    double sum = 0.0, sum_abs = 0.0, raw_sum = 0.0;
    for (std::size_t n = 0; n < map.particle.size(); ++n) {
      EXPECT_EQ(raw.component[d][n], p.velocity[d][map.particle[n]]);
      sum += fluctuation.component[d][n];
      sum_abs += std::abs(fluctuation.component[d][n]);
      raw_sum += raw.component[d][n];
    }
    std::printf("remove_mean component %d: |sum| / sum|u| = %.2e\n", d, std::abs(sum) / sum_abs);
    EXPECT_LT(std::abs(sum), 1e-12 * sum_abs);
    const double mean = raw_sum / static_cast<double>(map.particle.size());
    for (std::size_t n = 0; n < map.particle.size(); ++n)
      EXPECT_NEAR(fluctuation.component[d][n], raw.component[d][n] - mean, 1e-12);
  }
}

TEST(Sampling, UniformTranslationIsReproducedExactly) {
  for (int dim : {2, 3}) {
    sim::ParticleArrays p = random_particles(dim, 300, 1.0, Layout::kUniform, 50 + dim);
    const std::array<double, 3> translation{0.3, -1.7, 2.5e3};
    for (int d = 0; d < dim; ++d) p.velocity[d].assign(p.size(), translation[d]);
    const NearestParticleMap map = nearest_particle_map(make_grid(dim, 16, 1.0), p);
    const VectorField u = sample_velocity(map, p, false);
    const VectorField fluctuation = sample_velocity(map, p, true);
    for (int d = 0; d < 3; ++d) {
      if (d >= dim) {
        EXPECT_TRUE(u.component[d].empty());
        continue;
      }
      ASSERT_EQ(u.component[d].size(), map.grid.size());
      for (std::size_t n = 0; n < u.component[d].size(); ++n) {
        EXPECT_EQ(u.component[d][n], translation[d]);
        EXPECT_NEAR(fluctuation.component[d][n], 0.0, 1e-12 * std::abs(translation[d]));
      }
    }
  }
}

TEST(Sampling, NearestNodeAndScalarRoundTripOnALattice) {
  // Lattice particles at (i + ½) Δl on a grid of spacing Δl/2 sit exactly on node 2i + 1, whose
  // nearest particle is the particle itself.
  const sim::PeriodicBox box{.dimension = 3, .length = {2.0, 2.0, 2.0}};
  sim::ParticleArrays p = sim::make_lattice(box, 8);
  const Grid grid = make_grid(3, 16, 2.0);
  const std::vector<std::size_t> node = nearest_node(grid, p);
  const NearestParticleMap map = nearest_particle_map(grid, p);
  std::vector<double> value(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) value[i] = 10.0 + static_cast<double>(i);
  const std::vector<double> sampled = sample_scalar(map, value);
  ASSERT_EQ(sampled.size(), grid.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::array<int, 3> expected{};
    for (int d = 0; d < 3; ++d)
      expected[d] = 2 * static_cast<int>(std::lround(p.position[d][i] / 0.25 - 0.5)) + 1;
    EXPECT_EQ(node[i], grid.index(expected[0], expected[1], expected[2]));
    EXPECT_EQ(sampled[node[i]], value[i]);
  }

  // Rounding and periodic wrap: h = 0.125.
  sim::ParticleArrays q;
  q.dimension = 2;
  q.resize(3);
  q.position[0] = {0.49 * 0.125, 0.51 * 0.125, 2.0 - 1e-12};
  q.position[1] = {2.0 - 0.4 * 0.125, 1.0, 0.0};
  const std::vector<std::size_t> q_node = nearest_node(make_grid(2, 16, 2.0), q);
  const Grid grid2 = make_grid(2, 16, 2.0);
  EXPECT_EQ(q_node[0], grid2.index(0, 0));
  EXPECT_EQ(q_node[1], grid2.index(1, 8));
  EXPECT_EQ(q_node[2], grid2.index(0, 0));
}

}  // namespace
}  // namespace sphles::analysis
