// SPDX-License-Identifier: GPL-3.0-or-later
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

/// Entries a scan may write past the last one it keeps (whole-vector stores of 16 indices).
constexpr std::size_t kStoreSlack = 16;

/// Relative half-width of the band around the squared list radius inside which the
/// single-precision distance test defers to the double-precision one. The single-precision
/// distances are of coordinates within a few list radii of their home cell's corner, so their
/// squares are off by less than 10^-6 r^2: outside the band the two tests agree.
constexpr double kSinglePrecisionBand = 1e-4;

/// The box and list radius as the candidate tests need them.
struct ListGeometry {
  std::array<double, 3> length{}, half_length{};
  double radius2 = 0.0;
  float inner2 = 0.0f, outer2 = 0.0f;  // the band: surely inside below, surely outside above
};

/// The reference test: |x_i - x_j| under the minimum image below the list radius, in double
/// precision, summed over the axes in order (as the brute force of the tests does).
template <int Dim>
bool within_list_radius(const PositionsView& p, const ListGeometry& g, std::size_t i,
                        std::size_t j) {
  double r2 = 0.0;
  for (int d = 0; d < Dim; ++d) {
    const double dx = minimum_image(p.x[d][i] - p.x[d][j], g.length[d], g.half_length[d]);
    r2 += dx * dx;
  }
  return r2 < g.radius2;
}

/// The candidates of one home cell: the members of the cells around it in visiting order, with
/// their positions shifted to the periodic image nearest the home cell and taken relative to its
/// corner, in single precision (contiguous, so that the distance test is one long vector loop).
struct Candidates {
  static constexpr std::uint32_t kNone = 0xFFFFFFFFu;
  std::uint32_t cell = kNone;
  std::array<std::vector<float>, 3> x;
  std::vector<std::uint32_t> member;
  std::size_t count = 0;
  std::size_t home = 0;            // where the home cell's members begin
  std::vector<std::uint8_t> keep;  // the portable test's marks

  void reserve(std::size_t n, int dim) {
    if (member.size() >= n) return;
    for (int d = 0; d < dim; ++d) x[d].resize(n);
    member.resize(n);
    keep.resize(n);
  }
};

/// select_candidates' result without intrinsics: the single-precision test marks each
/// candidate inside, outside or in the band, the reference test decides the band's.
template <int Dim>
std::size_t select_candidates_portable(const Candidates& c, const std::array<float, 3>& xi,
                                       std::size_t self, const PositionsView& p,
                                       const ListGeometry& g, std::size_t i, std::uint32_t* out,
                                       std::uint8_t* keep) {
  const std::size_t count = c.count;
  const std::size_t me = c.home + self;
  const float* sx = c.x[0].data();
  const float* sy = c.x[1].data();
  const float* sz = c.x[Dim == 3 ? 2 : 0].data();
  const float inner2 = g.inner2, outer2 = g.outer2;
  // 0xFF: surely inside; 0x01: in the band; 0x00: surely outside.
#pragma omp simd
  for (std::size_t k = 0; k < count; ++k) {
    const float dx = xi[0] - sx[k];
    const float dy = xi[1] - sy[k];
    float r2 = dx * dx + dy * dy;
    if constexpr (Dim == 3) {
      const float dz = xi[2] - sz[k];
      r2 += dz * dz;
    }
    keep[k] = r2 < inner2 ? 0xFF : (r2 < outer2 ? 0x01 : 0x00);
  }
  for (std::size_t k = 0; k < count; ++k)
    if (keep[k] == 0x01) keep[k] = within_list_radius<Dim>(p, g, i, c.member[k]) ? 0xFF : 0x00;
  if (me < count) keep[me] = 0x00;  // j != i
  return append_selected(c.member.data(), keep, count, out);
}

