// SPDX-License-Identifier: GPL-3.0-or-later
// Implicit sub-filter stress (3.27), its norm (4.7) and principal axes (4.8), and the chapter-4
// statistics of SPEC §5.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <random>
#include <vector>

#include "analysis/statistics.hpp"
#include "analysis/subfilter_stress.hpp"
#include "sim/packing.hpp"
#include "test_support.hpp"

namespace sphles::analysis {
namespace {

constexpr int kSlot[3][3] = {{kXX, kXY, kXZ}, {kXY, kYY, kYZ}, {kXZ, kYZ, kZZ}};

Snapshot snapshot_of(const sim::SolverConfig& c, const sim::ParticleArrays& p) {
  Snapshot s;
  s.box = c.box;
  s.kernel = c.kernel;
  s.support_radius = c.support_radius;
  s.particle_spacing = c.particle_spacing;
  s.fluid = c.fluid;
  s.particles = p;
  return s;
}

double max_norm(const SubfilterStressField& f) {
  return *std::max_element(f.norm.begin(), f.norm.end());
}

class DimensionTest : public ::testing::TestWithParam<int> {};

// v_j - v_i = 0 exactly for a uniform translation, so τ is exactly zero on any arrangement; and
// τ is Galilean invariant: adding U to a random flow changes it only by round-off.
TEST_P(DimensionTest, UniformTranslationGivesZeroStress) {
  const int dim = GetParam();
  auto flow = sim::testing::random_flow(dim, dim == 3 ? 10 : 24, 6.0, 1.0, 3);
  const Snapshot random = snapshot_of(flow.config, flow.particles);
  const SubfilterStressField reference = implicit_subfilter_stress(random);
  ASSERT_GT(max_norm(reference), 0.0);

  const double velocity[3] = {0.3, -1.2, 0.7};
  sim::ParticleArrays uniform = flow.particles, shifted = flow.particles;
  for (std::size_t i = 0; i < uniform.size(); ++i) {
    for (int d = 0; d < dim; ++d) {
      uniform.velocity[d][i] = velocity[d];
      shifted.velocity[d][i] += velocity[d];
    }
  }
  const SubfilterStressField zero = implicit_subfilter_stress(snapshot_of(flow.config, uniform));
  for (std::size_t i = 0; i < uniform.size(); ++i) {
    for (int c = 0; c < 6; ++c) ASSERT_EQ(zero.tensor[i][c], 0.0) << i << " " << c;
    ASSERT_EQ(zero.norm[i], 0.0);
  }

  const SubfilterStressField moved = implicit_subfilter_stress(snapshot_of(flow.config, shifted));
  const double scale = max_norm(reference);
  double worst = 0.0;
  for (std::size_t i = 0; i < shifted.size(); ++i)
    for (int c = 0; c < 6; ++c)
      worst = std::max(worst, std::abs(moved.tensor[i][c] - reference.tensor[i][c]) / scale);
  std::printf("%dD Galilean invariance: max |τ(v+U) - τ(v)| / max|τ| = %.2e\n", dim, worst);
  EXPECT_LT(worst, 1e-13);
}

// Linear shear v = (γ y, 0, 0) on a perfect lattice with M = ρ Δl^n.
//
// Continuum limit: τ_xx = Σ_j (γ y_ji)² W_ij M_j → ρ γ² ∫ y² W(r) dⁿr = ρ γ² μ₂ / n, since by
// isotropy ∫ y² W = (1/n) ∫ r² W = μ₂ / n. Every other component carries a factor v_y or v_z
// differences, which are exactly zero.
//
// Wendland C4, W = (C_n / H^n) f(q), f = (1-q)^6 (1 + 6q + 35/3 q²), q = r/H, with
// B(a, b) = ∫₀¹ q^a (1-q)^b dq = a! b! / (a+b+1)!:
//   3D: μ₂ = 4π C_3 H² ∫ q⁴ f dq = 4π C_3 H² [B(4,6) + 6 B(5,6) + 35/3 B(6,6)]
//          = 4π (495/(32π)) H² [1/2310 + 6/5544 + 35/36036] = 4π (495/(32π)) (16/6435) H²
//          = 2 H² / 13.
//   2D: μ₂ = 2π C_2 H² ∫ q³ f dq = 2π C_2 H² [B(3,6) + 6 B(4,6) + 35/3 B(5,6)]
//          = 2π (9/π) H² [1/840 + 6/2310 + 35/16632] = 18 (7/1188) H² = 7 H² / 66.
// So τ_xx = ρ γ² 2H²/39 (3D) and ρ γ² 7H²/132 (2D).
//
// The lattice sum is a trapezoidal (Poisson-summation) quadrature of the smooth, compactly
// supported y² W. Its relative error at D_K/Δl = 8 (H = 4Δl) is of the size of the lattice
// normalisation error Σ_j W_ij Δl^n - 1 of the same kernel (4.2e-4 in 2D, 3.1e-4 in 3D); measured
// -3.5e-4 (2D) and -7.0e-5 (3D), the same numbers as an independent direct summation. We assert
// 1e-3: a wrong moment, factor n, normalisation or missing M_j is off by O(1). That the
// difference is quadrature error and not a modelling error is checked by refining: at
// D_K/Δl = 12 it drops to -7.4e-6 (2D) and 1.8e-6 (3D); asserted below 2e-5.
//
// Only particles farther than H from the y boundary are checked: the periodic wrap makes v_x
// jump by γ L there.
struct ShearCase {
  sim::SolverConfig config;
  sim::ParticleArrays particles;
};

ShearCase shear_lattice(int dim, int per_side, double density, double gamma,
                        double diameter_over_spacing = 8.0) {
  ShearCase s;
  sim::SolverConfig& c = s.config;
  c.box.dimension = dim;
  for (int d = 0; d < dim; ++d) c.box.length[d] = 1.0;
  c.kernel = sim::KernelType::WendlandC4;
  c.particle_spacing = 1.0 / per_side;
  c.support_radius = 0.5 * diameter_over_spacing * c.particle_spacing;  // H = D_K / 2
  s.particles = sim::make_lattice(c.box, per_side);
  const double mass = density * std::pow(c.particle_spacing, dim);
  for (std::size_t i = 0; i < s.particles.size(); ++i) {
    s.particles.mass[i] = mass;
    s.particles.velocity[0][i] = gamma * s.particles.position[1][i];
  }
  return s;
}

bool away_from_shear_jump(const ShearCase& s, std::size_t i) {
  const double y = s.particles.position[1][i];
  return y > s.config.support_radius && y < s.config.box.length[1] - s.config.support_radius;
}

TEST_P(DimensionTest, LinearShearMatchesKernelSecondMoment) {
  const int dim = GetParam();
  const int per_side = dim == 3 ? 16 : 32;
  const double density = 1.25, gamma = 0.75;
  const ShearCase s = shear_lattice(dim, per_side, density, gamma);
  const ShearCase doubled = shear_lattice(dim, per_side, density, 2.0 * gamma);
  const ShearCase tripled = shear_lattice(dim, per_side, density, 3.0 * gamma);
  const SubfilterStressField f = implicit_subfilter_stress(snapshot_of(s.config, s.particles));
  const SubfilterStressField f2 =
      implicit_subfilter_stress(snapshot_of(doubled.config, doubled.particles));
  const SubfilterStressField f3 =
      implicit_subfilter_stress(snapshot_of(tripled.config, tripled.particles));

  const double h = s.config.support_radius;
  const double mu2 = dim == 3 ? 2.0 * h * h / 13.0 : 7.0 * h * h / 66.0;
  const double expected = density * gamma * gamma * mu2 / dim;
  std::size_t checked = 0;
  double worst_error = 0.0, worst_scaling = 0.0;
  for (std::size_t i = 0; i < s.particles.size(); ++i) {
    for (int c = 1; c < 6; ++c) ASSERT_EQ(f.tensor[i][c], 0.0) << "component " << c;
    if (!away_from_shear_jump(s, i)) continue;
    ++checked;
    const double xx = f.tensor[i][kXX];
    worst_error = std::max(worst_error, std::abs(xx / expected - 1.0));
    // Exactly quadratic in γ: 2γ gives 4 τ_xx, 3γ gives 9 τ_xx (to round-off).
    worst_scaling = std::max(worst_scaling, std::abs(f2.tensor[i][kXX] / (4.0 * xx) - 1.0));
    worst_scaling = std::max(worst_scaling, std::abs(f3.tensor[i][kXX] / (9.0 * xx) - 1.0));
    // Principal axes of a rank-one tensor: τ_I = τ_xx along e_x, the rest zero.
    EXPECT_DOUBLE_EQ(f.principal[i][0], xx);
    EXPECT_DOUBLE_EQ(f.norm[i], xx);
    EXPECT_NEAR(f.direction[i][0][0], 1.0, 1e-15);
    for (int a = 1; a < dim; ++a) EXPECT_NEAR(f.principal[i][a], 0.0, 1e-14 * xx);
  }
  std::printf(
      "%dD shear, WC4 D_K=8dl: tau_xx lattice/closed form rel. error = %.3e (closed form "
      "%.10e, %zu particles); gamma^2 scaling rel. error = %.1e\n",
      dim, worst_error, expected, checked, worst_scaling);
  ASSERT_GT(checked, s.particles.size() / 3);
  EXPECT_LT(worst_error, 1e-3);
  EXPECT_LT(worst_scaling, 1e-14);

  // Refinement D_K/Δl = 8 → 12 at the same box: the lattice sum converges to the closed form.
  const ShearCase fine = shear_lattice(dim, per_side, density, gamma, 12.0);
  const SubfilterStressField ff =
      implicit_subfilter_stress(snapshot_of(fine.config, fine.particles));
  const double hf = fine.config.support_radius;
  const double expected_fine =
      density * gamma * gamma * (dim == 3 ? 2.0 * hf * hf / 13.0 : 7.0 * hf * hf / 66.0) / dim;
  double worst_fine = 0.0;
  std::size_t checked_fine = 0;
  for (std::size_t i = 0; i < fine.particles.size(); ++i) {
    if (!away_from_shear_jump(fine, i)) continue;
    ++checked_fine;
    worst_fine = std::max(worst_fine, std::abs(ff.tensor[i][kXX] / expected_fine - 1.0));
  }
  std::printf("%dD shear, WC4 D_K=12dl: rel. error = %.3e (%zu particles)\n", dim, worst_fine,
              checked_fine);
  ASSERT_GT(checked_fine, 0u);
  EXPECT_LT(worst_fine, 2e-5);
  EXPECT_LT(worst_fine, 0.1 * worst_error);
}

// Σ_a λ_a t_a t_aᵀ = τ to 1e-12 of |τ|, orthonormal directions, descending principal stresses,
// |τ|_F = sqrt(Σ λ²), and the sign convention (first non-negligible component positive).
TEST_P(DimensionTest, EigenDecompositionReproducesTensor) {
  const int dim = GetParam();
  auto flow = sim::testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, 17);
  const SubfilterStressField f =
      implicit_subfilter_stress(snapshot_of(flow.config, flow.particles));
  ASSERT_EQ(f.dimension, dim);
  ASSERT_EQ(f.tensor.size(), flow.particles.size());
  double worst_reconstruction = 0.0, worst_orthonormality = 0.0, worst_norm = 0.0;
  for (std::size_t i = 0; i < f.tensor.size(); ++i) {
    const double norm = f.norm[i];
    ASSERT_GT(norm, 0.0);
    for (int a = 0; a < dim; ++a) {
      for (int b = 0; b < dim; ++b) {
        double sum = 0.0;
        for (int k = 0; k < dim; ++k)
          sum += f.principal[i][k] * f.direction[i][k][a] * f.direction[i][k][b];
        worst_reconstruction =
            std::max(worst_reconstruction, std::abs(sum - f.tensor[i][kSlot[a][b]]) / norm);
        double dot = 0.0;
        for (int d = 0; d < 3; ++d) dot += f.direction[i][a][d] * f.direction[i][b][d];
        worst_orthonormality = std::max(worst_orthonormality, std::abs(dot - (a == b)));
      }
    }
    double squares = 0.0;
    for (int a = 0; a < dim; ++a) squares += f.principal[i][a] * f.principal[i][a];
    worst_norm = std::max(worst_norm, std::abs(std::sqrt(squares) / norm - 1.0));
    for (int a = 0; a + 1 < dim; ++a) ASSERT_GE(f.principal[i][a], f.principal[i][a + 1]);
    // Positive semi-definite: a sum of outer products with positive weights.
    ASSERT_GE(f.principal[i][dim - 1], -1e-12 * norm);
    for (int a = dim; a < 3; ++a) ASSERT_EQ(f.principal[i][a], 0.0);
    for (int a = 0; a < dim; ++a) {
      double largest = 0.0;
      for (int d = 0; d < dim; ++d) largest = std::max(largest, std::abs(f.direction[i][a][d]));
      for (int d = 0; d < dim; ++d) {
        if (std::abs(f.direction[i][a][d]) > 1e-12 * largest) {
          ASSERT_GT(f.direction[i][a][d], 0.0);
          break;
        }
      }
      for (int d = dim; d < 3; ++d) ASSERT_EQ(f.direction[i][a][d], 0.0);
    }
  }
  std::printf(
      "%dD random flow: reconstruction %.1e, orthonormality %.1e, norm vs sqrt(sum l^2) %.1e\n",
      dim, worst_reconstruction, worst_orthonormality, worst_norm);
  EXPECT_LT(worst_reconstruction, 1e-12);
  EXPECT_LT(worst_orthonormality, 1e-12);
  EXPECT_LT(worst_norm, 1e-12);
}

bool bitwise_equal(const void* a, const void* b, std::size_t bytes) {
  return std::memcmp(a, b, bytes) == 0;
}

SubfilterStressField stress_with_threads(int threads, const Snapshot& snapshot) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  SubfilterStressField f = implicit_subfilter_stress(snapshot);
  omp_set_num_threads(saved);
  return f;
}

