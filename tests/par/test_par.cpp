// SPDX-License-Identifier: GPL-3.0-or-later
// Decomposition, halo exchange and migration over real MPI ranks (par/, docs/scaling.md). Run by
// CTest under mpiexec with 1, 2, 3, 4 and 8 ranks (oversubscribed on small machines); every rank
// runs every test and the process fails when a test fails on any rank.
#include <gtest/gtest.h>
#include <mpi.h>

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "analysis/grid.hpp"
#include "analysis/products.hpp"
#include "analysis/spectrum.hpp"
#include "analysis/vorticity.hpp"
#include "analysis/writer.hpp"
#include "io/checkpoint.hpp"
#include "io/checkpoint_collective.hpp"
#include "io/particle_snapshot.hpp"
#include "io/particle_snapshot_collective.hpp"
#include "par/decomposition.hpp"
#include "par/exchange.hpp"
#include "par/halo.hpp"
#include "par/particle_products.hpp"
#include "par/reduce.hpp"
#include "par/setup.hpp"
#include "par/spectrum.hpp"
#include "par/state.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/kernels.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/pair_loop.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/process_grid.hpp"
#include "sim/solver.hpp"

namespace sphles::par {
namespace {

constexpr double kLength = 6.283185307179586;  // the 2π box of the TGV cases

int world_size() {
  int size = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  return size;
}

int world_rank() {
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  return rank;
}

sim::PeriodicBox box_of(int dim) {
  sim::PeriodicBox box;
  box.dimension = dim;
  for (int a = 0; a < dim; ++a) box.length[static_cast<std::size_t>(a)] = kLength;
  return box;
}

/// The same random periodic set on every rank: n particles, ids 0..n-1, uniform in the box.
sim::ParticleArrays global_set(int dim, std::size_t n, std::uint64_t seed) {
  sim::ParticleArrays p;
  p.dimension = dim;
  p.resize(n);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, kLength);
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < dim; ++a) p.position[static_cast<std::size_t>(a)][i] = u(rng);
  for (std::size_t i = 0; i < n; ++i) {
    p.mass[i] = 1.0 + 1e-3 * static_cast<double>(i);
    p.velocity[0][i] = -static_cast<double>(i);
  }
  return p;
}

/// The particles `mine` of `all` (indices), in that order, with every field and id.
sim::ParticleArrays subset(const sim::ParticleArrays& all, const std::vector<std::uint32_t>& mine) {
  sim::ParticleArrays p;
  p.dimension = all.dimension;
  p.resize(mine.size());
  if (!all.eddy_viscosity.empty()) p.eddy_viscosity.resize(mine.size());
  auto to = p.double_fields();
  const auto from = all.double_fields();
  for (std::size_t f = 0; f < to.size(); ++f)
    for (std::size_t k = 0; k < mine.size(); ++k) (*to[f])[k] = (*from[f])[mine[k]];
  for (std::size_t k = 0; k < mine.size(); ++k) p.id[k] = all.id[mine[k]];
  return p;
}

/// The particles of `all` this rank owns, in id order.
sim::ParticleArrays owned_part(const Decomposition& d, const sim::ParticleArrays& all) {
  std::vector<std::uint32_t> mine;
  for (std::size_t i = 0; i < all.size(); ++i)
    if (d.owns(all, i)) mine.push_back(static_cast<std::uint32_t>(i));
  return subset(all, mine);
}

using Entry = std::tuple<std::uint64_t, double, double, double>;  // id and position

/// Every periodic image of `all` within the halo width of this rank's sub-box that is not one
/// of its owned particles, by brute force over the shifts {-L, 0, L} per axis.
std::vector<Entry> expected_halo(const Decomposition& d, const sim::ParticleArrays& all) {
  const int dim = d.dimension();
  const double h = d.halo_width();
  std::vector<Entry> expected;
  const int images = dim == 3 ? 27 : 9;
  for (std::size_t i = 0; i < all.size(); ++i)
    for (int m = 0; m < images; ++m) {
      double y[3] = {0.0, 0.0, 0.0};
      bool inside = true, unshifted = true;
      int code = m;
      for (int a = 0; a < dim; ++a, code /= 3) {
        const int s = code % 3 - 1;
        const auto k = static_cast<std::size_t>(a);
        y[a] = s == 0 ? all.position[k][i] : all.position[k][i] + s * kLength;
        inside = inside && y[a] >= d.lower(a) - h && y[a] < d.upper(a) + h;
        unshifted = unshifted && s == 0;
      }
      if (!inside || (unshifted && d.owns(all, i))) continue;
      expected.emplace_back(all.id[i], y[0], y[1], y[2]);
    }
  std::sort(expected.begin(), expected.end());
  return expected;
}

/// True on every rank when `ok` holds on every rank.
bool all_ranks(bool ok) {
  int mine = ok ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  return all == 1;
}

TEST(Decomposition, SubBoxesTileTheBoxAndNeighboursAgree) {
  for (const int dim : {2, 3}) {
    const Decomposition d(MPI_COMM_WORLD, box_of(dim), 0.5, 0.1);
    int product = 1;
    for (int a = 0; a < dim; ++a) product *= d.dims()[static_cast<std::size_t>(a)];
    EXPECT_EQ(product, world_size());
    // The sub-box volumes add up to the box volume, and each face is the neighbour's face.
    double volume = 1.0;
    for (int a = 0; a < dim; ++a) {
      volume *= d.upper(a) - d.lower(a);
      EXPECT_EQ(d.bound(a, 0), 0.0);
      EXPECT_EQ(d.bound(a, d.dims()[static_cast<std::size_t>(a)]), kLength);
      int below_coords[3];
      MPI_Cart_coords(d.comm(), d.neighbour(a, -1), dim, below_coords);
      const int c = d.coords()[static_cast<std::size_t>(a)];
      const int n = d.dims()[static_cast<std::size_t>(a)];
      EXPECT_EQ(below_coords[a], (c + n - 1) % n);
      // Points on a face belong to the sub-box above it.
      EXPECT_EQ(d.coordinate_of(a, d.lower(a)), c);
      EXPECT_EQ(d.coordinate_of(a, std::nextafter(d.upper(a), 0.0)), c);
    }
    double total = 0.0;
    MPI_Allreduce(&volume, &total, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_NEAR(total, box_of(dim).volume(), 1e-9 * box_of(dim).volume());
  }
}

// The split a distributed run uses (sim::process_grid, which resource estimates use before MPI
// exists) is MPI_Dims_create's for every rank count up to 1024 in 2D and 3D.
TEST(Decomposition, ProcessGridIsMpiDimsCreates) {
  for (const int dim : {2, 3})
    for (int ranks = 1; ranks <= 1024; ++ranks) {
      int dims[3] = {0, 0, 0};
      MPI_Dims_create(ranks, dim, dims);
      const std::array<int, 3> grid = sim::process_grid(ranks, dim);
      for (int a = 0; a < dim; ++a)
        ASSERT_EQ(grid[static_cast<std::size_t>(a)], dims[a])
            << ranks << " ranks, " << dim << "D, axis " << a;
    }
}

TEST(Decomposition, SubBoxNarrowerThanTheHaloIsRefusedNamingRanksAndParticles) {
  // A halo wider than the box can never work; with more than one rank, one wider than a slab.
  const double too_wide = world_size() == 1 ? 1.5 * kLength : 0.75 * kLength;
  try {
    const Decomposition d(MPI_COMM_WORLD, box_of(3), too_wide, kLength / 32);
    if (world_size() > 1 || too_wide > kLength) FAIL() << "no error";
  } catch (const DecompositionError& e) {
    const std::string m = e.what();
    EXPECT_NE(
        m.find(std::to_string(world_size()) + (world_size() == 1 ? " MPI rank" : " MPI ranks")),
        std::string::npos)
        << m;
    EXPECT_NE(m.find("halo width"), std::string::npos) << m;
    EXPECT_NE(m.find("particles per side (the scene has 32)"), std::string::npos) << m;
  }
}

class HaloTest : public ::testing::TestWithParam<std::tuple<int, double>> {};

// The halo equals the brute-force set of periodic images within the halo width, positions bit
// for bit (the random positions make a tie with a bound, where the two rules could round
// differently, a measure-zero event), and update() refreshes the halo's values.
TEST_P(HaloTest, ContentsEqualBruteForceAndUpdateRefreshesThem) {
  const auto [dim, width_fraction] = GetParam();
  const Decomposition probe(MPI_COMM_WORLD, box_of(dim), 0.1, 0.1);
  double min_width = kLength;
  for (int a = 0; a < dim; ++a)  // the same on every rank (the arguments of a collective call)
    min_width = std::min(min_width, kLength / probe.dims()[static_cast<std::size_t>(a)]);
  const double width = width_fraction * min_width;
  const Decomposition d(MPI_COMM_WORLD, box_of(dim), width, 0.1);
  const sim::ParticleArrays all = global_set(dim, dim == 3 ? 3000 : 1500, 11 + dim);
  sim::ParticleArrays p = owned_part(d, all);
  const std::size_t owned = p.size();
  const Halo halo = Halo::build(d, p);
  EXPECT_EQ(halo.owned(), owned);
  EXPECT_EQ(p.size(), owned + halo.size());

  std::vector<Entry> got;
  for (std::size_t i = owned; i < p.size(); ++i)
    got.emplace_back(p.id[i], p.position[0][i], p.position[1][i],
                     dim == 3 ? p.position[2][i] : 0.0);
  std::sort(got.begin(), got.end());
  const std::vector<Entry> expected = expected_halo(d, all);
  EXPECT_EQ(got.size(), expected.size()) << "rank " << d.rank();
  EXPECT_TRUE(got == expected) << "rank " << d.rank();
  // The other fields came along with their particle.
  for (std::size_t i = owned; i < p.size(); ++i) {
    EXPECT_EQ(p.mass[i], all.mass[p.id[i]]);
    EXPECT_EQ(p.velocity[0][i], all.velocity[0][p.id[i]]);
  }

  // update(): new values on the owned particles reach every copy.
  for (std::size_t i = 0; i < owned; ++i) p.pressure[i] = 0.25 * static_cast<double>(p.id[i]);
  for (std::size_t i = owned; i < p.size(); ++i) p.pressure[i] = std::nan("");
  std::vector<double>* fields[] = {&p.pressure, &p.density};
  halo.update(d, fields);
  for (std::size_t i = owned; i < p.size(); ++i)
    ASSERT_EQ(p.pressure[i], 0.25 * static_cast<double>(p.id[i])) << "halo entry " << i;
  EXPECT_TRUE(all_ranks(!HasFailure()));
}

INSTANTIATE_TEST_SUITE_P(WidthsAndDimensions, HaloTest,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::Values(0.1, 0.5, 1.0)),
                         [](const auto& info) {
                           return std::to_string(std::get<0>(info.param)) + "D_width" +
                                  std::to_string(static_cast<int>(100 * std::get<1>(info.param)));
                         });

