// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/snapshot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

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

/// The particles, and the solver's neighbour list when `with_list` (only the "particle"
/// vorticity estimate reads it: holding it makes the solver allocate a new list at its next
/// rebuild, and a distributed solver builds one over the gathered particles to hand it out).
void copy_particles(const sim::Simulation& simulation, Snapshot& snapshot, bool with_list) {
  snapshot.particles = simulation.particles();
  if (with_list) snapshot.neighbours = simulation.neighbour_list();
}

bool cubic(const sim::PeriodicBox& box) {
  for (int a = 1; a < box.dimension; ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0]) return false;
  return true;
}

}  // namespace

DistributedProducts::~DistributedProducts() = default;

std::uint64_t view_stride(std::uint64_t total, std::uint64_t max_points) {
  if (max_points == 0 || total <= max_points) return 1;
  return total / max_points + (total % max_points != 0 ? 1 : 0);
}

std::vector<std::size_t> view_point_indices(const sim::ParticleArrays& p, std::size_t count,
                                            std::uint64_t stride) {
  std::vector<std::size_t> chosen;
  for (std::size_t i = 0; i < count; ++i)
    if (p.id[i] % stride == 0) chosen.push_back(i);
  std::sort(chosen.begin(), chosen.end(),
            [&](std::size_t a, std::size_t b) { return p.id[a] < p.id[b]; });
  return chosen;
}

ViewPoints select_view_points(const sim::ParticleArrays& p, std::size_t count,
                              std::span<const double> values, SliceField field,
                              std::uint64_t stride) {
  return view_points_at(p, view_point_indices(p, count, stride), values, field, stride);
}

ViewPoints view_points_at(const sim::ParticleArrays& p, std::span<const std::size_t> chosen,
                          std::span<const double> values, SliceField field, std::uint64_t stride) {
  ViewPoints v;
  v.field = field;
  v.stride = stride;
  for (int a = 0; a < p.dimension; ++a) {
    std::vector<double>& x = v.position[static_cast<std::size_t>(a)];
    x.reserve(chosen.size());
    for (const std::size_t i : chosen) x.push_back(p.position[a][i]);
  }
  v.values.reserve(chosen.size());
  for (const std::size_t i : chosen) v.values.push_back(values[i]);
  return v;
}

Grid analysis_grid(const Snapshot& snapshot, const AnalysisConfig& config) {
  Grid grid;
  grid.dimension = snapshot.dimension();
  grid.length = snapshot.box.length[0];
  const long per_side = std::lround(grid.length / snapshot.particle_spacing);
  grid.points_per_side = static_cast<int>(per_side) * config.grid_points_per_spacing;
  return grid;
}

std::string timed_file_name(const std::string& prefix, double time, const std::string& extension) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "_t%.4f", time);
  return prefix + buffer + extension;
}

bool served_by_ranks(const AnalysisConfig& config, Product p, bool particle_file) {
  const bool mls = config.gridding.vorticity == VorticityEstimate::Mls;
  switch (p) {
    case Product::Particles:
      return particle_file &&
             (mls || !config.particle_fields.contains(SliceField::VorticitySquared));
    case Product::Fields:
      return (!config.grid_velocity || config.gridding.velocity == VelocityGridding::Nearest) &&
             (mls || !config.grid_fields.contains(SliceField::VorticitySquared));
    case Product::Energy:
    case Product::Spectrum:
      return config.gridding.velocity == VelocityGridding::Nearest;
    case Product::Vorticity:
    case Product::SubfilterStatistics:
      return mls;
    case Product::Slices:
      // ω² is the mls estimate's; |τ_SFS| and ν_t are the nearest particle's under any.
      return std::ranges::all_of(config.slice.fields, [&](SliceField f) {
        return f != SliceField::VorticitySquared || mls;
      });
    default:
      return false;
  }
}

