// Real multi-dimensional FFTs of a periodic N^d grid (d = 2, 3) for the pseudo-spectral
// reference solver, bitwise the same for any number of threads.
//
// FFTW's own threaded plans divide the work by the thread count, and may then pick other
// algorithms; here every multi-dimensional transform is a sequence of one-dimensional FFTW
// transforms over fixed batches (a row, or a block of kBatch neighbouring columns), and only the
// batches are shared among the OpenMP threads. Every number is thus computed by the same plan
// from the same inputs whatever the thread count. The plans are made with FFTW_ESTIMATE (no
// timing: the same plan on every run) and FFTW_UNALIGNED (a batch may start at any address).
#pragma once

#include <complex>
#include <cstddef>
#include <memory>

namespace sphles::spectral {

using Complex = std::complex<double>;

class RealFft {
 public:
  /// dimension 2 or 3, n even and >= 4. Throws std::invalid_argument otherwise.
  /// With `kept` >= 0 the transforms are pruned to the modes |m_i| <= kept (the 2/3 rule's
  /// cube): backward() takes inputs that are zero outside it and skips the column transforms of
  /// zeros; forward() computes the modes inside it and sets the others to zero. The one-
  /// dimensional transforms done are the same for any thread count.
  RealFft(int dimension, int n, int kept = -1);
  ~RealFft();
  RealFft(const RealFft&) = delete;
  RealFft& operator=(const RealFft&) = delete;

  int dimension() const { return dimension_; }
  int n() const { return n_; }
  int half() const { return n_ / 2 + 1; }  // stored x modes, 0 .. n/2
  /// Grid values: x fastest, index x + n (y + n z).
  std::size_t real_size() const { return real_size_; }
  /// Modes: index kx + half (ky + n kz), ky and kz in FFTW order (0 .. n/2, then negative).
  std::size_t complex_size() const { return complex_size_; }
  /// Planes of the layout (n in 3D: one per z; 1 in 2D).
  int planes() const { return dimension_ == 3 ? n_ : 1; }

  /// out(k) = Σ_x in(x) e^{-i k·x} (unnormalised, FFTW's sign). `in` is left unchanged.
  void forward(const double* in, Complex* out) const;
  /// out(x) = Σ_k in(k) e^{+i k·x} over the stored half and its conjugates (unnormalised).
  /// `in` is left unchanged; `scratch` holds complex_size() values and is overwritten.
  void backward(const Complex* in, double* out, Complex* scratch) const;

 private:
  struct Plans;
  void columns(Complex* data, int axis, bool forward) const;
  void zero_outside(Complex* data) const;
  int dimension_, n_, kept_;
  std::size_t real_size_, complex_size_;
  std::unique_ptr<Plans> plans_;
};

}  // namespace sphles::spectral
