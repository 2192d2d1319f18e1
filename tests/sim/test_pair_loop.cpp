// SPDX-License-Identifier: GPL-3.0-or-later
// The pair loop and its evaluators (sim/pair_loop.hpp): every pairwise momentum term is
// antisymmetric bit for bit, the vectorised and the ordered summation agree to round-off, the
// interaction list holds exactly the pairs inside the support, and a pass over it equals the same
// pass over the Verlet list, and the shortcut for particles far from the box's faces is the minimum
// image bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <tuple>
#include <vector>

#include "sim/pair_loop.hpp"
#include "sim/physics/particle_shifting.hpp"
#include "sim/physics/subfilter_stress.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/physics/transport_velocity.hpp"
#include "sim/select.hpp"
#include "sim/subfilter.hpp"
#include "test_support.hpp"

namespace sphles::sim {
namespace {

using Kernel3 = Kernel<kernel_shape::WendlandC4, 3>;
using Kernel2 = Kernel<kernel_shape::WendlandC4, 2>;

/// Two particles i = 0, j = 1 at a random separation inside the support of radius 1, with random
/// velocities, pressures, densities, eddy viscosities and shifts, and *equal* volumes and masses:
/// then every pair term of M_i a_i is the evaluator's own output (up to the common factor V), and
/// antisymmetry means pair(i, j) == -pair(j, i) bit for bit.
struct TwoParticles {
  ParticleArrays p;
  std::array<std::vector<double>, 3> shift;
  std::array<std::vector<double>, 3> background;
  std::vector<double> nu_t;
  std::vector<double> tau;  // τ per particle, row-major 3x3, symmetric
  std::vector<double> weights;
  double dx[3];
};

TwoParticles two_particles(int dim, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  TwoParticles t;
  t.p.dimension = dim;
  t.p.resize(2);
  double r2 = 0.0;
  do {
    r2 = 0.0;
    for (int d = 0; d < dim; ++d) {
      t.dx[d] = 0.6 * u(rng);
      r2 += t.dx[d] * t.dx[d];
    }
  } while (r2 < 0.01 || r2 >= 0.9);
  for (int d = 0; d < dim; ++d) {
    t.p.position[d][0] = 1.0 + t.dx[d];
    t.p.position[d][1] = 1.0;
    t.shift[d] = {0.1 * u(rng), 0.1 * u(rng)};
    t.background[d] = {0.0, 0.0};
    t.p.acceleration[d] = {0.0, 0.0};
    for (std::size_t i = 0; i < 2; ++i) t.p.velocity[d][i] = u(rng);
  }
  for (std::size_t i = 0; i < 2; ++i) {
    t.p.volume[i] = 0.37;
    t.p.mass[i] = 0.41;
    t.p.density[i] = 1.0 + 0.1 * u(rng);
    t.p.pressure[i] = 5.0 * u(rng);
  }
  t.nu_t = {0.01 * (1.5 + u(rng)), 0.01 * (1.5 + u(rng))};
  t.tau.assign(18, 0.0);
  for (std::size_t i = 0; i < 2; ++i)
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b) t.tau[i * 9 + a * 3 + b] = t.tau[i * 9 + b * 3 + a] = u(rng);
  // Directional coefficients g_i near the isotropic g ≡ 1 (coefficient 1 of e_x^4 ...): 15 per
  // particle, of which 2D uses the first 5.
  t.weights.resize(2 * 15);
  for (std::size_t k = 0; k < t.weights.size(); ++k)
    t.weights[k] = (k % 15 == 0 ? 1.0 : 0.0) + 0.05 * u(rng);
  return t;
}

/// pair(i -> j) and pair(j -> i) of an evaluator, with x_ji = -x_ij exactly.
template <int Dim, class E>
void expect_antisymmetric(const E& e, const TwoParticles& t, int first_output, int outputs,
                          const char* what) {
  Pair<Dim> ij, ji;
  ij.j = 1;
  ji.j = 0;
  // The loop computes r² from x_ij with one compiled expression for both directions, so r² and
  // r are the same bits for (i, j) and (j, i); here they are taken from one evaluation too.
  ij.r2 = 0.0;
  for (int d = 0; d < Dim; ++d) {
    ij.dx[d] = t.dx[d];
    ji.dx[d] = -t.dx[d];
    ij.r2 += t.dx[d] * t.dx[d];
  }
  ji.r2 = ij.r2;
  ij.r = ji.r = std::sqrt(ij.r2);
  double out_ij[E::outputs], out_ji[E::outputs];
  e.pair(e.own(0), ij, out_ij);
  e.pair(e.own(1), ji, out_ji);
  for (int k = first_output; k < first_output + outputs; ++k) {
    EXPECT_NE(out_ij[k], 0.0) << what << " output " << k << " is zero: the test shows nothing";
    EXPECT_EQ(out_ij[k], -out_ji[k]) << what << " output " << k << ": " << std::hexfloat
                                     << out_ij[k] << " against " << -out_ji[k];
  }
}

template <int Dim, class KernelT>
void check_all(std::uint64_t seed) {
  const KernelT kernel(1.0);
  TwoParticles t = two_particles(Dim, seed);
  const FluidParameters fluid{.reference_density = 1.0,
                              .sound_speed = 10.0,
                              .reference_pressure = 3.0,
                              .dynamic_viscosity = 0.02};
  const VelocityView v = view_velocity(t.p);
  const VelocityView dv = view_of(t.shift, Dim);
  expect_antisymmetric<Dim>(ThesisMomentum<Dim, KernelT, false>(kernel, fluid, v, t.p, nullptr), t,
                            0, Dim, "thesis (A.9)+(A.14)");
  expect_antisymmetric<Dim>(
      ThesisMomentum<Dim, KernelT, true>(kernel, fluid, v, t.p, t.weights.data()), t, 0, Dim,
      "thesis with the corrected viscous operator");
  expect_antisymmetric<Dim>(
      TransportVelocityMomentum<Dim, KernelT>(kernel, fluid, v, dv, t.background, t.p), t, 0,
      2 * Dim, "transport velocity (eq. 8 and 13)");
  expect_antisymmetric<Dim>(
      ShiftingAle<Dim, AleCorrection::Conservative, KernelT>(kernel, v, dv, t.p), t, 0, Dim,
      "shifting ALE, conservative");
  std::vector<double> tau(2 * Dim * Dim);
  for (std::size_t i = 0; i < 2; ++i)
    for (int a = 0; a < Dim; ++a)
      for (int b = 0; b < Dim; ++b) tau[(i * Dim + a) * Dim + b] = t.tau[i * 9 + a * 3 + b];
  expect_antisymmetric<Dim>(SubfilterDivergence<Dim, KernelT>(kernel, tau, t.p), t, 0, Dim,
                            "sub-filter divergence (A.18)");
  expect_antisymmetric<Dim>(SubfilterMcg<Dim, KernelT>(kernel, v, t.nu_t, t.p), t, 0, Dim,
                            "SMAG-MCG (A.23)");
}

TEST(PairEvaluators, MomentumTermsAreAntisymmetricBitForBit) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    check_all<3, Kernel3>(seed);
    check_all<2, Kernel2>(seed);
  }
}