TEST_P(DimensionTest, ThreadCountDoesNotChangeTheField) {
  const int dim = GetParam();
  auto flow = sim::testing::random_flow(dim, dim == 3 ? 12 : 40, 6.0, 1.0, 29);
  const Snapshot snapshot = snapshot_of(flow.config, flow.particles);
  ASSERT_GT(snapshot.size(), 2u * 512u);  // more than one chunk of the parallel loops
  const SubfilterStressField one = stress_with_threads(1, snapshot);
  const SubfilterStressField two = stress_with_threads(2, snapshot);
  const std::size_t n = snapshot.size();
  ASSERT_EQ(two.tensor.size(), n);
  EXPECT_TRUE(bitwise_equal(one.tensor.data(), two.tensor.data(), n * sizeof(one.tensor[0])));
  EXPECT_TRUE(bitwise_equal(one.norm.data(), two.norm.data(), n * sizeof(double)));
  EXPECT_TRUE(
      bitwise_equal(one.principal.data(), two.principal.data(), n * sizeof(one.principal[0])));
  EXPECT_TRUE(
      bitwise_equal(one.direction.data(), two.direction.data(), n * sizeof(one.direction[0])));
}

INSTANTIATE_TEST_SUITE_P(Dimensions, DimensionTest, ::testing::Values(2, 3),
                         [](const auto& info) { return std::to_string(info.param) + "D"; });