// A halo built from particles that are not all inside their sub-box is refused on every rank.
TEST(HaloBuild, ParticleOutsideItsSubBoxIsRefusedOnEveryRank) {
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 0.1, 0.1);
  sim::ParticleArrays p = owned_part(d, global_set(2, 400, 3));
  if (d.rank() == 0 && p.size() > 0)
    p.position[0][0] = d.upper(0) < kLength ? d.upper(0) : -1.0;  // just outside (or off the box)
  try {
    Halo::build(d, p);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("outside their rank's sub-box"), std::string::npos)
        << e.what();
  }
}

// Particles displaced by up to 0.45 of a sub-box along each axis end up on the rank that owns
// their new position, each once, with their values.
TEST(Migration, EveryParticleEndsOnItsOwnerOnce) {
  for (const int dim : {2, 3}) {
    const Decomposition d(MPI_COMM_WORLD, box_of(dim), 0.1, 0.1);
    const std::size_t n = 2000;
    const sim::ParticleArrays all = global_set(dim, n, 5);
    sim::ParticleArrays p = owned_part(d, all);
    auto displacement = [&](std::uint64_t id, int a) {
      std::mt19937_64 rng(id * 3 + static_cast<std::uint64_t>(a));
      const auto k = static_cast<std::size_t>(a);
      const double slab = kLength / d.dims()[k];
      return std::uniform_real_distribution<double>(-0.45 * slab, 0.45 * slab)(rng);
    };
    for (std::size_t i = 0; i < p.size(); ++i)
      for (int a = 0; a < dim; ++a)
        p.position[static_cast<std::size_t>(a)][i] += displacement(p.id[i], a);
    migrate(d, p);
    unsigned long long count = p.size(), total = 0;
    MPI_Allreduce(&count, &total, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_EQ(total, n);
    std::vector<int> seen(n, 0);
    for (std::size_t i = 0; i < p.size(); ++i) {
      EXPECT_TRUE(d.owns(p, i)) << "id " << p.id[i];
      ++seen[p.id[i]];
      for (int a = 0; a < dim; ++a) {
        const auto k = static_cast<std::size_t>(a);
        EXPECT_EQ(p.position[k][i],
                  sim::wrap_periodic(all.position[k][p.id[i]] + displacement(p.id[i], a), kLength));
      }
      EXPECT_EQ(p.mass[i], all.mass[p.id[i]]);
    }
    std::vector<int> seen_all(n, 0);
    MPI_Allreduce(seen.data(), seen_all.data(), static_cast<int>(n), MPI_INT, MPI_SUM,
                  MPI_COMM_WORLD);
    EXPECT_TRUE(std::all_of(seen_all.begin(), seen_all.end(), [](int s) { return s == 1; }));
  }
  EXPECT_TRUE(all_ranks(!HasFailure()));
}

// Four or more ranks along an axis (8 ranks in 2D): a particle that jumps two sub-boxes is
// refused on every rank, naming it.
TEST(Migration, FurtherThanOneSubBoxIsRefusedOnEveryRank) {
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 0.1, 0.1);
  if (d.dims()[0] < 4) GTEST_SKIP() << "needs 4 or more ranks along x";
  sim::ParticleArrays p = owned_part(d, global_set(2, 500, 9));
  if (d.coords()[0] == 0 && p.size() > 0) p.position[0][0] += 2.0 * kLength / d.dims()[0];
  try {
    migrate(d, p);
    FAIL() << "no error";
  } catch (const MigrationError& e) {
    EXPECT_NE(std::string(e.what()).find("more than one sub-box"), std::string::npos);
  }
}

// --- One force evaluation distributed: the same answer as one process, bit for bit ---------

/// A lattice of per_side^dim particles displaced at random by up to 0.2 spacings, with a
/// Taylor-Green velocity plus noise; ids in lattice order.
sim::ParticleArrays perturbed_lattice(int dim, int per_side, std::uint64_t seed) {
  const double spacing = kLength / per_side;
  std::size_t n = 1;
  for (int a = 0; a < dim; ++a) n *= static_cast<std::size_t>(per_side);
  sim::ParticleArrays p;
  p.dimension = dim;
  p.resize(n);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t rest = i;
    double x[3] = {0.0, 0.0, 0.0};
    for (int a = 0; a < dim; ++a) {
      const auto k = static_cast<std::size_t>(a);
      x[a] = (static_cast<double>(rest % static_cast<std::size_t>(per_side)) + 0.5) * spacing;
      rest /= static_cast<std::size_t>(per_side);
      p.position[k][i] = sim::wrap_periodic(x[a] + 0.2 * spacing * u(rng), kLength);
    }
    p.velocity[0][i] = std::sin(x[0]) * std::cos(x[1]) + 0.01 * u(rng);
    p.velocity[1][i] = -std::cos(x[0]) * std::sin(x[1]) + 0.01 * u(rng);
    if (dim == 3) p.velocity[2][i] = 0.01 * u(rng);
    p.mass[i] = std::pow(spacing, dim);
  }
  return p;
}

/// The decomposition of a test's box over this run's ranks, or null when the rank count cannot
/// split it (every rank refuses alike, e.g. 5 ranks split 5 x 1 x 1 over a box of 16 particles
/// per side): a test at a fixed small resolution then skips, naming the refusal.
std::unique_ptr<const Decomposition> decomposition_or_refusal(const sim::PeriodicBox& box,
                                                              double halo_width, double spacing,
                                                              std::string& refusal) {
  try {
    return std::make_unique<const Decomposition>(MPI_COMM_WORLD, box, halo_width, spacing);
  } catch (const DecompositionError& e) {
    refusal = e.what();
    return nullptr;
  }
}

template <int Dim>
void distributed_forces_equal_one_process(int per_side) {
  using KernelT = sim::Kernel<sim::kernel_shape::WendlandC4, Dim>;
  const double spacing = kLength / per_side;
  const double support = 4.0 * spacing;  // D_K = 8Δl
  const KernelT kernel(support);
  const sim::PeriodicBox box = box_of(Dim);
  const sim::FluidParameters fluid{.reference_density = 1.0,
                                   .sound_speed = 10.0,
                                   .reference_pressure = 1.0,
                                   .dynamic_viscosity = 0.01};
  const sim::ParticleArrays all = perturbed_lattice(Dim, per_side, 17);

  // One process, every particle, in id order (which is then also the order within a cell).
  sim::ParticleArrays one = all;
  sim::VerletNeighbourSearch one_search(box, support, 0.15 * support);
  one_search.build(sim::view_positions(one));
  sim::InteractionList one_pairs;
  sim::density_pass<Dim>(kernel, box, one_search.list(), fluid, one, &one_pairs);
  sim::force_pass<Dim>(kernel, box, one_pairs, fluid, sim::view_velocity(one), one);

  // This rank's particles and a halo as wide as the Verlet list radius, at their own positions,
  // so the minimum image and the list see the same pairs; lists in id order within a cell.
  sim::VerletNeighbourSearch search(box, support, 0.15 * support);
  std::string refusal;
  const auto decomposition = decomposition_or_refusal(box, search.list_radius(), spacing, refusal);
  if (!decomposition) GTEST_SKIP() << refusal;
  const Decomposition& d = *decomposition;
  sim::ParticleArrays p = owned_part(d, all);
  const std::size_t owned = p.size();
  const Halo halo = Halo::build(d, p, HaloPositions::Wrapped);
  search.build(sim::view_positions(p), sim::order_by_key(p.id));
  const sim::PeriodicGeometry<Dim> geometry(box, p);
  sim::InteractionList pairs;
  sim::compacting_pair_pass<Dim>(sim::SummationDensity<Dim, KernelT>(kernel, fluid, p), geometry,
                                 search.list(), support, 0, owned, pairs);
  std::vector<double>* after_density[] = {&p.volume, &p.density, &p.pressure};  // exchange point
  halo.update(d, after_density);
  sim::pair_pass<Dim>(
      sim::ThesisMomentum<Dim, KernelT, false>(kernel, fluid, sim::view_velocity(p), p, nullptr),
      geometry, pairs, support, 0, owned);

  std::size_t differ = 0;
  for (std::size_t i = 0; i < owned; ++i) {
    const std::uint64_t g = p.id[i];
    bool same = p.volume[i] == one.volume[g] && p.density[i] == one.density[g] &&
                p.pressure[i] == one.pressure[g];
    for (int a = 0; a < Dim; ++a)
      same = same && p.acceleration[static_cast<std::size_t>(a)][i] ==
                         one.acceleration[static_cast<std::size_t>(a)][g];
    differ += same ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u) << "rank " << d.rank() << ": " << differ << " of " << owned
                        << " owned particles differ from one process";
  unsigned long long count = owned, total = 0;
  MPI_Allreduce(&count, &total, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  EXPECT_EQ(total, all.size());
}

// Density (A.1, A.2), EOS, pressure and viscous forces (A.9, A.14) of every particle, computed
// by its owning rank from its owned particles and halo, equal one process' bit for bit: the
// pair geometry is the same minimum image, and each particle's neighbours come in the same
// order (by id within a cell), so even the SIMD lanes' partial sums agree.
TEST(DistributedForces, EqualOneProcessBitForBit2D) {
  distributed_forces_equal_one_process<2>(40);
}
TEST(DistributedForces, EqualOneProcessBitForBit3D) {
  distributed_forces_equal_one_process<3>(16);
}

/// Every owned particle of `mine` against the particle of the same id in `one`: position,
/// velocity, acceleration, volume, density and pressure bit for bit. Returns how many differ.
std::size_t differing_particles(const sim::Simulation& mine, const sim::Simulation& one) {
  const sim::ParticleArrays& p = mine.particles();
  const sim::ParticleArrays& q = one.particles();
  std::vector<std::size_t> at(q.size());
  for (std::size_t k = 0; k < q.size(); ++k) at[q.id[k]] = k;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < mine.owned_count(); ++i) {
    const std::size_t k = at[p.id[i]];
    bool same = p.volume[i] == q.volume[k] && p.density[i] == q.density[k] &&
                p.pressure[i] == q.pressure[k];
    for (int a = 0; a < p.dimension; ++a) {
      const auto d = static_cast<std::size_t>(a);
      same = same && p.position[d][i] == q.position[d][k] && p.velocity[d][i] == q.velocity[d][k] &&
             p.acceleration[d][i] == q.acceleration[d][k];
    }
    differ += same ? 0 : 1;
  }
  return differ;
}

