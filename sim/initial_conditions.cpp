// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/initial_conditions.hpp"

#include <cmath>

#include "sim/neighbour_search.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/reduction.hpp"

namespace sphles::sim {

void set_taylor_green_3d(const Scene& s, ParticleArrays& p) {
  const double v0 = s.velocity_amplitude;
  const double rho_ref = s.fluid.reference_density;
  const double c2 = s.fluid.sound_speed * s.fluid.sound_speed;
  const double cell_volume = std::pow(s.particle_spacing(), 3);
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double x = p.position[0][i], y = p.position[1][i], z = p.position[2][i];
    p.velocity[0][i] =
        v0 * std::sin(x) * std::cos(y) * std::cos(z) + s.uniform_velocity[0];  // (5.1)
    p.velocity[1][i] = -v0 * std::cos(x) * std::sin(y) * std::cos(z) + s.uniform_velocity[1];
    p.velocity[2][i] = s.uniform_velocity[2];
    const double p0_minus_ref = rho_ref * v0 * v0 / 16.0 * (2.0 + std::cos(2.0 * z)) *
                                (std::cos(2.0 * x) + std::cos(2.0 * y));  // (5.2)
    const double rho0 = rho_ref + p0_minus_ref / c2;
    p.mass[i] = rho0 * cell_volume;
  }
}

void set_taylor_green_2d(const Scene& s, ParticleArrays& p) {
  const double v0 = s.velocity_amplitude;
  const double rho_ref = s.fluid.reference_density;
  const double c2 = s.fluid.sound_speed * s.fluid.sound_speed;
  const double cell_volume = std::pow(s.particle_spacing(), 2);
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double x = p.position[0][i], y = p.position[1][i];
    const std::array<double, 2> v = taylor_green_2d_velocity(v0, 0.0, 0.0, x, y);
    p.velocity[0][i] = v[0] + s.uniform_velocity[0];
    p.velocity[1][i] = v[1] + s.uniform_velocity[1];
    const double p0_minus_ref = rho_ref * v0 * v0 / 4.0 * (std::cos(2.0 * x) + std::cos(2.0 * y));
    p.mass[i] = (rho_ref + p0_minus_ref / c2) * cell_volume;
  }
}

std::array<double, 2> taylor_green_2d_velocity(double v0, double kinematic_viscosity, double time,
                                               double x, double y) {
  const double amplitude = v0 * std::exp(-2.0 * kinematic_viscosity * time);  // §6.2
  return {amplitude * std::sin(x) * std::cos(y), -amplitude * std::cos(x) * std::sin(y)};
}

double taylor_green_2d_energy(double v0, double kinematic_viscosity, double time) {
  return 0.25 * v0 * v0 * std::exp(-4.0 * kinematic_viscosity * time);
}

void set_kolmogorov_2d(const Scene& s, ParticleArrays& p) {
  const double cell_volume = std::pow(s.particle_spacing(), 2);
  for (std::size_t i = 0; i < p.size(); ++i) {
    p.velocity[0][i] = s.uniform_velocity[0];
    p.velocity[1][i] = s.uniform_velocity[1];
    p.mass[i] = s.fluid.reference_density * cell_volume;
  }
}

ExternalAcceleration kolmogorov_acceleration(const KolmogorovForcing& forcing, double wavenumber) {
  return [forcing, wavenumber](double, const ParticleArrays& p, const VelocityView& velocity,
                               std::array<std::vector<double>, 3>& acceleration) {
    const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t si = 0; si < n; ++si) {
      const auto i = static_cast<std::size_t>(si);
      // a = χ sin(k_y y) e_x - μ v (SPEC §6.3)
      acceleration[0][i] += forcing.amplitude * std::sin(wavenumber * p.position[1][i]) -
                            forcing.friction * velocity.v[0][i];
      acceleration[1][i] -= forcing.friction * velocity.v[1][i];
    }
  };
}

double kolmogorov_laminar_velocity(const KolmogorovForcing& forcing, double wavenumber,
                                   double kinematic_viscosity, double y) {
  return forcing.amplitude * std::sin(wavenumber * y) /
         (kinematic_viscosity * wavenumber * wavenumber + forcing.friction);
}

std::vector<double> summed_volumes(const SolverConfig& config, const ParticleArrays& particles,
                                   Exchange& exchange) {
  ParticleArrays p = particles;
  const std::size_t owned = p.size();
  p.volume.resize(owned);
  p.density.resize(owned);
  p.pressure.resize(owned);
  exchange.build_halo(p);  // every particle lies in this process' part: none migrates
  VerletNeighbourSearch search(config.box, config.support_radius, 0.0);
  search.build(view_positions(p), order_by_key(p.id), owned);
  with_kernel(config.kernel, config.box.dimension, config.support_radius, [&](const auto& kernel) {
    using KernelT = std::decay_t<decltype(kernel)>;
    density_pass<KernelT::dimension>(kernel, config.box, search.list(), config.fluid, p);
  });
  p.volume.resize(owned);
  return std::move(p.volume);
}

std::vector<double> summed_volumes(const SolverConfig& config, const ParticleArrays& particles) {
  LocalExchange one_process;
  return summed_volumes(config, particles, one_process);
}

void set_summation_masses(const SolverConfig& config, double lattice_cell_volume,
                          ParticleArrays& particles, Exchange& exchange) {
  const std::vector<double> volume = summed_volumes(config, particles, exchange);
  for (std::size_t i = 0; i < particles.size(); ++i) {
    const double rho0 = particles.mass[i] / lattice_cell_volume;  // the case's ρ0_i
    particles.mass[i] = rho0 * volume[i];                         // M_i = ρ0_i V_i, (A.1)-(A.2)
  }
}

void set_case_fields(const Scene& scene, const SolverConfig& config, ParticleArrays& particles,
                     Exchange& exchange) {
  switch (scene.case_type) {
    case CaseType::TaylorGreen3D:
      set_taylor_green_3d(scene, particles);
      break;
    case CaseType::TaylorGreen2D:
      set_taylor_green_2d(scene, particles);
      break;
    case CaseType::Kolmogorov2D:
      set_kolmogorov_2d(scene, particles);
      break;
  }
  if (scene.initial.mass == InitialMass::Summation)
    set_summation_masses(config, std::pow(scene.particle_spacing(), scene.dimension()), particles,
                         exchange);
}

SolverConfig make_solver_config(const Scene& scene) {
  SolverConfig c;
  c.box.dimension = scene.dimension();
  for (int d = 0; d < c.box.dimension; ++d) c.box.length[d] = scene.box_length();
  c.kernel = scene.kernel;
  c.support_radius = 0.5 * scene.kernel_diameter();
  c.particle_spacing = scene.particle_spacing();
  c.fluid = scene.fluid;
  c.time_step = scene.time_step;
  c.blow_up = scene.blow_up;
  c.neighbour_skin = scene.neighbour_skin;
  c.scheme = scene.scheme;
  c.subfilter = scene.subfilter;
  if (scene.case_type == CaseType::Kolmogorov2D)
    c.external = kolmogorov_acceleration(scene.forcing, scene.forcing_wavenumber());
  return c;
}

RunSetup setup_run(const Scene& scene, const SetupOptions& options) {
  RunSetup setup;
  setup.solver = make_solver_config(scene);
  setup.particles = packed_positions(scene, &setup.packing, options);
  LocalExchange one_process;
  set_case_fields(scene, setup.solver, setup.particles, one_process);
  return setup;
}

}  // namespace sphles::sim