/// A random flow with volumes, densities and pressures from the density pass.
testing::RandomFlow prepared_flow(int dim, int per_side, std::uint64_t seed) {
  testing::RandomFlow flow = testing::random_flow(dim, per_side, 8.0, 1.0, seed);
  ParticleArrays& p = flow.particles;
  for (int d = 0; d < dim; ++d) p.acceleration[d].assign(p.size(), 0.0);
  return flow;
}

/// Sorts the particles into the search's locality order and builds its lists.
void list_in_locality_order(VerletNeighbourSearch& search, ParticleArrays& p) {
  p.reorder(search.locality_order(view_positions(p)));
  search.build(view_positions(p));
}

template <int Dim>
void compare_summations(int per_side) {
  testing::RandomFlow flow = prepared_flow(Dim, per_side, 4);
  const SolverConfig& c = flow.config;
  ParticleArrays& p = flow.particles;
  VerletNeighbourSearch search(c.box, c.support_radius, 0.1 * c.support_radius);
  list_in_locality_order(search, p);
  const Kernel<kernel_shape::WendlandC4, Dim> kernel(c.support_radius);
  const PeriodicGeometry<Dim> geometry(c.box, p);
  InteractionList pairs;
  compacting_pair_pass<Dim, Summation::Lanes>(
      SummationDensity<Dim, decltype(kernel)>(kernel, c.fluid, p), geometry, search.list(),
      c.support_radius, 0, p.size(), pairs);
  const std::vector<double> density_lanes = p.density;
  compacting_pair_pass<Dim, Summation::Ordered>(
      SummationDensity<Dim, decltype(kernel)>(kernel, c.fluid, p), geometry, search.list(),
      c.support_radius, 0, p.size(), pairs);
  const auto force = [&](auto summation) {
    ThesisMomentum<Dim, decltype(kernel), false> e(kernel, c.fluid, view_velocity(p), p, nullptr);
    pair_pass<Dim, decltype(summation)::value>(e, geometry, pairs, c.support_radius, 0, p.size());
    return p.acceleration;
  };
  const auto lanes = force(std::integral_constant<Summation, Summation::Lanes>{});
  const auto ordered = force(std::integral_constant<Summation, Summation::Ordered>{});
  double worst_density = 0.0, worst_force = 0.0, force_scale = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    worst_density =
        std::max(worst_density, std::abs(density_lanes[i] - p.density[i]) / p.density[i]);
    for (int d = 0; d < Dim; ++d) {
      worst_force = std::max(worst_force, std::abs(lanes[d][i] - ordered[d][i]));
      force_scale = std::max(force_scale, std::abs(ordered[d][i]));
    }
  }
  std::printf(
      "%dD: lanes against list order: density %.2e relative, acceleration %.2e of max "
      "|a| = %.3g\n",
      Dim, worst_density, worst_force / force_scale, force_scale);
  EXPECT_LT(worst_density, 1e-14);
  EXPECT_LT(worst_force / force_scale, 1e-13);
}