TEST(BivariateHistogram, CountsSumToSamplesAndNormaliseByMaximum) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<double> x(1000), y(1000);
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] = 3.0 * uniform(rng);
    y[i] = 5.0 * uniform(rng) * uniform(rng);
  }
  const Histogram2D h = normalised_bivariate_histogram(x, y, 10, 8);
  ASSERT_EQ(h.counts.size(), 80u);
  std::uint64_t sum = 0;
  for (const std::uint64_t c : h.counts) sum += c;
  EXPECT_EQ(sum, x.size());
  EXPECT_EQ(h.total, x.size());

  // Placement: x* = 0, 1/4, 1/2, 1 and y* = 1, 1/2, 1/4, 0 on 4 × 4 bins; the maxima (value 1)
  // go into the last bin.
  const std::vector<double> px = {0.0, 1.0, 2.0, 4.0}, py = {4.0, 2.0, 1.0, 0.0};
  const Histogram2D p = normalised_bivariate_histogram(px, py, 4, 4);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(p.counts[k + 4 * (3 - k)], 1u) << k;
  EXPECT_EQ(p.total, 4u);

  // A zero maximum maps every value to 0.
  const std::vector<double> zeros(7, 0.0);
  const Histogram2D z = normalised_bivariate_histogram(zeros, zeros, 3, 3);
  EXPECT_EQ(z.counts[0], 7u);
  EXPECT_EQ(z.total, 7u);
}

