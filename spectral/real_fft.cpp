#include "spectral/real_fft.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

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

struct RealFft::Plans {
  Plan row_forward, row_backward;
  // Per axis 1 (y) and 2 (z): a batch of kBatch columns and the last, narrower one (if any),
  // forward and backward.
  Plan column[3][2][2];
  int chunks = 0, tail = 0;
  // The batches of columns transformed along axis 1 and 2: (group, chunk), in a fixed order.
  std::vector<std::pair<long, int>> units[3];
};

RealFft::RealFft(int dimension, int n, int kept) : dimension_(dimension), n_(n), kept_(kept) {
  if (dimension != 2 && dimension != 3)
    throw std::invalid_argument("reference grid: dimension must be 2 or 3, got " +
                                std::to_string(dimension));
  if (n < 4 || n % 2 != 0)
    throw std::invalid_argument("reference.points_per_side must be even and at least 4, got " +
                                std::to_string(n));
  const std::size_t ns = static_cast<std::size_t>(n);
  real_size_ = dimension == 3 ? ns * ns * ns : ns * ns;
  complex_size_ = static_cast<std::size_t>(half()) * (dimension == 3 ? ns * ns : ns);
  plans_ = std::make_unique<Plans>();
  Plans& p = *plans_;
  p.chunks = (half() + kBatch - 1) / kBatch;
  p.tail = half() - (p.chunks - 1) * kBatch;

  // FFTW_ESTIMATE plans do not touch the arrays they are planned on.
  double* real = fftw_alloc_real(ns);
  fftw_complex* cplx = fftw_alloc_complex(complex_size_);
  const auto lock = analysis::fftw_planner_lock();
  p.row_forward.reset(fftw_plan_many_dft_r2c(1, &n_, 1, real, nullptr, 1, n, cplx, nullptr, 1,
                                             half(), kFlags | FFTW_PRESERVE_INPUT));
  p.row_backward.reset(fftw_plan_many_dft_c2r(1, &n_, 1, cplx, nullptr, 1, half(), real, nullptr, 1,
                                              n, kFlags | FFTW_DESTROY_INPUT));
  for (int axis = 1; axis < dimension; ++axis) {
    const int stride = axis == 1 ? half() : half() * n;
    for (int last = 0; last < 2; ++last) {
      const int howmany = last ? p.tail : kBatch;
      for (int dir = 0; dir < 2; ++dir)
        p.column[axis][last][dir].reset(
            fftw_plan_many_dft(1, &n_, howmany, cplx, nullptr, stride, 1, cplx, nullptr, stride, 1,
                               dir == 0 ? FFTW_FORWARD : FFTW_BACKWARD, kFlags));
    }
  }
  fftw_free(real);
  fftw_free(cplx);
  // Pruning: only the chunks that hold kx <= kept, and along z only the y rows with
  // |ky| <= kept, carry non-zero values (or values that are kept).
  const int chunk_limit = kept < 0 ? p.chunks : std::min(p.chunks, kept / kBatch + 1);
  for (int axis = 1; axis < dimension; ++axis) {
    const long groups = axis == 1 ? planes() : n;
    for (long g = 0; g < groups; ++g) {
      if (axis == 2 && kept >= 0) {
        const long ky = g <= n / 2 ? g : g - n;
        if (ky > kept || -ky > kept) continue;
      }
      for (int c = 0; c < chunk_limit; ++c) p.units[axis].emplace_back(g, c);
    }
  }
  bool ok = p.row_forward && p.row_backward;
  for (int axis = 1; axis < dimension; ++axis)
    for (int last = 0; last < 2; ++last)
      for (int dir = 0; dir < 2; ++dir) ok = ok && p.column[axis][last][dir];
  if (!ok) throw std::runtime_error("FFTW could not plan the reference grid's transforms");
}

RealFft::~RealFft() = default;

void RealFft::columns(Complex* data, int axis, bool forward) const {
  const Plans& p = *plans_;
  // Axis 1: the columns of each z plane; axis 2: the columns along z through each y row.
  const long group_stride = axis == 1 ? static_cast<long>(half()) * n_ : half();
  const std::vector<std::pair<long, int>>& units = p.units[axis];
  const long count = static_cast<long>(units.size());
#pragma omp parallel for schedule(static)
  for (long u = 0; u < count; ++u) {
    const auto [group, chunk] = units[static_cast<std::size_t>(u)];
    Complex* start = data + group * group_stride + chunk * kBatch;
    const bool last = chunk == p.chunks - 1 && p.tail != kBatch;
    fftw_execute_dft(p.column[axis][last ? 1 : 0][forward ? 0 : 1].get(), as_fftw(start),
                     as_fftw(start));
  }
}

void RealFft::zero_outside(Complex* data) const {
  if (kept_ < 0) return;
  const long rows = static_cast<long>(complex_size_ / half());
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r) {
    const long y = r % n_, z = r / n_;
    const long ky = y <= n_ / 2 ? y : y - n_, kz = z <= n_ / 2 ? z : z - n_;
    const bool row_kept = std::abs(ky) <= kept_ && (dimension_ == 2 || std::abs(kz) <= kept_);
    Complex* row = data + r * half();
    std::fill(row + (row_kept ? std::min(kept_ + 1, half()) : 0), row + half(), Complex(0.0, 0.0));
  }
}

void RealFft::forward(const double* in, Complex* out) const {
  const long rows = static_cast<long>(complex_size_ / half());
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r)
    fftw_execute_dft_r2c(plans_->row_forward.get(), const_cast<double*>(in + r * n_),
                         as_fftw(out + r * half()));
  for (int axis = 1; axis < dimension_; ++axis) columns(out, axis, true);
  zero_outside(out);
}

void RealFft::backward(const Complex* in, double* out, Complex* scratch) const {
  const long rows = static_cast<long>(complex_size_ / half());
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r)
    std::copy(in + r * half(), in + (r + 1) * half(), scratch + r * half());
  for (int axis = dimension_ - 1; axis >= 1; --axis) columns(scratch, axis, false);
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r)
    fftw_execute_dft_c2r(plans_->row_backward.get(), as_fftw(scratch + r * half()), out + r * n_);
}

}  // namespace sphles::spectral