TEST(PairLoop, LanesAndListOrderAgreeToRoundOff) {
  compare_summations<3>(14);
  compare_summations<2>(40);
}

// Evaluators fused into one pass (Fused) give what their separate passes give, bit for bit: each
// output is summed as its own pass sums it, and the parts finish in order (the ALE correction
// adds to the acceleration the momentum part wrote). Here the particle-shifting scheme's pass:
// pressure and viscous term, ALE correction, shifting velocity.
template <int Dim>
void compare_fused(int per_side) {
  testing::RandomFlow flow = prepared_flow(Dim, per_side, 11);
  const SolverConfig& c = flow.config;
  ParticleArrays& p = flow.particles;
  VerletNeighbourSearch search(c.box, c.support_radius, 0.1 * c.support_radius);
  list_in_locality_order(search, p);
  const Kernel<kernel_shape::WendlandC4, Dim> kernel(c.support_radius);
  using KernelT = decltype(kernel);
  const PeriodicGeometry<Dim> geometry(c.box, p);
  InteractionList pairs;
  density_pass<Dim>(kernel, c.box, search.list(), c.fluid, p, &pairs);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::array<std::vector<double>, 3> drift, separate, fused;
  for (int d = 0; d < Dim; ++d) {
    drift[d].resize(p.size());
    for (double& x : drift[d]) x = u(rng);
    separate[d].assign(p.size(), 0.0);
    fused[d].assign(p.size(), 0.0);
  }
  const ShiftingParameters shifting =
      shifting_parameters(1.0, c.support_radius, kernel.value(c.particle_spacing));
  const VelocityView v = view_velocity(p);
  const VelocityView dv = view_of(drift, Dim);
  using Momentum = ThesisMomentum<Dim, KernelT, false>;
  using Ale = ShiftingAle<Dim, AleCorrection::Full, KernelT>;
  using Shift = ShiftingVelocity<Dim, KernelT>;
  const auto radius = c.support_radius;
  pair_pass<Dim>(Momentum(kernel, c.fluid, v, p, nullptr), geometry, pairs, radius, 0, p.size());
  pair_pass<Dim>(Ale(kernel, v, dv, p), geometry, pairs, radius, 0, p.size());
  pair_pass<Dim>(Shift(kernel, shifting, p, separate), geometry, pairs, radius, 0, p.size());
  const std::array<std::vector<double>, 3> acceleration = p.acceleration;
  for (int d = 0; d < Dim; ++d) p.acceleration[d].assign(p.size(), 0.0);
  static_assert(Fused<Momentum, Ale, Shift>::outputs == 3 * Dim);
  pair_pass<Dim>(
      Fused<Momentum, Ale, Shift>(Momentum(kernel, c.fluid, v, p, nullptr), Ale(kernel, v, dv, p),
                                  Shift(kernel, shifting, p, fused)),
      geometry, pairs, radius, 0, p.size());
  std::size_t moved = 0;
  for (int d = 0; d < Dim; ++d)
    for (std::size_t i = 0; i < p.size(); ++i) {
      ASSERT_EQ(std::memcmp(&p.acceleration[d][i], &acceleration[d][i], sizeof(double)), 0)
          << "acceleration " << d << " of particle " << i;
      ASSERT_EQ(std::memcmp(&fused[d][i], &separate[d][i], sizeof(double)), 0)
          << "shifting velocity " << d << " of particle " << i;
      moved += separate[d][i] != 0.0 && acceleration[d][i] != 0.0;
    }
  EXPECT_GT(moved, p.size() / 2) << "nothing to compare";
}