// A stress field with random major directions t_I and velocities built parallel or perpendicular
// to them (some with v = 0 or a small norm, which must be left out).
struct AlignmentCase {
  SubfilterStressField stress;
  sim::ParticleArrays particles;
  std::uint64_t expected_total = 0;
};

AlignmentCase alignment_case(int dim, bool perpendicular, double threshold) {
  std::mt19937_64 rng(41);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const std::size_t n = 500;
  AlignmentCase a;
  a.stress.dimension = dim;
  a.stress.tensor.assign(n, {});
  a.stress.norm.resize(n);
  a.stress.principal.assign(n, {});
  a.stress.direction.assign(n, {});
  a.particles.dimension = dim;
  a.particles.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::array<double, 3> t{}, v{};
    double length = 0.0;
    for (int d = 0; d < dim; ++d) {
      t[d] = normal(rng);
      length += t[d] * t[d];
    }
    for (int d = 0; d < dim; ++d) t[d] /= std::sqrt(length);
    const double speed = 0.1 + 2.0 * uniform(rng);
    if (!perpendicular) {
      const double scale = uniform(rng) < 0.5 ? -speed : speed;  // the line, not the arrow
      for (int d = 0; d < dim; ++d) v[d] = scale * t[d];
    } else if (dim == 2) {
      v = {-speed * t[1], speed * t[0], 0.0};
    } else {  // t × r for a random r
      const double r[3] = {normal(rng), normal(rng), normal(rng)};
      v = {t[1] * r[2] - t[2] * r[1], t[2] * r[0] - t[0] * r[2], t[0] * r[1] - t[1] * r[0]};
    }
    if (i % 10 == 3) v = {0.0, 0.0, 0.0};
    a.stress.direction[i][0] = t;
    a.stress.norm[i] = i == 0 ? 1.0 : uniform(rng);
    for (int d = 0; d < dim; ++d) a.particles.velocity[d][i] = v[d];
    if (a.stress.norm[i] > threshold && i % 10 != 3) ++a.expected_total;
  }
  return a;
}

