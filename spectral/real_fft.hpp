// SPDX-License-Identifier: GPL-3.0-or-later
// Real multi-dimensional FFTs of a periodic N^d grid (d = 2, 3) for the pseudo-spectral
// reference solver, bitwise the same for any number of threads and, in 3D, of MPI ranks.
//
// FFTW's own threaded and MPI plans divide the work by the thread or rank count, and may then
// pick other algorithms; here every multi-dimensional transform is a sequence of one-dimensional
// FFTW transforms over fixed batches (a row, or a block of kBatch neighbouring columns), and only
// the batches are shared among the OpenMP threads. In 3D the z planes of the grid and the k_y
// planes of the modes are shared among the ranks (slab_exchange.hpp): the rows and the y columns
// are transformed in the z slabs, the slabs are transposed, and the z columns are transformed in
// the k_y slabs, with the same layout on one process. Every number is thus computed by the same
// plan from the same inputs whatever the thread or rank count. The plans are made with
// FFTW_ESTIMATE (no timing: the same plan on every run) and FFTW_UNALIGNED (a batch may start at
// any address).
#pragma once

#include <array>
#include <complex>
#include <cstddef>
#include <memory>
#include <vector>

#include "spectral/fourier_terms.hpp"
#include "spectral/slab_exchange.hpp"

namespace sphles::spectral {

class RealFft {
 public:
  /// dimension 2 or 3, n even and >= 4. Throws std::invalid_argument otherwise.
  /// With `kept` >= 0 the transforms are pruned to the modes |m_i| <= kept (the 2/3 rule's
  /// cube): backward() takes inputs that are zero outside it and skips the column transforms of
  /// zeros; forward() computes the modes inside it and sets the others to zero. The one-
  /// dimensional transforms done are the same for any thread count.
  /// `exchange` (3D only; it must outlive this object and be made for n) shares the planes among
  /// ranks; without it this process holds them all.
  RealFft(int dimension, int n, int kept = -1, SlabExchange* exchange = nullptr);
  ~RealFft();
  RealFft(const RealFft&) = delete;
  RealFft& operator=(const RealFft&) = delete;

  int dimension() const { return dimension_; }
  int n() const { return n_; }
  int half() const { return n_ / 2 + 1; }  // stored x modes, 0 .. n/2
  /// The planes this rank holds: the z planes [first_plane, first_plane + planes) of the grid
  /// and the k_y planes of the same indices of the modes (3D; in 2D the one plane, 0 .. 1).
  int first_plane() const { return slab_.first; }
  int planes() const { return slab_.count; }
  /// Grid points of the whole grid, n^d (the transforms' normalisation).
  double points() const { return dimension_ == 3 ? 1.0 * n_ * n_ * n_ : 1.0 * n_ * n_; }
  /// This rank's grid values: x fastest, index x + n (y + n (z - first_plane)).
  std::size_t real_size() const { return real_size_; }
  /// This rank's modes: index k_x + half (row), a row being (k_z + n (k_y - first_plane)) in 3D
  /// and k_y in 2D; k_y and k_z in FFTW order (0 .. n/2, then negative).
  std::size_t complex_size() const { return complex_size_; }
  /// Rows of modes per plane: n in 3D (one per k_z), and in 2D n in the one plane.
  long rows() const { return static_cast<long>(complex_size_ / static_cast<std::size_t>(half())); }
  /// The signed integer wavenumbers (m_y, m_z) of a row of this rank's modes (m_z = 0 in 2D).
  /// Inline: the solver asks for every mode.
  std::array<int, 2> row_wavenumbers(long row) const {
    if (dimension_ == 2) return {signed_wavenumber(static_cast<int>(row), n_), 0};
    return {signed_wavenumber(slab_.first + static_cast<int>(row / n_), n_),
            signed_wavenumber(static_cast<int>(row % n_), n_)};
  }
  /// Rows of modes in one k_y plane (3D: n, one per k_z; 2D: every row, the one plane).
  long rows_per_plane() const { return dimension_ == 3 ? n_ : rows(); }
  SlabExchange& exchange() const { return *exchange_; }

  /// out(k) = Σ_x in(x) e^{-i k·x} (unnormalised, FFTW's sign). `in` is left unchanged.
  /// Collective over the ranks.
  void forward(const double* in, Complex* out) const;
  /// out(x) = Σ_k in(k) e^{+i k·x} over the stored half and its conjugates (unnormalised).
  /// `in` is left unchanged; `scratch` holds complex_size() values and is overwritten.
  /// Collective over the ranks.
  void backward(const Complex* in, double* out, Complex* scratch) const;

 private:
  struct Plans;
  /// The column transforms (stride half, n long) of the batches `units` of `data`.
  void columns(Complex* data, int axis, bool forward) const;
  void zero_outside(Complex* data) const;
  int dimension_, n_, kept_;
  std::unique_ptr<SlabExchange> own_exchange_;
  SlabExchange* exchange_;
  Slab slab_;
  std::size_t real_size_, complex_size_;
  std::unique_ptr<Plans> plans_;
  mutable std::vector<Complex> work_;  // the z-slab side of a 3D transform
};

}  // namespace sphles::spectral
