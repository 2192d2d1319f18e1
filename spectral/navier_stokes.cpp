// SPDX-License-Identifier: GPL-3.0-or-later
#include "spectral/navier_stokes.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace sphles::spectral {

namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

void check_flow(const FlowParameters& flow) {
  auto fail = [](const std::string& what) { throw std::invalid_argument("reference: " + what); };
  if (flow.dimension != 2 && flow.dimension != 3) fail("dimension must be 2 or 3");
  if (!(flow.box_length > 0.0) || !std::isfinite(flow.box_length))
    fail("box length must be positive and finite");
  if (!(flow.viscosity >= 0.0) || !std::isfinite(flow.viscosity))
    fail("viscosity must be non-negative and finite");
  if (!(flow.friction >= 0.0) || !std::isfinite(flow.friction))
    fail("friction must be non-negative and finite");
  if (!std::isfinite(flow.forcing_amplitude)) fail("forcing amplitude must be finite");
  if (flow.forcing_periods < 0) fail("forcing periods must be non-negative");
}

std::array<std::vector<Complex>, 3> complex_fields(std::size_t size, int count) {
  std::array<std::vector<Complex>, 3> f;
  for (int c = 0; c < count; ++c) f[c].assign(size, Complex(0.0, 0.0));
  return f;
}

}  // namespace

Complex forcing_coefficient(double amplitude, int my, int periods) {
  // χ sin(k y) = χ/(2i) e^{iky} - χ/(2i) e^{-iky}; 1/(2i) = -i/2.
  if (periods == 0 || amplitude == 0.0) return {0.0, 0.0};
  if (my == periods) return {0.0, -0.5 * amplitude};
  if (my == -periods) return {0.0, 0.5 * amplitude};
  return {0.0, 0.0};
}

std::vector<double> sum_over_planes(const RealFft& fft, const std::vector<double>& per_plane,
                                    std::size_t width) {
  const int planes = fft.dimension() == 3 ? fft.n() : 1;
  std::vector<double> all(static_cast<std::size_t>(planes) * width, kSumIdentity);
  std::copy(per_plane.begin(), per_plane.end(),
            all.begin() + static_cast<std::ptrdiff_t>(fft.first_plane() * width));
  fft.exchange().sum(all.data(), all.size());  // each plane on one rank: exact
  std::vector<double> total(width, 0.0);
  for (int p = 0; p < planes; ++p)
    for (std::size_t j = 0; j < width; ++j) total[j] += all[p * width + j];
  return total;
}

NavierStokesSolver::NavierStokesSolver(const FlowParameters& flow, int n, SlabExchange* exchange)
    : flow_(flow),
      fft_(flow.dimension, n, dealiased_max_wavenumber(n), exchange),
      kmax_(dealiased_max_wavenumber(n)) {
  check_flow(flow);
  if (flow.forcing_periods > kmax_)
    throw std::invalid_argument("reference: the forcing's wavenumber " +
                                std::to_string(flow.forcing_periods) + " is not resolved on " +
                                std::to_string(n) +
                                " points (largest kept: " + std::to_string(kmax_) + ")");
  dk_ = kTwoPi / flow.box_length;
  components_ = flow.dimension;
  const std::size_t size = fft_.complex_size();
  modes_ = complex_fields(size, components_);
  rhs_ = complex_fields(size, components_);
  stage_ = complex_fields(size, components_);
  sum_ = complex_fields(size, components_);
  grid_velocity_.assign(components_, std::vector<double>(fft_.real_size()));
  grid_vorticity_.assign(flow.dimension == 3 ? 3 : 1, std::vector<double>(fft_.real_size()));
  spectral_scratch_.assign(size, Complex(0.0, 0.0));
  transform_scratch_.assign(size, Complex(0.0, 0.0));
}

std::array<double, 3> NavierStokesSolver::wavevector(std::size_t row, int ix) const {
  const auto [my, mz] = fft_.row_wavenumbers(static_cast<long>(row));
  return {ix * dk_, my * dk_, mz * dk_};
}

