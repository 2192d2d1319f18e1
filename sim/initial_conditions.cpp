#include "sim/initial_conditions.hpp"

#include <cmath>

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
    p.velocity[0][i] = v0 * std::sin(x) * std::cos(y) + s.uniform_velocity[0];
    p.velocity[1][i] = -v0 * std::cos(x) * std::sin(y) + s.uniform_velocity[1];
    const double p0_minus_ref = rho_ref * v0 * v0 / 4.0 * (std::cos(2.0 * x) + std::cos(2.0 * y));
    p.mass[i] = (rho_ref + p0_minus_ref / c2) * cell_volume;
  }
}

double taylor_green_2d_energy(double v0, double kinematic_viscosity, double time) {
  return 0.25 * v0 * v0 * std::exp(-4.0 * kinematic_viscosity * time);
}

RunSetup setup_run(const Scene& scene) {
  RunSetup setup;
  SolverConfig& c = setup.solver;
  c.box.dimension = scene.dimension();
  for (int d = 0; d < c.box.dimension; ++d) c.box.length[d] = scene.box_length();
  c.kernel = scene.kernel;
  c.support_radius = 0.5 * scene.kernel_diameter();
  c.particle_spacing = scene.particle_spacing();
  c.fluid = scene.fluid;
  c.time_step = scene.time_step;
  c.neighbour_skin = scene.neighbour_skin;

  setup.particles = packed_positions(scene, &setup.packing);
  switch (scene.case_type) {
    case CaseType::TaylorGreen3D:
      set_taylor_green_3d(scene, setup.particles);
      break;
    case CaseType::TaylorGreen2D:
      set_taylor_green_2d(scene, setup.particles);
      break;
  }
  return setup;
}

}  // namespace sphles::sim