TEST(PairLoop, FusedPassEqualsItsPartsBitForBit) {
  compare_fused<3>(12);
  compare_fused<2>(36);
}

// The interaction list holds, for every particle, exactly the Verlet entries with 0 < r < H, in
// Verlet order; a pass over it summed in list order equals the same pass over the Verlet list bit
// for bit (the same pairs, the same order; the skin's entries add +0).
/// Whether every particle's interaction list holds exactly its Verlet entries closer than
/// `support` (r > 0), in Verlet order.
void expect_cut_to(const InteractionList& pairs, const NeighbourList& verlet,
                   const ParticleArrays& p, const PeriodicBox& box, double support) {
  ASSERT_EQ(pairs.num_particles(), p.size());
  std::size_t kept = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<std::uint32_t> expected;
    for (const std::uint32_t j : verlet.of(i)) {
      double r2 = 0.0;
      for (int d = 0; d < p.dimension; ++d) {
        const double dx =
            minimum_image(p.position[d][i] - p.position[d][j], box.length[d], 0.5 * box.length[d]);
        r2 += dx * dx;
      }
      if (r2 < support * support && r2 > 0.0) expected.push_back(j);
    }
    const auto got = pairs.of(i);
    ASSERT_EQ(std::vector<std::uint32_t>(got.begin(), got.end()), expected) << "particle " << i;
    kept += expected.size();
  }
  EXPECT_EQ(pairs.num_pairs(), kept);
}

/// The density pass with the run's kernel cut at `radius`, compacting into `pairs`.
void compacting_density_pass(const SolverConfig& c, int dim, double radius,
                             const VerletNeighbourSearch& search, ParticleArrays& p,
                             InteractionList& pairs) {
  with_kernel(c.kernel, dim, radius, [&](const auto& kernel) {
    constexpr int kDim = std::remove_cvref_t<decltype(kernel)>::dimension;
    density_pass<kDim>(kernel, c.box, search.list(), c.fluid, p, &pairs);
  });
}