struct DistributedRun {
  int dimension;
  int per_side;
  sim::SchemeType scheme;
  sim::ViscousOperator viscous;
  int steps;
  sim::SubfilterModel subfilter = sim::SubfilterModel::Implicit;
};

class DistributedRunTest : public ::testing::TestWithParam<DistributedRun> {};

// A run distributed over the ranks (migration and halo at each list rebuild, halo refreshes,
// global time step and rebuild decision) gives every particle the bits it has in one process
// holding them all, and the same diagnostics, after many steps with several rebuilds and
// particles crossing between ranks (a uniform velocity carries them over the faces, which the
// Taylor-Green flow alone does not cross).
TEST_P(DistributedRunTest, ParticleStatesEqualOneProcessBitForBit) {
  const DistributedRun run = GetParam();
  const double spacing = kLength / run.per_side;
  sim::SolverConfig config;
  config.box = box_of(run.dimension);
  config.kernel = sim::KernelType::WendlandC4;
  config.support_radius = 4.0 * spacing;  // D_K = 8Δl
  config.particle_spacing = spacing;
  config.fluid = {.reference_density = 1.0,
                  .sound_speed = 10.0,
                  .reference_pressure = 1.0,
                  .dynamic_viscosity = 0.01};
  config.scheme.type = run.scheme;
  config.scheme.viscous_operator = run.viscous;
  config.subfilter.model = run.subfilter;
  sim::ParticleArrays all = perturbed_lattice(run.dimension, run.per_side, 29);
  for (int a = 0; a < run.dimension; ++a)
    for (double& v : all.velocity[static_cast<std::size_t>(a)]) v += 1.5 - 0.5 * a;
  const auto one = sim::make_simulation(config, all);

  const sim::VerletNeighbourSearch search(config.box, config.support_radius,
                                          config.neighbour_skin * config.support_radius);
  const Decomposition d(MPI_COMM_WORLD, config.box, search.list_radius(), spacing);
  const auto exchange = std::make_shared<MpiExchange>(d);
  const auto mine = sim::make_simulation(config, owned_part(d, all), 0.0, 0, exchange);
  EXPECT_EQ(differing_particles(*mine, *one), 0u) << "rank " << d.rank() << " at the start";
  for (int s = 0; s < run.steps; ++s) {
    one->step();
    mine->step();
  }
  const std::size_t differ = differing_particles(*mine, *one);
  EXPECT_EQ(differ, 0u) << "rank " << d.rank() << ": " << differ << " of " << mine->owned_count()
                        << " owned particles differ from one process after " << run.steps
                        << " steps";
  const sim::StepDiagnostics& a = mine->diagnostics();
  const sim::StepDiagnostics& b = one->diagnostics();
  EXPECT_EQ(a.time, b.time);
  EXPECT_EQ(a.dt, b.dt);
  EXPECT_EQ(a.kinetic_energy, b.kinetic_energy);
  EXPECT_EQ(a.total_mass, b.total_mass);
  EXPECT_EQ(a.momentum, b.momentum);
  EXPECT_EQ(a.max_speed, b.max_speed);
  EXPECT_EQ(a.max_density_deviation, b.max_density_deviation);
  EXPECT_EQ(a.mean_neighbours, b.mean_neighbours);
  EXPECT_EQ(a.neighbour_builds, b.neighbour_builds);
  EXPECT_GE(b.neighbour_builds, 3u) << "the run should rebuild its lists several times";
  // Every particle is owned exactly once, and particles did change ranks.
  EXPECT_EQ(exchange->sum(std::uint64_t{mine->owned_count()}), all.size());
  if (d.size() > 1) {
    EXPECT_GT(exchange->sum(std::uint64_t{exchange->stats().migrated}), 0u);
  }
}

INSTANTIATE_TEST_SUITE_P(
    TaylorGreen, DistributedRunTest,
    ::testing::Values(
        DistributedRun{2, 40, sim::SchemeType::Thesis, sim::ViscousOperator::Thesis, 50},
        DistributedRun{3, 24, sim::SchemeType::Thesis, sim::ViscousOperator::Thesis, 50},
        DistributedRun{2, 40, sim::SchemeType::TransportVelocity, sim::ViscousOperator::Thesis, 50},
        DistributedRun{2, 40, sim::SchemeType::ParticleShifting, sim::ViscousOperator::Corrected,
                       50},
        DistributedRun{2, 40, sim::SchemeType::Thesis, sim::ViscousOperator::Thesis, 50,
                       sim::SubfilterModel::Smagorinsky},
        DistributedRun{2, 40, sim::SchemeType::Thesis, sim::ViscousOperator::Thesis, 50,
                       sim::SubfilterModel::SmagorinskyMcg}),
    [](const ::testing::TestParamInfo<DistributedRun>& info) {
      return std::to_string(info.param.dimension) + "D_" +
             std::string(sim::scheme_name(info.param.scheme)) + "_" +
             std::string(sim::viscous_operator_name(info.param.viscous)) + "_viscous_" +
             std::string(sim::subfilter_model_name(info.param.subfilter));
    });

// The Kolmogorov case's own diagnostics (energy injection, film dissipation, u_rms; SPEC (4.3))
// summed by every rank over its owned particles and combined exactly equal one process' bit
// for bit, without gathering the particles.
TEST(DistributedCaseDiagnostics, KolmogorovEqualOneProcessBitForBit) {
  const sim::Scene scene = scene::parse_scene(
      {{"preset", "kolmogorov2d"}, {"particles_per_side", 48}, {"packing", {{"enabled", false}}}});
  const sim::RunSetup setup = sim::setup_run(scene);
  const auto one = sim::make_simulation(setup.solver, setup.particles);
  const sim::SolverConfig& c = setup.solver;
  const sim::VerletNeighbourSearch search(c.box, c.support_radius,
                                          c.neighbour_skin * c.support_radius);
  const Decomposition d(MPI_COMM_WORLD, c.box, search.list_radius(), c.particle_spacing);
  const auto mine = sim::make_simulation(c, owned_part(d, setup.particles), 0.0, 0,
                                         std::make_shared<MpiExchange>(d));
  for (int s = 0; s < 30; ++s) {
    one->step();
    mine->step();
  }
  const std::vector<double> expected = sim::case_diagnostics(scene, one->particles());
  ASSERT_EQ(expected.size(), 3u);
  EXPECT_NE(expected[0], 0.0);  // the forcing injects energy
  EXPECT_EQ(one->case_diagnostics(scene), expected);
  EXPECT_EQ(mine->case_diagnostics(scene), expected) << "rank " << d.rank();
}

/// The 2D TGV of DistributedRunTest with the transport-velocity scheme (whose restart recomputes
/// its background acceleration) and a drift across the ranks.
/// Rank 0's `text`, on every rank.
std::string rank0_text(std::string text) {
  int length = static_cast<int>(text.size());
  MPI_Bcast(&length, 1, MPI_INT, 0, MPI_COMM_WORLD);
  text.resize(static_cast<std::size_t>(length));
  MPI_Bcast(text.data(), length, MPI_CHAR, 0, MPI_COMM_WORLD);
  return text;
}

/// `action` throws io::CheckpointError on every rank, with one message that contains `expected`.
template <class Action>
void expect_one_checkpoint_error(Action&& action, const std::string& expected) {
  std::string message;
  try {
    action();
  } catch (const io::CheckpointError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find(expected), std::string::npos) << message;
  EXPECT_EQ(message, rank0_text(message));
}

