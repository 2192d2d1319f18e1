// Energy spectrum by FFTW r2c transforms (SPEC §5).
//
// FFTW usage: one plan per call, made with FFTW_ESTIMATE (no timing measurements, so the same
// grid always gets the same algorithm) on buffers from fftw_alloc_* (always SIMD-aligned, so
// the planner cannot pick different codelets from one call to the next because of alignment).
// FFTW's planner, fftw_destroy_plan and its allocator are not thread-safe: they run under one
// static mutex. Only fftw_execute, which is thread-safe, runs outside the lock, so concurrent
// calls on different threads transform in parallel. The transform itself is single-threaded.
#include "analysis/spectrum.hpp"

#include <fftw3.h>

#include <cmath>
#include <mutex>
#include <new>
#include <numbers>
#include <stdexcept>

#include "sim/reduction.hpp"

namespace sphles::analysis {

namespace {

std::mutex& fftw_planner_mutex() {
  static std::mutex mutex;
  return mutex;
}

/// An r2c plan of an M^n real array (x fastest, i.e. x is FFTW's last, halved dimension) with
/// its own input and output buffers.
class RealToComplexTransform {
 public:
  RealToComplexTransform(int dimension, int points_per_side) {
    const auto m = static_cast<std::size_t>(points_per_side);
    real_size_ = 1;
    for (int d = 0; d < dimension; ++d) real_size_ *= m;
    complex_size_ = real_size_ / m * (m / 2 + 1);
    const int dims[3] = {points_per_side, points_per_side, points_per_side};
    std::lock_guard<std::mutex> lock(fftw_planner_mutex());
    input_ = fftw_alloc_real(real_size_);
    output_ = fftw_alloc_complex(complex_size_);
    if (input_ != nullptr && output_ != nullptr)
      plan_ = fftw_plan_dft_r2c(dimension, dims, input_, output_, FFTW_ESTIMATE);
    if (plan_ == nullptr) {
      release();
      throw std::bad_alloc();
    }
  }
  RealToComplexTransform(const RealToComplexTransform&) = delete;
  RealToComplexTransform& operator=(const RealToComplexTransform&) = delete;
  ~RealToComplexTransform() {
    std::lock_guard<std::mutex> lock(fftw_planner_mutex());
    release();
  }

  double* input() { return input_; }
  const fftw_complex* output() const { return output_; }
  std::size_t complex_size() const { return complex_size_; }
  void execute() { fftw_execute(plan_); }

 private:
  void release() {  // caller holds the planner lock
    if (plan_ != nullptr) fftw_destroy_plan(plan_);
    fftw_free(output_);
    fftw_free(input_);
    plan_ = nullptr;
    output_ = nullptr;
    input_ = nullptr;
  }