TEST(AngleHistogram, ParallelGoesToFirstBinPerpendicularToLast) {
  const double threshold = 0.1;
  const int bins = 9;  // 10° each
  for (const int dim : {2, 3}) {
    for (const bool perpendicular : {false, true}) {
      const AlignmentCase a = alignment_case(dim, perpendicular, threshold);
      const AngleHistogram h =
          principal_direction_alignment(a.stress, a.particles, bins, threshold);
      ASSERT_EQ(h.counts.size(), static_cast<std::size_t>(bins));
      EXPECT_EQ(h.total, a.expected_total);
      ASSERT_GT(a.expected_total, 300u);
      ASSERT_LT(a.expected_total, 500u);  // the threshold and v = 0 did exclude particles
      std::uint64_t sum = 0;
      for (const std::uint64_t c : h.counts) sum += c;
      EXPECT_EQ(sum, a.expected_total);
      EXPECT_EQ(h.counts[perpendicular ? bins - 1 : 0], a.expected_total)
          << dim << "D, perpendicular " << perpendicular;
    }
  }

  // Exactly π/2 (top edge) goes into the last bin; 35° into bin 3 of 9.
  AlignmentCase e = alignment_case(3, false, threshold);
  e.stress.norm.assign(e.stress.norm.size(), 1.0);
  for (std::size_t i = 0; i < e.particles.size(); ++i) {
    e.stress.direction[i][0] = {1.0, 0.0, 0.0};
    const double angle = i % 2 == 0 ? 0.5 * std::numbers::pi : 35.0 * std::numbers::pi / 180.0;
    e.particles.velocity[0][i] = std::cos(angle);
    e.particles.velocity[1][i] = i % 4 < 2 ? std::sin(angle) : 0.0;
    e.particles.velocity[2][i] = i % 4 < 2 ? 0.0 : -std::sin(angle);
  }
  const AngleHistogram h = principal_direction_alignment(e.stress, e.particles, bins, threshold);
  EXPECT_EQ(h.counts[bins - 1], e.particles.size() / 2);
  EXPECT_EQ(h.counts[3], e.particles.size() / 2);
  EXPECT_EQ(h.total, e.particles.size());
}

// The physical version: in a linear shear t_I = e_x and v ∥ e_x, so all counted particles fall
// into the first bin; with the velocity turned to e_z (stress unchanged) into the last.
TEST(AngleHistogram, ShearFlowMajorAxisAlongVelocity) {
  const ShearCase s = shear_lattice(3, 16, 1.0, 1.0);
  const SubfilterStressField f = implicit_subfilter_stress(snapshot_of(s.config, s.particles));
  const double threshold = 0.1;
  const double top = max_norm(f);
  std::uint64_t above = 0;
  for (const double norm : f.norm) above += norm / top > threshold;
  const AngleHistogram parallel = principal_direction_alignment(f, s.particles, 6, threshold);
  EXPECT_EQ(parallel.total, above);
  EXPECT_EQ(parallel.counts[0], above);

  sim::ParticleArrays turned = s.particles;
  std::swap(turned.velocity[0], turned.velocity[2]);
  const AngleHistogram perpendicular = principal_direction_alignment(f, turned, 6, threshold);
  EXPECT_EQ(perpendicular.total, above);
  EXPECT_EQ(perpendicular.counts[5], above);
  ASSERT_GT(above, 0u);
}

}  // namespace
}  // namespace sphles::analysis
