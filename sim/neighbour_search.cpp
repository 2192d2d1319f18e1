#include "sim/neighbour_search.hpp"

#include <omp.h>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "sim/select.hpp"

namespace sphles::sim {

namespace {

/// Entries a scan may write past the last one it keeps (whole-vector stores of 8 indices).
constexpr std::size_t kStoreSlack = 8;

/// When a region overflows, the estimate grows at least by this factor for the next round.
constexpr double kRegrowth = 1.25;

/// Particle indices sorted by cell into `members`, and where each cell's members begin into
/// `start` (num_cells + 1 entries). Within a cell, members follow `visit` when it is not empty (a
/// permutation of the indices), else ascending index (a stable counting sort).
void counting_sort_by_cell(const std::vector<std::uint32_t>& cell, std::size_t num_cells,
                           std::vector<std::uint32_t>& members, std::vector<std::size_t>& start,
                           std::span<const std::uint32_t> visit = {}) {
  start.assign(num_cells + 1, 0);
  for (const std::uint32_t c : cell) ++start[c + 1];
  for (std::size_t c = 0; c < num_cells; ++c) start[c + 1] += start[c];
  members.resize(cell.size());
  if (visit.empty()) {
    for (std::size_t i = 0; i < cell.size(); ++i)
      members[start[cell[i]]++] = static_cast<std::uint32_t>(i);
  } else {
    for (const std::uint32_t i : visit) members[start[cell[i]]++] = i;
  }
  // start[c] now holds where cell c ends, the start of c + 1: shift back.
  for (std::size_t c = num_cells; c > 0; --c) start[c] = start[c - 1];
  start[0] = 0;
}

}  // namespace

std::vector<std::uint32_t> order_by_key(std::span<const std::uint64_t> keys) {
  const std::size_t n = keys.size();
  std::vector<std::uint32_t> order(n);
  const bool permutation =
      std::all_of(keys.begin(), keys.end(), [n](std::uint64_t k) { return k < n; });
  if (permutation) {  // unique keys below n: each index's place is its key
    for (std::size_t i = 0; i < n; ++i) order[keys[i]] = static_cast<std::uint32_t>(i);
    return order;
  }
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
  return order;
}

VerletNeighbourSearch::VerletNeighbourSearch(const PeriodicBox& box, double cutoff, double skin)
    : box_(box), cutoff_(cutoff), skin_(skin) {
  if (!(cutoff > 0.0)) throw std::invalid_argument("neighbour search: cutoff must be > 0");
  if (!(skin >= 0.0)) throw std::invalid_argument("neighbour search: skin must be >= 0");
  const double min_length = box.min_length();
  if (min_length < 2.0 * cutoff) {
    throw std::invalid_argument("neighbour search: box length " + std::to_string(min_length) +
                                " is smaller than the kernel support diameter " +
                                std::to_string(2.0 * cutoff));
  }
  // Minimum-image lists need every listed pair closer than half a box.
  skin_ = std::min(skin_, 0.5 * min_length - cutoff);
  // Cells of at least radius / kCellsPerRadius: candidates lie at most kCellsPerRadius cells away.
  const double cell_size = list_radius() / kCellsPerRadius;
  for (int d = 0; d < box.dimension; ++d) {
    cells_[d] = std::max(1, static_cast<int>(std::floor(box.length[d] / cell_size)));
    inv_cell_size_[d] = cells_[d] / box.length[d];
  }
}

void VerletNeighbourSearch::cell_of(const PositionsView& positions,
                                    std::vector<std::uint32_t>& cell) const {
  cell.resize(positions.size);
  const auto n = static_cast<std::ptrdiff_t>(positions.size);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    std::uint32_t c = 0;
    for (int d = positions.dimension - 1; d >= 0; --d) {
      int k = static_cast<int>(positions.x[d][i] * inv_cell_size_[d]);
      k = std::clamp(k, 0, cells_[d] - 1);
      c = c * static_cast<std::uint32_t>(cells_[d]) + static_cast<std::uint32_t>(k);
    }
    cell[i] = c;
  }
}

