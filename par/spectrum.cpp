// Distributed energy spectrum (issue 19): gridding where the particles live, FFTW's MPI r2c
// transform, shell sums added in rank order (par/spectrum.hpp).
#include "par/spectrum.hpp"

#include <fftw3-mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/grid.hpp"
#include "par/halo.hpp"
#include "par/reduce.hpp"
#include "sim/reduction.hpp"

namespace sphles::par {

namespace {

/// The nodes i h (h = L/M) whose sub-box coordinate along `axis` is this rank's: a contiguous
/// range, since the sub-box bounds increase with the coordinate.
void own_nodes(const Decomposition& d, int axis, int m, double spacing, int& first, int& count) {
  const int mine = d.coords()[static_cast<std::size_t>(axis)];
  first = m;
  count = 0;
  for (int i = 0; i < m; ++i)
    if (d.coordinate_of(axis, i * spacing) == mine) {
      first = std::min(first, i);
      ++count;
    }
  if (count == 0) first = 0;
}

/// FFTW's MPI r2c transform of an M^n grid over the ranks of a communicator: this rank's slab of
/// the slowest axis (z in 3D, y in 2D) in its padded real layout, and its part of the output.
class DistributedTransform {
 public:
  DistributedTransform(int dimension, int m, MPI_Comm comm) : dimension_(dimension), m_(m) {
    static std::once_flag initialised;
    std::call_once(initialised, [] { fftw_mpi_init(); });
    std::array<ptrdiff_t, 3> complex_dims{m, m, m};
    complex_dims[static_cast<std::size_t>(dimension - 1)] = m / 2 + 1;
    const std::array<ptrdiff_t, 3> real_dims{m, m, m};
    const std::unique_lock<std::mutex> lock = analysis::fftw_planner_lock();
    const ptrdiff_t alloc =
        fftw_mpi_local_size(dimension, complex_dims.data(), comm, &local_planes_, &first_plane_);
    // An alloc of at least one element: a rank without planes still takes part in the plan.
    const auto complex_count = static_cast<std::size_t>(std::max<ptrdiff_t>(alloc, 1));
    input_ = fftw_alloc_real(2 * complex_count);
    output_ = fftw_alloc_complex(complex_count);
    if (input_ != nullptr && output_ != nullptr)
      plan_ =
          fftw_mpi_plan_dft_r2c(dimension, real_dims.data(), input_, output_, comm, FFTW_ESTIMATE);
    if (plan_ == nullptr) {
      release();
      throw std::bad_alloc();
    }
    real_count_ = 2 * complex_count;
  }
  DistributedTransform(const DistributedTransform&) = delete;
  DistributedTransform& operator=(const DistributedTransform&) = delete;
  ~DistributedTransform() {
    const std::unique_lock<std::mutex> lock = analysis::fftw_planner_lock();
    release();
  }

  int first_plane() const { return static_cast<int>(first_plane_); }
  int planes() const { return static_cast<int>(local_planes_); }
  std::size_t real_count() const { return real_count_; }
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
  /// Transforms `real` (real_count() values in the padded layout); collective.
  const double* transform(const std::vector<double>& real) {
    std::copy(real.begin(), real.end(), input_);
    fftw_execute(plan_);
    return reinterpret_cast<const double*>(output_);
  }

 private:
  void release() {  // caller holds the planner lock
    if (plan_ != nullptr) fftw_destroy_plan(plan_);
    fftw_free(output_);
    fftw_free(input_);
    plan_ = nullptr;
    output_ = nullptr;
    input_ = nullptr;
  }

  int dimension_;
  int m_;
  ptrdiff_t local_planes_ = 0;
  ptrdiff_t first_plane_ = 0;
  std::size_t real_count_ = 0;
  double* input_ = nullptr;
  fftw_complex* output_ = nullptr;
  fftw_plan plan_ = nullptr;
};

/// True on every rank when `ok` holds on every rank of d.
bool on_every_rank(const Decomposition& d, bool ok) {
  int mine = ok ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, d.comm());
  return all == 1;
}

}  // namespace