  std::size_t real_size_ = 0;
  std::size_t complex_size_ = 0;
  double* input_ = nullptr;
  fftw_complex* output_ = nullptr;
  fftw_plan plan_ = nullptr;
};

void check_velocity(const VectorField& velocity) {
  const Grid& grid = velocity.grid;
  if (grid.dimension != 2 && grid.dimension != 3)
    throw std::invalid_argument("energy spectrum: dimension must be 2 or 3");
  if (grid.points_per_side <= 0 || !(grid.length > 0.0))
    throw std::invalid_argument("energy spectrum: empty grid");
  for (int d = 0; d < grid.dimension; ++d)
    if (velocity.component[d].size() != grid.size())
      throw std::invalid_argument("energy spectrum: component size does not match the grid");
}

}  // namespace

EnergySpectrum energy_spectrum(const VectorField& velocity) {
  check_velocity(velocity);
  const Grid& grid = velocity.grid;
  const int dim = grid.dimension;
  const int m = grid.points_per_side;
  const int half = m / 2;  // largest |k| / Δk per axis
  const int kx_count = half + 1;

  // Shell of every integer |k|² / Δk²: p = nint(|k| / Δk). No |k|/Δk is a half-integer, since
  // (p + ½)² is never an integer, so rounding has no ties.
  const int max_q2 = dim * half * half;
  std::vector<int> shell_of(static_cast<std::size_t>(max_q2) + 1);
  for (int q2 = 0; q2 <= max_q2; ++q2)
    shell_of[q2] = static_cast<int>(std::lround(std::sqrt(static_cast<double>(q2))));
  const int num_shells = shell_of[max_q2] + 1;  // all shells up to the corner of the cube

  // Σ over shell modes of weight |FFTW output|², weight 2 for 0 < k_x < M/2 (the r2c half
  // spectrum stores k and not its conjugate partner -k), else 1 (k_x = 0 and, for even M, the
  // Nyquist plane k_x = M/2, whose partners are stored themselves).
  std::vector<double> shell_sum(static_cast<std::size_t>(num_shells), 0.0);
  std::vector<double> shell_k2_sum(static_cast<std::size_t>(num_shells), 0.0);
  const auto signed_index = [m](int q) { return 2 * q <= m ? q : q - m; };
  RealToComplexTransform transform(dim, m);
  const std::size_t nodes = grid.size();
  const int z_count = dim == 3 ? m : 1;
  for (int c = 0; c < dim; ++c) {
    const std::vector<double>& u = velocity.component[c];
    double* in = transform.input();
    for (std::size_t n = 0; n < nodes; ++n) in[n] = u[n];
    transform.execute();
    const fftw_complex* out = transform.output();
    std::size_t n = 0;
    for (int qz = 0; qz < z_count; ++qz) {
      const int kz = dim == 3 ? signed_index(qz) : 0;
      for (int qy = 0; qy < m; ++qy) {
        const int ky = signed_index(qy);
        for (int kx = 0; kx < kx_count; ++kx, ++n) {
          const double weight = (kx == 0 || 2 * kx == m) ? 1.0 : 2.0;
          const double modulus2 = out[n][0] * out[n][0] + out[n][1] * out[n][1];
          const int q2 = kx * kx + ky * ky + kz * kz;
          shell_sum[shell_of[q2]] += weight * modulus2;
          shell_k2_sum[shell_of[q2]] += weight * modulus2 * q2;
        }
      }
    }
  }

  // û = M^-n (FFTW output); E(k_p) = Σ_shell ½ |û|² / Δk (SPEC §5, Durran et al. 2017).
  EnergySpectrum spectrum;
  spectrum.delta_k = 2.0 * std::numbers::pi / grid.length;
  const double inv_nodes = 1.0 / static_cast<double>(nodes);
  const double scale = 0.5 * inv_nodes * inv_nodes / spectrum.delta_k;
  spectrum.wavenumber.resize(shell_sum.size());
  spectrum.energy.resize(shell_sum.size());
  spectrum.k2_energy.resize(shell_sum.size());
  const double delta_k2 = spectrum.delta_k * spectrum.delta_k;
  for (std::size_t p = 0; p < shell_sum.size(); ++p) {
    spectrum.wavenumber[p] = static_cast<double>(p) * spectrum.delta_k;
    spectrum.energy[p] = scale * shell_sum[p];
    spectrum.k2_energy[p] = scale * delta_k2 * shell_k2_sum[p];
  }
  return spectrum;
}

double spectrum_energy(const EnergySpectrum& spectrum) {
  double sum = 0.0;
  for (double e : spectrum.energy) sum += e;
  return sum * spectrum.delta_k;
}

double spectral_dissipation(const EnergySpectrum& spectrum, double kinematic_viscosity,
                            double max_wavenumber) {
  // ε = 2ν Σ_p (Σ_shell |k|² ½|û|² / Δk) Δk (4.6), exact |k| per mode.
  double sum = 0.0;
  for (std::size_t p = 0; p < spectrum.k2_energy.size(); ++p)
    if (spectrum.wavenumber[p] <= max_wavenumber) sum += spectrum.k2_energy[p];
  return 2.0 * kinematic_viscosity * sum * spectrum.delta_k;
}

double grid_kinetic_energy(const VectorField& velocity) {
  check_velocity(velocity);
  const std::size_t nodes = velocity.grid.size();
  const int dim = velocity.grid.dimension;
  const double sum_u2 = sim::deterministic_sum(nodes, [&](std::size_t n) {
    double u2 = 0.0;
    for (int c = 0; c < dim; ++c) u2 += velocity.component[c][n] * velocity.component[c][n];
    return u2;
  });
  return 0.5 * sum_u2 / static_cast<double>(nodes);
}

}  // namespace sphles::analysis