std::vector<std::uint32_t> VerletNeighbourSearch::locality_order(
    const PositionsView& positions) const {
  std::vector<std::uint32_t> cell, order;
  std::vector<std::size_t> start;
  cell_of(positions, cell);
  counting_sort_by_cell(cell, num_cells(), order, start);
  return order;
}

template <int Dim>
void VerletNeighbourSearch::build_impl(const PositionsView& positions,
                                       std::span<const std::uint32_t> cell_order,
                                       std::size_t listed) {
  const std::size_t n = positions.size;
  // Scratch kept between builds (BuildScratch): fresh vectors of this size would be mapped and
  // zeroed page by page at every build.
  std::vector<std::uint32_t>& cell = scratch_.cell;
  std::vector<std::size_t>& cell_start = scratch_.cell_start;
  std::vector<std::uint32_t>& cell_members = scratch_.cell_members;
  cell_of(positions, cell);
  const std::size_t num_cells = this->num_cells();
  counting_sort_by_cell(cell, num_cells, cell_members, cell_start, cell_order);

  // Distinct cell offsets per direction: -reach..reach, reduced modulo the number of cells when
  // a direction has fewer than 2 reach + 1 cells, so that no cell is visited twice.
  std::array<std::vector<int>, 3> offsets;
  for (int d = 0; d < Dim; ++d) {
    if (cells_[d] >= 2 * kCellsPerRadius + 1) {
      for (int o = -kCellsPerRadius; o <= kCellsPerRadius; ++o) offsets[d].push_back(o);
    } else {
      for (int o = 0; o < cells_[d]; ++o) offsets[d].push_back(o);
    }
  }

  std::size_t max_occupancy = 0;
  for (std::size_t c = 0; c < num_cells; ++c)
    max_occupancy = std::max(max_occupancy, cell_start[c + 1] - cell_start[c]);
  std::size_t max_candidates = max_occupancy;
  for (int d = 0; d < Dim; ++d) max_candidates *= offsets[d].size();

  std::array<double, 3> length{}, half_length{};
  for (int d = 0; d < Dim; ++d) {
    length[d] = box_.length[d];
    half_length[d] = 0.5 * box_.length[d];
  }
  const double radius2 = list_radius() * list_radius();

  // Positions in cell order, so that a run of neighbouring cells along x is one contiguous run of
  // candidates: the distance test below is a vectorised loop over contiguous memory. rank[i] is
  // particle i's place in that order.
  std::array<std::vector<double>, 3>& sorted = scratch_.sorted;
  for (int d = 0; d < Dim; ++d) sorted[d].resize(n);
  std::vector<std::uint32_t>& rank = scratch_.rank;
  rank.resize(n);
  const auto signed_n = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t sk = 0; sk < signed_n; ++sk) {
    const auto k = static_cast<std::size_t>(sk);
    for (int d = 0; d < Dim; ++d) sorted[d][k] = positions.x[d][cell_members[k]];
    rank[cell_members[k]] = static_cast<std::uint32_t>(k);
  }

  // Pruning: a cell whose nearest point is farther than the list radius from x_i holds no
  // neighbour, so rows of cells (fixed y, z offsets) beyond the radius are skipped and the x cells
  // of a row are cut to the chord the sphere leaves in it. Only with centred offsets (at least
  // 2 reach + 1 cells per direction, where each offset is the nearest periodic image); the margin
  // covers the rounding of cell bounds against the cell assignment, so the list is unchanged.
  bool prune = true;
  for (int d = 0; d < Dim; ++d) prune = prune && cells_[d] >= 2 * kCellsPerRadius + 1;
  std::array<double, 3> cell_size{};
  for (int d = 0; d < Dim; ++d) cell_size[d] = box_.length[d] / cells_[d];
  const double radius = list_radius();
  const double margin = 1e-9 * radius;

  // Visits every candidate j of particle i in a fixed order (z, y, x cell offsets ascending, the
  // members of a cell in ascending index) and appends those within the list radius to `out`,
  // returning their number. The cells of one (z, y) offset are scanned as at most two contiguous
  // runs (two when the x offsets wrap around the box); `keep` is scratch space.
  const auto visit = [&](std::size_t i, std::uint32_t* out, std::vector<std::uint8_t>& keep) {
    std::array<int, 3> ci{0, 0, 0};
    {
      std::uint32_t c = cell[i];
      for (int d = 0; d < Dim; ++d) {
        ci[d] = static_cast<int>(c % static_cast<std::uint32_t>(cells_[d]));
        c /= static_cast<std::uint32_t>(cells_[d]);
      }
    }
    double xi[3] = {0.0, 0.0, 0.0};
    for (int d = 0; d < Dim; ++d) xi[d] = positions.x[d][i];
    // Distance from x_i to the slab of the cell at offset o along axis d (0 inside it).
    const auto slab_distance = [&](int d, int o) {
      const double lo = (ci[d] + o) * cell_size[d];
      return std::max({0.0, lo - xi[d], xi[d] - (lo + cell_size[d])});
    };
    std::size_t used = 0;
    const std::uint32_t self = rank[i];
    const auto scan = [&](std::size_t begin, std::size_t end) {
      const std::size_t count = end - begin;
#if defined(__AVX512F__) && defined(__AVX512VL__)
      // 8 candidates per vector, the last block masked (the runs are short: a few cells of a
      // row, so a scalar remainder would cost as much as the vector part). The same operations
      // in the same order as the portable loop (#else), so the list is the same.
      (void)keep;
      // Every loop invariant in a local: the index store below is of a type that may alias
      // anything, so values reached through the captures (the arrays' pointers, xi, the box)
      // would otherwise be reloaded and re-broadcast at every block.
      const double* const x0 = sorted[0].data();
      const double* const x1 = sorted[1].data();
      const double* const x2 = sorted[Dim == 3 ? 2 : 0].data();
      const std::uint32_t* const member = cell_members.data();
      std::uint32_t* const dest = out;
      const std::size_t me = self;
      std::size_t kept = used;
      const __m512d xi0 = _mm512_set1_pd(xi[0]), xi1 = _mm512_set1_pd(xi[1]),
                    xi2 = _mm512_set1_pd(xi[Dim == 3 ? 2 : 0]);
      const __m512d len0 = _mm512_set1_pd(length[0]), len1 = _mm512_set1_pd(length[1]),
                    len2 = _mm512_set1_pd(length[Dim == 3 ? 2 : 0]);
      const __m512d half0 = _mm512_set1_pd(half_length[0]), half1 = _mm512_set1_pd(half_length[1]),
                    half2 = _mm512_set1_pd(half_length[Dim == 3 ? 2 : 0]);
      const __m512d low0 = _mm512_set1_pd(-half_length[0]), low1 = _mm512_set1_pd(-half_length[1]),
                    low2 = _mm512_set1_pd(-half_length[Dim == 3 ? 2 : 0]);
      const __m512d r2_limit = _mm512_set1_pd(radius2);
      const auto image = [](__m512d dx, __m512d l, __m512d half, __m512d low) {
        dx = _mm512_mask_sub_pd(dx, _mm512_cmp_pd_mask(dx, half, _CMP_GT_OQ), dx, l);
        return _mm512_mask_add_pd(dx, _mm512_cmp_pd_mask(dx, low, _CMP_LT_OQ), dx, l);
      };
      for (std::size_t k = 0; k < count; k += 8) {
        const std::size_t left = count - k;
        const auto live = static_cast<__mmask8>(left >= 8 ? 0xFF : (1u << left) - 1u);
        const std::size_t at = begin + k;
        const __m512d dx =
            image(_mm512_sub_pd(xi0, _mm512_maskz_loadu_pd(live, x0 + at)), len0, half0, low0);
        const __m512d dy =
            image(_mm512_sub_pd(xi1, _mm512_maskz_loadu_pd(live, x1 + at)), len1, half1, low1);
        __m512d r2 = _mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy));
        if constexpr (Dim == 3) {
          const __m512d dz =
              image(_mm512_sub_pd(xi2, _mm512_maskz_loadu_pd(live, x2 + at)), len2, half2, low2);
          r2 = _mm512_add_pd(r2, _mm512_mul_pd(dz, dz));
        }
        auto inside =
            static_cast<unsigned>(_mm512_mask_cmp_pd_mask(live, r2, r2_limit, _CMP_LT_OQ));
        if (me >= at && me < at + 8) inside &= ~(1u << (me - at));  // j != i
        const __m256i members = _mm256_maskz_loadu_epi32(live, member + at);
        // Compress in a register and store all 8 lanes (a masked compress-store is slow on some
        // cores); the lanes past the kept ones are overwritten by the next block or ignored.
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(dest + kept),
                            _mm256_maskz_compress_epi32(static_cast<__mmask8>(inside), members));
        kept += static_cast<std::size_t>(__builtin_popcount(inside));
      }
      used = kept;