void NavierStokesSolver::set_velocity(const std::array<std::vector<double>, 3>& grid, double time,
                                      std::uint64_t step) {
  const std::size_t size = fft_.complex_size();
  const long rows = static_cast<long>(size / fft_.half());
  const double scale = 1.0 / static_cast<double>(fft_.points());
  for (int c = 0; c < components_; ++c) {
    if (grid[c].size() != fft_.real_size())
      throw std::invalid_argument("reference: velocity component " + std::to_string(c) + " has " +
                                  std::to_string(grid[c].size()) + " values, expected " +
                                  std::to_string(fft_.real_size()));
    fft_.forward(grid[c].data(), modes_[c].data());
  }
  const int half = fft_.half();
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r) {
    const auto [my, mz] = fft_.row_wavenumbers(r);
    for (int ix = 0; ix < half; ++ix) {
      const std::size_t i = static_cast<std::size_t>(r) * half + ix;
      ComplexVector u{};
      for (int c = 0; c < components_; ++c) u[c] = modes_[c][i] * scale;
      if (!kept_mode(ix, my, mz, kmax_)) u = ComplexVector{};
      u = project(wavevector(static_cast<std::size_t>(r), ix), u);
      for (int c = 0; c < components_; ++c) modes_[c][i] = u[c];
    }
  }
  time_ = time;
  step_ = step;
  have_rhs_ = false;
}

// The canonical layout holds, per k_z plane, the k_y rows of k_x values; this rank's modes are
// the k_y planes [first, first + planes) of (k_z rows of k_x values). One canonical k_z plane at
// a time goes between the ranks, so that no rank but rank 0 holds more than its share.
std::array<std::vector<Complex>, 3> NavierStokesSolver::gathered_modes() const {
  const int n = fft_.n(), half = fft_.half();
  SlabExchange& x = fft_.exchange();
  std::array<std::vector<Complex>, 3> all;
  if (flow_.dimension == 2) {  // one process holds every mode, already in canonical order
    for (int c = 0; c < components_; ++c) all[c] = modes_[c];
    return all;
  }
  const std::size_t plane = static_cast<std::size_t>(half) * n;
  if (x.rank() == 0)
    for (int c = 0; c < components_; ++c) all[c].resize(plane * n);
  std::vector<Complex> buffer(plane);
  for (int c = 0; c < components_; ++c)
    for (int kz = 0; kz < n; ++kz) {
      std::fill(buffer.begin(), buffer.end(), Complex(kSumIdentity, kSumIdentity));
      for (int p = 0; p < fft_.planes(); ++p) {
        const Complex* row = modes_[c].data() + (static_cast<std::size_t>(p) * n + kz) * half;
        std::copy(row, row + half,
                  buffer.begin() + static_cast<std::ptrdiff_t>((fft_.first_plane() + p) * half));
      }
      x.sum(reinterpret_cast<double*>(buffer.data()), 2 * plane);  // each row on one rank
      if (x.rank() == 0) std::copy(buffer.begin(), buffer.end(), all[c].begin() + kz * plane);
    }
  return all;
}

void NavierStokesSolver::set_modes(const std::array<std::vector<Complex>, 3>& modes, double time,
                                   std::uint64_t step) {
  const int n = fft_.n(), half = fft_.half();
  SlabExchange& x = fft_.exchange();
  const std::size_t whole =
      static_cast<std::size_t>(half) * n * (flow_.dimension == 3 ? static_cast<std::size_t>(n) : 1);
  for (int c = 0; c < components_; ++c)
    if (x.rank() == 0 && modes[c].size() != whole)
      throw std::invalid_argument("reference: the state's component " + std::to_string(c) +
                                  " has " + std::to_string(modes[c].size()) + " modes, expected " +
                                  std::to_string(whole));
  if (flow_.dimension == 2) {
    for (int c = 0; c < components_; ++c) modes_[c] = modes[c];
  } else {
    const std::size_t plane = static_cast<std::size_t>(half) * n;
    std::vector<Complex> buffer(plane);
    for (int c = 0; c < components_; ++c)
      for (int kz = 0; kz < n; ++kz) {
        if (x.rank() == 0)
          std::copy(modes[c].begin() + static_cast<std::ptrdiff_t>(kz * plane),
                    modes[c].begin() + static_cast<std::ptrdiff_t>((kz + 1) * plane),
                    buffer.begin());
        x.broadcast(reinterpret_cast<double*>(buffer.data()), 2 * plane);
        for (int p = 0; p < fft_.planes(); ++p)
          std::copy_n(
              buffer.begin() + static_cast<std::ptrdiff_t>((fft_.first_plane() + p) * half), half,
              modes_[c].begin() +
                  static_cast<std::ptrdiff_t>((static_cast<std::size_t>(p) * n + kz) * half));
      }
  }
  double when[2] = {time, static_cast<double>(step)};
  x.broadcast(when, 2);
  time_ = when[0];
  step_ = static_cast<std::uint64_t>(when[1]);
  have_rhs_ = false;
}

