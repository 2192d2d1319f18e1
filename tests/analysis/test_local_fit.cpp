// SPDX-License-Identifier: GPL-3.0-or-later
// Local polynomial fits (analysis/local_fit.hpp), the "mls" vorticity estimate: exact reproduction
// of polynomials up to the fit's degree, the fallback to lower degrees, the order of convergence
// for a smooth periodic field, thread-count independence and error paths.
#include <gtest/gtest.h>
#include <omp.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <random>
#include <span>
#include <type_traits>
#include <vector>

#include "analysis/local_fit.hpp"
#include "analysis/vorticity.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "test_support.hpp"

namespace sphles::analysis {
namespace {

constexpr double kPi = std::numbers::pi;

TEST(MonomialBasis, SizesAndGradedOrder) {
  EXPECT_EQ((MonomialBasis<2, 2>::size), 6);
  EXPECT_EQ((MonomialBasis<2, 3>::size), 10);
  EXPECT_EQ((MonomialBasis<3, 2>::size), 10);
  EXPECT_EQ((MonomialBasis<3, 3>::size), 20);
  constexpr auto e3 = MonomialBasis<3, 3>::exponents();
  EXPECT_EQ(e3[0], (std::array<int, 3>{0, 0, 0}));
  for (int d = 0; d < 3; ++d) {
    std::array<int, 3> unit{0, 0, 0};
    unit[static_cast<std::size_t>(d)] = 1;
    EXPECT_EQ(e3[static_cast<std::size_t>(1 + d)], unit) << "monomial 1 + d must be ξ_d";
  }
  int previous_degree = 0;
  for (const auto& x : e3) {
    const int degree = x[0] + x[1] + x[2];
    EXPECT_GE(degree, previous_degree) << "graded order";
    previous_degree = degree;
  }
  const auto m = MonomialBasis<2, 3>::evaluate({2.0, 3.0, 0.0});
  // 1, x, y, x², xy, y², x³, x²y, xy², y³
  const std::array<double, 10> expected{1, 2, 3, 4, 6, 9, 8, 12, 18, 27};
  for (std::size_t k = 0; k < expected.size(); ++k) EXPECT_EQ(m[k], expected[k]) << k;
}

/// A polynomial of total degree `degree` in Dim dimensions with fixed random coefficients, its
/// value and gradient.
struct Polynomial {
  int dim, degree;
  std::vector<std::array<int, 3>> exponents;
  std::vector<double> coefficients;

  Polynomial(int dim_, int degree_, unsigned seed) : dim(dim_), degree(degree_) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int a = 0; a <= degree; ++a)
      for (int b = 0; a + b <= degree; ++b)
        for (int c = 0; a + b + c <= degree; ++c) {
          if (dim == 2 && c > 0) continue;
          exponents.push_back({a, b, c});
          coefficients.push_back(u(rng));
        }
  }
  double value(const std::array<double, 3>& x) const {
    double sum = 0.0;
    for (std::size_t k = 0; k < exponents.size(); ++k)
      sum += coefficients[k] * std::pow(x[0], exponents[k][0]) * std::pow(x[1], exponents[k][1]) *
             std::pow(x[2], exponents[k][2]);
    return sum;
  }
  double derivative(const std::array<double, 3>& x, int axis) const {
    double sum = 0.0;
    for (std::size_t k = 0; k < exponents.size(); ++k) {
      const int p = exponents[k][static_cast<std::size_t>(axis)];
      if (p == 0) continue;
      double term = coefficients[k] * p;
      for (int d = 0; d < 3; ++d) {
        const int q = exponents[k][static_cast<std::size_t>(d)] - (d == axis ? 1 : 0);
        term *= std::pow(x[static_cast<std::size_t>(d)], q);
      }
      sum += term;
    }
    return sum;
  }
};