RanksRequest ranks_request(const Snapshot& snapshot, const AnalysisConfig& config,
                           const ParticleFileTarget* particles) {
  RanksRequest r;
  r.points_per_side = analysis_grid(snapshot, config).points_per_side;
  r.fit_radius = config.gridding.fit_radius * snapshot.support_radius;
  r.vorticity = config.wants(Product::Vorticity);
  const bool slices = config.wants(Product::Slices);
  r.slice_omega2 = slices && config.slice.fields.contains(SliceField::VorticitySquared);
  r.slice_tau = slices && config.slice.fields.contains(SliceField::SubfilterStressNorm);
  r.slice_eddy = slices && config.slice.fields.contains(SliceField::EddyViscosity);
  if (r.slice_omega2 || r.slice_tau || r.slice_eddy) {
    r.slice_axis = config.slice.axis;
    r.slice_position = config.slice.position;
  }
  r.statistics = config.wants(Product::SubfilterStatistics);
  if (r.statistics) {
    r.histogram_bins = config.histogram_bins;
    r.angle_bins = config.angle_bins;
    r.angle_threshold = config.angle_threshold;
  }
  if (config.wants(Product::Fields)) {
    r.fields.velocity = config.grid_velocity;
    r.fields.omega2 = config.grid_fields.contains(SliceField::VorticitySquared);
    r.fields.tau = config.grid_fields.contains(SliceField::SubfilterStressNorm);
    r.fields.eddy = config.grid_fields.contains(SliceField::EddyViscosity);
  }
  if (particles && config.wants(Product::Particles)) {
    r.particles.path =
        (particles->directory / timed_file_name("particles", snapshot.time, ".h5")).string();
    r.particles.omega2 = config.particle_fields.contains(SliceField::VorticitySquared);
    r.particles.tau = config.particle_fields.contains(SliceField::SubfilterStressNorm);
    r.particles.eddy = config.particle_fields.contains(SliceField::EddyViscosity);
    r.particles.time = snapshot.time;
    r.particles.step = snapshot.step;
    r.particles.metadata = particles->metadata;
  }
  if (config.wants(Product::Particles) && config.particle_fields.contains(snapshot.view.field))
    r.view = snapshot.view;
  return r;
}

SnapshotPtr make_snapshot(const sim::Simulation& simulation, double energy_dissipation) {
  auto snapshot = describe(simulation, energy_dissipation);
  copy_particles(simulation, *snapshot, true);
  return snapshot;
}

SnapshotPtr make_snapshot(const sim::Simulation& simulation, const AnalysisConfig& config,
                          double energy_dissipation, const ParticleFileTarget* particles,
                          const ViewPointsRequest& view, const DistributedProducts* ranks) {
  auto snapshot = describe(simulation, energy_dissipation);
  snapshot->view = view;
  const bool on_ranks = ranks && cubic(snapshot->box);
  const auto served = [&](Product p) {
    return on_ranks && served_by_ranks(config, p, particles != nullptr);
  };
  // What the ranks could not compute (they throw std::invalid_argument: a void wider than their
  // halo) is gathered and computed whole.
  if ((config.wants(Product::Energy) && served(Product::Energy)) ||
      (config.wants(Product::Spectrum) && served(Product::Spectrum))) {
    try {
      snapshot->velocity_spectrum =
          ranks->velocity_spectrum(analysis_grid(*snapshot, config).points_per_side);
    } catch (const std::invalid_argument&) {
    }
  }
  // The particle products only when the ranks serve every product, so that nothing is gathered
  // (with particles gathered for another product, analyse computes them from those).
  const bool all_served = !config.products.empty() && std::ranges::all_of(config.products, served);
  const bool particle_products = config.wants(Product::Vorticity) ||
                                 config.wants(Product::Slices) ||
                                 config.wants(Product::SubfilterStatistics) ||
                                 config.wants(Product::Particles) || config.wants(Product::Fields);
  if (all_served && particle_products) {
    try {
      snapshot->ranks = ranks->particle_products(ranks_request(*snapshot, config, particles));
    } catch (const std::invalid_argument&) {
    }
  }
  const auto from_ranks = [&](Product p) {
    if (p == Product::Energy || p == Product::Spectrum)
      return snapshot->velocity_spectrum.has_value();
    if (p == Product::Particles) return snapshot->ranks && snapshot->ranks->particles;
    return snapshot->ranks.has_value();
  };
  if (all_served && std::ranges::all_of(config.products, from_ranks))
    snapshot->has_particles = false;
  else
    copy_particles(simulation, *snapshot, config.gridding.vorticity == VorticityEstimate::Particle);
  return snapshot;
}

}  // namespace sphles::analysis
