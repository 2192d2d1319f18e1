// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/reduce.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

namespace sphles::par {

sim::ExactSum allreduce(const Decomposition& d, sim::ExactSum partial) {
  // Normalised digits are below 2^32 (the top one small), so 2^31 ranks' digits add up in
  // 64-bit integers without overflow; the sum is normalised again by from_limbs.
  std::array<std::int64_t, sim::ExactSum::kLimbs> limbs{};
  MPI_Allreduce(partial.normalized_limbs().data(), limbs.data(), sim::ExactSum::kLimbs, MPI_INT64_T,
                MPI_SUM, d.comm());
  double special = 0.0;
  const double my_special = partial.special();
  MPI_Allreduce(&my_special, &special, 1, MPI_DOUBLE, MPI_SUM, d.comm());
  return sim::ExactSum::from_limbs(limbs, special);
}

void allreduce(const Decomposition& d, std::span<sim::ExactSum> partial) {
  constexpr std::size_t K = sim::ExactSum::kLimbs;
  const std::size_t n = partial.size();
  std::vector<std::int64_t> mine(n * K), all(n * K);
  std::vector<double> my_special(n), special(n);
  for (std::size_t s = 0; s < n; ++s) {
    const auto limbs = partial[s].normalized_limbs();
    std::copy(limbs.begin(), limbs.end(), mine.begin() + static_cast<std::ptrdiff_t>(s * K));
    my_special[s] = partial[s].special();
  }
  MPI_Allreduce(mine.data(), all.data(), static_cast<int>(n * K), MPI_INT64_T, MPI_SUM, d.comm());
  MPI_Allreduce(my_special.data(), special.data(), static_cast<int>(n), MPI_DOUBLE, MPI_SUM,
                d.comm());
  for (std::size_t s = 0; s < n; ++s)
    partial[s] = sim::ExactSum::from_limbs(std::span<const std::int64_t, K>(all.data() + s * K, K),
                                           special[s]);
}

bool on_every_rank(const Decomposition& d, bool ok) {
  int mine = ok ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, d.comm());
  return all == 1;
}

void allreduce_counts(const Decomposition& d, std::span<std::uint64_t> counts) {
  MPI_Allreduce(MPI_IN_PLACE, counts.data(), static_cast<int>(counts.size()), MPI_UINT64_T, MPI_SUM,
                d.comm());
}

}  // namespace sphles::par