/// Random points in the ball of radius R around `centre`, with positive weights.
std::vector<FitPoint> scattered_points(int dim, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<FitPoint> points;
  while (static_cast<int>(points.size()) < count) {
    FitPoint p{{0.0, 0.0, 0.0}, 0.0, static_cast<std::uint32_t>(points.size())};
    double r2 = 0.0;
    for (int d = 0; d < dim; ++d) {
      p.xi[static_cast<std::size_t>(d)] = u(rng);
      r2 += p.xi[static_cast<std::size_t>(d)] * p.xi[static_cast<std::size_t>(d)];
    }
    if (r2 >= 1.0) continue;
    p.weight = std::pow(1.0 - std::sqrt(r2), 4) * (0.5 + 0.5 * (u(rng) + 1.0));
    points.push_back(p);
  }
  return points;
}

// A fit of degree P reproduces every polynomial of degree ≤ P: its value and gradient at the
// centre to round-off, on scattered points with uneven weights.
template <int Dim, int Degree>
void check_reproduces_polynomials() {
  const double radius = 0.37;
  const std::array<double, 3> centre{0.3, -0.2, Dim == 3 ? 0.55 : 0.0};
  const std::vector<FitPoint> points = scattered_points(Dim, 60, 7);
  const Polynomial f(Dim, Degree, 11), g(Dim, Degree, 12);
  const auto at = [&](const FitPoint& p) {
    std::array<double, 3> x = centre;
    for (int d = 0; d < Dim; ++d) x[static_cast<std::size_t>(d)] += radius * p.xi[d];
    return x;
  };
  const auto values = [&](std::uint32_t j, int field) {
    return field == 0 ? f.value(at(points[j])) : g.value(at(points[j]));
  };
  const FitResult<2> fit = fit_polynomial<Dim, Degree, 2>(points, radius, values);
  ASSERT_EQ(fit.degree, Degree);
  EXPECT_NEAR(fit.value[0], f.value(centre), 1e-12);
  EXPECT_NEAR(fit.value[1], g.value(centre), 1e-12);
  for (int d = 0; d < Dim; ++d) {
    EXPECT_NEAR(fit.gradient[0][d], f.derivative(centre, d), 1e-11) << d;
    EXPECT_NEAR(fit.gradient[1][d], g.derivative(centre, d), 1e-11) << d;
  }
  if (Dim == 2) {
    EXPECT_EQ(fit.gradient[0][2], 0.0);
  }
}

TEST(LocalFit, ReproducesPolynomialsUpToItsDegree) {
  check_reproduces_polynomials<2, 2>();
  check_reproduces_polynomials<2, 3>();
  check_reproduces_polynomials<3, 2>();
  check_reproduces_polynomials<3, 3>();
}

// Points on a plane (3D) cannot determine the z terms: the fit falls back to lower degrees
// until its normal matrix is positive definite, which no degree ≥ 1 is here, so it returns the
// weighted mean (degree 0). Too few points for the cubic give the quadratic. No points give NaN.
TEST(LocalFit, FallsBackToLowerDegrees) {
  std::vector<FitPoint> plane = scattered_points(2, 40, 3);  // ξ_z = 0
  const auto one = [](std::uint32_t j, int) { return 1.0 + 0.25 * j; };
  const FitResult<1> flat = fit_polynomial<3, 3, 1>(plane, 1.0, one);
  EXPECT_EQ(flat.degree, 0);
  double weighted = 0.0, weights = 0.0;
  for (const FitPoint& p : plane) {
    weighted += p.weight * one(p.index, 0);
    weights += p.weight;
  }
  EXPECT_NEAR(flat.value[0], weighted / weights, 1e-14);

  const std::vector<FitPoint> few = scattered_points(3, 15, 4);  // 15 < 20 cubic monomials
  EXPECT_EQ((fit_polynomial<3, 3, 1>(few, 1.0, one).degree), 2);

  const FitResult<1> none = fit_polynomial<3, 3, 1>({}, 1.0, one);
  EXPECT_EQ(none.degree, -1);
  EXPECT_TRUE(std::isnan(none.value[0]));
}