/// The list is sized by its use: after a pass at half the support (an eighth of the pairs in
/// 3D, a quarter in 2D) a pass at the full support needs more than the array holds, grows it
/// once, and holds the right pairs; the array is then about InteractionList::kMargin times the
/// pairs and the unused tails of the threads' regions, well below the Verlet list's entries.
TEST(PairLoop, InteractionListIsSizedByItsUseAndGrowsWhenAPassNeedsMore) {
  for (const int dim : {2, 3}) {
    testing::RandomFlow flow = prepared_flow(dim, dim == 3 ? 12 : 36, 4);
    const SolverConfig& c = flow.config;
    ParticleArrays& p = flow.particles;
    VerletNeighbourSearch search(c.box, c.support_radius, 0.15 * c.support_radius);
    search.build(view_positions(p));
    InteractionList pairs;
    compacting_density_pass(c, dim, 0.5 * c.support_radius, search, p, pairs);
    expect_cut_to(pairs, search.list(), p, c.box, 0.5 * c.support_radius);
    const std::size_t few = pairs.num_pairs();
    EXPECT_LT(pairs.capacity(), search.list().num_entries());
    const std::size_t region =
        InteractionList::region_size(pairs.capacity(), omp_get_max_threads());
    compacting_density_pass(c, dim, c.support_radius, search, p, pairs);
    expect_cut_to(pairs, search.list(), p, c.box, c.support_radius);
    // Sized from the first pass (kMargin times its pairs), the array had to grow.
    EXPECT_GT(static_cast<double>(pairs.num_pairs()),
              4.0 * InteractionList::kMargin * static_cast<double>(few));
    EXPECT_GE(pairs.capacity(), pairs.num_pairs());
    // Unused: the rest of each thread's last region, and before each new region at most the
    // candidates of the particle that did not fit.
    std::size_t most_candidates = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
      most_candidates = std::max(most_candidates, search.list().of(i).size());
    const auto threads = static_cast<std::size_t>(omp_get_max_threads());
    const std::size_t regions = pairs.num_pairs() / (region - most_candidates) + threads;
    const std::size_t unused = threads * region + regions * most_candidates;
    EXPECT_LE(static_cast<double>(pairs.capacity()),
              InteractionList::kMargin * static_cast<double>(pairs.num_pairs() + unused) + 1.0);
    EXPECT_LT(pairs.capacity(), search.list().num_entries());
  }
}

TEST(PairLoop, InteractionListIsTheVerletListCutToTheSupport) {
  for (const int dim : {2, 3}) {
    testing::RandomFlow flow = prepared_flow(dim, dim == 3 ? 12 : 36, 9);
    const SolverConfig& c = flow.config;
    ParticleArrays& p = flow.particles;
    VerletNeighbourSearch search(c.box, c.support_radius, 0.2 * c.support_radius);
    search.build(view_positions(p));
    InteractionList pairs;
    with_kernel(c.kernel, dim, c.support_radius, [&](const auto& kernel) {
      constexpr int kDim = std::remove_cvref_t<decltype(kernel)>::dimension;
      density_pass<kDim>(kernel, c.box, search.list(), c.fluid, p, &pairs);
      expect_cut_to(pairs, search.list(), p, c.box, c.support_radius);
      const std::size_t kept = pairs.num_pairs();
      EXPECT_LT(kept, search.list().num_entries());  // the skin's entries are gone
      const PeriodicGeometry<kDim> geometry(c.box, p);
      const auto momentum = [&] {
        return ThesisMomentum<kDim, std::remove_cvref_t<decltype(kernel)>, false>(
            kernel, c.fluid, view_velocity(p), p, nullptr);
      };
      pair_pass<kDim, Summation::Ordered>(momentum(), geometry, search.list(), c.support_radius, 0,
                                          p.size());
      const auto over_verlet = p.acceleration;
      pair_pass<kDim, Summation::Ordered>(momentum(), geometry, pairs, c.support_radius, 0,
                                          p.size());
      for (int d = 0; d < kDim; ++d)
        EXPECT_EQ(
            std::memcmp(over_verlet[d].data(), p.acceleration[d].data(), p.size() * sizeof(double)),
            0)
            << dim << "D axis " << d;
    });
  }
}