/// A directory made by rank 0 and named on every rank (removed by ~SharedDirectory on rank 0).
struct SharedDirectory {
  std::filesystem::path path;
  SharedDirectory() {
    std::string name;
    if (world_rank() == 0) {
      char pattern[] = "/tmp/sphles-par-ckpt-XXXXXX";
      name = ::mkdtemp(pattern);
    }
    path = rank0_text(name);
  }
  ~SharedDirectory() {
    MPI_Barrier(MPI_COMM_WORLD);
    if (world_rank() == 0) std::filesystem::remove_all(path);
  }
  /// The files in it (rank 0's view), sorted.
  std::vector<std::string> files() const {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(path))
      names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }
};

sim::SolverConfig restart_config(double spacing) {
  sim::SolverConfig config;
  config.box = box_of(2);
  config.kernel = sim::KernelType::WendlandC4;
  config.support_radius = 4.0 * spacing;
  config.particle_spacing = spacing;
  config.fluid = {.reference_density = 1.0,
                  .sound_speed = 10.0,
                  .reference_pressure = 1.0,
                  .dynamic_viscosity = 0.01};
  config.scheme.type = sim::SchemeType::TransportVelocity;
  return config;
}

// A state gathered from the N ranks of a run, in id order, is the one-process state bit for bit;
// restarted on M ranks (a sub-communicator of about half of them) and on one process, both
// continue exactly as the one-process run that never stopped.
TEST(DistributedRestart, StateOfNRanksRestartsBitwiseOnMRanksAndOnOne) {
  constexpr int kPerSide = 40;
  const double spacing = kLength / kPerSide;
  const sim::SolverConfig config = restart_config(spacing);
  sim::ParticleArrays all = perturbed_lattice(2, kPerSide, 31);
  for (double& v : all.velocity[0]) v += 1.0;
  for (double& v : all.velocity[1]) v += 0.5;
  const auto one = sim::make_simulation(config, all);
  for (int s = 0; s < 32; ++s) one->step();
  const sim::SolverState saved_one = one->state();
  for (int s = 0; s < 20; ++s) one->step();

  const sim::VerletNeighbourSearch search(config.box, config.support_radius,
                                          config.neighbour_skin * config.support_radius);
  const Decomposition d(MPI_COMM_WORLD, config.box, search.list_radius(), spacing);
  sim::SolverState whole;
  // Also through a checkpoint file written by these ranks and read by the M below, each its
  // part (io::write_checkpoint_collective, par::read_share).
  const SharedDirectory directory;
  const std::filesystem::path file = directory.path / "ckpt.h5";
  {
    const auto mine =
        sim::make_simulation(config, owned_part(d, all), 0.0, 0, std::make_shared<MpiExchange>(d));
    for (int s = 0; s < 32; ++s) mine->step();
    whole = gather_state(d, mine->state(), kEveryRank);
    std::uint64_t first = 0, total = 0;
    const sim::SolverState block = id_block(d, mine->state(), first, total);
    io::write_checkpoint_collective(d.comm(), file, block, first, total, {"{}", "test", "none"});
  }
  // The gathered state is the one-process state in id order (which is the order of `all`).
  ASSERT_EQ(whole.particles.size(), all.size());
  std::vector<std::size_t> at(all.size());
  for (std::size_t k = 0; k < saved_one.particles.size(); ++k) at[saved_one.particles.id[k]] = k;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < whole.particles.size(); ++i) {
    EXPECT_EQ(whole.particles.id[i], i);
    const std::size_t k = at[i];
    bool same = whole.particles.density[i] == saved_one.particles.density[k] &&
                whole.particles.mass[i] == saved_one.particles.mass[k];
    for (std::size_t a = 0; a < 2; ++a)
      same = same && whole.particles.position[a][i] == saved_one.particles.position[a][k] &&
             whole.particles.velocity[a][i] == saved_one.particles.velocity[a][k] &&
             whole.particles.acceleration[a][i] == saved_one.particles.acceleration[a][k] &&
             whole.list_reference_positions[a][i] == saved_one.list_reference_positions[a][k];
    differ += same ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u) << "particles of the gathered state differ from one process";
  EXPECT_EQ(whole.time, saved_one.time);
  EXPECT_EQ(whole.neighbour_builds, saved_one.neighbour_builds);
  // The restart must rebuild the list at the reference positions, not the current ones.
  std::size_t moved = 0;
  for (std::size_t i = 0; i < whole.particles.size(); ++i)
    moved += whole.particles.position[0][i] != whole.list_reference_positions[0][i] ? 1 : 0;
  EXPECT_GT(moved, whole.particles.size() / 2) << "saved right after a list rebuild";

  // One process restarting from the gathered state.
  const auto restarted_one = sim::restore_simulation(config, whole);
  for (int s = 0; s < 20; ++s) restarted_one->step();
  EXPECT_EQ(differing_particles(*restarted_one, *one), 0u) << "one-process restart";

  // M ranks: the first half of the world (at least one).
  const int m = std::max(1, world_size() / 2);
  MPI_Comm half = MPI_COMM_NULL;
  MPI_Comm_split(MPI_COMM_WORLD, d.rank() < m ? 0 : MPI_UNDEFINED, d.rank(), &half);
  if (half != MPI_COMM_NULL) {
    {
      const Decomposition dm(half, config.box, search.list_radius(), spacing);
      const auto exchange = std::make_shared<MpiExchange>(dm);
      const auto restarted = sim::restore_simulation(config, share_of(dm, whole), exchange);
      for (int s = 0; s < 20; ++s) restarted->step();
      const std::size_t wrong = differing_particles(*restarted, *one);
      EXPECT_EQ(wrong, 0u) << "restart on " << m << " rank(s), rank " << dm.rank() << ": " << wrong
                           << " of " << restarted->owned_count() << " differ";
      EXPECT_EQ(restarted->diagnostics().kinetic_energy, one->diagnostics().kinetic_energy);
      EXPECT_EQ(exchange->sum(std::uint64_t{restarted->owned_count()}), all.size());
    }
    {
      const Decomposition dm(half, config.box, search.list_radius(), spacing);
      const auto exchange = std::make_shared<MpiExchange>(dm);
      const auto restarted = sim::restore_simulation(config, read_share(dm, file), exchange);
      for (int s = 0; s < 20; ++s) restarted->step();
      const std::size_t wrong = differing_particles(*restarted, *one);
      EXPECT_EQ(wrong, 0u) << "restart from the file on " << m << " rank(s), rank " << dm.rank()
                           << ": " << wrong << " of " << restarted->owned_count() << " differ";
    }
    MPI_Comm_free(&half);
  }
}

// Shares sent out from rank 0 (scatter_state) are the shares each rank would pick from the
// whole state itself (share_of): the same particles in the same order, every array bit for bit.
TEST(StateScatter, EachRankReceivesItsShareOfTheWholeState) {
  sim::SolverState whole;
  whole.particles = global_set(3, 2000, 41);
  whole.particles.eddy_viscosity.assign(2000, 0.5);
  whole.time = 1.25;
  whole.step = 77;
  whole.neighbour_builds = 9;
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  for (std::size_t a = 0; a < 3; ++a) {
    whole.list_reference_positions[a] = whole.particles.position[a];
    for (double& x : whole.list_reference_positions[a]) x = sim::wrap_periodic(x + u(rng), kLength);
  }
  const Decomposition d(MPI_COMM_WORLD, box_of(3), 0.3, 0.1);
  const sim::SolverState mine = scatter_state(d, d.rank() == 0 ? whole : sim::SolverState{});
  const sim::SolverState expected = share_of(d, whole);
  EXPECT_EQ(mine.time, whole.time);
  EXPECT_EQ(mine.step, whole.step);
  EXPECT_EQ(mine.neighbour_builds, whole.neighbour_builds);
  ASSERT_EQ(mine.particles.size(), expected.particles.size());
  EXPECT_EQ(mine.particles.id, expected.particles.id);
  const auto a = mine.particles.double_fields();
  const auto b = expected.particles.double_fields();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t f = 0; f < a.size(); ++f) EXPECT_EQ(*a[f], *b[f]) << "field " << f;
  EXPECT_EQ(mine.list_reference_positions, expected.list_reference_positions);
  unsigned long long count = mine.particles.size(), total = 0;
  MPI_Allreduce(&count, &total, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  EXPECT_EQ(total, whole.particles.size());
}

// Diagnostics' global sums: each rank sums its own particles exactly, the exact sums are
// combined across ranks, and the result is one process' exact sum bit for bit, for any rank
// count (a plain double sum would depend on the split).
TEST(ExactAllreduce, KineticEnergyEqualsOneProcessBitForBit) {
  const sim::ParticleArrays all = perturbed_lattice(3, 16, 29);
  const Decomposition d(MPI_COMM_WORLD, box_of(3), 0.5, kLength / 16);
  const sim::ParticleArrays p = owned_part(d, all);
  auto energy = [](const sim::ParticleArrays& q) {
    return sim::exact_sum(q.size(), [&](std::size_t i) {
      double v2 = 0.0;
      for (int a = 0; a < 3; ++a)
        v2 +=
            q.velocity[static_cast<std::size_t>(a)][i] * q.velocity[static_cast<std::size_t>(a)][i];
      return 0.5 * q.mass[i] * v2;
    });
  };
  const double one = energy(all).value();
  const double distributed = allreduce(d, energy(p)).value();
  EXPECT_EQ(distributed, one);
  EXPECT_GT(one, 0.0);
}

/// This rank's particles as the owners of `all` shifted by `drift` along x left them (as if the
/// particles had moved since the last migration), at their positions in `all`.
sim::ParticleArrays owned_before_drift(const Decomposition& d, const sim::ParticleArrays& all,
                                       double drift) {
  sim::ParticleArrays earlier = all;
  for (double& x : earlier.position[0]) x = sim::wrap_periodic(x + drift, kLength);
  sim::ParticleArrays mine = owned_part(d, earlier);
  for (std::size_t k = 0; k < mine.size(); ++k)
    mine.position[0][k] = all.position[0][static_cast<std::size_t>(mine.id[k])];
  return mine;
}

