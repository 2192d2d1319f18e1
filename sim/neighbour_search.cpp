#include "sim/neighbour_search.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace sphles::sim {

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

std::vector<std::uint32_t> VerletNeighbourSearch::cell_of(const PositionsView& positions) const {
  std::vector<std::uint32_t> cell(positions.size);
  for (std::size_t i = 0; i < positions.size; ++i) {
    std::uint32_t c = 0;
    for (int d = positions.dimension - 1; d >= 0; --d) {
      int k = static_cast<int>(positions.x[d][i] * inv_cell_size_[d]);
      k = std::clamp(k, 0, cells_[d] - 1);
      c = c * static_cast<std::uint32_t>(cells_[d]) + static_cast<std::uint32_t>(k);
    }
    cell[i] = c;
  }
  return cell;
}

std::vector<std::uint32_t> VerletNeighbourSearch::locality_order(
    const PositionsView& positions) const {
  const std::vector<std::uint32_t> cell = cell_of(positions);
  std::vector<std::uint32_t> order(positions.size);
  for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return cell[a] < cell[b]; });
  return order;
}

template <int Dim>
void VerletNeighbourSearch::build_impl(const PositionsView& positions) {
  const std::size_t n = positions.size;
  const std::vector<std::uint32_t> cell = cell_of(positions);
  std::size_t num_cells = 1;
  for (int d = 0; d < Dim; ++d) num_cells *= static_cast<std::size_t>(cells_[d]);

  // Counting sort of particle indices by cell (stable: ascending index within a cell).
  std::vector<std::size_t> cell_start(num_cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++cell_start[cell[i] + 1];
  for (std::size_t c = 0; c < num_cells; ++c) cell_start[c + 1] += cell_start[c];
  std::vector<std::uint32_t> cell_members(n);
  {
    std::vector<std::size_t> fill(cell_start.begin(), cell_start.end() - 1);
    for (std::size_t i = 0; i < n; ++i)
      cell_members[fill[cell[i]]++] = static_cast<std::uint32_t>(i);
  }

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

  // Visits every candidate j of particle i in a fixed order and calls emit(j, inside) for each,
  // so that the caller can append without a data-dependent branch.
  const auto visit = [&](std::size_t i, auto&& emit) {
    std::array<int, 3> ci{0, 0, 0};
    {
      std::uint32_t c = cell[i];
      for (int d = 0; d < Dim; ++d) {
        ci[d] = static_cast<int>(c % static_cast<std::uint32_t>(cells_[d]));
        c /= static_cast<std::uint32_t>(cells_[d]);
      }
    }
    double xi[Dim];
    for (int d = 0; d < Dim; ++d) xi[d] = positions.x[d][i];
    const auto scan_cell = [&](std::size_t c) {
      for (std::size_t k = cell_start[c]; k < cell_start[c + 1]; ++k) {
        const std::uint32_t j = cell_members[k];
        double r2 = 0.0;
        for (int d = 0; d < Dim; ++d) {
          const double dx = minimum_image(xi[d] - positions.x[d][j], length[d], half_length[d]);
          r2 += dx * dx;
        }
        emit(j, r2 < radius2 && j != i);
      }
    };
    const auto wrap_cell = [&](int d, int k) { return (k + cells_[d]) % cells_[d]; };
    if constexpr (Dim == 2) {
      for (int oy : offsets[1])
        for (int ox : offsets[0])
          scan_cell(static_cast<std::size_t>(wrap_cell(1, ci[1] + oy)) * cells_[0] +
                    static_cast<std::size_t>(wrap_cell(0, ci[0] + ox)));
    } else {
      for (int oz : offsets[2])
        for (int oy : offsets[1])
          for (int ox : offsets[0])
            scan_cell((static_cast<std::size_t>(wrap_cell(2, ci[2] + oz)) * cells_[1] +
                       static_cast<std::size_t>(wrap_cell(1, ci[1] + oy))) *
                          cells_[0] +
                      static_cast<std::size_t>(wrap_cell(0, ci[0] + ox)));
    }
  };

  // One scan per particle: each thread fills a buffer for a contiguous range of particles, the
  // buffers are then placed at their offsets. Per-particle content and order do not depend on
  // the thread count.
  // A list still held by a reader (an analysis snapshot) is left intact: build into a new one.
  if (!list_ || list_.use_count() > 1) list_ = std::make_shared<NeighbourList>();
  NeighbourList& list = *list_;
  list.offsets.assign(n + 1, 0);
  std::vector<std::vector<std::uint32_t>> buffers(static_cast<std::size_t>(omp_get_max_threads()));
  std::vector<std::size_t> range_begin(buffers.size() + 1, n);
#pragma omp parallel
  {
    const auto thread = static_cast<std::size_t>(omp_get_thread_num());
    const auto threads = static_cast<std::size_t>(omp_get_num_threads());
    const std::size_t begin = n * thread / threads, end = n * (thread + 1) / threads;
    range_begin[thread] = begin;
    // `buffer` is kept at least max_candidates longer than the entries in use, so candidates are
    // written unconditionally and kept by advancing `used` by 0 or 1.
    std::vector<std::uint32_t>& buffer = buffers[thread];
    std::size_t used = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if (buffer.size() < used + max_candidates) buffer.resize(2 * (used + max_candidates));
      std::uint32_t* out = buffer.data();
      const std::size_t before = used;
      visit(i, [&](std::uint32_t j, bool inside) {
        out[used] = j;
        used += inside;
      });
      list.offsets[i + 1] = used - before;
    }
    buffer.resize(used);
  }
  for (std::size_t i = 0; i < n; ++i) list.offsets[i + 1] += list.offsets[i];
  list.indices.resize(list.offsets[n]);
  const auto num_buffers = static_cast<std::ptrdiff_t>(buffers.size());
#pragma omp parallel for schedule(static, 1)
  for (std::ptrdiff_t t = 0; t < num_buffers; ++t) {
    const std::vector<std::uint32_t>& buffer = buffers[static_cast<std::size_t>(t)];
    if (!buffer.empty())
      std::copy(buffer.begin(), buffer.end(),
                list.indices.begin() + static_cast<std::ptrdiff_t>(
                                           list.offsets[range_begin[static_cast<std::size_t>(t)]]));
  }

  for (int d = 0; d < Dim; ++d) reference_positions_[d].assign(positions.x[d], positions.x[d] + n);
  ++num_builds_;
}

void VerletNeighbourSearch::build(const PositionsView& positions) {
  if (positions.dimension != box_.dimension)
    throw std::invalid_argument("neighbour search: dimension of positions and box differ");
  if (positions.size >= (std::size_t{1} << 32))
    throw std::invalid_argument("neighbour search: more than 2^32 particles");
  if (positions.dimension == 2)
    build_impl<2>(positions);
  else
    build_impl<3>(positions);
}

bool VerletNeighbourSearch::needs_rebuild(const PositionsView& positions) const {
  if (num_builds_ == 0 || reference_positions_[0].size() != positions.size) return true;
  const double limit2 = 0.25 * skin_ * skin_;
  const auto signed_n = static_cast<std::ptrdiff_t>(positions.size);
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