/// Particles of a jittered lattice (20 % of Δl) with their volumes from the density pass, and
/// velocities of a smooth periodic field: 2D v = (sin x cos y, -cos x sin y) (the TGV, ∂v_x/∂x =
/// cos x cos y), 3D the TGV of (5.1).
struct FittedCase {
  sim::ParticleArrays particles;
  Grid grid;
  FitSettings fit;
};

FittedCase jittered_taylor_green(int dim, int per_side, double fit_radius_over_spacing,
                                 unsigned seed) {
  auto flow = sim::testing::random_flow(dim, per_side, 8.0, 0.0, seed);
  const double l = 2.0 * kPi;
  sim::SolverConfig& c = flow.config;
  sim::ParticleArrays& p = flow.particles;
  for (int d = 0; d < dim; ++d) {
    c.box.length[d] = l;
    for (double& x : p.position[d]) x *= l;
  }
  c.particle_spacing *= l;
  c.support_radius *= l;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double x = p.position[0][i], y = p.position[1][i];
    const double z = dim == 3 ? p.position[2][i] : 0.0;
    p.velocity[0][i] = std::sin(x) * std::cos(y) * std::cos(z);
    p.velocity[1][i] = -std::cos(x) * std::sin(y) * std::cos(z);
    if (dim == 3) p.velocity[2][i] = 0.0;
    p.mass[i] = std::pow(c.particle_spacing, dim);
  }
  sim::VerletNeighbourSearch search(c.box, c.support_radius, 0.0);
  search.build(sim::view_positions(p));
  sim::with_kernel(c.kernel, dim, c.support_radius, [&](const auto& kernel) {
    constexpr int kDim = std::remove_cvref_t<decltype(kernel)>::dimension;
    sim::density_pass<kDim>(kernel, c.box, search.list(), c.fluid, p);
  });
  FittedCase out;
  out.particles = std::move(p);
  out.grid = {.dimension = dim, .points_per_side = 2 * per_side, .length = l};
  out.fit = {c.kernel, fit_radius_over_spacing * c.particle_spacing};
  return out;
}

/// RMS error of ∂v_x/∂x = cos x cos y cos z over the particles.
double gradient_error(const FittedCase& c) {
  const std::vector<sim::VelocityGradient> j = fitted_velocity_gradient(c.grid, c.particles, c.fit);
  double sum = 0.0;
  for (std::size_t i = 0; i < c.particles.size(); ++i) {
    const double z = c.grid.dimension == 3 ? c.particles.position[2][i] : 0.0;
    const double exact =
        std::cos(c.particles.position[0][i]) * std::cos(c.particles.position[1][i]) * std::cos(z);
    sum += (j[i][0][0] - exact) * (j[i][0][0] - exact);
  }
  return std::sqrt(sum / static_cast<double>(c.particles.size()));
}

// At fixed R/Δl the gradient error of a smooth field falls as (kR)^3 on a disordered arrangement
// (the cubic fit's quartic remainder does not cancel where a neighbourhood is not symmetric):
// RMS errors 1.5e-4, 1.8e-5, 2.2e-6 at 32², 64², 128², orders 3.07 and 3.02. The SPH gradient
// (A.20) at fixed D_K/Δl does not converge in this sense: it tends to the kernel-filtered one.
TEST(FittedGradient, ConvergesAtThirdOrder) {
  std::vector<double> errors;
  const std::vector<int> sides{32, 64, 128};
  for (const int n : sides) errors.push_back(gradient_error(jittered_taylor_green(2, n, 3.0, 9)));
  for (std::size_t k = 0; k + 1 < errors.size(); ++k) {
    const double order = std::log2(errors[k] / errors[k + 1]);
    std::printf("2D fitted gradient: N = %d RMS error %.3e, N = %d %.3e, order %.2f\n", sides[k],
                errors[k], sides[k + 1], errors[k + 1], order);
    EXPECT_GT(order, 2.7);
  }
}