/// The spectrum of particles spread over the ranks against the one-process spectrum of all of
/// them (SPEC §5 gridding, FFTW r2c): every shell to 1e-12 relative (of the shell, or of the
/// largest shell for shells below 1e-6 of it), and the same bits on every rank and from a new
/// DistributedSpectrum as from one used before.
/// The ranks start from the owners of the positions shifted by `drift` spacings along x, as if
/// the particles had moved since the last migration.
template <int Dim>
void distributed_spectrum_equals_one_process(int per_side, double drift) {
  const sim::ParticleArrays all = perturbed_lattice(Dim, per_side, 11);
  const double spacing = kLength / per_side;
  const Decomposition d(MPI_COMM_WORLD, box_of(Dim), 2.5 * spacing, spacing);
  const sim::ParticleArrays mine = owned_before_drift(d, all, drift * spacing);
  const int m = 2 * per_side;  // spacing Δl / 2, as the analysis grids
  // A second call of one object (its plan and buffers reused) after a call on other velocities.
  DistributedSpectrum spectra(d, m);
  sim::ParticleArrays other = mine;
  for (double& v : other.velocity[0]) v = 2.0 * v + 1.0;
  const analysis::EnergySpectrum before = spectra.compute(other);
  const analysis::EnergySpectrum got = spectra.compute(mine);
  EXPECT_NE(before.energy, got.energy);
  EXPECT_EQ(distributed_energy_spectrum(d, mine, m).energy, got.energy);

  analysis::Grid grid;
  grid.dimension = Dim;
  grid.points_per_side = m;
  grid.length = kLength;
  const analysis::EnergySpectrum expected = analysis::energy_spectrum(
      analysis::sample_velocity(analysis::nearest_particle_map(grid, all), all, true));
  ASSERT_EQ(got.energy.size(), expected.energy.size());
  EXPECT_EQ(got.delta_k, expected.delta_k);
  const double top = *std::max_element(expected.energy.begin(), expected.energy.end());
  const double top_k2 = *std::max_element(expected.k2_energy.begin(), expected.k2_energy.end());
  double worst = 0.0;
  for (std::size_t p = 0; p < expected.energy.size(); ++p) {
    EXPECT_EQ(got.wavenumber[p], expected.wavenumber[p]);
    const double scale = std::max(std::abs(expected.energy[p]), 1e-6 * top);
    const double error = std::abs(got.energy[p] - expected.energy[p]) / scale;
    worst = std::max(worst, error);
    EXPECT_LT(error, 1e-12) << "shell " << p;
    const double scale_k2 = std::max(std::abs(expected.k2_energy[p]), 1e-6 * top_k2);
    EXPECT_LT(std::abs(got.k2_energy[p] - expected.k2_energy[p]) / scale_k2, 1e-12)
        << "shell " << p;
  }
  EXPECT_GT(top, 0.0);
  // Every rank holds rank 0's bits.
  std::vector<double> first = got.energy;
  MPI_Bcast(first.data(), static_cast<int>(first.size()), MPI_DOUBLE, 0, MPI_COMM_WORLD);
  EXPECT_TRUE(all_ranks(first == got.energy));
  if (d.rank() == 0)
    std::printf("[ spectrum %dD, %d ranks ] largest relative shell difference %.3g\n", Dim,
                d.size(), worst);
}

TEST(DistributedSpectrum, EqualsOneProcessSpectrum2D) {
  distributed_spectrum_equals_one_process<2>(32, 0.0);
}
TEST(DistributedSpectrum, EqualsOneProcessSpectrum3D) {
  distributed_spectrum_equals_one_process<3>(16, 0.0);
}
TEST(DistributedSpectrum, ParticlesOutsideTheirSubBoxesMoveFirst) {
  distributed_spectrum_equals_one_process<2>(32, 0.7);
  distributed_spectrum_equals_one_process<3>(16, -0.7);
}

/// A perturbed 32² lattice with the particles of x ≥ L/2 left out (a void wider than a halo).
sim::ParticleArrays left_half_lattice() {
  const sim::ParticleArrays lattice = perturbed_lattice(2, 32, 5);
  std::vector<std::uint32_t> kept;
  for (std::size_t i = 0; i < lattice.size(); ++i)
    if (lattice.position[0][i] < 0.5 * kLength) kept.push_back(static_cast<std::uint32_t>(i));
  return subset(lattice, kept);
}

