// Stream compaction of index lists: keep the entries a vectorised test selected, in order.
// Used by the Verlet list build (candidates within the list radius) and by the density pass
// (the pairs inside the kernel support, sim/pair_loop.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif

namespace sphles::sim {

/// Appends members[k] for every k < count with selected[k] != 0 (each 0x00 or 0xFF) to `out`,
/// in order; returns how many. May write up to 16 entries past the last appended one, but never
/// past out + count.
inline std::size_t append_selected(const std::uint32_t* members, const std::uint8_t* selected,
                                   std::size_t count, std::uint32_t* out) {
  std::size_t used = 0, k = 0;
#if defined(__AVX512F__)
  // 16 candidates at a time: the selection bytes' sign bits form the mask of a compress.
  for (; k + 16 <= count; k += 16) {
    const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(selected + k));
    const auto mask = static_cast<__mmask16>(_mm_movemask_epi8(bytes));
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

/// The same with 32-bit selections (each 0 or 0xFFFFFFFF): the mask a vectorised loop over
/// 32-bit list entries writes without narrowing, so that the loop's vector length is set by its
/// indices, not by a byte (sim/pair_loop.hpp).
inline std::size_t append_selected(const std::uint32_t* members, const std::uint32_t* selected,
                                   std::size_t count, std::uint32_t* out) {
  std::size_t used = 0, k = 0;
#if defined(__AVX512F__)
  for (; k + 16 <= count; k += 16) {
    const __m512i marks = _mm512_loadu_si512(selected + k);
    const __mmask16 mask = _mm512_test_epi32_mask(marks, marks);
    const __m512i indices = _mm512_loadu_si512(members + k);
    _mm512_storeu_si512(out + used, _mm512_maskz_compress_epi32(mask, indices));
    used += static_cast<std::size_t>(__builtin_popcount(mask));
  }
#endif
  for (; k < count; ++k) {
    out[used] = members[k];
    used += selected[k] & 1u;
  }
  return used;
}

}  // namespace sphles::sim
