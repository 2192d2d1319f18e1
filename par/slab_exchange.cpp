// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/slab_exchange.hpp"

#include <fftw3-mpi.h>

#include <algorithm>
#include <climits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/fftw_r2c.hpp"
#include "analysis/spectrum.hpp"

namespace sphles::par {

namespace {

// MPI counts are ints: larger arrays go in pieces.
constexpr std::size_t kPiece = static_cast<std::size_t>(INT_MAX) / 2;

template <class Call>
void in_pieces(double* values, std::size_t count, Call&& call) {
  for (std::size_t done = 0; done < count; done += kPiece)
    call(values + done, static_cast<int>(std::min(kPiece, count - done)));
}

}  // namespace

struct MpiSlabExchange::Plan {
  fftw_plan transpose = nullptr;
  std::size_t slab_values = 0;
  std::vector<double> in, out;  // for a rank whose slab is shorter than FFTW's arrays
  ~Plan() {
    if (transpose == nullptr) return;
    const auto lock = analysis::fftw_planner_lock();
    fftw_destroy_plan(transpose);
  }
};

MpiSlabExchange::MpiSlabExchange(MPI_Comm comm, int n)
    : comm_(comm), plan_(std::make_unique<Plan>()) {
  static std::once_flag initialised;
  std::call_once(initialised, [] { fftw_mpi_init(); });
  MPI_Comm_size(comm, &ranks_);
  MPI_Comm_rank(comm, &rank_);
  // The n × n matrix of k_x rows (n/2 + 1 complex values, as doubles) in blocks of
  // spectral::Slab's size both ways. The matrix is square and the blocks equal, so one plan
  // takes the z slabs to the k_y slabs and back.
  const ptrdiff_t element = 2 * (n / 2 + 1);
  const ptrdiff_t block = (n + ranks_ - 1) / ranks_;
  ptrdiff_t local_n0 = 0, first0 = 0, local_n1 = 0, first1 = 0;
  const ptrdiff_t dims[2] = {n, n};
  const ptrdiff_t size = fftw_mpi_local_size_many_transposed(
      2, dims, element, block, block, comm, &local_n0, &first0, &local_n1, &first1);
  const spectral::Slab slab(n, ranks_, rank_);
  // Every rank refuses alike (a rank that alone threw would leave the others in the plan).
  int agrees = local_n0 == slab.count && first0 == slab.first && local_n1 == slab.count &&
               first1 == slab.first;
  MPI_Allreduce(MPI_IN_PLACE, &agrees, 1, MPI_INT, MPI_MIN, comm);
  if (!agrees)
    throw std::runtime_error("FFTW's MPI slabs of the " + std::to_string(n) +
                             "^3 reference grid differ from the reference's own (rank " +
                             std::to_string(rank_) + ": FFTW " + std::to_string(first0) + " + " +
                             std::to_string(local_n0) + ", size " + std::to_string(size) +
                             "; own " + std::to_string(slab.first) + " + " +
                             std::to_string(slab.count) + ")");
  // FFTW's transpose works in arrays of `size` values on every rank, more than a rank with a
  // shorter slab holds: such a rank transposes through buffers of that size.
  const std::size_t values = static_cast<std::size_t>(std::max<ptrdiff_t>(size, 1));
  plan_->slab_values = static_cast<std::size_t>(slab.count) * n * element;
  if (values > plan_->slab_values) {
    plan_->in.assign(values, 0.0);
    plan_->out.assign(values, 0.0);
  }
  double* in = fftw_alloc_real(values);
  double* out = fftw_alloc_real(values);
  {
    const auto lock = analysis::fftw_planner_lock();
    plan_->transpose =
        fftw_mpi_plan_many_transpose(n, n, element, block, block, in, out, comm, FFTW_ESTIMATE);
  }
  fftw_free(in);
  fftw_free(out);
  if (plan_->transpose == nullptr)
    throw std::runtime_error("FFTW could not plan the transpose of the " + std::to_string(n) +
                             "^3 reference grid over " + std::to_string(ranks_) + " ranks");
}

MpiSlabExchange::~MpiSlabExchange() = default;

void MpiSlabExchange::transpose(std::complex<double>* in, std::complex<double>* out, bool) {
  Plan& p = *plan_;
  double* from = reinterpret_cast<double*>(in);
  double* to = reinterpret_cast<double*>(out);
  if (p.in.empty()) {
    fftw_mpi_execute_r2r(p.transpose, from, to);
    return;
  }
  std::copy(from, from + p.slab_values, p.in.begin());
  fftw_mpi_execute_r2r(p.transpose, p.in.data(), p.out.data());
  std::copy(p.out.begin(), p.out.begin() + static_cast<std::ptrdiff_t>(p.slab_values), to);
}

void MpiSlabExchange::sum(double* values, std::size_t count) {
  in_pieces(values, count, [this](double* v, int c) {
    MPI_Allreduce(MPI_IN_PLACE, v, c, MPI_DOUBLE, MPI_SUM, comm_);
  });
}

double MpiSlabExchange::max(double value) {
  MPI_Allreduce(MPI_IN_PLACE, &value, 1, MPI_DOUBLE, MPI_MAX, comm_);
  return value;
}

void MpiSlabExchange::broadcast(double* values, std::size_t count) {
  in_pieces(values, count, [this](double* v, int c) { MPI_Bcast(v, c, MPI_DOUBLE, 0, comm_); });
}

}  // namespace sphles::par
