// SPDX-License-Identifier: GPL-3.0-or-later
// The cell-list Verlet search equals brute force on random periodic sets (SWIFT test27cells
// style), including particles on and near the faces and boxes of one, two and three cells.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <set>

#include "sim/neighbour_search.hpp"

namespace sphles::sim {
namespace {

struct SearchCase {
  int dim;
  std::array<double, 3> length;
  double cutoff;
  double skin;
  std::size_t count;
};

ParticleArrays random_particles(const SearchCase& c, std::uint64_t seed) {
  ParticleArrays p;
  p.dimension = c.dim;
  p.resize(c.count);
  std::mt19937_64 rng(seed);
  for (std::size_t i = 0; i < c.count; ++i) {
    for (int d = 0; d < c.dim; ++d) {
      std::uniform_real_distribution<double> uniform(0.0, c.length[d]);
      double x = uniform(rng);
      // Every fifth particle sits on or within 1e-9 L of a face.
      if (i % 5 == 0) x = (i % 2 ? 0.0 : std::nextafter(c.length[d], 0.0));
      if (i % 7 == 0) x = (i % 2 ? 1e-9 : c.length[d] - 1e-9) * (d == 0 ? 1.0 : 0.5);
      p.position[d][i] = x;
    }
  }
  return p;
}

std::vector<std::set<std::uint32_t>> brute_force(const ParticleArrays& p, const PeriodicBox& box,
                                                 double radius) {
  std::vector<std::set<std::uint32_t>> result(p.size());
  for (std::size_t i = 0; i < p.size(); ++i)
    for (std::size_t j = 0; j < p.size(); ++j) {
      if (i == j) continue;
      double r2 = 0.0;
      for (int d = 0; d < p.dimension; ++d) {
        const double dx =
            minimum_image(p.position[d][i] - p.position[d][j], box.length[d], 0.5 * box.length[d]);
        r2 += dx * dx;
      }
      if (r2 < radius * radius) result[i].insert(static_cast<std::uint32_t>(j));
    }
  return result;
}

class NeighbourSearchTest : public ::testing::TestWithParam<SearchCase> {};

TEST_P(NeighbourSearchTest, EqualsBruteForce) {
  const SearchCase c = GetParam();
  PeriodicBox box{c.dim, c.length};
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    ParticleArrays p = random_particles(c, seed);
    VerletNeighbourSearch search(box, c.cutoff, c.skin);
    p.reorder(search.locality_order(view_positions(p)));
    search.build(view_positions(p));
    const auto expected = brute_force(p, box, search.list_radius());
    const NeighbourList& list = search.list();
    ASSERT_EQ(list.num_particles(), p.size());
    std::size_t total = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      const auto span = list.of(i);
      const std::set<std::uint32_t> found(span.begin(), span.end());
      EXPECT_EQ(found.size(), span.size()) << "duplicate neighbour of particle " << i;
      EXPECT_EQ(found, expected[i]) << "particle " << i << " seed " << seed;
      total += span.size();
    }
    EXPECT_GT(total, 0u);
  }
}