/// Appends to `out` the candidates c.member[k] within the list radius of particle i (x_i at
/// `xi` in c's frame; at c.home + `self` in c, excluded), in order; returns how many. The
/// single-precision test decides outside the band, the reference test inside it, so the result
/// is the reference's. May write up to kStoreSlack entries past the last one kept.
template <int Dim>
[[gnu::noinline]] std::size_t select_candidates(const Candidates& c, const std::array<float, 3>& xi,
                                                std::size_t self, const PositionsView& p,
                                                const ListGeometry& g, std::size_t i,
                                                std::uint32_t* out, std::uint8_t* keep) {
#if defined(__AVX512F__)
  (void)keep;
  const std::size_t count = c.count;
  const std::size_t me = c.home + self;
  // 16 candidates per vector, the last block masked. Loop invariants in locals: the index store
  // may alias anything, so values behind references would be reloaded at every block.
  const float* const x0 = c.x[0].data();
  const float* const x1 = c.x[1].data();
  const float* const x2 = c.x[Dim == 3 ? 2 : 0].data();
  const std::uint32_t* const member = c.member.data();
  std::uint32_t* const dest = out;
  const __m512 xi0 = _mm512_set1_ps(xi[0]), xi1 = _mm512_set1_ps(xi[1]),
               xi2 = _mm512_set1_ps(xi[Dim == 3 ? 2 : 0]);
  const __m512 inner2 = _mm512_set1_ps(g.inner2), outer2 = _mm512_set1_ps(g.outer2);
  // Lanes in the band are kept provisionally and decided after the loop (a call inside it would
  // make the compiler keep the loop's state in memory): the block's first output position, its
  // kept lanes and its band lanes, for at most kMaxBands blocks (more: the whole scan again with
  // every band decided in place, which the band's width makes vanishingly rare).
  constexpr int kMaxBands = 16;
  struct Band {
    std::size_t at;
    unsigned kept, band;
  } bands[kMaxBands];
  int num_bands = 0;
  std::size_t kept = 0;
  for (std::size_t k = 0; k < count; k += 16) {
    const std::size_t left = count - k;
    auto live = left >= 16 ? 0xFFFFu : (1u << left) - 1u;
    if (me >= k && me < k + 16) live &= ~(1u << (me - k));  // j != i
    const auto lanes = static_cast<__mmask16>(live);
    const __m512 dx = _mm512_sub_ps(xi0, _mm512_maskz_loadu_ps(lanes, x0 + k));
    const __m512 dy = _mm512_sub_ps(xi1, _mm512_maskz_loadu_ps(lanes, x1 + k));
    __m512 r2 = _mm512_add_ps(_mm512_mul_ps(dx, dx), _mm512_mul_ps(dy, dy));
    if constexpr (Dim == 3) {
      const __m512 dz = _mm512_sub_ps(xi2, _mm512_maskz_loadu_ps(lanes, x2 + k));
      r2 = _mm512_add_ps(r2, _mm512_mul_ps(dz, dz));
    }
    const auto maybe =
        static_cast<unsigned>(_mm512_mask_cmp_ps_mask(lanes, r2, outer2, _CMP_LT_OQ));
    const auto band =
        maybe & ~static_cast<unsigned>(_mm512_mask_cmp_ps_mask(lanes, r2, inner2, _CMP_LT_OQ));
    if (band != 0) [[unlikely]] {
      if (num_bands < kMaxBands) bands[num_bands] = {kept, maybe, band};
      ++num_bands;
    }
    // Compress in a register and store all 16 lanes (a masked compress-store is slow on some
    // cores); the lanes past the kept ones are overwritten by the next block or ignored.
    _mm512_storeu_si512(dest + kept,
                        _mm512_maskz_compress_epi32(static_cast<__mmask16>(maybe),
                                                    _mm512_maskz_loadu_epi32(lanes, member + k)));
    kept += static_cast<std::size_t>(__builtin_popcount(maybe));
  }
  if (num_bands > kMaxBands)
    return select_candidates_portable<Dim>(c, xi, self, p, g, i, out, keep);
  // Decide the band's lanes, the last first, so that a removal moves no pending entry.
  for (int b = num_bands - 1; b >= 0; --b) {
    for (unsigned band = bands[b].band; band != 0;) {
      const int lane = 31 - __builtin_clz(band);
      band &= ~(1u << lane);
      const std::size_t at =
          bands[b].at +
          static_cast<std::size_t>(__builtin_popcount(bands[b].kept & ((1u << lane) - 1u)));
      if (!within_list_radius<Dim>(p, g, i, dest[at])) {
        std::copy(dest + at + 1, dest + kept, dest + at);
        --kept;
      }
    }
  }
  return kept;
#else
  return select_candidates_portable<Dim>(c, xi, self, p, g, i, out, keep);
#endif
}

/// When a region overflows, the estimate grows at least by this factor for the next round.
constexpr double kRegrowth = 1.25;

/// The box and list radius as the candidate tests take them; the band of kSinglePrecisionBand
/// around the squared radius.
template <int Dim>
ListGeometry list_geometry(const PeriodicBox& box, double radius) {
  ListGeometry geometry;
  for (int d = 0; d < Dim; ++d) {
    geometry.length[d] = box.length[d];
    geometry.half_length[d] = 0.5 * box.length[d];
  }
  const double radius2 = radius * radius;
  geometry.radius2 = radius2;
  geometry.inner2 = static_cast<float>(radius2 * (1.0 - kSinglePrecisionBand));
  geometry.outer2 = static_cast<float>(radius2 * (1.0 + kSinglePrecisionBand));
  return geometry;
}