/// The particle products of particles spread over the ranks (the "mls" ⟨ω²⟩, the ω² and |τ_SFS|
/// slices, sfs_stats) against analysis::analyse of all of them in one process, in reverse id
/// order: the same bits (the fits and τ_SFS sums visit their particles in an order set by
/// positions and ids alone). The ranks start as in the spectrum test, `drift` spacings from
/// their owners.
template <int Dim>
void distributed_particle_products_equal_one_process(int per_side, double drift) {
  sim::ParticleArrays all = perturbed_lattice(Dim, per_side, 23);
  const double spacing = kLength / per_side;
  for (std::size_t i = 0; i < all.size(); ++i)
    all.volume[i] = std::pow(spacing, Dim) * (1.0 + 0.1 * std::sin(3.0 * static_cast<double>(i)));
  // ν_t of an explicit model, one value per particle (travels with it to the ranks' halos).
  all.eddy_viscosity.resize(all.size());
  for (std::size_t i = 0; i < all.size(); ++i)
    all.eddy_viscosity[i] = 1e-3 * (1.5 + std::cos(7.0 * static_cast<double>(i)));
  const double support = 2.5 * spacing;  // H, as far as the halo reaches
  const Decomposition d(MPI_COMM_WORLD, box_of(Dim), support, spacing);
  const sim::ParticleArrays mine = owned_before_drift(d, all, drift * spacing);

  std::vector<std::uint32_t> reverse(all.size());
  for (std::size_t i = 0; i < all.size(); ++i)
    reverse[i] = static_cast<std::uint32_t>(all.size() - 1 - i);
  analysis::Snapshot one;
  one.box = box_of(Dim);
  one.kernel = sim::KernelType::WendlandC4;
  one.support_radius = support;
  one.particle_spacing = spacing;
  one.particles = subset(all, reverse);
  analysis::AnalysisConfig config;
  config.every = 1.0;
  config.products = {analysis::Product::Vorticity, analysis::Product::Slices,
                     analysis::Product::SubfilterStatistics, analysis::Product::Fields};
  config.grid_fields = {analysis::SliceField::VorticitySquared,
                        analysis::SliceField::SubfilterStressNorm,
                        analysis::SliceField::EddyViscosity};
  config.slice.axis = Dim == 3 ? 1 : 0;
  config.slice.position = 0.4 * kLength;
  config.slice.fields.insert(analysis::SliceField::EddyViscosity);
  config.histogram_bins = 20;
  const analysis::AnalysisFrame frame = analysis::analyse(one, config);
  ASSERT_TRUE(frame.vorticity && frame.subfilter && frame.fields && frame.fields->velocity);
  ASSERT_EQ(frame.fields->scalars.size(), 3u);
  ASSERT_EQ(frame.slices.size(), 3u);
  ASSERT_EQ(frame.slices[2].field, analysis::SliceField::EddyViscosity);

  const analysis::RanksRequest request = analysis::ranks_request(one, config);
  EXPECT_TRUE(request.vorticity && request.slice_omega2 && request.slice_tau &&
              request.slice_eddy && request.statistics);
  EXPECT_TRUE(request.fields.velocity && request.fields.omega2 && request.fields.tau &&
              request.fields.eddy);
  const analysis::RanksProducts got =
      distributed_particle_products(d, mine, sim::KernelType::WendlandC4, support, request);
  EXPECT_EQ(got.request, request);
  EXPECT_GT(frame.vorticity->mean_vorticity_squared, 0.0);
  EXPECT_EQ(got.mean_vorticity_squared, frame.vorticity->mean_vorticity_squared);
  ASSERT_TRUE(got.statistics);
  const analysis::SubfilterStatisticsProduct& want = *frame.subfilter;
  EXPECT_GT(want.max_norm, 0.0);
  EXPECT_EQ(got.statistics->max_norm, want.max_norm);
  EXPECT_EQ(got.statistics->mean_norm, want.mean_norm);
  EXPECT_EQ(got.statistics->joint.counts, want.joint.counts);
  EXPECT_EQ(got.statistics->joint.total, want.joint.total);
  EXPECT_EQ(got.statistics->joint.total, all.size());
  ASSERT_EQ(got.statistics->alignment.has_value(), Dim == 2);
  if (Dim == 2) {
    EXPECT_EQ(got.statistics->alignment->counts, want.alignment->counts);
    EXPECT_EQ(got.statistics->alignment->total, want.alignment->total);
    EXPECT_GT(want.alignment->total, 0u);
  }
  if (d.rank() == 0) {
    EXPECT_EQ(got.slice_omega2, frame.slices[0].values);
    EXPECT_EQ(got.slice_tau, frame.slices[1].values);
    EXPECT_EQ(got.slice_eddy, frame.slices[2].values);
    // The whole grid ("fields"): the nearest particle's velocity (with its mean), |τ_SFS| and ν_t,
    // ω² fitted at every node, assembled on rank 0 in node order.
    for (int a = 0; a < Dim; ++a)
      EXPECT_EQ(got.fields_velocity[static_cast<std::size_t>(a)],
                frame.fields->velocity->component[static_cast<std::size_t>(a)]);
    EXPECT_EQ(got.fields_omega2, frame.fields->scalars[0].values);
    EXPECT_EQ(got.fields_tau, frame.fields->scalars[1].values);
    EXPECT_EQ(got.fields_eddy, frame.fields->scalars[2].values);
    EXPECT_EQ(got.fields_tau.size(), frame.fields->grid.size());
  } else {
    EXPECT_TRUE(got.slice_omega2.empty() && got.slice_tau.empty() && got.slice_eddy.empty());
    EXPECT_TRUE(got.fields_velocity[0].empty() && got.fields_omega2.empty() &&
                got.fields_tau.empty() && got.fields_eddy.empty());
  }
  // Without ν_t (the implicit model) the ν_t slice is empty on every rank, as analyse has none.
  sim::ParticleArrays implicit = mine;
  implicit.eddy_viscosity.clear();
  const analysis::RanksProducts without_eddy =
      distributed_particle_products(d, implicit, sim::KernelType::WendlandC4, support, request);
  EXPECT_TRUE(without_eddy.slice_eddy.empty() && without_eddy.fields_eddy.empty());
  EXPECT_TRUE(all_ranks(!::testing::Test::HasFailure()));

  // The product "particles": the ranks write, each its id block, the snapshot file that a
  // RunDirectoryWriter writes from analyse's frame of all particles in one process, at the name
  // it gives it; the other products are those of before.
  using analysis::SliceField;
  const SharedDirectory directory;
  const io::SnapshotMetadata metadata{"{\"case\": \"test\"}", "test-version"};
  analysis::AnalysisConfig with_particles = config;
  with_particles.products.insert(analysis::Product::Particles);
  with_particles.particle_fields = {SliceField::VorticitySquared, SliceField::SubfilterStressNorm,
                                    SliceField::EddyViscosity};
  one.time = 0.25;
  one.step = 7;
  // With the 3D particle view's points: every k-th particle by id (k > 1 here).
  one.view = {300, SliceField::VorticitySquared};
  const analysis::AnalysisFrame one_frame = analysis::analyse(one, with_particles);
  ASSERT_TRUE(one_frame.particles && one_frame.particles->view);
  EXPECT_GT(one_frame.particles->view->stride, 1u);
  if (d.rank() == 0) {
    analysis::RunDirectoryWriter writer(directory.path / "one", metadata);
    writer.write(one_frame);
    EXPECT_EQ(writer.last_error(), "");
    std::filesystem::create_directories(directory.path / "ranks" / "snapshots");
  }
  MPI_Barrier(MPI_COMM_WORLD);
  const analysis::ParticleFileTarget target{directory.path / "ranks" / "snapshots", metadata};
  const analysis::RanksRequest file_request = analysis::ranks_request(one, with_particles, &target);
  const std::string name = "particles_t0.2500.h5";
  EXPECT_EQ(file_request.particles.path, (target.directory / name).string());
  const analysis::RanksProducts written =
      distributed_particle_products(d, mine, sim::KernelType::WendlandC4, support, file_request);
  ASSERT_TRUE(written.particles);
  EXPECT_EQ(written.particles->count, all.size());
  EXPECT_EQ(written.particles->fields,
            (std::vector<SliceField>{SliceField::VorticitySquared, SliceField::SubfilterStressNorm,
                                     SliceField::EddyViscosity}));
  EXPECT_EQ(written.mean_vorticity_squared, got.mean_vorticity_squared);
  EXPECT_EQ(written.slice_tau, got.slice_tau);
  // The view's points, sent to rank 0 only: those one process selects, bit for bit, for each
  // field (the others asked without a file).
  ASSERT_TRUE(written.view);
  EXPECT_EQ(written.view->stride, one_frame.particles->view->stride);
  if (d.rank() == 0) {
    EXPECT_EQ(*written.view, *one_frame.particles->view);
  } else {
    EXPECT_EQ(written.view->size(), 0u);
  }
  for (const SliceField field : {SliceField::SubfilterStressNorm, SliceField::EddyViscosity}) {
    one.view = {300, field};
    const analysis::AnalysisFrame f = analysis::analyse(one, with_particles);
    ASSERT_TRUE(f.particles && f.particles->view);
    analysis::RanksRequest view_only = request;
    view_only.view = one.view;
    const analysis::RanksProducts v =
        distributed_particle_products(d, mine, sim::KernelType::WendlandC4, support, view_only);
    ASSERT_TRUE(v.view);
    if (d.rank() == 0) {
      EXPECT_EQ(*v.view, *f.particles->view) << analysis::slice_field_name(field);
    }
    // ν_t of an implicit run: no view, on every rank.
    if (field == SliceField::EddyViscosity) {
      EXPECT_FALSE(distributed_particle_products(d, implicit, sim::KernelType::WendlandC4, support,
                                                 view_only)
                       .view);
    }
  }
  if (d.rank() == 0) {
    const io::ParticleSnapshotContents want =
        io::read_particle_snapshot(directory.path / "one" / "snapshots" / name);
    const io::ParticleSnapshotContents have = io::read_particle_snapshot(target.directory / name);
    EXPECT_EQ(have.attributes, want.attributes);
    ASSERT_EQ(want.datasets.size(), 9u);
    for (const auto& [dataset, values] : want.datasets) {
      ASSERT_TRUE(have.datasets.contains(dataset)) << dataset;
      const io::ParticleSnapshotContents::Dataset& other = have.datasets.at(dataset);
      EXPECT_EQ(other.units, values.units) << dataset;
      ASSERT_EQ(other.values.size(), values.values.size()) << dataset;
      std::size_t differing = 0;
      for (std::size_t k = 0; k < values.values.size(); ++k)
        differing += other.values[k] != values.values[k];  // bit for bit
      EXPECT_EQ(differing, 0u) << dataset;
    }
    EXPECT_EQ(want.attributes.at("time"), "0.25");
    EXPECT_EQ(want.attributes.at("num_particles"), std::to_string(all.size()));
    EXPECT_GT(want.datasets.at("omega2").values.at(0), 0.0);
  }
  EXPECT_TRUE(all_ranks(!::testing::Test::HasFailure()));

  // Fits reaching further than the halo are refused on every rank (one rank has no halo).
  analysis::RanksRequest wide = request;
  wide.fit_radius = 1.2 * support;
  bool refused = false;
  try {
    distributed_particle_products(d, mine, sim::KernelType::WendlandC4, support, wide);
  } catch (const std::invalid_argument& e) {
    refused = std::string(e.what()).find("halo") != std::string::npos;
  }
  bool alone = true;
  for (int a = 0; a < Dim; ++a) alone = alone && d.dims()[static_cast<std::size_t>(a)] == 1;
  EXPECT_TRUE(all_ranks(refused != alone));
}

TEST(DistributedParticleProducts, EqualOneProcessBitForBit2D) {
  distributed_particle_products_equal_one_process<2>(32, 0.0);
}
TEST(DistributedParticleProducts, EqualOneProcessBitForBit3D) {
  distributed_particle_products_equal_one_process<3>(16, 0.0);
}
TEST(DistributedParticleProducts, ParticlesOutsideTheirSubBoxesMoveFirst) {
  distributed_particle_products_equal_one_process<2>(32, -0.7);
  distributed_particle_products_equal_one_process<3>(16, 0.7);
}

/// A particle file the ranks cannot write (its directory does not exist; a block out of id
/// order) fails on every rank with one message naming the file, and leaves no file.
TEST(DistributedParticleProducts, ParticleFileThatCannotBeWrittenFailsOnEveryRank) {
  const sim::ParticleArrays all = perturbed_lattice(2, 24, 5);
  const double spacing = kLength / 24;
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 2.5 * spacing, spacing);
  const SharedDirectory directory;
  analysis::RanksRequest request;
  request.points_per_side = 48;
  request.particles.path = (directory.path / "missing" / "particles_t0.0000.h5").string();
  request.particles.tau = true;
  expect_one_checkpoint_error(
      [&] {
        distributed_particle_products(d, owned_part(d, all), sim::KernelType::WendlandC4,
                                      2.0 * spacing, request);
      },
      "missing/particles_t0.0000.h5");
  if (d.rank() == 0) {
    EXPECT_TRUE(directory.files().empty());
  }
  // A block that is not in id order (the writer's own check).
  const io::Block block = io::equal_block(all.size(), d.rank(), d.size());
  std::vector<std::uint32_t> rows(block.count);
  for (std::size_t k = 0; k < rows.size(); ++k)
    rows[k] = static_cast<std::uint32_t>(block.first + block.count - 1 - k);
  const sim::ParticleArrays reversed = subset(all, rows);
  const std::filesystem::path file = directory.path / "reversed.h5";
  expect_one_checkpoint_error(
      [&] {
        io::write_particle_snapshot_collective(MPI_COMM_WORLD, file, reversed, block.first,
                                               all.size(), 0.0, 0, {}, {});
      },
      "not in id order");
  if (d.rank() == 0) {
    EXPECT_TRUE(directory.files().empty());
  }
  EXPECT_TRUE(all_ranks(!HasFailure()));
}

/// Particles only in x < L/2: a |τ_SFS| slice node's nearest particle lies further than the
/// halo on some rank, and every rank refuses, naming the halo (one process answers).
TEST(DistributedParticleProducts, VoidWiderThanTheHaloIsRefusedOnEveryRank) {
  const sim::ParticleArrays all = left_half_lattice();
  const double spacing = kLength / 32;
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 2.5 * spacing, spacing);
  analysis::RanksRequest request;
  request.points_per_side = 64;
  request.slice_tau = true;
  const auto products = [&] {
    return distributed_particle_products(d, owned_part(d, all), sim::KernelType::WendlandC4,
                                         2.0 * spacing, request);
  };
  if (d.size() == 1) {
    EXPECT_NO_THROW(products());
    return;
  }
  bool refused = false;
  try {
    products();
  } catch (const std::invalid_argument& e) {
    refused = std::string(e.what()).find("halo width") != std::string::npos;
  }
  EXPECT_TRUE(all_ranks(refused));
}

