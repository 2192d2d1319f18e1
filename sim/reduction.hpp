// SPDX-License-Identifier: GPL-3.0-or-later
// Reductions whose result does not depend on the number of threads: values are summed
// sequentially in fixed-size blocks, and the block sums are added in block order.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
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

/// An exact sum of doubles: every added value is kept to its last bit in a fixed-point number
/// wide enough for the whole double range (a long accumulator after Kulisch), so the result
/// depends only on the set of values added, not on their order or on how they were split into
/// partial sums (threads, MPI ranks: par/). value() rounds the exact sum to the nearest double
/// (ties to even) when it is a normal number. Non-finite values are summed apart, as IEEE
/// addition does (∞ + (−∞) = NaN, NaN spreads).
class ExactSum {
  __extension__ using Uint128 = unsigned __int128;

 public:
  /// 32-bit digits held in 64-bit limbs, so that a limb takes 2^31 additions before a carry.
  static constexpr int kLimbs = 72;
  /// Exponent of the lowest limb's lowest bit: a multiple of 32 below the unit 2^-1074 of the
  /// subnormals (the largest numbers' unit, 2^971, lands in limb 66 of 72).
  static constexpr int kLowestExponent = -1152;

  void add(double x) {
    // The IEEE 754 fields of x: |x| = m 2^unit exactly, with m the 52 stored bits plus the
    // hidden bit (normal numbers) or without it (subnormals, unit -1074). Read from the bits,
    // not by frexp and ldexp: those are library calls, and this runs for every particle and
    // every sum of each step's diagnostics.
    const auto bits = std::bit_cast<std::uint64_t>(x);
    const auto biased = static_cast<int>((bits >> 52) & 0x7ff);
    if (biased == 0x7ff) {  // ±∞ or NaN
      special_ += x;
      return;
    }
    std::uint64_t m = bits & ((std::uint64_t{1} << 52) - 1);
    int unit = -1074;
    if (biased != 0) {
      m |= std::uint64_t{1} << 52;
      unit = biased - 1075;
    } else if (m == 0) {
      return;  // ±0
    }
    const int offset = unit - kLowestExponent;  // bit position of the mantissa's unit
    const auto magnitude = static_cast<Uint128>(m) << (offset % 32);
    const int k = offset / 32;
    const std::int64_t sign = (bits >> 63) != 0 ? -1 : 1;
    limbs_[static_cast<std::size_t>(k)] += sign * static_cast<std::int64_t>(magnitude & kDigit);
    limbs_[static_cast<std::size_t>(k) + 1] +=
        sign * static_cast<std::int64_t>((magnitude >> 32) & kDigit);
    limbs_[static_cast<std::size_t>(k) + 2] += sign * static_cast<std::int64_t>(magnitude >> 64);
    if (++pending_ == kCarryInterval) normalize();
  }

  /// Adds another exact sum (a partial sum of other values).
  void add(const ExactSum& other) {
    ExactSum o = other;
    o.normalize();
    normalize();
    for (std::size_t k = 0; k < limbs_.size(); ++k) limbs_[k] += o.limbs_[k];
    special_ += o.special_;
    normalize();
  }

  /// The digits in their unique normalised form (every limb but the top one in [0, 2^32), the
  /// top one signed), for combining sums across processes (par/); from_limbs takes them back.
  std::span<const std::int64_t, kLimbs> normalized_limbs() {
    normalize();
    return limbs_;
  }
  double special() const { return special_; }
  static ExactSum from_limbs(std::span<const std::int64_t, kLimbs> limbs, double special) {
    ExactSum s;
    std::copy(limbs.begin(), limbs.end(), s.limbs_.begin());
    s.special_ = special;
    s.normalize();
    return s;
  }