/// Distinct cell offsets per direction: -reach..reach, reduced modulo the number of cells when
/// a direction has fewer than 2 reach + 1 cells, so that no cell is visited twice.
template <int Dim>
std::array<std::vector<int>, 3> stencil_offsets(const std::array<int, 3>& cells, int reach) {
  std::array<std::vector<int>, 3> offsets;
  for (int d = 0; d < Dim; ++d) {
    if (cells[d] >= 2 * reach + 1) {
      for (int o = -reach; o <= reach; ++o) offsets[d].push_back(o);
    } else {
      for (int o = 0; o < cells[d]; ++o) offsets[d].push_back(o);
    }
  }
  return offsets;
}

/// Per chunk of particles: the candidates of the last home cell and its origin.
struct Scratch {
  Candidates candidates;
  std::array<double, 3> origin{};
};

/// One build's particles in cells as the scans read them (VerletNeighbourSearch::bin_particles:
/// each particle's cell, the members cell by cell and where each cell begins, the positions in
/// that order and each particle's place in it), and the scans for one particle's neighbours.
template <int Dim>
struct CellScan {
  static constexpr int kReach = VerletNeighbourSearch::kCellsPerRadius;
  const PositionsView& positions;
  ListGeometry geometry;
  std::array<int, 3> cells;
  std::array<double, 3> cell_size;
  std::array<std::vector<int>, 3> offsets;
  const std::vector<std::uint32_t>& cell;
  const std::vector<std::size_t>& cell_start;
  const std::vector<std::uint32_t>& cell_members;
  const std::array<std::vector<double>, 3>& sorted;
  const std::vector<std::uint32_t>& rank;
  // With at least 2 reach + 1 cells along every axis, each cell of the stencil is one periodic
  // image of the home cell's surroundings, so the candidates of all particles of a home cell are
  // gathered once (Candidates) and tested in one long single-precision vector loop. Otherwise
  // (boxes of a few cells), each particle's candidates are tested in place in double precision.
  bool gathered;

  /// The most candidates one particle has: the fullest cell's members in every stencil cell.
  std::size_t max_candidates() const {
    std::size_t max_occupancy = 0;
    for (std::size_t c = 0; c + 1 < cell_start.size(); ++c)
      max_occupancy = std::max(max_occupancy, cell_start[c + 1] - cell_start[c]);
    std::size_t max_candidates = max_occupancy;
    for (int d = 0; d < Dim; ++d) max_candidates *= offsets[d].size();
    return max_candidates;
  }

  // Cell k of axis d, k in [-cells, 2 cells) (a cell index plus an offset of at most one box),
  // and the shift to the periodic image of its members nearest the unwrapped cell k.
  int wrap_cell(int d, int k) const {
    const int n = cells[d];
    return k < 0 ? k + n : (k >= n ? k - n : k);
  }
  double image_shift(int d, int k) const {
    return k < 0 ? -geometry.length[d] : (k >= cells[d] ? geometry.length[d] : 0.0);
  }
  std::array<int, 3> cell_coordinates(std::uint32_t c) const {
    std::array<int, 3> cc{0, 0, 0};
    for (int d = 0; d < Dim; ++d) {
      cc[d] = static_cast<int>(c % static_cast<std::uint32_t>(cells[d]));
      c /= static_cast<std::uint32_t>(cells[d]);
    }
    return cc;
  }

  /// Appends the neighbours of particle i to `out` and returns their number: z, y, x cell
  /// offsets ascending, the members of a cell in the order of cell_members.
  std::size_t neighbours(std::size_t i, std::uint32_t* out, Scratch& scratch) const {
    if (!gathered) return scan_in_place(i, out, scratch.candidates.keep);
    const std::uint32_t home = cell[i];
    const std::size_t self = rank[i] - cell_start[home];
    Candidates& c = scratch.candidates;
    if (c.cell != home) gather(home, c, scratch.origin);
    std::array<float, 3> xi{0.0f, 0.0f, 0.0f};
    for (int d = 0; d < Dim; ++d) xi[d] = static_cast<float>(positions.x[d][i] - scratch.origin[d]);
    return select_candidates<Dim>(c, xi, self, positions, geometry, i, out, c.keep.data());
  }