// The build keeps its scratch from one build to the next and scans candidates in cell order
// whatever order the particles are stored in: one search object, particles not reordered, then
// a set of another size, then the first set again.
TEST_P(NeighbourSearchTest, EqualsBruteForceUnsortedAndAcrossRebuildsOfOtherSizes) {
  const SearchCase c = GetParam();
  PeriodicBox box{c.dim, c.length};
  VerletNeighbourSearch search(box, c.cutoff, c.skin);
  for (const auto& [seed, count] :
       {std::pair<std::uint64_t, std::size_t>{4, c.count}, {5, c.count / 3 + 1}, {4, c.count}}) {
    SearchCase sized = c;
    sized.count = count;
    const ParticleArrays p = random_particles(sized, seed);
    search.build(view_positions(p));
    const auto expected = brute_force(p, box, search.list_radius());
    const NeighbourList& list = search.list();
    ASSERT_EQ(list.num_particles(), p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      const auto span = list.of(i);
      const std::set<std::uint32_t> found(span.begin(), span.end());
      EXPECT_EQ(found.size(), span.size()) << "duplicate neighbour of particle " << i;
      EXPECT_EQ(found, expected[i]) << "particle " << i << " of " << count << ", seed " << seed;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Boxes, NeighbourSearchTest,
    ::testing::Values(SearchCase{3, {1.0, 1.0, 1.0}, 0.12, 0.02, 1500},  // many cells
                      SearchCase{3, {1.0, 0.8, 0.6}, 0.2, 0.03, 800},    // 4, 3, 2 cells
                      SearchCase{3, {1.0, 1.0, 1.0}, 0.5, 0.1, 300},     // support = half box
                      SearchCase{3, {0.5, 1.0, 1.0}, 0.25, 0.0, 400},    // one cell in x
                      SearchCase{2, {1.0, 1.0, 0.0}, 0.07, 0.01, 2000},  // 2D, many cells
                      SearchCase{2, {1.0, 0.3, 0.0}, 0.14, 0.01, 600},   // 2D, two cells in y
                      SearchCase{2, {1.0, 1.0, 0.0}, 0.5, 0.0, 300}),    // 2D, one cell
    [](const ::testing::TestParamInfo<SearchCase>& info) {
      return std::to_string(info.param.dim) + "D_case" + std::to_string(info.index);
    });

// On a lattice whose spacing is a tenth of the box and half the list radius, many pairs lie at
// the list radius itself, where the rounding of x_i - x_j decides (differently for pairs across
// the periodic faces). The build tests distances in single precision and defers to the double-
// precision test near the radius: its lists must be brute force's, pair for pair.
TEST(NeighbourSearch, EqualsBruteForceOnALatticeWithPairsAtTheListRadius) {
  for (const int dim : {2, 3}) {
    const std::size_t per_side = 10;
    const PeriodicBox box{dim, {1.0, 1.0, dim == 3 ? 1.0 : 0.0}};
    ParticleArrays p;
    p.dimension = dim;
    p.resize(dim == 3 ? per_side * per_side * per_side : per_side * per_side);
    for (std::size_t i = 0; i < p.size(); ++i) {
      std::size_t k = i;
      for (int d = 0; d < dim; ++d) {
        p.position[d][i] = (static_cast<double>(k % per_side) + 0.5) * 0.1;
        k /= per_side;
      }
    }
    VerletNeighbourSearch search(box, 0.2, 0.0);
    search.build(view_positions(p));
    const auto expected = brute_force(p, box, search.list_radius());
    std::size_t at_radius = 0;  // pairs whose distance rounds to the radius either way
    for (std::size_t i = 0; i < p.size(); ++i) {
      const auto span = search.list().of(i);
      EXPECT_EQ(std::set<std::uint32_t>(span.begin(), span.end()), expected[i])
          << "particle " << i << " (" << dim << "D)";
      EXPECT_EQ(span.size(), expected[i].size());
      for (std::size_t j = 0; j < p.size(); ++j) {
        double r2 = 0.0;
        for (int d = 0; d < dim; ++d) {
          const double dx = minimum_image(p.position[d][i] - p.position[d][j], 1.0, 0.5);
          r2 += dx * dx;
        }
        at_radius += std::abs(r2 - 0.04) < 1e-12 ? 1 : 0;
      }
    }
    EXPECT_GT(at_radius, p.size()) << "the lattice must put pairs at the list radius";
  }
}

// With a cell order by id, a particle's list names the same neighbours in the same order
// whatever the order of the arrays (what makes a distributed particle's sums those of one
// process, par/): here the arrays shuffled, and a subset holding every neighbour of the first
// quarter of the particles.
TEST_P(NeighbourSearchTest, CellOrderByIdMakesListsIndependentOfTheArrayOrder) {
  const SearchCase c = GetParam();
  const PeriodicBox box{c.dim, c.length};
  const ParticleArrays p = random_particles(c, 23);
  auto ids_of_lists = [&](const ParticleArrays& q) {
    VerletNeighbourSearch search(box, c.cutoff, c.skin);
    search.build(view_positions(q), order_by_key(q.id));
    std::vector<std::vector<std::uint64_t>> lists(p.size());
    for (std::size_t i = 0; i < q.size(); ++i)
      for (const std::uint32_t j : search.list().of(i)) lists[q.id[i]].push_back(q.id[j]);
    return lists;
  };
  const auto reference = ids_of_lists(p);

  std::vector<std::uint32_t> shuffle(p.size());
  for (std::uint32_t k = 0; k < p.size(); ++k) shuffle[k] = k;
  std::shuffle(shuffle.begin(), shuffle.end(), std::mt19937_64(3));
  ParticleArrays shuffled = p;
  shuffled.reorder(shuffle);
  EXPECT_EQ(ids_of_lists(shuffled), reference);

  // The first quarter and their neighbours, in reverse id order.
  std::set<std::uint64_t> keep;
  for (std::uint64_t g = 0; g < p.size() / 4; ++g) {
    keep.insert(g);
    keep.insert(reference[g].begin(), reference[g].end());
  }
  std::vector<std::uint32_t> subset(keep.rbegin(), keep.rend());
  ParticleArrays part;
  part.dimension = p.dimension;
  part.resize(subset.size());
  auto to = part.double_fields();
  const auto from = p.double_fields();
  for (std::size_t f = 0; f < to.size(); ++f)
    for (std::size_t k = 0; k < subset.size(); ++k) (*to[f])[k] = (*from[f])[subset[k]];
  for (std::size_t k = 0; k < subset.size(); ++k) part.id[k] = subset[k];
  const auto lists = ids_of_lists(part);
  for (std::uint64_t g = 0; g < p.size() / 4; ++g) EXPECT_EQ(lists[g], reference[g]) << g;
}

// The build writes each thread's particles into a region of the list sized from the last build
// (or the number density at the first); a clustered set overflows those regions many times over.
// The lists must still equal brute force, whether the estimate comes from the density or from a
// sparse earlier build; and a list a reader holds stays as it was through later builds.
TEST(NeighbourSearch, ClusteredSetsOverflowTheRegionsAndStillEqualBruteForce) {
  for (const int dim : {2, 3}) {
    const SearchCase c{dim, {1.0, 1.0, dim == 3 ? 1.0 : 0.0}, 0.08, 0.01, 1200};
    const PeriodicBox box{dim, c.length};
    const ParticleArrays uniform = random_particles(c, 31);
    ParticleArrays clustered = uniform;  // 9 in 10 particles in a cube of side 0.1 at 0.98
    for (std::size_t i = 0; i < clustered.size(); ++i)
      if (i % 10 != 0)
        for (int d = 0; d < dim; ++d)
          clustered.position[d][i] =
              wrap_periodic(0.98 + 0.1 * (uniform.position[d][i] - 0.5), c.length[d]);
    const auto check = [&](const VerletNeighbourSearch& search, const ParticleArrays& p,
                           const NeighbourList& list, const char* what) {
      const auto expected = brute_force(p, box, search.list_radius());
      ASSERT_EQ(list.num_particles(), p.size()) << what;
      std::size_t entries = 0;
      for (std::size_t i = 0; i < p.size(); ++i) {
        const auto span = list.of(i);
        EXPECT_EQ(std::set<std::uint32_t>(span.begin(), span.end()), expected[i])
            << what << ": particle " << i << " (" << dim << "D)";
        EXPECT_EQ(span.size(), expected[i].size()) << what << ": particle " << i;
        entries += span.size();
      }
      EXPECT_EQ(list.num_entries(), entries) << what;
    };
    {
      VerletNeighbourSearch fresh(box, c.cutoff, c.skin);
      fresh.build(view_positions(clustered));
      check(fresh, clustered, fresh.list(), "clustered, first build");
    }
    VerletNeighbourSearch search(box, c.cutoff, c.skin);
    search.build(view_positions(uniform));
    const std::shared_ptr<const NeighbourList> held = search.shared_list();
    const NeighbourList copy = *held;
    search.build(view_positions(clustered));  // into a new list: the reader holds the first
    check(search, clustered, search.list(), "clustered after uniform");
    search.build(view_positions(uniform));  // into the second list again; the first is still held
    check(search, uniform, search.list(), "uniform again");
    EXPECT_EQ(held->start, copy.start);
    EXPECT_EQ(held->count, copy.count);
    EXPECT_EQ(held->indices, copy.indices);
    check(search, uniform, *held, "the held list");
  }
}

TEST(NeighbourSearch, RejectsBoxSmallerThanSupportDiameter) {
  PeriodicBox box{3, {1.0, 1.0, 0.5}};
  try {
    VerletNeighbourSearch search(box, 0.3, 0.0);
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("smaller than the kernel support diameter"),
              std::string::npos);
  }
}

TEST(NeighbourSearch, SkinShrinksToFitSmallBox) {
  PeriodicBox box{2, {1.0, 1.0, 0.0}};
  VerletNeighbourSearch search(box, 0.45, 0.2);
  EXPECT_NEAR(search.list_radius(), 0.5, 1e-15);
}

TEST(NeighbourSearch, RebuildOnlyAfterHalfSkinDisplacement) {
  const SearchCase c{3, {1.0, 1.0, 1.0}, 0.15, 0.04, 500};
  PeriodicBox box{3, c.length};
  ParticleArrays p = random_particles(c, 9);
  VerletNeighbourSearch search(box, c.cutoff, c.skin);
  EXPECT_TRUE(search.needs_rebuild(view_positions(p)));
  search.build(view_positions(p));
  EXPECT_FALSE(search.needs_rebuild(view_positions(p)));
  // Move one particle by 0.49 skin across the periodic face: still valid.
  p.position[0][3] = wrap_periodic(p.position[0][3] - 0.49 * c.skin, 1.0);
  EXPECT_FALSE(search.needs_rebuild(view_positions(p)));
  p.position[0][3] = wrap_periodic(p.position[0][3] - 0.02 * c.skin, 1.0);
  EXPECT_TRUE(search.needs_rebuild(view_positions(p)));
}

TEST(Periodic, MinimumImageIsExactlyAntisymmetric) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> uniform(0.0, 2.0);
  const double length = 2.0;
  for (int k = 0; k < 100000; ++k) {
    const double a = uniform(rng), b = uniform(rng);
    EXPECT_EQ(minimum_image(a - b, length, 1.0), -minimum_image(b - a, length, 1.0));
  }
  EXPECT_EQ(wrap_periodic(-1e-18, 1.0), 0.0);
  EXPECT_EQ(wrap_periodic(1.0, 1.0), 0.0);
  EXPECT_DOUBLE_EQ(wrap_periodic(1.25, 1.0), 0.25);
}

}  // namespace
}  // namespace sphles::sim
