// SPDX-License-Identifier: GPL-3.0-or-later
// Distributed energy spectrum: gridding where the particles live, FFTW's MPI r2c transform, shell
// sums added in rank order (par/spectrum.hpp).
#include "par/spectrum.hpp"

#include <fftw3-mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <mutex>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/fftw_r2c.hpp"
#include "analysis/grid.hpp"
#include "par/grid_share.hpp"
#include "par/halo.hpp"
#include "par/reduce.hpp"
#include "sim/reduction.hpp"

namespace sphles::par {

namespace {

/// This rank's part of FFTW's MPI distribution of an M^n r2c transform: the planes
/// [first, first + planes) of the slowest axis (z in 3D, y in 2D), and the complex values its
/// buffers need (at least one: a rank without planes still takes part in the plan). Allocates
/// nothing.
struct Slab {
  ptrdiff_t first = 0;
  ptrdiff_t planes = 0;
  std::size_t complex_count = 1;

  Slab(int dimension, int m, MPI_Comm comm) {
    static std::once_flag initialised;
    std::call_once(initialised, [] { fftw_mpi_init(); });
    std::array<ptrdiff_t, 3> complex_dims{m, m, m};
    complex_dims[static_cast<std::size_t>(dimension - 1)] = m / 2 + 1;
    const ptrdiff_t alloc =
        fftw_mpi_local_size(dimension, complex_dims.data(), comm, &planes, &first);
    complex_count = static_cast<std::size_t>(std::max<ptrdiff_t>(alloc, 1));
  }
};

/// FFTW's MPI r2c transform of an M^n grid over the ranks of a communicator: this rank's slab in
/// its padded real layout, and its part of the output.
class DistributedTransform {
 public:
  DistributedTransform(int dimension, int m, const Slab& slab, MPI_Comm comm)
      : dimension_(dimension),
        m_(m),
        first_plane_(slab.first),
        plan_(2 * slab.complex_count, slab.complex_count, [&](double* in, fftw_complex* out) {
          const std::array<ptrdiff_t, 3> real_dims{m, m, m};
          return fftw_mpi_plan_dft_r2c(dimension, real_dims.data(), in, out, comm, FFTW_ESTIMATE);
        }) {}

  /// Where node (i, j, k) of this rank's slab sits in the padded real input (x padded to
  /// 2 (M/2 + 1) values).
  std::size_t real_index(int i, int j, int k) const {
    const auto padded = static_cast<std::size_t>(2 * (m_ / 2 + 1));
    const std::size_t row = dimension_ == 3 ? static_cast<std::size_t>(k - first_plane_) *
                                                      static_cast<std::size_t>(m_) +
                                                  static_cast<std::size_t>(j)
                                            : static_cast<std::size_t>(j - first_plane_);
    return row * padded + static_cast<std::size_t>(i);
  }
  /// The real input, 2 (M/2 + 1) values per row of the slab.
  double* input() { return plan_.input(); }
  /// Transforms the input; collective. The output as (re, im) pairs.
  const double* execute() {
    plan_.execute();
    return reinterpret_cast<const double*>(plan_.output());
  }

 private:
  int dimension_;
  int m_;
  ptrdiff_t first_plane_;
  analysis::R2cPlan plan_;
};

}  // namespace

struct DistributedSpectrum::Impl {
  const Decomposition& d;
  analysis::Grid grid;
  /// This rank's nodes, and every rank's blocks and slabs (the planes [first, first + count) of
  /// the slow axis: z in 3D, y in 2D, FFTW's first, distributed dimension).
  analysis::NodeBlock block;
  std::vector<analysis::NodeBlock> blocks;
  std::vector<std::array<int, 2>> slabs;
  Slab slab;
  std::optional<DistributedTransform> transform;  // planned once the layout is known to fit
  /// Doubles sent to and received from each rank, and where they start.
  std::vector<int> send_count, send_offset, receive_count, receive_offset;
  /// Kept between calls: the particles with their halo, the messages.
  sim::ParticleArrays local;
  std::vector<double> send, received;