  /// Gathers the members of the cells around `home` in visiting order (z, y, x offsets
  /// ascending; a cell's members in the order of cell_members) into c, relative to the home
  /// cell's corner `origin`.
  void gather(std::uint32_t home, Candidates& c, std::array<double, 3>& origin) const {
    const std::array<int, 3> hc = cell_coordinates(home);
    for (int d = 0; d < Dim; ++d) origin[d] = hc[d] * cell_size[d];
    c.cell = home;
    c.count = 0;
    const std::size_t home_begin = cell_start[home];
    std::array<double, 3> shift{0.0, 0.0, 0.0};
    // Members begin..end of sorted, with the shift of their image along x.
    const auto append = [&](std::size_t begin, std::size_t end, double shift_x) {
      shift[0] = shift_x;
      for (int d = 0; d < Dim; ++d) {
        float* const to = c.x[d].data() + c.count;
        const double* const from = sorted[d].data();
        const double offset = shift[d] - origin[d];
        for (std::size_t k = begin; k < end; ++k)
          to[k - begin] = static_cast<float>(from[k] + offset);
      }
      std::copy(cell_members.data() + begin, cell_members.data() + end, c.member.data() + c.count);
      if (home_begin >= begin && home_begin < end) c.home = c.count + (home_begin - begin);
      c.count += end - begin;
    };
    // The x cells of one row: one run, or two where the offsets wrap around the box.
    const auto row = [&](std::size_t row_start) {
      const std::size_t* const at = cell_start.data() + row_start;
      const int first = hc[0] - kReach, last = hc[0] + kReach;
      const int n = cells[0];
      if (first < 0) {
        append(at[first + n], at[n], -geometry.length[0]);
        append(at[0], at[last + 1], 0.0);
      } else if (last >= n) {
        append(at[first], at[n], 0.0);
        append(at[0], at[last + 1 - n], geometry.length[0]);
      } else {
        append(at[first], at[last + 1], 0.0);
      }
    };
    if constexpr (Dim == 2) {
      for (int oy = -kReach; oy <= kReach; ++oy) {
        shift[1] = image_shift(1, hc[1] + oy);
        row(static_cast<std::size_t>(wrap_cell(1, hc[1] + oy)) * cells[0]);
      }
    } else {
      for (int oz = -kReach; oz <= kReach; ++oz) {
        const std::size_t plane = static_cast<std::size_t>(wrap_cell(2, hc[2] + oz)) * cells[1];
        for (int oy = -kReach; oy <= kReach; ++oy) {
          shift[2] = image_shift(2, hc[2] + oz);
          shift[1] = image_shift(1, hc[1] + oy);
          row((plane + static_cast<std::size_t>(wrap_cell(1, hc[1] + oy))) * cells[0]);
        }
      }
    }
  }

