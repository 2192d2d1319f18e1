#include "analysis/snapshot.hpp"

#include "sim/solver.hpp"

namespace sphles::analysis {

SnapshotPtr make_snapshot(const sim::Simulation& simulation, double energy_dissipation) {
  auto snapshot = std::make_shared<Snapshot>();
  const sim::SolverConfig& config = simulation.config();
  snapshot->time = simulation.time();
  snapshot->step = simulation.step_count();
  snapshot->box = config.box;
  snapshot->kernel = config.kernel;
  snapshot->support_radius = config.support_radius;
  snapshot->particle_spacing = config.particle_spacing;
  snapshot->fluid = config.fluid;
  snapshot->kinetic_energy = simulation.diagnostics().kinetic_energy;
  snapshot->energy_dissipation = energy_dissipation;
  snapshot->particles = simulation.particles();
  snapshot->neighbours = simulation.neighbour_list();
  return snapshot;
}

}  // namespace sphles::analysis