/// PeriodicGeometry without its interior shortcut: the minimum image for every particle.
template <int Dim>
class MinimumImageEverywhere {
 public:
  explicit MinimumImageEverywhere(const PeriodicGeometry<Dim>& g) : g_(g) {}
  void position(std::size_t i, double (&xi)[Dim]) const { g_.position(i, xi); }
  double separation(const double (&xi)[Dim], std::uint32_t j, double (&dx)[Dim]) const {
    return g_.separation(xi, j, dx);
  }

 private:
  PeriodicGeometry<Dim> g_;
};

template <int Dim>
void check_interior_shortcut(int per_side) {
  testing::RandomFlow flow = prepared_flow(Dim, per_side, 11);
  const SolverConfig& c = flow.config;
  ParticleArrays& p = flow.particles;
  // Particles right at the shortcut's edge, x = H (1 + margin) from a face and just inside it,
  // and right at the faces: the pairs that decide whether the edge is drawn correctly.
  const double h = c.support_radius;
  const double edge = h * (1.0 + PeriodicGeometry<Dim>::kInteriorMargin);
  const double length = c.box.length[0];
  const double at[] = {
      std::nextafter(edge, 0.0),  edge, std::nextafter(edge, 2 * edge), length - edge, 0.0,
      std::nextafter(length, 0.0)};
  for (std::size_t k = 0; k < std::size(at); ++k) p.position[k % Dim][k] = at[k];
  VerletNeighbourSearch search(c.box, h, 0.15 * h);
  list_in_locality_order(search, p);
  const Kernel<kernel_shape::WendlandC4, Dim> kernel(h);
  const PeriodicGeometry<Dim> shortcut(c.box, p);
  const MinimumImageEverywhere<Dim> everywhere(shortcut);
  std::size_t interior = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    double xi[Dim];
    shortcut.position(i, xi);
    interior += shortcut.interior(xi, h) ? 1 : 0;
  }
  EXPECT_GT(interior, p.size() / 10) << Dim << "D: the shortcut is taken";
  EXPECT_LT(interior, p.size()) << Dim << "D: and not taken";
  const auto run = [&](const auto& geometry) {
    InteractionList pairs;
    compacting_pair_pass<Dim>(SummationDensity<Dim, decltype(kernel)>(kernel, c.fluid, p), geometry,
                              search.list(), h, 0, p.size(), pairs);
    std::vector<std::vector<std::uint32_t>> lists(p.size());
    for (std::size_t i = 0; i < p.size(); ++i)
      lists[i].assign(pairs.of(i).begin(), pairs.of(i).end());
    ThesisMomentum<Dim, decltype(kernel), false> e(kernel, c.fluid, view_velocity(p), p, nullptr);
    pair_pass<Dim>(e, geometry, pairs, h, 0, p.size());
    return std::tuple(p.density, lists, p.acceleration);
  };
  const auto [density_everywhere, lists_everywhere, a_everywhere] = run(everywhere);
  const auto [density_shortcut, lists_shortcut, a_shortcut] = run(shortcut);
  EXPECT_EQ(
      std::memcmp(density_everywhere.data(), density_shortcut.data(), p.size() * sizeof(double)), 0)
      << Dim << "D density";
  std::size_t lists_differing = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    lists_differing += lists_everywhere[i] == lists_shortcut[i] ? 0 : 1;
  EXPECT_EQ(lists_differing, 0u) << Dim << "D interaction lists";
  for (int d = 0; d < Dim; ++d)
    EXPECT_EQ(std::memcmp(a_everywhere[d].data(), a_shortcut[d].data(), p.size() * sizeof(double)),
              0)
        << Dim << "D acceleration, axis " << d;
}

TEST(PairLoop, InteriorShortcutIsTheMinimumImageBitForBit) {
  check_interior_shortcut<3>(20);
  check_interior_shortcut<2>(48);
}