TEST(FittedGradient, ThreadCountDoesNotChangeTheResult) {
  for (const int dim : {2, 3}) {
    const FittedCase c = jittered_taylor_green(dim, dim == 3 ? 14 : 40, 3.0, 5);
    const auto run = [&](int threads) {
      const int saved = omp_get_max_threads();
      omp_set_num_threads(threads);
      std::vector<sim::VelocityGradient> j = fitted_velocity_gradient(c.grid, c.particles, c.fit);
      std::vector<double> omega_x = c.particles.velocity[0];
      const std::span<const double> field(omega_x);
      std::vector<double> sampled = fitted_sample(c.grid, c.particles, c.fit, {&field, 1})[0];
      omp_set_num_threads(saved);
      return std::make_pair(j, sampled);
    };
    const auto one = run(1), two = run(2);
    ASSERT_EQ(one.first.size(), two.first.size());
    EXPECT_EQ(std::memcmp(one.first.data(), two.first.data(),
                          one.first.size() * sizeof(sim::VelocityGradient)),
              0)
        << dim << "D gradient";
    ASSERT_EQ(one.second.size(), c.grid.size());
    EXPECT_EQ(std::memcmp(one.second.data(), two.second.data(), one.second.size() * sizeof(double)),
              0)
        << dim << "D sample";
  }
}

// Interpolation onto the grid: the quadratic fit of the velocity at every node is within
// O((kR)^3) of the field; at a subset of nodes it gives the same values as on the whole grid.
TEST(FittedSample, InterpolatesASmoothFieldAndSubsetsAgree) {
  const FittedCase c = jittered_taylor_green(2, 64, 3.0, 21);
  const std::span<const double> field(c.particles.velocity[0]);
  const std::vector<double> all = fitted_sample(c.grid, c.particles, c.fit, {&field, 1})[0];
  const int m = c.grid.points_per_side;
  const double h = c.grid.spacing();
  double worst = 0.0;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i)
      worst =
          std::max(worst, std::abs(all[c.grid.index(i, j)] - std::sin(i * h) * std::cos(j * h)));
  std::printf("2D fitted sample of sin x cos y at 64^2, R = 3 dl: max error %.2e\n", worst);
  EXPECT_LT(worst, 2e-3);
  const std::vector<std::size_t> nodes{0, 17, c.grid.size() - 1, 1000};
  const std::vector<double> some = fitted_sample(c.grid, c.particles, c.fit, {&field, 1}, nodes)[0];
  for (std::size_t k = 0; k < nodes.size(); ++k) EXPECT_EQ(some[k], all[nodes[k]]) << nodes[k];
}

TEST(FittedSample, RejectsBadInputNamingTheProblem) {
  const FittedCase c = jittered_taylor_green(2, 16, 3.0, 2);
  const auto message = [&](auto&& call) -> std::string {
    try {
      call();
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  const std::vector<double> short_field(c.particles.size() - 1, 1.0);
  const std::span<const double> bad(short_field), good(c.particles.velocity[0]);
  EXPECT_NE(message([&] {
              fitted_sample(c.grid, c.particles, c.fit, {&bad, 1});
            }).find("one value per particle"),
            std::string::npos);
  const std::array<std::span<const double>, 4> four{good, good, good, good};
  EXPECT_NE(message([&] {
              fitted_sample(c.grid, c.particles, c.fit, four);
            }).find("between 1 and 3 fields"),
            std::string::npos);
  const std::vector<std::size_t> outside{c.grid.size()};
  EXPECT_NE(message([&] {
              fitted_sample(c.grid, c.particles, c.fit, {&good, 1}, outside);
            }).find("node outside the grid"),
            std::string::npos);
  FitSettings wide = c.fit;
  wide.radius = 0.6 * c.grid.length;
  EXPECT_NE(
      message([&] { fitted_velocity_gradient(c.grid, c.particles, wide); }).find("fit radius"),
      std::string::npos);
  sim::ParticleArrays no_volume = c.particles;
  no_volume.volume.clear();
  EXPECT_NE(message([&] {
              fitted_velocity_gradient(c.grid, no_volume, c.fit);
            }).find("particle volumes missing"),
            std::string::npos);
}

}  // namespace
}  // namespace sphles::analysis
