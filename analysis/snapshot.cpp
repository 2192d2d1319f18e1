#include "analysis/snapshot.hpp"

#include <algorithm>
#include <set>
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

bool served_by_ranks(const AnalysisConfig& config, Product p) {
  const bool mls = config.gridding.vorticity == VorticityEstimate::Mls;
  switch (p) {
    case Product::Energy:
    case Product::Spectrum:
      return config.gridding.velocity == VelocityGridding::Nearest;
    case Product::Vorticity:
      return mls;
    case Product::Slices:
      return mls && config.slice.fields == std::set<SliceField>{SliceField::VorticitySquared};
    default:
      return false;
  }
}

VorticityRequest vorticity_request(const Snapshot& snapshot, const AnalysisConfig& config) {
  VorticityRequest r;
  r.points_per_side = analysis_grid(snapshot, config).points_per_side;
  r.fit_radius = config.gridding.fit_radius * snapshot.support_radius;
  r.slice =
      config.wants(Product::Slices) && config.slice.fields.contains(SliceField::VorticitySquared);
  if (r.slice) {
    r.slice_axis = config.slice.axis;
    r.slice_position = config.slice.position;
  }
  return r;
}

SnapshotPtr make_snapshot(const sim::Simulation& simulation, double energy_dissipation) {
  auto snapshot = describe(simulation, energy_dissipation);
  copy_particles(simulation, *snapshot);
  return snapshot;
}

SnapshotPtr make_snapshot(const sim::Simulation& simulation, const AnalysisConfig& config,
                          double energy_dissipation) {
  auto snapshot = describe(simulation, energy_dissipation);
  const auto* ranks = dynamic_cast<const DistributedProducts*>(&simulation);
  const auto served = [&](Product p) { return ranks && served_by_ranks(config, p); };
  // What the ranks could not compute (they throw std::invalid_argument: a void wider than their
  // halo) is gathered and computed whole.
  const bool spectrum = served(Product::Energy) || served(Product::Spectrum);
  if (spectrum && (config.wants(Product::Energy) || config.wants(Product::Spectrum)) &&
      cubic(snapshot->box)) {
    try {
      snapshot->velocity_spectrum =
          ranks->velocity_spectrum(analysis_grid(*snapshot, config).points_per_side);
    } catch (const std::invalid_argument&) {
    }
  }
  // Only when no other product needs ω at every particle (which analyse would then compute from
  // the gathered particles anyway): the histogram of sfs_stats, ω² in particle snapshots or on
  // the whole grid.
  const bool particle_vorticity_needed =
      config.wants(Product::SubfilterStatistics) ||
      (config.wants(Product::Particles) &&
       config.particle_fields.contains(SliceField::VorticitySquared)) ||
      (config.wants(Product::Fields) && config.grid_fields.contains(SliceField::VorticitySquared));
  if (!particle_vorticity_needed &&
      ((config.wants(Product::Vorticity) && served(Product::Vorticity)) ||
       (config.wants(Product::Slices) && served(Product::Slices)))) {
    try {
      snapshot->vorticity = ranks->fitted_vorticity(vorticity_request(*snapshot, config));
    } catch (const std::invalid_argument&) {
    }
  }
  const auto from_ranks = [&](Product p) {
    switch (p) {
      case Product::Energy:
      case Product::Spectrum:
        return snapshot->velocity_spectrum.has_value();
      case Product::Vorticity:
        return snapshot->vorticity.has_value();
      case Product::Slices:
        return snapshot->vorticity.has_value() && served(Product::Slices);
      default:
        return false;
    }
  };
  if (!config.products.empty() && std::ranges::all_of(config.products, from_ranks))
    snapshot->has_particles = false;
  else
    copy_particles(simulation, *snapshot);
  return snapshot;
}

}  // namespace sphles::analysis