/// A reduction other than a sum: the largest r² inside the support and the count of pairs there
/// (a max and a sum through one accumulate), identity -1 for entries outside it.
template <int Dim>
struct FarthestInSupport {
  static constexpr int outputs = 2;
  static constexpr bool coincident_pairs = false;
  static constexpr double identity = -1.0;
  struct Own {};
  static void accumulate(double (&acc)[outputs], const double (&c)[outputs]) {
    acc[0] = std::max(acc[0], c[0]);
    if (c[1] > 0.0) acc[1] = (acc[1] < 0.0 ? 0.0 : acc[1]) + 1.0;
  }
  Own own(std::size_t) const { return {}; }
  void pair(const Own&, const Pair<Dim>& q, double (&out)[outputs]) const {
    out[0] = q.r2;
    out[1] = 1.0;
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    farthest[i] = sum[0];
    count[i] = sum[1];
  }
  double* farthest;
  double* count;
};

// Custom reductions (identity + accumulate) see exactly the in-support pairs; a particle with
// none keeps the identity.
// The stream compaction behind the list build (byte marks) and the density pass (32-bit marks):
// both keep exactly the marked members, in order, for counts around the 16-wide vector blocks.
TEST(PairLoop, AppendSelectedKeepsTheMarkedMembersInOrder) {
  std::mt19937 random(7);
  for (std::size_t count = 0; count <= 49; ++count) {
    std::vector<std::uint32_t> members(count), wide(count);
    std::vector<std::uint8_t> bytes(count);
    std::vector<std::uint32_t> expected;
    for (std::size_t k = 0; k < count; ++k) {
      members[k] = static_cast<std::uint32_t>(random());
      const bool keep = random() % 3 != 0;
      bytes[k] = keep ? 0xFF : 0x00;
      wide[k] = keep ? 0xFFFFFFFFu : 0u;
      if (keep) expected.push_back(members[k]);
    }
    std::vector<std::uint32_t> out_bytes(count + 16, 0xDEADBEEF), out_wide(count + 16, 0xDEADBEEF);
    const std::size_t kept_bytes =
        append_selected(members.data(), bytes.data(), count, out_bytes.data());
    const std::size_t kept_wide =
        append_selected(members.data(), wide.data(), count, out_wide.data());
    ASSERT_EQ(kept_bytes, expected.size()) << "count " << count;
    ASSERT_EQ(kept_wide, expected.size()) << "count " << count;
    for (std::size_t k = 0; k < expected.size(); ++k) {
      EXPECT_EQ(out_bytes[k], expected[k]) << "count " << count << ", entry " << k;
      EXPECT_EQ(out_wide[k], expected[k]) << "count " << count << ", entry " << k;
    }
  }
}

TEST(PairLoop, CustomReductionsSeeTheSupportAndStartFromTheIdentity) {
  testing::RandomFlow flow = prepared_flow(3, 10, 4);
  const SolverConfig& c = flow.config;
  const ParticleArrays& p = flow.particles;
  VerletNeighbourSearch search(c.box, c.support_radius, 0.2 * c.support_radius);
  search.build(view_positions(p));
  const PeriodicGeometry<3> geometry(c.box, p);
  for (const double radius : {c.support_radius, 0.5 * c.support_radius, 1e-9}) {
    std::vector<double> farthest(p.size()), count(p.size());
    pair_pass<3>(FarthestInSupport<3>{farthest.data(), count.data()}, geometry, search.list(),
                 radius, 0, p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      double expected = -1.0, n = -1.0;
      for (const std::uint32_t j : search.list().of(i)) {
        double dx[3];
        double xi[3];
        geometry.position(i, xi);
        const double r2 = geometry.separation(xi, j, dx);
        if (r2 < radius * radius && r2 > 0.0) {
          expected = std::max(expected, r2);
          n = (n < 0.0 ? 0.0 : n) + 1.0;
        }
      }
      ASSERT_EQ(farthest[i], expected) << "radius " << radius << " particle " << i;
      ASSERT_EQ(count[i], n) << "radius " << radius << " particle " << i;
    }
  }
}

}  // namespace
}  // namespace sphles::sim
