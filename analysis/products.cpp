// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/products.hpp"

#include <chrono>
#include <cmath>
#include <numbers>
#include <set>
#include <utility>

#include "analysis/grid.hpp"
#include "analysis/local_fit.hpp"
#include "analysis/subfilter_stress.hpp"
#include "analysis/vorticity.hpp"
#include "sim/reduction.hpp"

namespace sphles::analysis {

namespace {

/// Runs a stage, records its wall time, returns its result.
class StageTimer {
 public:
  explicit StageTimer(AnalysisFrame& frame) : frame_(frame) {}
  template <class F>
  auto operator()(const char* name, F&& stage) {
    const auto start = std::chrono::steady_clock::now();
    auto result = stage();
    frame_.timings.emplace_back(
        name, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    return result;
  }

 private:
  AnalysisFrame& frame_;
};

std::string units(SliceField field) {
  return std::string(slice_field_units(field));
}

/// The slice's geometry and, in `nodes`, the grid node of every slice value (u fastest).
SliceProduct slice_layout(const Grid& grid, SliceField name, const SliceConfig& config,
                          std::vector<std::size_t>& nodes) {
  SliceProduct s;
  s.field = name;
  s.units = units(name);
  s.spacing = grid.spacing();
  const int m = grid.points_per_side;
  s.width = m;
  s.height = m;
  nodes.resize(static_cast<std::size_t>(m) * static_cast<std::size_t>(m));
  if (grid.dimension == 2) {
    s.normal_axis = 2;
    s.axis_u = 0;
    s.axis_v = 1;
    for (std::size_t n = 0; n < nodes.size(); ++n) nodes[n] = n;
    return s;
  }
  s.normal_axis = config.axis;
  s.axis_u = config.axis == 0 ? 1 : 0;
  s.axis_v = config.axis == 2 ? 1 : 2;
  const long plane_index = std::lround(config.position / grid.spacing());
  const int plane = static_cast<int>(((plane_index % m) + m) % m);
  s.position = plane * grid.spacing();
  for (int iv = 0; iv < m; ++iv)
    for (int iu = 0; iu < m; ++iu) {
      std::array<int, 3> node{0, 0, 0};
      node[static_cast<std::size_t>(config.axis)] = plane;
      node[static_cast<std::size_t>(s.axis_u)] = iu;
      node[static_cast<std::size_t>(s.axis_v)] = iv;
      nodes[static_cast<std::size_t>(iu) + static_cast<std::size_t>(m) * iv] =
          grid.index(node[0], node[1], node[2]);
    }
  return s;
}

SliceProduct extract_slice(const Grid& grid, const std::vector<double>& field, SliceField name,
                           const SliceConfig& config) {
  std::vector<std::size_t> nodes;
  SliceProduct s = slice_layout(grid, name, config, nodes);
  s.values.resize(nodes.size());
  for (std::size_t n = 0; n < nodes.size(); ++n) s.values[n] = field[nodes[n]];
  return s;
}

}  // namespace

std::vector<std::size_t> slice_nodes(const Grid& grid, const SliceConfig& config) {
  std::vector<std::size_t> nodes;
  slice_layout(grid, SliceField::VorticitySquared, config, nodes);
  return nodes;
}

Grid analysis_grid(const Snapshot& snapshot, const AnalysisConfig& config) {
  Grid grid;
  grid.dimension = snapshot.dimension();
  grid.length = snapshot.box.length[0];
  const long per_side = std::lround(grid.length / snapshot.particle_spacing);
  grid.points_per_side = static_cast<int>(per_side) * config.grid_points_per_spacing;
  return grid;
}

AnalysisFrame analyse(const Snapshot& snapshot, const AnalysisConfig& config) {
  return analyse(SnapshotPtr(std::shared_ptr<const Snapshot>(), &snapshot), config);
}

AnalysisFrame analyse(const SnapshotPtr& snapshot_ptr, const AnalysisConfig& asked) {
  const Snapshot& snapshot = *snapshot_ptr;
  // The particle products the ranks computed, when they are what `asked` wants (a live change
  // may have changed the configuration since the snapshot was taken).
  // (The particle file, which only make_snapshot names, is not compared.)
  const auto matches = [&](RanksRequest request) {
    request.particles = {};
    return request == ranks_request(snapshot, asked);
  };
  const RanksProducts* ranks =
      snapshot.ranks && matches(snapshot.ranks->request) ? &*snapshot.ranks : nullptr;
  // A snapshot without particles (make_snapshot: every product it was taken for came from the
  // ranks) serves only the products that do not need them.
  AnalysisConfig reduced;
  if (!snapshot.has_particles) {
    reduced = asked;
    std::erase_if(reduced.products, [&](Product p) {
      if (p == Product::Energy || p == Product::Spectrum) return !snapshot.velocity_spectrum;
      return !ranks || !served_by_ranks(asked, p);
    });
  }
  const AnalysisConfig& config = snapshot.has_particles ? asked : reduced;
  const auto start = std::chrono::steady_clock::now();
  AnalysisFrame frame;
  frame.time = snapshot.time;
  frame.step = snapshot.step;
  frame.dimension = snapshot.dimension();
  frame.kinetic_energy = snapshot.kinetic_energy;
  frame.energy_dissipation = snapshot.energy_dissipation;
  StageTimer timed(frame);

  const bool want_vorticity_slice =
      config.wants(Product::Slices) && config.slice.fields.contains(SliceField::VorticitySquared);
  const bool want_stress_slice = config.wants(Product::Slices) &&
                                 config.slice.fields.contains(SliceField::SubfilterStressNorm);
  const bool vorticity_from_ranks = config.wants(Product::Vorticity) && ranks;
  const bool slice_from_ranks = want_vorticity_slice && ranks;
  const bool stress_slice_from_ranks = want_stress_slice && ranks;
  const bool statistics_from_ranks = config.wants(Product::SubfilterStatistics) && ranks;
  // The particle file the ranks wrote (make_snapshot) is this snapshot's product "particles",
  // even if a live change has since stopped asking for it: it is on disk.
  const WrittenParticles* written_by_ranks =
      snapshot.ranks && snapshot.ranks->particles ? &*snapshot.ranks->particles : nullptr;
  const bool want_particles = config.wants(Product::Particles) && !written_by_ranks;
  // The grid fields the ranks computed (on the ranks' grid, which is the configuration's).
  const bool fields_from_ranks = config.wants(Product::Fields) && ranks;
  const bool want_fields = config.wants(Product::Fields) && !fields_from_ranks;
  const auto grid_field = [&](SliceField f) {
    return want_fields && config.grid_fields.contains(f);
  };
  const bool want_field_velocity = want_fields && config.grid_velocity;
  const auto particle_field = [&](SliceField f) {
    return want_particles && config.particle_fields.contains(f);
  };
  const bool want_statistics = config.wants(Product::SubfilterStatistics) && !statistics_from_ranks;
  const bool want_stress_grid = (want_stress_slice && !stress_slice_from_ranks) ||
                                grid_field(SliceField::SubfilterStressNorm);
  const bool need_stress =
      want_statistics || want_stress_grid || particle_field(SliceField::SubfilterStressNorm);
  // ω² on the grid (mean, slice, fields) and at the particles (histogram, particle snapshot).
  const bool need_grid_vorticity = (config.wants(Product::Vorticity) && !vorticity_from_ranks) ||
                                   (want_vorticity_slice && !slice_from_ranks) ||
                                   grid_field(SliceField::VorticitySquared);
  const bool need_particle_omega2 = want_statistics || particle_field(SliceField::VorticitySquared);
  const VorticityEstimate estimate = config.gridding.vorticity;
  // The particle and mls estimates start from ω on every particle; grid from the gridded velocity.
  const bool particle_estimate = estimate != VorticityEstimate::Grid;
  const bool need_particle_vorticity =
      particle_estimate && (need_grid_vorticity || need_particle_omega2);
  // The spectrum the ranks computed (Snapshot::velocity_spectrum) serves energy and spectrum.
  const EnergySpectrum* ranks_spectrum =
      snapshot.velocity_spectrum ? &*snapshot.velocity_spectrum : nullptr;
  const bool need_velocity_grid =
      (!ranks_spectrum && (config.wants(Product::Energy) || config.wants(Product::Spectrum))) ||
      want_field_velocity || (!particle_estimate && (need_grid_vorticity || need_particle_omega2));
  const bool shepard_velocity_grid = config.gridding.velocity == VelocityGridding::Shepard;
  const bool has_eddy_viscosity = snapshot.particles.eddy_viscosity.size() == snapshot.size();
  const bool asks_eddy_slice =
      config.wants(Product::Slices) && config.slice.fields.contains(SliceField::EddyViscosity);
  // The ranks answer the ν_t slice when the run has ν_t (an empty slice otherwise).
  const bool eddy_slice_from_ranks = asks_eddy_slice && ranks && !ranks->slice_eddy.empty();
  const bool want_eddy_slice = asks_eddy_slice && has_eddy_viscosity && !ranks;
  const bool want_eddy_grid =
      want_eddy_slice || (grid_field(SliceField::EddyViscosity) && has_eddy_viscosity);
  // The node → particle map serves the nearest-particle velocity and the τ_SFS and ν_t grids.
  const bool need_map =
      (need_velocity_grid && !shepard_velocity_grid) || want_stress_grid || want_eddy_grid;
  const auto spectrum_product = [&](EnergySpectrum spectrum) {
    SpectrumProduct p;
    p.spectrum = std::move(spectrum);
    p.kinetic_energy_grid = spectrum_energy(p.spectrum);
    p.dissipation = spectral_dissipation(p.spectrum, snapshot.fluid.kinematic_viscosity());
    p.kernel_wavenumber = 2.0 * std::numbers::pi / (2.0 * snapshot.support_radius);
    p.resolution_wavenumber = std::numbers::pi / snapshot.particle_spacing;
    p.dissipation_resolved = spectral_dissipation(p.spectrum, snapshot.fluid.kinematic_viscosity(),
                                                  p.resolution_wavenumber);
    p.length_scale = config.spectrum_length_scale;
    return p;
  };
  if (ranks_spectrum) {
    // ½⟨|u'|²⟩ on the grid by Parseval (spectrum.hpp): grid_kinetic_energy to round-off.
    if (config.wants(Product::Energy))
      frame.grid_kinetic_energy = timed("energy", [&] { return spectrum_energy(*ranks_spectrum); });
    if (config.wants(Product::Spectrum))
      frame.spectrum = timed("spectrum", [&] { return spectrum_product(*ranks_spectrum); });
  }
  if (vorticity_from_ranks)
    frame.vorticity = timed("vorticity", [&] {
      VorticityProduct p;
      p.estimate = VorticityEstimate::Mls;
      p.mean_vorticity_squared = ranks->mean_vorticity_squared;
      p.dissipation = snapshot.fluid.kinematic_viscosity() * p.mean_vorticity_squared;  // (4.6)
      return p;
    });
  // A slice of the ranks' values: the layout of the analysis grid, their values.
  const auto ranks_slice = [&](SliceField field, const std::vector<double>& values) {
    std::vector<std::size_t> nodes;
    SliceProduct slice = slice_layout(analysis_grid(snapshot, config), field, config.slice, nodes);
    slice.values = values;
    return slice;
  };
  if (slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::VorticitySquared, ranks->slice_omega2));
  if (statistics_from_ranks) frame.subfilter = *ranks->statistics;
  if (stress_slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::SubfilterStressNorm, ranks->slice_tau));
  if (eddy_slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::EddyViscosity, ranks->slice_eddy));
  if (written_by_ranks) {
    ParticlesProduct p;
    p.snapshot = snapshot_ptr;
    p.file = snapshot.ranks->request.particles.path;
    p.count = written_by_ranks->count;
    for (const SliceField f : written_by_ranks->fields) p.fields.push_back({f, units(f), {}});
    p.view = snapshot.ranks->view;
    frame.particles = std::move(p);
  }
  if (fields_from_ranks) {
    GridFieldsProduct f{analysis_grid(snapshot, config), std::nullopt, {}};
    if (config.grid_velocity) {
      VectorField v{f.grid, {}};
      for (int a = 0; a < snapshot.dimension(); ++a)
        v.component[static_cast<std::size_t>(a)] =
            ranks->fields_velocity[static_cast<std::size_t>(a)];
      f.velocity = std::move(v);
    }
    const std::pair<SliceField, const std::vector<double>*> scalars[] = {
        {SliceField::VorticitySquared, &ranks->fields_omega2},
        {SliceField::SubfilterStressNorm, &ranks->fields_tau},
        {SliceField::EddyViscosity, &ranks->fields_eddy}};
    for (const auto& [field, values] : scalars)
      // ν_t only when the run has it (the ranks answer none otherwise, as analyse has none).
      if (config.grid_fields.contains(field) && !values->empty())
        f.scalars.push_back({field, units(field), *values});
    frame.fields = std::move(f);
  }
  if (!need_map && !need_velocity_grid && !need_stress && !need_particle_vorticity &&
      !want_particles && !want_fields) {
    // Nothing from the particles; the ranks' spectrum may have made energy and spectrum.
    frame.total_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return frame;
  }

  const Grid grid = analysis_grid(snapshot, config);
  const sim::ParticleArrays& particles = snapshot.particles;
  const InterpolationKernel kernel{snapshot.kernel, snapshot.support_radius};
  std::optional<NearestParticleMap> map;
  if (need_map) map = timed("grid_map", [&] { return nearest_particle_map(grid, particles); });
  std::optional<VectorField> velocity;  // mean removed (SPEC §5)
  std::optional<GridFieldsProduct> fields;
  if (want_fields) fields = GridFieldsProduct{grid, std::nullopt, {}};
  if (need_velocity_grid)
    velocity = timed("grid_velocity", [&] {
      // The fields product keeps the velocity with its mean; the rest uses the fluctuation.
      VectorField v = shepard_velocity_grid
                          ? shepard_velocity(grid, particles, kernel, !want_field_velocity)
                          : sample_velocity(*map, particles, !want_field_velocity);
      if (want_field_velocity) {
        fields->velocity = v;
        remove_spatial_mean(v);
      }
      return v;
    });

  if (!ranks_spectrum && config.wants(Product::Energy))
    frame.grid_kinetic_energy = timed("energy", [&] { return grid_kinetic_energy(*velocity); });
  if (!ranks_spectrum && config.wants(Product::Spectrum))
    frame.spectrum =
        timed("spectrum", [&] { return spectrum_product(energy_spectrum(*velocity)); });

  // One neighbour list for the per-particle passes (the solver's, when the snapshot has it).
  std::shared_ptr<const sim::NeighbourList> neighbours;
  const auto neighbour_list = [&]() -> const sim::NeighbourList& {
    if (!neighbours)
      neighbours = timed("neighbours", [&] { return snapshot_neighbours(snapshot); });
    return *neighbours;
  };

  // ω per particle (particle and mls estimates), and ω² per particle: the particle estimate's
  // own value, or the grid value at the nearest node.
  const FitSettings fit{snapshot.kernel, config.gridding.fit_radius * snapshot.support_radius};
  std::optional<ParticleVorticity> omega;
  std::vector<double> particle_vorticity_squared;
  if (need_particle_vorticity) {
    omega = timed("particle_vorticity", [&] {
      return estimate == VorticityEstimate::Mls ? fitted_particle_vorticity(snapshot, grid, fit)
                                                : particle_vorticity(snapshot, neighbour_list());
    });
    particle_vorticity_squared = omega->squared_magnitude();
  }

  // ω² on the grid nodes: the whole grid, except for the mls estimate when only the slice needs
  // it (its local fits cost (R/Δl)^n per node), which fits the slice's nodes alone.
  const bool mls = estimate == VorticityEstimate::Mls;
  const bool need_whole_grid_vorticity =
      mls ? grid_field(SliceField::VorticitySquared)
          : need_grid_vorticity || (!particle_estimate && need_particle_omega2);
  std::vector<double> vorticity_squared;
  if (need_whole_grid_vorticity)
    vorticity_squared = timed("vorticity", [&] {
      if (mls) return fitted_vorticity_squared(grid, particles, fit, *omega, {});
      if (particle_estimate) {
        const std::span<const double> field(particle_vorticity_squared);
        return std::move(shepard_sample(grid, particles, kernel, {&field, 1}).front());
      }
      return squared_magnitude(vorticity(*velocity));
    });
  if (config.wants(Product::Vorticity) && !vorticity_from_ranks) {
    VorticityProduct p;
    p.estimate = estimate;
    // mls: the volume-weighted mean over the particles, Σ V ω² / Σ V (the fits are pointwise,
    // and a grid of Δl/2 would cost 2^n fits per particle); otherwise the mean over the nodes.
    p.mean_vorticity_squared = mls ? volume_weighted_mean(particles, particle_vorticity_squared)
                                   : mean_value(vorticity_squared);
    p.dissipation = snapshot.fluid.kinematic_viscosity() * p.mean_vorticity_squared;  // (4.6)
    frame.vorticity = p;
  }
  if (!particle_estimate && need_particle_omega2) {
    const std::vector<std::size_t> node = nearest_node(grid, particles);
    particle_vorticity_squared.resize(particles.size());
    for (std::size_t i = 0; i < particles.size(); ++i)
      particle_vorticity_squared[i] = vorticity_squared[node[i]];
  }

  std::optional<SubfilterStressField> stress;
  if (need_stress)
    stress = timed("subfilter_stress", [&] { return implicit_subfilter_stress(snapshot); });

  if (want_statistics) {
    frame.subfilter = timed("sfs_statistics", [&] {
      // As the ranks of a distributed run compute it (par/particle_products.hpp): maxima, an
      // exact sum, counts.
      SubfilterStatisticsProduct p;
      const std::vector<double>& norm = stress->norm;
      p.max_norm = max_value(norm);
      p.mean_norm =
          norm.empty()
              ? 0.0
              : sim::exact_sum(norm.size(), [&](std::size_t i) { return norm[i]; }).value() /
                    static_cast<double>(norm.size());
      p.joint = bivariate_histogram(norm, particle_vorticity_squared, p.max_norm,
                                    max_value(particle_vorticity_squared), config.histogram_bins,
                                    config.histogram_bins);
      if (snapshot.dimension() == 2)
        p.alignment = principal_direction_alignment(*stress, particles, config.angle_bins,
                                                    config.angle_threshold, p.max_norm);
      return p;
    });
  }

  if (want_vorticity_slice && !slice_from_ranks)
    frame.slices.push_back(timed("slice_omega2", [&] {
      if (!vorticity_squared.empty())
        return extract_slice(grid, vorticity_squared, SliceField::VorticitySquared, config.slice);
      std::vector<std::size_t> nodes;
      SliceProduct slice = slice_layout(grid, SliceField::VorticitySquared, config.slice, nodes);
      slice.values = fitted_vorticity_squared(grid, particles, fit, *omega, nodes);
      return slice;
    }));
  std::vector<double> stress_grid;  // |τ_SFS| at the nearest particle of each node
  if (want_stress_grid)
    stress_grid = timed("grid_tau_sfs", [&] { return sample_scalar(*map, stress->norm); });
  if (want_stress_slice && !stress_slice_from_ranks)
    frame.slices.push_back(timed("slice_tau_sfs", [&] {
      return extract_slice(grid, stress_grid, SliceField::SubfilterStressNorm, config.slice);
    }));

  if (want_particles) {
    ParticlesProduct p;
    p.snapshot = snapshot_ptr;
    if (particle_field(SliceField::VorticitySquared))
      p.fields.push_back({SliceField::VorticitySquared, units(SliceField::VorticitySquared),
                          particle_vorticity_squared});
    if (particle_field(SliceField::SubfilterStressNorm))
      p.fields.push_back(
          {SliceField::SubfilterStressNorm, units(SliceField::SubfilterStressNorm), stress->norm});
    if (particle_field(SliceField::EddyViscosity) &&
        snapshot.particles.eddy_viscosity.size() == snapshot.size())
      p.fields.push_back({SliceField::EddyViscosity, units(SliceField::EddyViscosity),
                          snapshot.particles.eddy_viscosity});
    if (snapshot.view.max_points > 0)
      for (const ParticleFieldProduct& f : p.fields)
        if (f.field == snapshot.view.field)
          p.view = select_view_points(snapshot.particles, snapshot.size(), f.values, f.field,
                                      view_stride(snapshot.size(), snapshot.view.max_points));
    frame.particles = std::move(p);
  }

  std::vector<double> eddy_grid;  // ν_t at the nearest particle of each node
  if (want_eddy_grid)
    eddy_grid =
        timed("grid_nu_t", [&] { return sample_scalar(*map, snapshot.particles.eddy_viscosity); });
  if (want_eddy_slice)
    frame.slices.push_back(timed("slice_nu_t", [&] {
      return extract_slice(grid, eddy_grid, SliceField::EddyViscosity, config.slice);
    }));

  if (want_fields) {
    if (grid_field(SliceField::VorticitySquared))
      fields->scalars.push_back({SliceField::VorticitySquared, units(SliceField::VorticitySquared),
                                 std::move(vorticity_squared)});
    if (grid_field(SliceField::SubfilterStressNorm))
      fields->scalars.push_back({SliceField::SubfilterStressNorm,
                                 units(SliceField::SubfilterStressNorm), std::move(stress_grid)});
    if (grid_field(SliceField::EddyViscosity) && has_eddy_viscosity)
      fields->scalars.push_back(
          {SliceField::EddyViscosity, units(SliceField::EddyViscosity), std::move(eddy_grid)});
    frame.fields = std::move(fields);
  }

  frame.total_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return frame;
}

}  // namespace sphles::analysis