std::vector<std::vector<double>> NavierStokesSolver::to_grid(
    const std::array<std::vector<Complex>, 3>& fields, int count) const {
  std::vector<std::vector<double>> grid(count, std::vector<double>(fft_.real_size()));
  std::vector<Complex> scratch(fft_.complex_size());
  for (int c = 0; c < count; ++c) fft_.backward(fields[c].data(), grid[c].data(), scratch.data());
  return grid;
}

std::vector<std::vector<double>> NavierStokesSolver::velocity_grid() const {
  return to_grid(modes_, components_);
}

void NavierStokesSolver::vorticity_modes(const std::array<std::vector<Complex>, 3>& u,
                                         std::array<std::vector<Complex>, 3>& w) const {
  const int half = fft_.half();
  const long rows = static_cast<long>(fft_.complex_size() / half);
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r)
    for (int ix = 0; ix < half; ++ix) {
      const std::size_t i = static_cast<std::size_t>(r) * half + ix;
      ComplexVector v{};
      for (int c = 0; c < components_; ++c) v[c] = u[c][i];
      const ComplexVector omega = curl(wavevector(static_cast<std::size_t>(r), ix), v);
      if (flow_.dimension == 3)
        for (int c = 0; c < 3; ++c) w[c][i] = omega[c];
      else
        w[0][i] = omega[2];
    }
}

std::vector<std::vector<double>> NavierStokesSolver::vorticity_grid() const {
  const int count = flow_.dimension == 3 ? 3 : 1;
  std::array<std::vector<Complex>, 3> w = complex_fields(fft_.complex_size(), count);
  vorticity_modes(modes_, w);
  return to_grid(w, count);
}

void NavierStokesSolver::nonlinear(const std::array<std::vector<Complex>, 3>& u,
                                   std::array<std::vector<Complex>, 3>& out, double* max_speed) {
  const int n = fft_.n(), half = fft_.half(), dim = flow_.dimension;
  const int vorticity_count = dim == 3 ? 3 : 1;
  const long rows = static_cast<long>(fft_.complex_size() / half);
  // ω̂ = i k × û into `out` (used as scratch until the product's transform overwrites it).
  vorticity_modes(u, out);
  for (int c = 0; c < vorticity_count; ++c)
    fft_.backward(out[c].data(), grid_vorticity_[c].data(), transform_scratch_.data());
  for (int c = 0; c < components_; ++c)
    fft_.backward(u[c].data(), grid_velocity_[c].data(), transform_scratch_.data());

  // u × ω on the grid, written over the velocity; the largest Σ|u_i| per grid row.
  const long grid_rows = static_cast<long>(fft_.real_size() / n);
  std::vector<double> row_max(static_cast<std::size_t>(grid_rows), 0.0);
#pragma omp parallel for schedule(static)
  for (long r = 0; r < grid_rows; ++r) {
    double m = 0.0;
    for (int x = 0; x < n; ++x) {
      const std::size_t i = static_cast<std::size_t>(r) * n + x;
      std::array<double, 3> vel{0.0, 0.0, 0.0}, omega{0.0, 0.0, 0.0};
      for (int c = 0; c < components_; ++c) vel[c] = grid_velocity_[c][i];
      if (dim == 3)
        for (int c = 0; c < 3; ++c) omega[c] = grid_vorticity_[c][i];
      else
        omega[2] = grid_vorticity_[0][i];
      m = std::max(m, std::abs(vel[0]) + std::abs(vel[1]) + std::abs(vel[2]));
      const std::array<double, 3> p = cross(vel, omega);
      for (int c = 0; c < components_; ++c) grid_velocity_[c][i] = p[c];
    }
    row_max[static_cast<std::size_t>(r)] = m;
  }
  if (max_speed) {
    const double local = row_max.empty() ? 0.0 : *std::max_element(row_max.begin(), row_max.end());
    *max_speed = fft_.exchange().max(local);
  }

  for (int c = 0; c < components_; ++c) fft_.forward(grid_velocity_[c].data(), out[c].data());
  const double scale = 1.0 / static_cast<double>(fft_.points());
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r) {
    const auto [my, mz] = fft_.row_wavenumbers(r);
    for (int ix = 0; ix < half; ++ix) {
      const std::size_t i = static_cast<std::size_t>(r) * half + ix;
      ComplexVector p{};
      if (kept_mode(ix, my, mz, kmax_) && !(ix == 0 && my == 0 && mz == 0)) {
        for (int c = 0; c < components_; ++c) p[c] = out[c][i] * scale;
        p = project(wavevector(static_cast<std::size_t>(r), ix), p);
      }
      for (int c = 0; c < components_; ++c) out[c][i] = p[c];
    }
  }
}

