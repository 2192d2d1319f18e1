#include "analysis/snapshot.hpp"

#include <algorithm>
#include <stdexcept>

#include "analysis/products.hpp"
#include "sim/solver.hpp"

namespace sphles::analysis {

namespace {

std::shared_ptr<Snapshot> describe(const sim::Simulation& simulation, double energy_dissipation) {
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
  return snapshot;
}

void copy_particles(const sim::Simulation& simulation, Snapshot& snapshot) {
  snapshot.particles = simulation.particles();
  snapshot.neighbours = simulation.neighbour_list();
}

bool cubic(const sim::PeriodicBox& box) {
  for (int a = 1; a < box.dimension; ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0]) return false;
  return true;
}

}  // namespace

DistributedProducts::~DistributedProducts() = default;

SnapshotPtr make_snapshot(const sim::Simulation& simulation, double energy_dissipation) {
  auto snapshot = describe(simulation, energy_dissipation);
  copy_particles(simulation, *snapshot);
  return snapshot;
}

SnapshotPtr make_snapshot(const sim::Simulation& simulation, const AnalysisConfig& config,
                          double energy_dissipation) {
  auto snapshot = describe(simulation, energy_dissipation);
  const auto* ranks = dynamic_cast<const DistributedProducts*>(&simulation);
  const bool wants_spectrum = std::ranges::any_of(config.products, served_by_ranks);
  if (ranks && wants_spectrum && config.gridding.velocity == VelocityGridding::Nearest &&
      cubic(snapshot->box)) {
    try {
      snapshot->velocity_spectrum =
          ranks->velocity_spectrum(analysis_grid(*snapshot, config).points_per_side);
    } catch (const std::invalid_argument&) {
      // The ranks could not grid it (a void wider than their halo): gathered and gridded whole.
    }
  }
  const bool needs_particles =
      !snapshot->velocity_spectrum || !std::ranges::all_of(config.products, served_by_ranks);
  if (needs_particles)
    copy_particles(simulation, *snapshot);
  else
    snapshot->has_particles = false;
  return snapshot;
}

}  // namespace sphles::analysis