#else
      if (keep.size() < count) keep.resize(count);
      std::uint8_t* inside = keep.data();
      const double* sx = sorted[0].data() + begin;
      const double* sy = sorted[1].data() + begin;
      const double* sz = sorted[Dim == 3 ? 2 : 0].data() + begin;
#pragma omp simd
      for (std::size_t k = 0; k < count; ++k) {
        const double dx = minimum_image(xi[0] - sx[k], length[0], half_length[0]);
        const double dy = minimum_image(xi[1] - sy[k], length[1], half_length[1]);
        double r2 = dx * dx + dy * dy;
        if constexpr (Dim == 3) {
          const double dz = minimum_image(xi[2] - sz[k], length[2], half_length[2]);
          r2 += dz * dz;
        }
        inside[k] = r2 < radius2 ? 0xFF : 0x00;
      }
      if (self >= begin && self < end) inside[self - begin] = 0x00;  // j != i
      used += append_selected(cell_members.data() + begin, inside, count, out + used);
#endif
    };
    // Cell k of axis d, k in [-cells, 2 cells) (a cell index plus an offset of at most one box):
    // a compare instead of an integer division, which the scan of every row would wait for.
    const auto wrap_cell = [&](int d, int k) {
      const int n = cells_[d];
      return k < 0 ? k + n : (k >= n ? k - n : k);
    };
    // The x cells of one row in visiting order, as runs of consecutive cells; with pruning only
    // those within `reach` (the chord's half-length) of x_i.
    const auto scan_row = [&](std::size_t row_start, double reach) {
      if (prune) {
        // The wanted x offsets are one interval around 0 (the slab distance grows with |offset|);
        // its cells in offset order are one run, or two where the interval wraps around the box.
        int lo = -kCellsPerRadius, hi = kCellsPerRadius;
        while (lo < 0 && slab_distance(0, lo) > reach) ++lo;
        while (hi > 0 && slab_distance(0, hi) > reach) --hi;
        const int first = wrap_cell(0, ci[0] + lo);
        const int end = first + (hi - lo) + 1;  // one past the last cell, unwrapped
        const std::size_t* const row = cell_start.data() + row_start;
        if (end <= cells_[0]) {
          scan(row[first], row[end]);
        } else {
          scan(row[first], row[cells_[0]]);
          scan(row[0], row[end - cells_[0]]);
        }
        return;
      }
      const std::vector<int>& xs = offsets[0];
      std::size_t k = 0;
      while (k < xs.size()) {
        const int first = wrap_cell(0, ci[0] + xs[k]);
        int last = first;
        while (k + 1 < xs.size() && wrap_cell(0, ci[0] + xs[k + 1]) == last + 1) {
          ++last;
          ++k;
        }
        ++k;
        scan(cell_start[row_start + static_cast<std::size_t>(first)],
             cell_start[row_start + static_cast<std::size_t>(last) + 1]);
      }
    };
    // The half-chord left for x once y (and z) are at least `transverse` away; < 0: none.
    const auto chord = [&](double transverse2) {
      const double left = radius2 - transverse2;
      return left < 0.0 ? -1.0 : std::sqrt(left) + margin;
    };
    if constexpr (Dim == 2) {
      for (int oy : offsets[1]) {
        const double dy = prune ? std::max(0.0, slab_distance(1, oy) - margin) : 0.0;
        const double reach = chord(dy * dy);
        if (reach < 0.0) continue;
        scan_row(static_cast<std::size_t>(wrap_cell(1, ci[1] + oy)) * cells_[0], reach);
      }
    } else {
      for (int oz : offsets[2]) {
        const double dz = prune ? std::max(0.0, slab_distance(2, oz) - margin) : 0.0;
        for (int oy : offsets[1]) {
          const double dy = prune ? std::max(0.0, slab_distance(1, oy) - margin) : 0.0;
          const double reach = chord(dy * dy + dz * dz);
          if (reach < 0.0) continue;
          scan_row((static_cast<std::size_t>(wrap_cell(2, ci[2] + oz)) * cells_[1] +
                    static_cast<std::size_t>(wrap_cell(1, ci[1] + oy))) *
                       cells_[0],
                   reach);
        }
      }
    }
    return used;
  };

  // A list still held by a reader (an analysis snapshot) is left intact: build into the spare
  // one if its reader has let it go, else into a new one.
  if (list_ && list_.use_count() > 1) {
    std::swap(list_, spare_);
    if (list_ && list_.use_count() > 1) list_.reset();
  }
  if (!list_) list_ = std::make_shared<NeighbourList>();
  NeighbourList& list = *list_;
  list.start.resize(listed);
  list.count.resize(listed);

  // One scan per particle, written straight into the list: each of `chunks` contiguous ranges of
  // particles fills its own region of list.indices, sized from the entries per particle of the
  // last build (or the number density at the first). A range that outgrows its region goes on in
  // a new region appended to the list. (Per-thread buffers copied into the list afterwards kept a
  // second array as large as the list, a third of the solver's memory.) A particle's entries do
  // not depend on the thread count or on where its region lies.
  double per_particle = entries_per_particle_;
  if (per_particle <= 0.0) {
    double volume = 1.0;
    for (int d = 0; d < Dim; ++d) volume *= box_.length[d];
    const double pi = std::acos(-1.0);
    const double ball = Dim == 2 ? pi * radius2 : 4.0 / 3.0 * pi * radius2 * radius;
    per_particle = static_cast<double>(n) / volume * ball;
  }
  const std::size_t room = max_candidates + kStoreSlack;  // what one scan may write
  struct Range {
    std::size_t first, next, end;  // particles: the range, and the next one to scan
    std::size_t at, limit;         // where the next entries go in list.indices, and the region end
    std::size_t written;           // entries of the range's particles so far
  };
  const auto chunks = static_cast<std::size_t>(std::max(1, omp_get_max_threads()));
  std::vector<Range> ranges(chunks);
  std::size_t top = 0;
  const auto place = [&](Range& r) {
    const auto wanted = static_cast<std::size_t>(kRegionMargin * per_particle *
                                                 static_cast<double>(r.end - r.next));
    r.at = top;
    r.limit = top + wanted + room;
    top = r.limit;
  };
  for (std::size_t t = 0; t < chunks; ++t) {
    const std::size_t first = listed * t / chunks, end = listed * (t + 1) / chunks;
    ranges[t] = {first, first, end, 0, 0, 0};
    place(ranges[t]);
  }
  const auto num_chunks = static_cast<std::ptrdiff_t>(chunks);
  for (bool first_round = true;; first_round = false) {
    // Grown with headroom, so that the next builds' few per cent more entries fit without a
    // reallocation (which maps and zeroes a new array, and is the next step's interaction list's
    // too); at the first round nothing is kept, so a reallocation need not copy.
    if (list.indices.size() < top) {
      const auto grown = static_cast<std::size_t>(kRegionMargin * static_cast<double>(top));
      if (first_round && list.indices.capacity() < top) list.indices.clear();
      list.indices.resize(list.indices.capacity() >= top ? top : grown);
    }
#pragma omp parallel for schedule(static, 1)
    for (std::ptrdiff_t t = 0; t < num_chunks; ++t) {
      Range& r = ranges[static_cast<std::size_t>(t)];
      std::vector<std::uint8_t> keep;
      for (; r.next < r.end && r.at + room <= r.limit; ++r.next) {
        const std::size_t found = visit(r.next, list.indices.data() + r.at, keep);
        list.start[r.next] = r.at;
        list.count[r.next] = static_cast<std::uint32_t>(found);
        r.at += found;
        r.written += found;
      }
    }
    // Ranges that outgrew their regions: new regions at the end, sized from what this build has
    // seen so far (at least a quarter more than before, so that the rounds end quickly).
    std::size_t done = 0, written = 0;
    bool pending = false;
    for (const Range& r : ranges) {
      done += r.next - r.first;
      written += r.written;
      pending = pending || r.next < r.end;
    }
    if (!pending) {
      list.entries = written;
      break;
    }
    const double seen = done == 0 ? 0.0 : static_cast<double>(written) / static_cast<double>(done);
    per_particle = std::max(seen, kRegrowth * per_particle);
    for (Range& r : ranges)
      if (r.next < r.end) place(r);
  }
  entries_per_particle_ =
      listed == 0 ? 0.0 : static_cast<double>(list.entries) / static_cast<double>(listed);

  for (int d = 0; d < Dim; ++d) reference_positions_[d].assign(positions.x[d], positions.x[d] + n);
  ++num_builds_;
}