const Budget& NavierStokesSolver::budget() {
  if (have_rhs_) return budget_;
  double max_speed = 0.0;
  nonlinear(modes_, rhs_, &max_speed);
  const int n = fft_.n(), half = fft_.half();
  const long rows = static_cast<long>(fft_.complex_size() / half);
  // Per row: Σ w|û|², Σ w k²|û|², Σ w Re(f̂*·û), Σ w Re(û*·P(u × ω)^).
  std::vector<std::array<double, 4>> partial(static_cast<std::size_t>(rows));
#pragma omp parallel for schedule(static)
  for (long r = 0; r < rows; ++r) {
    std::array<double, 4> s{0.0, 0.0, 0.0, 0.0};
    const auto [my, mz] = fft_.row_wavenumbers(r);
    for (int ix = 0; ix < half; ++ix) {
      const std::size_t i = static_cast<std::size_t>(r) * half + ix;
      const double w = conjugate_weight(ix, n);
      const std::array<double, 3> k = wavevector(static_cast<std::size_t>(r), ix);
      const double k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
      double u2 = 0.0, un = 0.0;
      for (int c = 0; c < components_; ++c) {
        u2 += std::norm(modes_[c][i]);
        un += std::real(std::conj(modes_[c][i]) * rhs_[c][i]);
      }
      s[0] += w * u2;
      s[1] += w * k2 * u2;
      if (ix == 0 && mz == 0) {
        const Complex f = forcing_coefficient(flow_.forcing_amplitude, my, flow_.forcing_periods);
        s[2] += w * std::real(std::conj(f) * modes_[0][i]);
      }
      s[3] += w * un;
    }
    partial[static_cast<std::size_t>(r)] = s;
  }
  // Per k_y plane, its rows in order; then the planes in order (sum_over_planes).
  std::vector<double> per_plane(static_cast<std::size_t>(fft_.planes()) * 4, 0.0);
  for (long r = 0; r < rows; ++r)
    for (int j = 0; j < 4; ++j)
      per_plane[static_cast<std::size_t>(r / fft_.rows_per_plane()) * 4 + j] +=
          partial[static_cast<std::size_t>(r)][j];
  const std::vector<double> total = sum_over_planes(fft_, per_plane, 4);
  Budget& b = budget_;
  b.energy = 0.5 * total[0];
  b.enstrophy = 0.5 * total[1];
  b.dissipation = 2.0 * flow_.viscosity * b.enstrophy;
  b.film = 2.0 * flow_.friction * b.energy;
  b.injection = total[2];
  b.transfer = total[3];
  b.rate = b.injection + b.transfer - b.dissipation - b.film;
  b.max_speed = max_speed;
  have_rhs_ = true;
  return budget_;
}