  Impl(const Decomposition& decomposition, int m)
      : d(decomposition), slab(decomposition.dimension(), m, decomposition.comm()) {
    const int dim = d.dimension();
    grid.dimension = dim;
    grid.points_per_side = m;
    grid.length = d.box().length[0];
    block = own_block(d, grid);
    const auto ranks = static_cast<std::size_t>(d.size());
    std::vector<int> layout(8 * ranks);  // per rank: block first[3], count[3]; slab first, count
    const int mine[8] = {block.first[0],
                         block.first[1],
                         block.first[2],
                         block.count[0],
                         block.count[1],
                         block.count[2],
                         static_cast<int>(slab.first),
                         static_cast<int>(slab.planes)};
    MPI_Allgather(mine, 8, MPI_INT, layout.data(), 8, MPI_INT, d.comm());
    blocks.resize(ranks);
    slabs.resize(ranks);
    for (std::size_t r = 0; r < ranks; ++r) {
      for (std::size_t a = 0; a < 3; ++a) {
        blocks[r].first[a] = layout[8 * r + a];
        blocks[r].count[a] = layout[8 * r + 3 + a];
      }
      slabs[r] = {layout[8 * r + 6], layout[8 * r + 7]};
    }
    // Rank r sends rank q, per component, the nodes of its planes inside q's slab: a block's
    // nodes of one plane are contiguous (x fastest), so that is one run, placed by q without
    // indices since q knows r's block.
    const auto me = static_cast<std::size_t>(d.rank());
    std::vector<std::size_t> sends(ranks), receives(ranks);
    for (std::size_t q = 0; q < ranks; ++q) {
      sends[q] = run(block, q) * static_cast<std::size_t>(dim);
      receives[q] = run(blocks[q], me) * static_cast<std::size_t>(dim);
    }
    // MPI counts and displacements are ints: every rank's messages in all must stay below 2^31
    // values.
    const auto limit = static_cast<std::size_t>(std::numeric_limits<int>::max());
    const auto total = [](const std::vector<std::size_t>& v) {
      return std::accumulate(v.begin(), v.end(), std::size_t{0});
    };
    if (!on_every_rank(d, total(sends) <= limit && total(receives) <= limit))
      throw std::invalid_argument(
          "distributed_energy_spectrum: " + std::to_string(m) + "^" + std::to_string(dim) +
          " nodes on " + std::to_string(ranks) +
          " ranks put more than 2^31 velocity values on one rank, more than MPI's int counts "
          "allow: use more ranks or fewer points per side");
    transform.emplace(dim, m, slab, d.comm());
    send_count.assign(sends.begin(), sends.end());
    receive_count.assign(receives.begin(), receives.end());
    send_offset.assign(ranks, 0);
    receive_offset.assign(ranks, 0);
    for (std::size_t q = 1; q < ranks; ++q) {
      send_offset[q] = send_offset[q - 1] + send_count[q - 1];
      receive_offset[q] = receive_offset[q - 1] + receive_count[q - 1];
    }
  }

  /// Planes [lo, hi) of block b inside the slab of rank q.
  std::array<int, 2> overlap(const analysis::NodeBlock& b, std::size_t q) const {
    const auto slow = static_cast<std::size_t>(grid.dimension - 1);
    const int lo = std::max(b.first[slow], slabs[q][0]);
    const int hi = std::min(b.first[slow] + b.count[slow], slabs[q][0] + slabs[q][1]);
    return {lo, std::max(lo, hi)};
  }
  std::size_t plane_size(const analysis::NodeBlock& b) const {
    return static_cast<std::size_t>(b.count[0]) *
           static_cast<std::size_t>(grid.dimension == 3 ? b.count[1] : 1);
  }
  /// Nodes of block b in the slab of rank q, per component.
  std::size_t run(const analysis::NodeBlock& b, std::size_t q) const {
    const std::array<int, 2> planes = overlap(b, q);
    return static_cast<std::size_t>(planes[1] - planes[0]) * plane_size(b);
  }

  analysis::EnergySpectrum compute(const sim::ParticleArrays& owned);
};

analysis::EnergySpectrum DistributedSpectrum::Impl::compute(const sim::ParticleArrays& owned) {
  const int dim = grid.dimension;
  const auto components = static_cast<std::size_t>(dim);
  const auto ranks = static_cast<std::size_t>(d.size());

  // This rank's particles (those that left its sub-box since the last migration moved to their
  // owners) and the halo around its sub-box, at their own positions in [0, L).
  local = owned;
  migrate(d, local);
  Halo::build(d, local, HaloPositions::Wrapped);
  std::uint64_t my_count = owned.size(), total = 0;
  MPI_Allreduce(&my_count, &total, 1, MPI_UINT64_T, MPI_SUM, d.comm());

  // Nearest particles of this rank's nodes, checked to be the whole set's.
  const analysis::NearestInBlock nearest =
      nearest_within_halo(d, grid, local, block, total, "distributed_energy_spectrum");

  // The spatial mean of the velocity over all nodes (SPEC §5), summed exactly.
  const std::size_t nodes = block.size();
  const std::uint32_t* nearest_particle = nearest.particle.data();
  std::array<const double*, 3> velocity{};
  for (std::size_t c = 0; c < components; ++c) velocity[c] = local.velocity[c].data();
  std::array<sim::ExactSum, 3> sums =
      sim::exact_sums<3>(nodes, [&](std::size_t n, std::array<double, 3>& t) {
        for (std::size_t c = 0; c < 3; ++c)
          t[c] = c < components ? velocity[c][nearest_particle[n]] : 0.0;
      });
  allreduce(d, std::span<sim::ExactSum>(sums.data(), components));
  std::array<double, 3> mean{};
  for (std::size_t c = 0; c < components; ++c)
    mean[c] = sums[c].value() / static_cast<double>(grid.size());

  // The fluctuation at the nodes, straight into the messages: to rank q, per component, the
  // run of this block's planes inside q's slab.
  send.resize(static_cast<std::size_t>(send_offset.back() + send_count.back()));
  for (std::size_t q = 0; q < ranks; ++q) {
    const std::size_t length = run(block, q);
    const auto slow = static_cast<std::size_t>(dim - 1);
    const std::size_t begin =
        static_cast<std::size_t>(overlap(block, q)[0] - block.first[slow]) * plane_size(block);
    for (std::size_t c = 0; c < components; ++c) {
      double* out = send.data() + send_offset[q] + c * length;
      const double* v = velocity[c];
      const double mean_c = mean[c];
      const auto signed_length = static_cast<std::ptrdiff_t>(length);
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t k = 0; k < signed_length; ++k)
        out[k] = v[nearest_particle[begin + static_cast<std::size_t>(k)]] - mean_c;
    }
  }
  received.resize(static_cast<std::size_t>(receive_offset.back() + receive_count.back()));
  MPI_Alltoallv(send.data(), send_count.data(), send_offset.data(), MPI_DOUBLE, received.data(),
                receive_count.data(), receive_offset.data(), MPI_DOUBLE, d.comm());

