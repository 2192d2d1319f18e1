// SPDX-License-Identifier: GPL-3.0-or-later
#include "spectral/real_fft.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "analysis/fftw_r2c.hpp"
#include "analysis/spectrum.hpp"

namespace sphles::spectral {

namespace {

// Columns transformed by one plan call: wide enough that a column transform reads whole cache
// lines, narrow enough that a plane's columns make several batches for the threads.
constexpr int kBatch = 16;
constexpr unsigned kFlags = FFTW_ESTIMATE | FFTW_UNALIGNED;

fftw_complex* as_fftw(Complex* p) {
  return reinterpret_cast<fftw_complex*>(p);
}

struct PlanDeleter {
  void operator()(fftw_plan_s* plan) const {
    if (plan == nullptr) return;
    const auto lock = analysis::fftw_planner_lock();
    fftw_destroy_plan(plan);
  }
};
using Plan = std::unique_ptr<fftw_plan_s, PlanDeleter>;

}  // namespace

void OneProcess::transpose(Complex* in, Complex* out, bool forward) {
  // [a][b][k_x] -> [b][a][k_x]: the same move both ways on a square; k_y is b going forward
  // (z slab to k_y slab), a going back.
  const long n = n_, half = n_ / 2 + 1;
  const long copied = kept_ < 0 ? half : std::min<long>(kept_ + 1, half);
  auto kept_ky = [&](long i) {
    return kept_ < 0 || std::abs(signed_wavenumber(static_cast<int>(i), n_)) <= kept_;
  };
  // In tiles of kTile × kTile elements: both sides stay within a few pages per tile.
  constexpr long kTile = 8;
  const long tiles = (n + kTile - 1) / kTile;
#pragma omp parallel for schedule(static)
  for (long t = 0; t < tiles * tiles; ++t) {
    const long b0 = t / tiles * kTile, a0 = t % tiles * kTile;
    for (long b = b0; b < std::min(n, b0 + kTile); ++b)
      for (long a = a0; a < std::min(n, a0 + kTile); ++a) {
        Complex* to = out + (b * n + a) * half;
        const long count = kept_ky(forward ? b : a) ? copied : 0;
        std::copy(in + (a * n + b) * half, in + (a * n + b) * half + count, to);
        // Going forward the transform zeroes what lies beyond the kept modes itself.
        if (!forward || count == 0) std::fill(to + count, to + half, Complex(0.0, 0.0));
      }
  }
}

struct RealFft::Plans {
  Plan row_forward, row_backward;
  // A batch of kBatch columns (stride half, n long) and the last, narrower one (if any),
  // forward and backward: the y columns of a z plane and the z columns of a k_y plane alike.
  Plan column[2][2];
  int chunks = 0, tail = 0;
  // The batches of columns transformed along y (axis 1) and z (axis 2): (local plane, chunk),
  // in a fixed order.
  std::vector<std::pair<long, int>> units[3];
};

RealFft::RealFft(int dimension, int n, int kept, SlabExchange* exchange)
    : dimension_(dimension), n_(n), kept_(kept), exchange_(exchange), slab_(1, 1, 0) {
  if (dimension != 2 && dimension != 3)
    throw std::invalid_argument("reference grid: dimension must be 2 or 3, got " +
                                std::to_string(dimension));
  if (n < 4 || n % 2 != 0)
    throw std::invalid_argument("reference.points_per_side must be even and at least 4, got " +
                                std::to_string(n));
  if (exchange_ == nullptr) {
    own_exchange_ = std::make_unique<OneProcess>(n, kept);
    exchange_ = own_exchange_.get();
  }
  if (dimension == 2 && exchange_->ranks() > 1)
    throw std::invalid_argument("reference grid: a 2D reference runs on one process");
  if (dimension == 3) slab_ = Slab(n, exchange_->ranks(), exchange_->rank());
  const std::size_t ns = static_cast<std::size_t>(n);
  const std::size_t planes = static_cast<std::size_t>(slab_.count);
  real_size_ = dimension == 3 ? ns * ns * planes : ns * ns;
  complex_size_ = static_cast<std::size_t>(half()) * (dimension == 3 ? ns * planes : ns);
  if (dimension == 3) work_.assign(complex_size_, Complex(0.0, 0.0));
  plans_ = std::make_unique<Plans>();
  Plans& p = *plans_;
  p.chunks = (half() + kBatch - 1) / kBatch;
  p.tail = half() - (p.chunks - 1) * kBatch;

  // FFTW_ESTIMATE plans do not touch the arrays they are planned on.
  double* real = fftw_alloc_real(ns);
  fftw_complex* cplx = fftw_alloc_complex(static_cast<std::size_t>(half()) * ns);
  const auto lock = analysis::fftw_planner_lock();
  p.row_forward.reset(fftw_plan_many_dft_r2c(1, &n_, 1, real, nullptr, 1, n, cplx, nullptr, 1,
                                             half(), kFlags | FFTW_PRESERVE_INPUT));
  p.row_backward.reset(fftw_plan_many_dft_c2r(1, &n_, 1, cplx, nullptr, 1, half(), real, nullptr, 1,
                                              n, kFlags | FFTW_DESTROY_INPUT));
  for (int last = 0; last < 2; ++last) {
    const int howmany = last ? p.tail : kBatch;
    for (int dir = 0; dir < 2; ++dir)
      p.column[last][dir].reset(
          fftw_plan_many_dft(1, &n_, howmany, cplx, nullptr, half(), 1, cplx, nullptr, half(), 1,
                             dir == 0 ? FFTW_FORWARD : FFTW_BACKWARD, kFlags));
  }
  fftw_free(real);
  fftw_free(cplx);
  // Pruning: only the chunks that hold kx <= kept, and along z only the k_y planes with
  // |ky| <= kept, carry non-zero values (or values that are kept).
  const int chunk_limit = kept < 0 ? p.chunks : std::min(p.chunks, kept / kBatch + 1);
  const long groups = dimension == 3 ? slab_.count : 1;
  for (int axis = 1; axis < dimension; ++axis)
    for (long g = 0; g < groups; ++g) {
      if (axis == 2 && kept >= 0) {
        if (std::abs(signed_wavenumber(first_plane() + static_cast<int>(g), n)) > kept) continue;
      }
      for (int c = 0; c < chunk_limit; ++c) p.units[axis].emplace_back(g, c);
    }
  bool ok = p.row_forward && p.row_backward;
  for (int last = 0; last < 2; ++last)
    for (int dir = 0; dir < 2; ++dir) ok = ok && p.column[last][dir];
  if (!ok) throw std::runtime_error("FFTW could not plan the reference grid's transforms");
}

RealFft::~RealFft() = default;

void RealFft::columns(Complex* data, int axis, bool forward) const {
  const Plans& p = *plans_;
  const long group_stride = static_cast<long>(half()) * n_;
  const std::vector<std::pair<long, int>>& units = p.units[axis];
  const long count = static_cast<long>(units.size());
#pragma omp parallel for schedule(static)
  for (long u = 0; u < count; ++u) {
    const auto [group, chunk] = units[static_cast<std::size_t>(u)];
    Complex* start = data + group * group_stride + chunk * kBatch;
    const bool last = chunk == p.chunks - 1 && p.tail != kBatch;
    fftw_execute_dft(p.column[last ? 1 : 0][forward ? 0 : 1].get(), as_fftw(start), as_fftw(start));
  }
}

void RealFft::zero_outside(Complex* data) const {
  if (kept_ < 0) return;
  const long count = rows();
#pragma omp parallel for schedule(static)
  for (long r = 0; r < count; ++r) {
    const auto [ky, kz] = row_wavenumbers(r);
    const bool row_kept = std::abs(ky) <= kept_ && std::abs(kz) <= kept_;
    Complex* row = data + r * half();
    std::fill(row + (row_kept ? std::min(kept_ + 1, half()) : 0), row + half(), Complex(0.0, 0.0));
  }
}

void RealFft::forward(const double* in, Complex* out) const {
  // 3D: rows and y columns in the z slab (work_), then the transpose into the k_y slab (out).
  Complex* slab = dimension_ == 3 ? work_.data() : out;
  const long count = rows();
#pragma omp parallel for schedule(static)
  for (long r = 0; r < count; ++r)
    fftw_execute_dft_r2c(plans_->row_forward.get(), const_cast<double*>(in + r * n_),
                         as_fftw(slab + r * half()));
  columns(slab, 1, true);
  if (dimension_ == 3) {
    exchange_->transpose(slab, out, true);
    columns(out, 2, true);
  }
  zero_outside(out);
}

void RealFft::backward(const Complex* in, double* out, Complex* scratch) const {
  const long count = rows();
#pragma omp parallel for schedule(static)
  for (long r = 0; r < count; ++r)
    std::copy(in + r * half(), in + (r + 1) * half(), scratch + r * half());
  Complex* slab = scratch;
  if (dimension_ == 3) {
    columns(scratch, 2, false);
    exchange_->transpose(scratch, work_.data(), false);
    slab = work_.data();
  }
  columns(slab, 1, false);
#pragma omp parallel for schedule(static)
  for (long r = 0; r < count; ++r)
    fftw_execute_dft_c2r(plans_->row_backward.get(), as_fftw(slab + r * half()), out + r * n_);
}

}  // namespace sphles::spectral