/// A grid whose values on one rank would pass MPI's int counts is refused on every rank before
/// anything of its size is allocated (10^10 nodes: 1.25·10^9 or more on each of up to 8 ranks).
TEST(DistributedSpectrum, GridBeyondMpiCountsIsRefusedBeforeAllocating) {
  const double spacing = kLength / 32;
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 2.5 * spacing, spacing);
  bool refused = false;
  try {
    DistributedSpectrum spectra(d, 100000);
  } catch (const std::invalid_argument& e) {
    refused = std::string(e.what()).find("MPI's int counts") != std::string::npos;
  }
  EXPECT_TRUE(all_ranks(refused));
}

/// Particles only in x < L/2: on more than one rank some node's nearest particle is further
/// than the halo width, and every rank refuses, naming the halo; one process sees every
/// particle and computes the spectrum.
TEST(DistributedSpectrum, VoidWiderThanTheHaloIsRefusedOnEveryRank) {
  const sim::ParticleArrays all = left_half_lattice();
  const double spacing = kLength / 32;
  const Decomposition d(MPI_COMM_WORLD, box_of(2), 2.5 * spacing, spacing);
  if (d.size() == 1) {
    EXPECT_NO_THROW(distributed_energy_spectrum(d, owned_part(d, all), 64));
    return;
  }
  bool refused = false;
  try {
    distributed_energy_spectrum(d, owned_part(d, all), 64);
  } catch (const std::invalid_argument& e) {
    refused = std::string(e.what()).find("halo width") != std::string::npos;
  }
  EXPECT_TRUE(all_ranks(refused));
}

// --- Checkpoints written by every rank (io::write_checkpoint_collective) -----------------------

/// A state of `n` particles in id order with every field set (ν_t too), time and counters.
sim::SolverState checkpoint_state(std::size_t n) {
  sim::SolverState whole;
  whole.particles = global_set(3, n, 53);
  sim::ParticleArrays& p = whole.particles;
  p.eddy_viscosity.assign(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = static_cast<double>(i);
    p.volume[i] = 1e-3 * (1.0 + 1e-4 * x);
    p.density[i] = p.mass[i] / p.volume[i];
    p.pressure[i] = std::sin(x);
    p.eddy_viscosity[i] = 1e-4 * std::cos(x) * std::cos(x);
    for (std::size_t a = 0; a < 3; ++a) {
      p.velocity[a][i] = std::cos(x + static_cast<double>(a));
      p.acceleration[a][i] = std::sin(2.0 * x + static_cast<double>(a));
    }
  }
  for (std::size_t a = 0; a < 3; ++a) {
    whole.list_reference_positions[a] = p.position[a];
    for (double& x : whole.list_reference_positions[a]) x = sim::wrap_periodic(x + 0.01, kLength);
  }
  whole.time = 0.75;
  whole.step = 120;
  whole.neighbour_builds = 17;
  return whole;
}

/// A 3D state's particles and list reference positions put in `order` (new[k] = old[order[k]]).
void reorder_state(sim::SolverState& s, const std::vector<std::uint32_t>& order) {
  s.particles.reorder(order);
  for (std::size_t a = 0; a < 3; ++a) {
    std::vector<double> x(order.size());
    for (std::size_t k = 0; k < order.size(); ++k) x[k] = s.list_reference_positions[a][order[k]];
    s.list_reference_positions[a] = x;
  }
}

/// This rank's share of `whole` (by list reference position), in reverse order: a solver's
/// owned particles are in cell order, not id order.
sim::SolverState shuffled_share(const Decomposition& d, const sim::SolverState& whole) {
  sim::SolverState share = share_of(d, whole);
  std::vector<std::uint32_t> reverse(share.particles.size());
  for (std::size_t k = 0; k < reverse.size(); ++k)
    reverse[k] = static_cast<std::uint32_t>(reverse.size() - 1 - k);
  share.particles.reorder(reverse);
  for (std::size_t a = 0; a < 3; ++a)
    std::reverse(share.list_reference_positions[a].begin(),
                 share.list_reference_positions[a].end());
  return share;
}

void expect_same_checkpoint(const io::Checkpoint& a, const io::Checkpoint& b) {
  EXPECT_EQ(a.state.time, b.state.time);
  EXPECT_EQ(a.state.step, b.state.step);
  EXPECT_EQ(a.state.neighbour_builds, b.state.neighbour_builds);
  EXPECT_EQ(a.metadata.scene_json, b.metadata.scene_json);
  EXPECT_EQ(a.metadata.code_version, b.metadata.code_version);
  EXPECT_EQ(a.metadata.packing, b.metadata.packing);
  EXPECT_EQ(a.state.particles.id, b.state.particles.id);
  const auto fa = a.state.particles.double_fields();
  const auto fb = b.state.particles.double_fields();
  ASSERT_EQ(fa.size(), fb.size());
  for (std::size_t f = 0; f < fa.size(); ++f) EXPECT_EQ(*fa[f], *fb[f]) << "field " << f;
  EXPECT_EQ(a.state.list_reference_positions, b.state.list_reference_positions);
}

const io::CheckpointMetadata kCheckpointMetadata{"{\"name\": \"ranks\"}", "test", "none"};

// Each rank's block of the particles in id order, written by every rank into one file, is the
// checkpoint one process writes of the gathered state: every dataset bit for bit, with and
// without gzip, and no temporary left behind.
TEST(CheckpointByTheRanks, EqualsTheCheckpointOfTheWholeState) {
  const sim::SolverState whole = checkpoint_state(150001);  // more than two 65536-entry chunks
  const Decomposition d(MPI_COMM_WORLD, box_of(3), 0.3, 0.1);
  const sim::SolverState local = shuffled_share(d, whole);
  std::uint64_t first = 0, total = 0;
  const sim::SolverState block = id_block(d, local, first, total);
  EXPECT_EQ(total, whole.particles.size());
  // Blocks in rank order, equal lengths but for one particle.
  const std::uint64_t expected_first =
      static_cast<std::uint64_t>(d.rank()) * (total / static_cast<std::uint64_t>(d.size())) +
      std::min<std::uint64_t>(static_cast<std::uint64_t>(d.rank()),
                              total % static_cast<std::uint64_t>(d.size()));
  EXPECT_EQ(first, expected_first);
  for (std::size_t k = 0; k < block.particles.size(); ++k) {
    ASSERT_EQ(block.particles.id[k], first + k);
    ASSERT_EQ(block.particles.pressure[k], whole.particles.pressure[first + k]);
    ASSERT_EQ(block.list_reference_positions[2][k], whole.list_reference_positions[2][first + k]);
  }

  const SharedDirectory directory;
  for (const int gzip : {0, 1}) {
    const std::string suffix = std::to_string(gzip) + ".h5";
    const io::CheckpointShape shape =
        io::write_checkpoint_collective(MPI_COMM_WORLD, directory.path / ("ranks" + suffix), block,
                                        first, total, kCheckpointMetadata, {.gzip_level = gzip});
    EXPECT_EQ(shape.particles, total);
    EXPECT_TRUE(shape.eddy_viscosity);
    if (d.rank() == 0) {
      io::write_checkpoint(directory.path / ("one" + suffix), whole, kCheckpointMetadata,
                           {.gzip_level = gzip});
      expect_same_checkpoint(io::read_checkpoint(directory.path / ("ranks" + suffix)),
                             io::read_checkpoint(directory.path / ("one" + suffix)));
    }
  }
  if (d.rank() == 0) {
    EXPECT_EQ(directory.files(),
              (std::vector<std::string>{"one0.h5", "one1.h5", "ranks0.h5", "ranks1.h5"}));
  }
}

// A rank whose file-size limit is below the checkpoint fails the write on every rank with one
// message before anything is written: the previous checkpoint at the path stays as it was, no
// temporary is left, and no process crashes (HDF5 cannot survive a failed write, so the limit
// must be caught before). A missing directory fails on every rank as well.
TEST(CheckpointByTheRanks, FailuresOnOneRankFailEveryRankAndKeepThePreviousFile) {
  const sim::SolverState whole = checkpoint_state(20000);
  const Decomposition d(MPI_COMM_WORLD, box_of(3), 0.3, 0.1);
  std::uint64_t first = 0, total = 0;
  sim::SolverState block = id_block(d, shuffled_share(d, whole), first, total);
  const SharedDirectory directory;
  const std::filesystem::path file = directory.path / "ckpt.h5";
  io::write_checkpoint_collective(MPI_COMM_WORLD, file, block, first, total, kCheckpointMetadata);
  block.time = 2.5;

  const auto message_on_every_rank = [&](const std::filesystem::path& path,
                                         const std::string& expected) {
    expect_one_checkpoint_error(
        [&] {
          io::write_checkpoint_collective(MPI_COMM_WORLD, path, block, first, total,
                                          kCheckpointMetadata);
        },
        expected);
  };

  // The last rank's file-size limit below the checkpoint (SIGXFSZ ignored meanwhile, as a
  // process that sets such a limit would).
  {
    rlimit saved{};
    const bool last = d.rank() == d.size() - 1;
    const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
    if (last) {
      ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
      rlimit low = saved;
      low.rlim_cur = 4096;
      ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &low), 0);
    }
    message_on_every_rank(file, "RLIMIT_FSIZE");
    if (last) {
      ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &saved), 0);
    }
    std::signal(SIGXFSZ, old_handler);
  }
  message_on_every_rank(directory.path / "missing" / "ckpt.h5", "missing");
  // Parts that do not tile the particles.
  {
    std::string message;
    try {
      io::write_checkpoint_collective(MPI_COMM_WORLD, file, block, first, total + 1,
                                      kCheckpointMetadata);
    } catch (const io::CheckpointError& e) {
      message = e.what();
    }
    EXPECT_NE(message.find("for a checkpoint of " + std::to_string(total + 1)), std::string::npos)
        << message;
  }
  if (d.rank() == 0) {
    EXPECT_EQ(directory.files(), std::vector<std::string>{"ckpt.h5"});
    EXPECT_EQ(io::read_checkpoint(file).state.time, whole.time);  // the first write's
  }
}

