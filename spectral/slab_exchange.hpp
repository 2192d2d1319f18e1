// SPDX-License-Identifier: GPL-3.0-or-later
// What the spectral reference needs from the processes it runs on: the transpose of its slabs
// and a few exact collectives. One process needs nothing (OneProcess); under mpirun the ranks
// exchange through FFTW's MPI transposes and MPI (par::MpiSlabExchange). The solver holds the
// same numbers whatever the implementation: a transpose only moves values, `sum` is applied
// only where at most one rank holds a value other than -0.0 (the identity of floating-point
// addition, x + -0.0 = x for every x, ±0 included), and `max` is exact.
//
// The slabs: of the n planes of a 3D grid, rank r holds [r b, min(n, (r + 1) b)), b = ceil(n/P),
// both in real space (the z planes) and in Fourier space (the k_y planes, RealFft's layout).
#pragma once

#include <complex>
#include <cstddef>

namespace sphles::spectral {

/// The value a rank fills the entries it does not hold with before a sum.
inline constexpr double kSumIdentity = -0.0;

class SlabExchange {
 public:
  virtual ~SlabExchange() = default;
  virtual int ranks() const = 0;
  virtual int rank() const = 0;
  /// Transposes the n × n matrix of elements (an element: the n/2 + 1 complex values of one k_x
  /// row) between the slabs: forward from [z][k_y][k_x] held in z slabs to [k_y][z][k_x] held in
  /// k_y slabs, backward the reverse. `in` and `out` hold this rank's slab (they may not
  /// overlap); `in` may be overwritten.
  virtual void transpose(std::complex<double>* in, std::complex<double>* out, bool forward) = 0;
  /// values[i] = Σ over ranks of values[i], on every rank (exact where at most one rank holds a
  /// value other than kSumIdentity).
  virtual void sum(double* values, std::size_t count) = 0;
  /// The largest of the ranks' values, on every rank.
  virtual double max(double value) = 0;
  /// Rank 0's values, on every rank.
  virtual void broadcast(double* values, std::size_t count) = 0;
};

/// The slab of planes [first, first + count) rank `rank` of `ranks` holds of n.
struct Slab {
  int first = 0;
  int count = 0;
  Slab(int n, int ranks, int rank) {
    const int block = (n + ranks - 1) / ranks;
    first = block * rank < n ? block * rank : n;
    count = (block * (rank + 1) < n ? block * (rank + 1) : n) - first;
  }
};

/// A reference on one process: holds every plane, nothing to exchange. With `kept` >= 0 (the
/// 2/3 rule's |m| <= kept, RealFft) its transpose moves only the values a pruned transform
/// reads, and writes zeros for the others (which an MPI transpose would move as zeros, or which
/// the transform then zeroes): the same bits, a third of the copying.
class OneProcess final : public SlabExchange {
 public:
  explicit OneProcess(int n, int kept = -1) : n_(n), kept_(kept) {}
  int ranks() const override { return 1; }
  int rank() const override { return 0; }
  void transpose(std::complex<double>* in, std::complex<double>* out, bool forward) override;
  void sum(double*, std::size_t) override {}
  double max(double value) override { return value; }
  void broadcast(double*, std::size_t) override {}

 private:
  int n_, kept_;
};

}  // namespace sphles::spectral