double NavierStokesSolver::stable_step(double cfl) {
  const double speed = budget().max_speed;
  const double dx = grid_spacing();
  double dt = speed > 0.0 ? cfl * dx / speed : std::numeric_limits<double>::infinity();
  if (flow_.forcing_amplitude != 0.0)
    dt = std::min(dt, cfl * std::sqrt(dx / std::abs(flow_.forcing_amplitude)));
  return dt;
}

void NavierStokesSolver::advance(double h) {
  if (!(h > 0.0) || !std::isfinite(h))
    throw std::invalid_argument("reference: time step must be positive and finite");
  budget();  // a = N(û) of the current state, in rhs_
  const int half = fft_.half();
  const long rows = static_cast<long>(fft_.complex_size() / half);
  std::vector<double> factor(fft_.complex_size());
  auto each_mode = [&](auto&& body) {
#pragma omp parallel for schedule(static)
    for (long r = 0; r < rows; ++r) {
      const auto [my, mz] = fft_.row_wavenumbers(r);
      for (int ix = 0; ix < half; ++ix)
        if (kept_mode(ix, my, mz, kmax_))
          body(static_cast<std::size_t>(r) * half + ix, static_cast<std::size_t>(r), ix, my, mz);
    }
  };
  // The constant forcing is integrated exactly: with the forced response s = f̂/(ν|k|² + μ),
  // v = û - s obeys dv/dt = L v + N(v + s), so the laminar state (v = 0, N = 0 for a parallel
  // flow) is a fixed point of the scheme. Without viscosity and friction, f̂ joins N instead.
  auto forcing = [&](std::size_t r, int ix, int my, int mz, Complex& shift, Complex& extra) {
    shift = extra = Complex(0.0, 0.0);
    if (ix != 0 || mz != 0) return;
    const Complex f = forcing_coefficient(flow_.forcing_amplitude, my, flow_.forcing_periods);
    if (f == Complex(0.0, 0.0)) return;
    const std::array<double, 3> k = wavevector(r, ix);
    const double rate =
        -linear_rate(k[0] * k[0] + k[1] * k[1] + k[2] * k[2], flow_.viscosity, flow_.friction);
    if (rate > 0.0)
      shift = f / rate;
    else
      extra = f;
  };
  // After the stage k's N(·) is in rhs_ (k = 0: a = N(û)): add it with its weight to the sum
  // and form the next stage's state (k = 3: the new state).
  auto finish_stage = [&](int k) {
    each_mode([&](std::size_t i, std::size_t r, int ix, int my, int mz) {
      if (k == 0) {
        const std::array<double, 3> kv = wavevector(r, ix);
        factor[i] = std::exp(0.5 * h *
                             linear_rate(kv[0] * kv[0] + kv[1] * kv[1] + kv[2] * kv[2],
                                         flow_.viscosity, flow_.friction));
      }
      const double e = factor[i];
      Complex shift, extra;
      forcing(r, ix, my, mz, shift, extra);
      for (int c = 0; c < components_; ++c) {
        const Complex s = c == 0 ? shift : Complex(0.0, 0.0);
        const Complex v = modes_[c][i] - s;
        const Complex n = rhs_[c][i] + (c == 0 ? extra : Complex(0.0, 0.0));
        switch (k) {
          case 0:
            sum_[c][i] = e * e * n;
            stage_[c][i] = LawsonRk4::stage1(e, h, v, n) + s;
            break;
          case 1:
            sum_[c][i] += 2.0 * e * n;
            stage_[c][i] = LawsonRk4::stage2(e, h, v, n) + s;
            break;
          case 2:
            sum_[c][i] += 2.0 * e * n;
            stage_[c][i] = LawsonRk4::stage3(e, h, v, n) + s;
            break;
          default:
            modes_[c][i] = LawsonRk4::final_step(e, h, v, sum_[c][i] + n) + s;
        }
      }
    });
  };
  for (int k = 0; k < 4; ++k) {
    if (k > 0) nonlinear(stage_, rhs_, nullptr);
    finish_stage(k);
  }
  time_ += h;
  ++step_;
  have_rhs_ = false;
}

}  // namespace sphles::spectral