  // Per component: this rank's slab in FFTW's padded input, row by row of each sender's block
  // (the blocks tile the grid, so every row is written), the transform, and the shell sums of
  // the slab's modes.
  analysis::ShellSums shells = analysis::empty_shell_sums(dim, grid.points_per_side);
  const auto me = static_cast<std::size_t>(d.rank());
  for (std::size_t c = 0; c < components; ++c) {
    double* input = transform->input();
    for (std::size_t r = 0; r < ranks; ++r) {
      const analysis::NodeBlock& b = blocks[r];
      const std::array<int, 2> planes = overlap(b, me);
      const auto row = static_cast<std::size_t>(b.count[0]);
      const int rows = dim == 3 ? b.count[1] : 1;
      const double* from = received.data() + receive_offset[r] + c * run(b, me);
      for (int plane = planes[0]; plane < planes[1]; ++plane)
        for (int y = 0; y < rows; ++y, from += row) {
          const std::size_t at = dim == 3 ? transform->real_index(b.first[0], b.first[1] + y, plane)
                                          : transform->real_index(b.first[0], plane, 0);
          std::copy_n(from, row, input + at);
        }
    }
    const double* modes = transform->execute();
    if (slab.planes > 0)
      analysis::add_transform_planes(shells, modes, static_cast<int>(slab.first),
                                     static_cast<int>(slab.planes));
  }

  // Every rank's sums, added in rank order on every rank: the same bits everywhere.
  const std::size_t count = shells.modulus2.size();
  std::vector<double> mine(2 * count);
  std::copy(shells.modulus2.begin(), shells.modulus2.end(), mine.begin());
  std::copy(shells.k2_modulus2.begin(), shells.k2_modulus2.end(),
            mine.begin() + static_cast<std::ptrdiff_t>(count));
  std::vector<double> all(mine.size() * ranks);
  MPI_Allgather(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, all.data(),
                static_cast<int>(mine.size()), MPI_DOUBLE, d.comm());
  std::fill(shells.modulus2.begin(), shells.modulus2.end(), 0.0);
  std::fill(shells.k2_modulus2.begin(), shells.k2_modulus2.end(), 0.0);
  for (std::size_t r = 0; r < ranks; ++r) {
    const double* from = all.data() + r * mine.size();
    for (std::size_t p = 0; p < count; ++p) {
      shells.modulus2[p] += from[p];
      shells.k2_modulus2[p] += from[count + p];
    }
  }
  return analysis::spectrum_from_shell_sums(shells, grid.length);
}

DistributedSpectrum::DistributedSpectrum(const Decomposition& d, int points_per_side) {
  const sim::PeriodicBox& box = d.box();
  for (int a = 1; a < d.dimension(); ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0])
      throw std::invalid_argument("distributed_energy_spectrum: the box must be a cube");
  if (points_per_side < 2)
    throw std::invalid_argument("distributed_energy_spectrum: points_per_side must be >= 2");
  impl_ = std::make_unique<Impl>(d, points_per_side);
}

DistributedSpectrum::~DistributedSpectrum() = default;

analysis::EnergySpectrum DistributedSpectrum::compute(const sim::ParticleArrays& owned) {
  return impl_->compute(owned);
}

analysis::EnergySpectrum distributed_energy_spectrum(const Decomposition& d,
                                                     const sim::ParticleArrays& owned,
                                                     int points_per_side) {
  return DistributedSpectrum(d, points_per_side).compute(owned);
}

}  // namespace sphles::par