// Read by the ranks, each a block of the file, a checkpoint gives every rank exactly its share
// (share_of of the whole state), from a file written by one process in any particle order and
// from one written by the ranks; a file read_checkpoint rejects is rejected on every rank with
// one message.
TEST(CheckpointByTheRanks, ReadByTheRanksGivesEachRankItsShare) {
  sim::SolverState whole = checkpoint_state(30011);
  const Decomposition d(MPI_COMM_WORLD, box_of(3), 0.3, 0.1);
  const sim::SolverState expected = share_of(d, whole);
  const SharedDirectory directory;
  // One process' file in another order than the ids (a solver's own order).
  sim::SolverState shuffled = whole;
  {
    std::vector<std::uint32_t> order(shuffled.particles.size());
    for (std::size_t k = 0; k < order.size(); ++k)
      order[k] = static_cast<std::uint32_t>((k * 7919) % order.size());
    reorder_state(shuffled, order);
  }
  if (d.rank() == 0) io::write_checkpoint(directory.path / "one.h5", shuffled, kCheckpointMetadata);
  std::uint64_t first = 0, total = 0;
  const sim::SolverState block = id_block(d, shuffled_share(d, whole), first, total);
  io::write_checkpoint_collective(MPI_COMM_WORLD, directory.path / "ranks.h5", block, first, total,
                                  kCheckpointMetadata);
  MPI_Barrier(MPI_COMM_WORLD);
  for (const char* name : {"one.h5", "ranks.h5"}) {
    io::CheckpointMetadata metadata;
    sim::SolverState share = read_share(d, directory.path / name, &metadata);
    EXPECT_EQ(metadata.scene_json, kCheckpointMetadata.scene_json);
    EXPECT_EQ(share.time, whole.time);
    EXPECT_EQ(share.step, whole.step);
    EXPECT_EQ(share.neighbour_builds, whole.neighbour_builds);
    // The same particles as share_of's (which keeps the whole state's id order).
    reorder_state(share, sim::order_by_key(share.particles.id));
    ASSERT_EQ(share.particles.id, expected.particles.id) << name;
    const auto got = share.particles.double_fields();
    const auto want = expected.particles.double_fields();
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t f = 0; f < got.size(); ++f) EXPECT_EQ(*got[f], *want[f]) << name;
    EXPECT_EQ(share.list_reference_positions, expected.list_reference_positions) << name;
  }

  // Rejected on every rank with one message: a missing file, a repeated id, a non-finite value
  // (in the last block, so that one rank finds it).
  const auto rejected = [&](const std::filesystem::path& path, const std::string& expected) {
    expect_one_checkpoint_error([&] { read_share(d, path); }, expected);
  };
  rejected(directory.path / "absent.h5", "file does not exist");
  sim::SolverState repeated = whole;
  repeated.particles.id[5] = repeated.particles.id[whole.particles.size() - 1];
  sim::SolverState infinite = whole;
  infinite.particles.velocity[1][whole.particles.size() - 2] =
      std::numeric_limits<double>::infinity();
  if (d.rank() == 0) {
    io::write_checkpoint(directory.path / "repeated.h5", repeated, kCheckpointMetadata);
    io::write_checkpoint(directory.path / "infinite.h5", infinite, kCheckpointMetadata);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  rejected(directory.path / "repeated.h5", "not a permutation");
  rejected(directory.path / "infinite.h5", "non-finite value in 'particles/velocity_y' at index " +
                                               std::to_string(whole.particles.size() - 2));
}

/// The bytes of a file.
std::string file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A new run's particles made by the ranks, each the lattice of its sub-box relaxed together
// with the other ranks' (par::set_up_share), are the particles sim::setup_run makes in one
// process, bit for bit: packed positions, case fields and summation masses, each particle on
// the rank whose sub-box holds it. The packing cache the ranks write, each its block, is the
// file one process writes, byte for byte; the ranks read it back, and so does one process; a
// damaged byte makes them pack again.
TEST(DistributedSetUp, EqualsTheOneProcessSetUpBitForBitAndSharesItsCache) {
  const SharedDirectory directory;
  for (const int dim : {2, 3}) {
    const sim::Scene scene = scene::parse_scene({{"case", dim == 3 ? "tgv3d" : "tgv2d"},
                                                 {"particles_per_side", dim == 3 ? 16 : 40},
                                                 {"kernel", {{"diameter_over_spacing", 6}}},
                                                 {"initial", {{"mass", "summation"}}}});
    const sim::SetupOptions ranks{.packing_cache_dir = directory.path / "ranks"};
    const sim::SetupOptions alone{.packing_cache_dir =
                                      directory.path / ("one" + std::to_string(world_rank()))};
    const sim::RunSetup one = sim::setup_run(scene, alone);
    ASSERT_FALSE(one.packing.from_cache);
    ASSERT_GT(one.packing.iterations, 0);
    std::vector<std::size_t> at(one.particles.size());
    for (std::size_t k = 0; k < at.size(); ++k) at[one.particles.id[k]] = k;

    const sim::SolverConfig& config = one.solver;
    std::string refusal;
    const auto decomposition = decomposition_or_refusal(
        config.box, sim::packing_list_radius(config.box, config.support_radius),
        config.particle_spacing, refusal);
    if (!decomposition) GTEST_SKIP() << refusal;
    const Decomposition& d = *decomposition;
    for (const bool cached : {false, true}) {
      sim::PackingReport report;
      const sim::ParticleArrays share = set_up_share(d, scene, config, ranks, report);
      EXPECT_EQ(report.from_cache, cached) << dim << "D";
      if (!cached) {
        EXPECT_EQ(report.iterations, one.packing.iterations);
        EXPECT_EQ(report.initial_residual, one.packing.initial_residual);
        EXPECT_EQ(report.final_residual, one.packing.final_residual);
        EXPECT_TRUE(report.converged);
      }
      std::size_t differ = 0, outside = 0;
      for (std::size_t i = 0; i < share.size(); ++i) {
        const std::size_t k = at[share.id[i]];
        bool same =
            share.mass[i] == one.particles.mass[k] && share.density[i] == one.particles.density[k];
        for (int a = 0; a < dim; ++a) {
          const auto x = static_cast<std::size_t>(a);
          same = same && share.position[x][i] == one.particles.position[x][k] &&
                 share.velocity[x][i] == one.particles.velocity[x][k];
          outside += d.coordinate_of(a, share.position[x][i]) != d.coords()[x] ? 1 : 0;
        }
        differ += same ? 0 : 1;
      }
      EXPECT_EQ(differ, 0u) << dim << "D, rank " << d.rank() << (cached ? ", cached" : "");
      EXPECT_EQ(outside, 0u) << dim << "D, rank " << d.rank();
      unsigned long long mine = share.size(), all = 0;
      MPI_Allreduce(&mine, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
      EXPECT_EQ(all, one.particles.size());
    }
    const std::filesystem::path ranks_file = sim::packing_cache_file(scene, ranks).path;
    EXPECT_EQ(file_bytes(ranks_file), file_bytes(sim::packing_cache_file(scene, alone).path))
        << dim << "D";
    sim::PackingReport read;
    const sim::ParticleArrays again = sim::packed_positions(scene, &read, ranks);
    EXPECT_TRUE(read.from_cache);
    for (int a = 0; a < dim; ++a)
      EXPECT_EQ(again.position[static_cast<std::size_t>(a)],
                one.particles.position[static_cast<std::size_t>(a)]);
    // One byte of one rank's block damaged: the blocks' checksums no longer add up, so every
    // rank packs again, with the same bits, and the ranks write the file anew.
    MPI_Barrier(MPI_COMM_WORLD);
    if (world_rank() == 0) {
      std::fstream f(ranks_file, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(static_cast<std::streamoff>(std::filesystem::file_size(ranks_file) * 3 / 4));
      f.put('\x5a');
    }
    MPI_Barrier(MPI_COMM_WORLD);
    sim::PackingReport repacked;
    const sim::ParticleArrays share = set_up_share(d, scene, config, ranks, repacked);
    EXPECT_FALSE(repacked.from_cache) << dim << "D: a damaged cache was read";
    for (std::size_t i = 0; i < share.size(); ++i)
      ASSERT_EQ(share.position[0][i], one.particles.position[0][at[share.id[i]]]);
    EXPECT_EQ(file_bytes(ranks_file), file_bytes(sim::packing_cache_file(scene, alone).path));
    MPI_Barrier(MPI_COMM_WORLD);
  }
}

}  // namespace
}  // namespace sphles::par

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  ::testing::InitGoogleTest(&argc, argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  // One rank prints the progress; every rank's failures are printed (gtest's failure messages
  // go to stdout with the rank in the assertion texts).
  if (rank != 0) {
    auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  const int failed = RUN_ALL_TESTS() != 0 ? 1 : 0;
  int any = 0;
  MPI_Allreduce(&failed, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  if (failed) std::fprintf(stderr, "rank %d: a test failed\n", rank);
  MPI_Finalize();
  return any;
}
