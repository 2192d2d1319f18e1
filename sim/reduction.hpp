// Reductions whose result does not depend on the number of threads: values are summed
// sequentially in fixed-size blocks, and the block sums are added in block order.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace sphles::sim {

inline constexpr std::size_t kReductionBlock = 4096;

/// Σ_{i<n} term(i), bitwise identical for any OpenMP thread count.
template <class Term>
double deterministic_sum(std::size_t n, Term&& term) {
  const std::size_t num_blocks = (n + kReductionBlock - 1) / kReductionBlock;
  std::vector<double> block_sum(num_blocks, 0.0);
  const auto signed_blocks = static_cast<std::ptrdiff_t>(num_blocks);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < signed_blocks; ++b) {
    const std::size_t begin = static_cast<std::size_t>(b) * kReductionBlock;
    const std::size_t end = std::min(n, begin + kReductionBlock);
    double s = 0.0;
    for (std::size_t i = begin; i < end; ++i) s += term(i);
    block_sum[static_cast<std::size_t>(b)] = s;
  }
  double total = 0.0;
  for (double s : block_sum) total += s;
  return total;
}

/// max_{i<n} value(i) (max is exact, so any order gives the same result); 0 for n = 0.
template <class Value>
double parallel_max(std::size_t n, Value&& value) {
  double result = 0.0;
  const auto signed_n = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for reduction(max : result)
  for (std::ptrdiff_t i = 0; i < signed_n; ++i)
    result = std::max(result, value(static_cast<std::size_t>(i)));
  return result;
}

}  // namespace sphles::sim