  /// neighbours() in a box of a few cells: the members of each stencil cell tested in place by
  /// the reference test, `keep` its marks.
  std::size_t scan_in_place(std::size_t i, std::uint32_t* out,
                            std::vector<std::uint8_t>& keep) const {
    const std::array<int, 3> ci = cell_coordinates(cell[i]);
    std::size_t used = 0;
    const auto scan = [&](std::size_t begin, std::size_t end) {
      const std::size_t count = end - begin;
      const std::uint32_t* const js = cell_members.data() + begin;
#pragma omp simd
      for (std::size_t k = 0; k < count; ++k)
        keep[k] = within_list_radius<Dim>(positions, geometry, i, js[k]) ? 0xFF : 0x00;
      if (rank[i] >= begin && rank[i] < end) keep[rank[i] - begin] = 0x00;  // j != i
      used += append_selected(js, keep.data(), count, out + used);
    };
    // The x cells of a row in visiting order, as runs of consecutive cells.
    const auto scan_row = [&](std::size_t row_start) {
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
    if constexpr (Dim == 2) {
      for (int oy : offsets[1])
        scan_row(static_cast<std::size_t>(wrap_cell(1, ci[1] + oy)) * cells[0]);
    } else {
      for (int oz : offsets[2])
        for (int oy : offsets[1])
          scan_row((static_cast<std::size_t>(wrap_cell(2, ci[2] + oz)) * cells[1] +
                    static_cast<std::size_t>(wrap_cell(1, ci[1] + oy))) *
                   cells[0]);
    }
    return used;
  }
};

/// Writes the row of each particle of `visit_order` into `list` (start, count, indices) and
/// list.entries; `room` is what one scan may write, `per_particle` the entries expected per
/// particle. One scan per particle, written straight into the list: each of `chunks` contiguous
/// ranges of the order fills its own region of list.indices, sized from the entries per particle
/// of the last build (or the number density at the first). A range that outgrows its region goes
/// on in a new region appended to the list. (Per-thread buffers copied into the list afterwards
/// kept a second array as large as the list, a third of the solver's memory.) A particle's
/// entries do not depend on the thread count or on where its region lies.
template <int Dim>
void write_rows(NeighbourList& list, std::span<const std::uint32_t> visit_order,
                double per_particle, std::size_t room, const CellScan<Dim>& scan) {
  const std::size_t listed = visit_order.size();
  struct Range {
    std::size_t first, next, end;  // places in visit_order: the range, and the next one to scan
    std::size_t at, limit;         // where the next entries go in list.indices, and the region end
    std::size_t written;           // entries of the range's particles so far
  };
  const auto chunks = static_cast<std::size_t>(std::max(1, omp_get_max_threads()));
  std::vector<Range> ranges(chunks);
  std::size_t top = 0;
  const auto place = [&](Range& r) {
    const auto wanted = static_cast<std::size_t>(
        VerletNeighbourSearch::kRegionMargin * per_particle * static_cast<double>(r.end - r.next));
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
      const auto grown =
          static_cast<std::size_t>(VerletNeighbourSearch::kRegionMargin * static_cast<double>(top));
      if (first_round && list.indices.capacity() < top) list.indices.clear();
      list.indices.resize(list.indices.capacity() >= top ? top : grown);
    }
#pragma omp parallel for schedule(static, 1)
    for (std::ptrdiff_t t = 0; t < num_chunks; ++t) {
      Range& r = ranges[static_cast<std::size_t>(t)];
      Scratch scratch;
      scratch.candidates.reserve(room, Dim);
      for (; r.next < r.end && r.at + room <= r.limit; ++r.next) {
        const std::uint32_t i = visit_order[r.next];
        const std::size_t found = scan.neighbours(i, list.indices.data() + r.at, scratch);
        list.start[i] = r.at;
        list.count[i] = static_cast<std::uint32_t>(found);
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
      return;
    }
    const double seen = done == 0 ? 0.0 : static_cast<double>(written) / static_cast<double>(done);
    per_particle = std::max(seen, kRegrowth * per_particle);
    for (Range& r : ranges)
      if (r.next < r.end) place(r);
  }
}

}  // namespace

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

NeighbourList& VerletNeighbourSearch::list_to_build(std::size_t listed) {
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
  return list;
}

template <int Dim>
void VerletNeighbourSearch::build_impl(const PositionsView& positions,
                                       std::span<const std::uint32_t> cell_order,
                                       std::size_t listed) {
  const std::size_t n = positions.size;
  // Into the scratch kept between builds (BuildScratch): fresh vectors of this size would be
  // mapped and zeroed page by page at every build.
  bin_particles<Dim>(positions, cell_order);
  std::array<double, 3> cell_size{};
  bool gathered = true;
  for (int d = 0; d < Dim; ++d) {
    cell_size[d] = box_.length[d] / cells_[d];
    gathered = gathered && cells_[d] >= 2 * kCellsPerRadius + 1;
  }
  const CellScan<Dim> scan{positions,
                           list_geometry<Dim>(box_, list_radius()),
                           cells_,
                           cell_size,
                           stencil_offsets<Dim>(cells_, kCellsPerRadius),
                           scratch_.cell,
                           scratch_.cell_start,
                           scratch_.cell_members,
                           scratch_.sorted,
                           scratch_.rank,
                           gathered};
  NeighbourList& list = list_to_build(listed);

  // The listed particles cell by cell (in the order of cell_members), so that the candidates of
  // a home cell are gathered once for all its particles whatever order the arrays are in (the
  // solver's are in cell order already; a set-up's lattice or a gathered snapshot are not).
  std::vector<std::uint32_t>& visit_order = scratch_.visit_order;
  visit_order.clear();
  visit_order.reserve(listed);
  for (const std::uint32_t i : scratch_.cell_members)
    if (i < listed) visit_order.push_back(i);

  // The entries per particle of the last build, or at the first the number density times the
  // volume of the list radius's ball.
  double per_particle = entries_per_particle_;
  if (per_particle <= 0.0) {
    double volume = 1.0;
    for (int d = 0; d < Dim; ++d) volume *= box_.length[d];
    const double pi = std::acos(-1.0);
    const double radius2 = list_radius() * list_radius();
    const double ball = Dim == 2 ? pi * radius2 : 4.0 / 3.0 * pi * radius2 * list_radius();
    per_particle = static_cast<double>(n) / volume * ball;
  }
  write_rows<Dim>(list, visit_order, per_particle, scan.max_candidates() + kStoreSlack, scan);
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
