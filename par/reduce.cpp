#include "par/reduce.hpp"

#include <array>
#include <cstdint>

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

}  // namespace sphles::par
