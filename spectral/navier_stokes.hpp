// SPDX-License-Identifier: GPL-3.0-or-later
// An incompressible pseudo-spectral (Fourier-Galerkin) Navier-Stokes solver of a periodic box:
// the reference sphles judges its particle runs against (SPEC §9, docs/reference.md).
//
// State: the Fourier coefficients û(k) of the velocity (u(x) = Σ_k û(k) e^{ik·x}), divergence-
// free and zero outside the 2/3 rule's cube. Time stepping: RK4 in integrating-factor form
// (fourier_terms.hpp, LawsonRk4), its step chosen by the caller (stable_step: the CFL limit).
// Deterministic: the same bits for any number of OpenMP threads and, in 3D, MPI ranks
// (real_fft.hpp; every sum over modes is taken row by row within a k_y plane, and the planes'
// sums are added in the order of the planes, whichever rank holds them).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "spectral/fourier_terms.hpp"
#include "spectral/real_fft.hpp"

namespace sphles::spectral {

/// The flow: box, viscosity and, for the Kolmogorov flow (SPEC §6.3), the forcing
/// f = χ sin(k_y y) e_x with k_y = 2π periods / L and the linear friction -μu.
struct FlowParameters {
  int dimension = 3;
  double box_length = 6.283185307179586;  // L [m]
  double viscosity = 0.0;                 // ν [m²/s]
  double friction = 0.0;                  // μ [1/s]
  double forcing_amplitude = 0.0;         // χ [m/s²]
  int forcing_periods = 0;
};

/// The energy budget at one instant, exact for the discrete (truncated) system: per unit volume,
/// dE/dt = injection + transfer - dissipation - film.
struct Budget {
  double energy = 0.0;       // E = ½⟨|u|²⟩ [m²/s²]
  double enstrophy = 0.0;    // Z = ½⟨|ω|²⟩ [1/s²]
  double dissipation = 0.0;  // ε = 2νZ [m²/s³]
  double film = 0.0;         // 2μE, the friction's loss [m²/s³]
  double injection = 0.0;    // ⟨f·u⟩ [m²/s³]
  /// ⟨u·P(u × ω)⟩: the nonlinear term moves energy between modes and adds none; zero up to
  /// round-off (a check of the dealiasing and the projection).
  double transfer = 0.0;
  double rate = 0.0;       // dE/dt, Σ_k Re(û*·dû/dt) [m²/s³]
  double max_speed = 0.0;  // max over the grid of |u_x| + |u_y| + |u_z| [m/s]
};

class NavierStokesSolver {
 public:
  /// n points per side (even, >= 4). Throws std::invalid_argument on a bad flow or n.
  /// `exchange` (3D; made for n, outliving the solver) shares the planes among MPI ranks: every
  /// call below is then collective, and grids and modes are this rank's slab (RealFft).
  NavierStokesSolver(const FlowParameters& flow, int n, SlabExchange* exchange = nullptr);

  const FlowParameters& flow() const { return flow_; }
  const RealFft& fft() const { return fft_; }
  int n() const { return fft_.n(); }
  double time() const { return time_; }
  std::uint64_t step() const { return step_; }
  /// Largest |m| of the kept modes (2/3 rule) and its physical wavenumber K 2π/L.
  int max_wavenumber() const { return kmax_; }
  double grid_spacing() const { return flow_.box_length / n(); }

  /// Sets the state from grid values of the velocity (component c at node x + n (y + n z), the
  /// node at (x, y, z) L/n; this rank's z slab): transformed, truncated and projected onto
  /// divergence-free fields.
  void set_velocity(const std::array<std::vector<double>, 3>& grid, double time = 0.0,
                    std::uint64_t step = 0);
  /// The coefficients û_c(k) of this rank in RealFft's layout (normalised: u = Σ û e^{ik·x}).
  std::span<const Complex> modes(int component) const { return modes_[component]; }
  /// Every coefficient in the canonical layout of a checkpoint, k_x + half (k_y + n k_z) (the
  /// layout of FFTW's r2c output), on rank 0 (empty elsewhere).
  std::array<std::vector<Complex>, 3> gathered_modes() const;
  /// Restores a state from gathered_modes() given on rank 0 (ignored elsewhere); throws
  /// std::invalid_argument on a size mismatch.
  void set_modes(const std::array<std::vector<Complex>, 3>& modes, double time, std::uint64_t step);

  /// The budget of the current state (computes the nonlinear term once per state).
  const Budget& budget();
  /// The CFL step cfl Δx / max Σ|u_i|, and with a forcing at most cfl sqrt(Δx / χ) (the step
  /// of a fluid at rest that the forcing sets moving).
  double stable_step(double cfl);
  /// Advances by dt (Lawson RK4).
  void advance(double dt);
  /// Sets the clock after a step meant to land on an output time (t + dt rounds).
  void set_time(double time) { time_ = time; }

  /// Velocity (c < dimension) and vorticity (3D: 3 components; 2D: ω_z) on this rank's grid.
  std::vector<std::vector<double>> velocity_grid() const;
  std::vector<std::vector<double>> vorticity_grid() const;

 private:
  std::array<double, 3> wavevector(std::size_t row, int ix) const;
  /// ω̂ = i k × û of every mode (3D: three components; 2D: ω_z into w[0]).
  void vorticity_modes(const std::array<std::vector<Complex>, 3>& u,
                       std::array<std::vector<Complex>, 3>& w) const;
  void nonlinear(const std::array<std::vector<Complex>, 3>& u,
                 std::array<std::vector<Complex>, 3>& out, double* max_speed);
  std::vector<std::vector<double>> to_grid(const std::array<std::vector<Complex>, 3>& fields,
                                           int count) const;

  FlowParameters flow_;
  RealFft fft_;
  int kmax_;
  double dk_;
  int components_;  // velocity components stored: dimension
  double time_ = 0.0;
  std::uint64_t step_ = 0;
  std::array<std::vector<Complex>, 3> modes_;
  // Work arrays: N(û) of the current state (valid when have_rhs_), stage state, accumulator.
  std::array<std::vector<Complex>, 3> rhs_, stage_, sum_;
  bool have_rhs_ = false;
  Budget budget_;
  // Grid work arrays of the nonlinear term.
  std::vector<std::vector<double>> grid_velocity_, grid_vorticity_;
  std::vector<Complex> spectral_scratch_, transform_scratch_;
};

/// Σ over every mode of `width` values per k_y plane: `per_plane` holds this rank's planes
/// (fft.planes() × width, each the sum of its rows in row order); the planes' sums are added in
/// plane order, the same bits for any rank count. Collective.
std::vector<double> sum_over_planes(const RealFft& fft, const std::vector<double>& per_plane,
                                    std::size_t width);

/// The forcing's coefficient f̂_x at the mode (0, ±periods): χ sin(k_y y) = χ (e^{ik_y y} -
/// e^{-ik_y y}) / 2i.
Complex forcing_coefficient(double amplitude, int my, int periods);

}  // namespace sphles::spectral