analysis::EnergySpectrum distributed_energy_spectrum(const Decomposition& d,
                                                     const sim::ParticleArrays& owned,
                                                     int points_per_side) {
  const int dim = d.dimension();
  const int m = points_per_side;
  const sim::PeriodicBox& box = d.box();
  for (int a = 1; a < dim; ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0])
      throw std::invalid_argument("distributed_energy_spectrum: the box must be a cube");
  if (m < 2)
    throw std::invalid_argument("distributed_energy_spectrum: points_per_side must be >= 2");
  analysis::Grid grid;
  grid.dimension = dim;
  grid.points_per_side = m;
  grid.length = box.length[0];
  const double spacing = grid.spacing();

  // This rank's particles (those that left its sub-box since the last migration moved to their
  // owners) and the halo around its sub-box, at their own positions in [0, L).
  sim::ParticleArrays local = owned;
  migrate(d, local);
  Halo::build(d, local, HaloPositions::Wrapped);
  std::uint64_t my_count = owned.size(), total = 0;
  MPI_Allreduce(&my_count, &total, 1, MPI_UINT64_T, MPI_SUM, d.comm());

  // Nearest particles of this rank's nodes; a cell list of the whole set's density.
  analysis::NodeBlock block;
  for (int a = 0; a < dim; ++a) {
    const auto k = static_cast<std::size_t>(a);
    own_nodes(d, a, m, spacing, block.first[k], block.count[k]);
  }
  analysis::NearestInBlock nearest;
  bool found = true;
  if (block.size() > 0 && local.size() > 0) {
    const double per_side = std::pow(static_cast<double>(total), 1.0 / dim);
    nearest = analysis::nearest_particles_in_block(grid, local, block,
                                                   static_cast<int>(std::lround(per_side)));
  } else if (block.size() > 0) {
    found = false;  // nodes but no particle near them
  }
  // A particle left out of `local` is at least the halo width from every node of the sub-box;
  // along an axis this rank is alone on, none is left out. The margin covers the ties' window.
  bool alone = true;
  for (int a = 0; a < dim; ++a) alone = alone && d.dims()[static_cast<std::size_t>(a)] == 1;
  const double halo2 = d.halo_width() * d.halo_width();
  found = found && (alone || nearest.max_distance2 * (1.0 + 1e-9) < halo2);
  if (!on_every_rank(d, found))
    throw std::invalid_argument(
        "distributed_energy_spectrum: a grid node's nearest particle lies further than the halo "
        "width (" +
        std::to_string(d.halo_width()) +
        " m) on some rank, so a particle of another rank may be nearer: the particles leave a "
        "void wider than the halo");

  // Velocities at the nodes, the spatial mean over all nodes removed (SPEC §5), summed exactly.
  const std::size_t nodes = block.size();
  std::array<std::vector<double>, 3> u;
  std::array<sim::ExactSum, 3> sums;
  for (int c = 0; c < dim; ++c) {
    const auto k = static_cast<std::size_t>(c);
    u[k].resize(nodes);
    for (std::size_t n = 0; n < nodes; ++n) {
      u[k][n] = local.velocity[k][nearest.particle[n]];
      sums[k].add(u[k][n]);
    }
  }
  allreduce(d, std::span<sim::ExactSum>(sums.data(), static_cast<std::size_t>(dim)));
  const double grid_nodes = static_cast<double>(grid.size());
  for (int c = 0; c < dim; ++c) {
    const auto k = static_cast<std::size_t>(c);
    const double mean = sums[k].value() / grid_nodes;
    for (double& value : u[k]) value -= mean;
  }

  // The nodes to the ranks whose slabs hold them: records (node index, u_0 .. u_{n-1}), in
  // rank order, each rank's in this rank's node order.
  DistributedTransform transform(dim, m, d.comm());
  const int ranks = d.size();
  std::vector<int> slab_first(static_cast<std::size_t>(ranks));
  std::vector<int> slab_count(static_cast<std::size_t>(ranks));
  const int my_first = transform.first_plane(), my_planes = transform.planes();
  MPI_Allgather(&my_first, 1, MPI_INT, slab_first.data(), 1, MPI_INT, d.comm());
  MPI_Allgather(&my_planes, 1, MPI_INT, slab_count.data(), 1, MPI_INT, d.comm());
  const int slow_axis = dim - 1;  // z (3D) or y (2D): FFTW's first, distributed dimension
  const auto owner_of_plane = [&](int plane) {
    for (int r = 0; r < ranks; ++r) {
      const auto k = static_cast<std::size_t>(r);
      if (plane >= slab_first[k] && plane < slab_first[k] + slab_count[k]) return r;
    }
    throw std::logic_error("distributed_energy_spectrum: a plane outside FFTW's slabs");
  };
  const auto node_coordinates = [&](std::size_t n) {
    const auto nx = static_cast<std::size_t>(block.count[0]);
    const auto ny = static_cast<std::size_t>(block.count[1]);
    return std::array<int, 3>{block.first[0] + static_cast<int>(n % nx),
                              block.first[1] + static_cast<int>((n / nx) % ny),
                              block.first[2] + static_cast<int>(n / (nx * ny))};
  };
  const int record = 1 + dim;
  std::vector<int> destination(nodes);
  std::vector<int> send_count(static_cast<std::size_t>(ranks), 0);
  for (std::size_t n = 0; n < nodes; ++n) {
    destination[n] = owner_of_plane(node_coordinates(n)[static_cast<std::size_t>(slow_axis)]);
    send_count[static_cast<std::size_t>(destination[n])] += record;
  }
  std::vector<int> send_offset(static_cast<std::size_t>(ranks), 0);
  for (int r = 1; r < ranks; ++r)
    send_offset[static_cast<std::size_t>(r)] =
        send_offset[static_cast<std::size_t>(r - 1)] + send_count[static_cast<std::size_t>(r - 1)];
  std::vector<double> send(nodes * static_cast<std::size_t>(record));
  std::vector<int> cursor = send_offset;
  for (std::size_t n = 0; n < nodes; ++n) {
    const std::array<int, 3> ijk = node_coordinates(n);
    double* out = send.data() + cursor[static_cast<std::size_t>(destination[n])];
    cursor[static_cast<std::size_t>(destination[n])] += record;
    out[0] = static_cast<double>(grid.index(ijk[0], ijk[1], ijk[2]));  // exact below 2^53
    for (int c = 0; c < dim; ++c) out[1 + c] = u[static_cast<std::size_t>(c)][n];
  }
  std::vector<int> receive_count(static_cast<std::size_t>(ranks));
  MPI_Alltoall(send_count.data(), 1, MPI_INT, receive_count.data(), 1, MPI_INT, d.comm());
  std::vector<int> receive_offset(static_cast<std::size_t>(ranks), 0);
  for (int r = 1; r < ranks; ++r)
    receive_offset[static_cast<std::size_t>(r)] = receive_offset[static_cast<std::size_t>(r - 1)] +
                                                  receive_count[static_cast<std::size_t>(r - 1)];
  std::vector<double> received(
      static_cast<std::size_t>(receive_offset.back() + receive_count.back()));
  MPI_Alltoallv(send.data(), send_count.data(), send_offset.data(), MPI_DOUBLE, received.data(),
                receive_count.data(), receive_offset.data(), MPI_DOUBLE, d.comm());

  // This rank's slab of every component, then the transforms and the shell sums of its modes.
  std::array<std::vector<double>, 3> slab;
  for (int c = 0; c < dim; ++c)
    slab[static_cast<std::size_t>(c)].assign(transform.real_count(), 0.0);
  const auto side = static_cast<std::uint64_t>(m);
  for (std::size_t at = 0; at < received.size(); at += static_cast<std::size_t>(record)) {
    const auto index = static_cast<std::uint64_t>(received[at]);
    const auto i = static_cast<int>(index % side);
    const auto j = static_cast<int>((index / side) % side);
    const auto k = static_cast<int>(index / (side * side));
    const std::size_t where = transform.real_index(i, j, k);
    for (int c = 0; c < dim; ++c)
      slab[static_cast<std::size_t>(c)][where] = received[at + 1 + static_cast<std::size_t>(c)];
  }
  analysis::ShellSums shells = analysis::empty_shell_sums(dim, m);
  for (int c = 0; c < dim; ++c) {
    const double* modes = transform.transform(slab[static_cast<std::size_t>(c)]);
    if (transform.planes() > 0)
      analysis::add_transform_planes(shells, modes, transform.first_plane(), transform.planes());
  }

  // Every rank's sums, added in rank order on every rank: the same bits everywhere.
  const std::size_t count = shells.modulus2.size();
  std::vector<double> mine(2 * count);
  std::copy(shells.modulus2.begin(), shells.modulus2.end(), mine.begin());
  std::copy(shells.k2_modulus2.begin(), shells.k2_modulus2.end(),
            mine.begin() + static_cast<std::ptrdiff_t>(count));
  std::vector<double> all(mine.size() * static_cast<std::size_t>(ranks));
  MPI_Allgather(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, all.data(),
                static_cast<int>(mine.size()), MPI_DOUBLE, d.comm());
  std::fill(shells.modulus2.begin(), shells.modulus2.end(), 0.0);
  std::fill(shells.k2_modulus2.begin(), shells.k2_modulus2.end(), 0.0);
  for (int r = 0; r < ranks; ++r) {
    const double* from = all.data() + static_cast<std::size_t>(r) * mine.size();
    for (std::size_t p = 0; p < count; ++p) {
      shells.modulus2[p] += from[p];
      shells.k2_modulus2[p] += from[count + p];
    }
  }
  return analysis::spectrum_from_shell_sums(shells, grid.length);
}

}  // namespace sphles::par