  /// The sum rounded to a double (a function of the exact sum only).
  double value() const {
    if (special_ != 0.0) return special_;  // ±∞ or NaN (NaN != 0 too)
    ExactSum s = *this;
    s.normalize();
    const bool negative = s.limbs_.back() < 0;
    if (negative) {
      for (std::int64_t& l : s.limbs_) l = -l;
      s.normalize();
    }
    int top = kLimbs - 1;
    while (top >= 0 && s.limbs_[static_cast<std::size_t>(top)] == 0) --top;
    if (top < 0) return 0.0;
    // The top four digits as a 128-bit integer; any lower digit only as a sticky bit, far below
    // the rounding position (the top digit is nonzero, so the integer has more than 96 bits).
    const int low = std::max(top - 3, 0);
    Uint128 head = 0;
    for (int k = top; k >= low; --k)
      head = (head << 32) | static_cast<std::uint64_t>(s.limbs_[static_cast<std::size_t>(k)]);
    bool sticky = false;
    for (int k = 0; k < low; ++k) sticky = sticky || s.limbs_[static_cast<std::size_t>(k)] != 0;
    if (sticky) head |= 1u;
    const double magnitude = std::ldexp(static_cast<double>(head), 32 * low + kLowestExponent);
    return negative ? -magnitude : magnitude;
  }

 private:
  static constexpr std::int64_t kDigit = 0xffffffff;
  static constexpr int kCarryInterval = 1 << 30;

  /// Carries every limb's excess into the next: afterwards limbs 0..K-2 are in [0, 2^32).
  void normalize() {
    for (std::size_t k = 0; k + 1 < limbs_.size(); ++k) {
      const std::int64_t carry = limbs_[k] >> 32;  // floor division by 2^32
      limbs_[k] -= carry * (std::int64_t{1} << 32);
      limbs_[k + 1] += carry;
    }
    pending_ = 0;
  }

  std::array<std::int64_t, kLimbs> limbs_{};
  double special_ = 0.0;
  int pending_ = 0;
};

/// Σ_{i<n} term(i) summed exactly (ExactSum), on all threads: the same bits for any thread
/// count, any order of the terms and any split of them over processes.
template <class Term>
ExactSum exact_sum(std::size_t n, Term&& term) {
  const std::size_t num_blocks = (n + kReductionBlock - 1) / kReductionBlock;
  std::vector<ExactSum> block_sum(num_blocks);
  const auto signed_blocks = static_cast<std::ptrdiff_t>(num_blocks);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < signed_blocks; ++b) {
    const std::size_t begin = static_cast<std::size_t>(b) * kReductionBlock;
    const std::size_t end = std::min(n, begin + kReductionBlock);
    ExactSum& s = block_sum[static_cast<std::size_t>(b)];
    for (std::size_t i = begin; i < end; ++i) s.add(term(i));
  }
  ExactSum total;
  for (const ExactSum& s : block_sum) total.add(s);
  return total;
}

/// K exact sums in one sweep: sums[k] = Σ_{i<n} t_k(i), where term(i, t) writes t_0..t_{K-1}
/// of particle i into t (a std::array<double, K>&). Same guarantees as exact_sum.
template <std::size_t K, class Term>
std::array<ExactSum, K> exact_sums(std::size_t n, Term&& term) {
  const std::size_t num_blocks = (n + kReductionBlock - 1) / kReductionBlock;
  std::vector<std::array<ExactSum, K>> block_sum(num_blocks);
  const auto signed_blocks = static_cast<std::ptrdiff_t>(num_blocks);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < signed_blocks; ++b) {
    const std::size_t begin = static_cast<std::size_t>(b) * kReductionBlock;
    const std::size_t end = std::min(n, begin + kReductionBlock);
    std::array<ExactSum, K>& s = block_sum[static_cast<std::size_t>(b)];
    std::array<double, K> t{};
    for (std::size_t i = begin; i < end; ++i) {
      term(i, t);
      for (std::size_t k = 0; k < K; ++k) s[k].add(t[k]);
    }
  }
  std::array<ExactSum, K> total;
  for (const std::array<ExactSum, K>& s : block_sum)
    for (std::size_t k = 0; k < K; ++k) total[k].add(s[k]);
  return total;
}

}  // namespace sphles::sim