void VerletNeighbourSearch::build(const PositionsView& positions,
                                  std::span<const std::uint32_t> cell_order, std::size_t listed) {
  if (positions.dimension != box_.dimension)
    throw std::invalid_argument("neighbour search: dimension of positions and box differ");
  if (positions.size >= (std::size_t{1} << 32))
    throw std::invalid_argument("neighbour search: more than 2^32 particles");
  if (!cell_order.empty() && cell_order.size() != positions.size)
    throw std::invalid_argument("neighbour search: cell order does not match the particles");
  listed = std::min(listed, positions.size);
  if (positions.dimension == 2)
    build_impl<2>(positions, cell_order, listed);
  else
    build_impl<3>(positions, cell_order, listed);
}

bool VerletNeighbourSearch::needs_rebuild(const PositionsView& positions,
                                          std::size_t checked) const {
  if (num_builds_ == 0 || reference_positions_[0].size() != positions.size) return true;
  const double limit2 = 0.25 * skin_ * skin_;
  const auto signed_n = static_cast<std::ptrdiff_t>(std::min(checked, positions.size));
  bool moved_too_far = false;
#pragma omp parallel for reduction(|| : moved_too_far)
  for (std::ptrdiff_t i = 0; i < signed_n; ++i) {
    double r2 = 0.0;
    for (int d = 0; d < positions.dimension; ++d) {
      const double dx = minimum_image(positions.x[d][i] - reference_positions_[d][i],
                                      box_.length[d], 0.5 * box_.length[d]);
      r2 += dx * dx;
    }
    moved_too_far = moved_too_far || r2 > limit2;
  }
  return moved_too_far;
}

}  // namespace sphles::sim
