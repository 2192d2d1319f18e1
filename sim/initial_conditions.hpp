// SPDX-License-Identifier: GPL-3.0-or-later
// Initial states of the test cases (SPEC §6) and the translation of a Scene into solver input.
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include "sim/case_diagnostics.hpp"
#include "sim/packing.hpp"
#include "sim/particles.hpp"
#include "sim/reduction.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::sim {

/// Sets velocity (5.1) (+ uniform velocity), density ρ0 = ρ_ref + (p0 - p_ref)/c_s² from
/// pressure (5.2) and mass M0 = ρ0 Δl³ at the given positions (3D Taylor-Green, SPEC §6.1).
void set_taylor_green_3d(const Scene& scene, ParticleArrays& particles);

/// 2D Taylor-Green (SPEC §6.2): v = v0 (sin x cos y, -cos x sin y) (+ uniform velocity),
/// p0 = p_ref + ρ_ref v0²/4 (cos 2x + cos 2y), ρ0 from the EOS, M0 = ρ0 Δl².
void set_taylor_green_2d(const Scene& scene, ParticleArrays& particles);

/// Analytic velocity of the decaying 2D Taylor-Green vortex at (x, y) and time t (SPEC §6.2):
/// v = v0 e^(-2νt) (sin x cos y, -cos x sin y), without any uniform velocity.
std::array<double, 2> taylor_green_2d_velocity(double v0, double kinematic_viscosity, double time,
                                               double x, double y);

/// Analytic kinetic energy e_v(t) = e_v(0) exp(-4 ν t) of the 2D Taylor-Green vortex with
/// e_v(0) = v0²/4 (SPEC §6.2).
double taylor_green_2d_energy(double v0, double kinematic_viscosity, double time);

/// Kolmogorov flow (SPEC §6.3): fluid at rest (plus any uniform velocity) with M0 = ρ_ref Δl².
void set_kolmogorov_2d(const Scene& scene, ParticleArrays& particles);

/// a_ext = χ sin(k_y y) e_x - μ v of the Kolmogorov flow (SPEC §6.3), evaluated at the velocity
/// the forces use.
ExternalAcceleration kolmogorov_acceleration(const KolmogorovForcing& forcing, double wavenumber);

/// Laminar steady state v_x = χ sin(k_y y) / (ν k_y² + μ) of the Kolmogorov flow.
double kolmogorov_laminar_velocity(const KolmogorovForcing& forcing, double wavenumber,
                                   double kinematic_viscosity, double y);

/// V_i = 1/Σ_j W_ij (A.1) of every particle of an arrangement, with the kernel, support and box
/// of `config`: the volumes the solver's first density pass computes. With a distributed
/// `exchange`, `particles` are the ones this process owns (each in its part of the box) and the
/// neighbours on other processes count too (collective); bitwise the one-process values.
std::vector<double> summed_volumes(const SolverConfig& config, const ParticleArrays& particles,
                                   Exchange& exchange);
std::vector<double> summed_volumes(const SolverConfig& config, const ParticleArrays& particles);

/// Replaces the lattice masses M0 = ρ0 Δl^n of a case by M_i = ρ0_i V_i (initial.mass =
/// "summation"), so that ρ_i = M_i / V_i (A.2) is the prescribed ρ0_i exactly.
void set_summation_masses(const SolverConfig& config, double lattice_cell_volume,
                          ParticleArrays& particles, Exchange& exchange);

/// The fields of the scene's case at the particles' positions (velocity, density, mass; SPEC
/// §6) and the masses initial.mass asks for: what setup_run gives packed or lattice positions.
/// With a distributed `exchange`, as summed_volumes. Collective.
void set_case_fields(const Scene& scene, const SolverConfig& config, ParticleArrays& particles,
                     Exchange& exchange);

struct RunSetup {
  SolverConfig solver;
  ParticleArrays particles;
  PackingReport packing;
};

/// Box, kernel, fluid, time stepping, sub-filter model and forcing of a scene (no particles).
SolverConfig make_solver_config(const Scene& scene);

/// Box, kernel, fluid and time stepping from the scene; positions from packed_positions();
/// fields from the scene's case, masses as initial.mass says. Throws SetupCancelled when
/// options.cancelled says so.
RunSetup setup_run(const Scene& scene, const SetupOptions& options = {});

}  // namespace sphles::sim
