// SPDX-License-Identifier: GPL-3.0-or-later
// Stream compaction of index lists: keep the entries a vectorised test selected, in order.
// Used by the Verlet list build (candidates within the list radius) and by the density pass
// (the pairs inside the kernel support, sim/pair_loop.hpp).
#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif

namespace sphles::sim {

namespace select_detail {
#if defined(__AVX512F__)
/// The selection of 16 consecutive marks as a mask: the sign bits of 16 byte marks, or the
/// non-zero 32-bit marks.
inline __mmask16 mask_of(const std::uint8_t* marks) {
  return static_cast<__mmask16>(
      _mm_movemask_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(marks))));
}
inline __mmask16 mask_of(const std::uint32_t* marks) {
  const __m512i wide = _mm512_loadu_si512(marks);
  return _mm512_test_epi32_mask(wide, wide);
}
#endif
}  // namespace select_detail

/// Appends members[k] for every k < count with selected[k] != 0 to `out`, in order; returns how
/// many. The marks are bytes (0x00 or 0xFF, the list build) or 32 bits (0 or 0xFFFFFFFF, the
/// density pass, whose vectorised loop a byte mark would stretch to 32 entries per iteration,
/// sim/pair_loop.hpp). May write up to 16 entries past the last appended one, but never past
/// out + count.
template <class Mark>
requires std::same_as<Mark, std::uint8_t> || std::same_as<Mark, std::uint32_t>
inline std::size_t append_selected(const std::uint32_t* members, const Mark* selected,
                                   std::size_t count, std::uint32_t* out) {
  std::size_t used = 0, k = 0;
#if defined(__AVX512F__)
  // 16 candidates at a time, compressed by the mask of their marks.
  for (; k + 16 <= count; k += 16) {
    const __mmask16 mask = select_detail::mask_of(selected + k);
    const __m512i indices = _mm512_loadu_si512(members + k);
    _mm512_storeu_si512(out + used, _mm512_maskz_compress_epi32(mask, indices));
    used += static_cast<std::size_t>(__builtin_popcount(mask));
  }
#endif
  // Branch-free: every candidate is written, the count advances for those selected.
  for (; k < count; ++k) {
    out[used] = members[k];
    used += selected[k] & 1u;
  }
  return used;
}

}  // namespace sphles::sim
