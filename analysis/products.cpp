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

AnalysisFrame analyse(const Snapshot& snapshot, const AnalysisConfig& config) {
  return analyse(SnapshotPtr(std::shared_ptr<const Snapshot>(), &snapshot), config);
}

namespace {

/// What a frame needs from which source, decided once from the configuration and from what the
/// ranks of a distributed run have already computed.
struct Plan {
  Plan(const AnalysisConfig& c, const RanksProducts* r) : config(c), ranks(r) {}

  const AnalysisConfig& config;
  const RanksProducts* ranks;                      // the ranks' particle products, when they match
  const EnergySpectrum* ranks_spectrum = nullptr;  // the ranks' spectrum (energy and spectrum)
  const WrittenParticles* written_by_ranks = nullptr;  // the particle file the ranks wrote
  bool want_vorticity_slice{}, want_stress_slice{};
  bool vorticity_from_ranks{}, slice_from_ranks{}, stress_slice_from_ranks{},
      statistics_from_ranks{};
  bool want_particles{}, fields_from_ranks{}, want_fields{}, want_field_velocity{},
      want_statistics{};
  bool want_stress_grid{}, need_stress{}, need_grid_vorticity{}, need_particle_omega2{};
  VorticityEstimate estimate{};
  bool particle_estimate{}, need_particle_vorticity{}, need_velocity_grid{},
      shepard_velocity_grid{};
  bool has_eddy_viscosity{}, eddy_slice_from_ranks{}, want_eddy_slice{}, want_eddy_grid{},
      need_map{};

  bool grid_field(SliceField f) const { return want_fields && config.grid_fields.contains(f); }
  bool particle_field(SliceField f) const {
    return want_particles && config.particle_fields.contains(f);
  }
  bool needs_particles() const {
    return need_map || need_velocity_grid || need_stress || need_particle_vorticity ||
           want_particles || want_fields;
  }
};

Plan plan_frame(const Snapshot& snapshot, const AnalysisConfig& config,
                const RanksProducts* ranks) {
  Plan p(config, ranks);
  p.want_vorticity_slice =
      config.wants(Product::Slices) && config.slice.fields.contains(SliceField::VorticitySquared);
  p.want_stress_slice = config.wants(Product::Slices) &&
                        config.slice.fields.contains(SliceField::SubfilterStressNorm);
  p.vorticity_from_ranks = config.wants(Product::Vorticity) && ranks;
  p.slice_from_ranks = p.want_vorticity_slice && ranks;
  p.stress_slice_from_ranks = p.want_stress_slice && ranks;
  p.statistics_from_ranks = config.wants(Product::SubfilterStatistics) && ranks;
  // The particle file the ranks wrote (make_snapshot) is this snapshot's product "particles",
  // even if a live change has since stopped asking for it: it is on disk.
  p.written_by_ranks =
      snapshot.ranks && snapshot.ranks->particles ? &*snapshot.ranks->particles : nullptr;
  p.want_particles = config.wants(Product::Particles) && !p.written_by_ranks;
  // The grid fields the ranks computed (on the ranks' grid, which is the configuration's).
  p.fields_from_ranks = config.wants(Product::Fields) && ranks;
  p.want_fields = config.wants(Product::Fields) && !p.fields_from_ranks;
  p.want_field_velocity = p.want_fields && config.grid_velocity;
  p.want_statistics = config.wants(Product::SubfilterStatistics) && !p.statistics_from_ranks;
  p.want_stress_grid = (p.want_stress_slice && !p.stress_slice_from_ranks) ||
                       p.grid_field(SliceField::SubfilterStressNorm);
  p.need_stress =
      p.want_statistics || p.want_stress_grid || p.particle_field(SliceField::SubfilterStressNorm);
  // ω² on the grid (mean, slice, fields) and at the particles (histogram, particle snapshot).
  p.need_grid_vorticity = (config.wants(Product::Vorticity) && !p.vorticity_from_ranks) ||
                          (p.want_vorticity_slice && !p.slice_from_ranks) ||
                          p.grid_field(SliceField::VorticitySquared);
  p.need_particle_omega2 = p.want_statistics || p.particle_field(SliceField::VorticitySquared);
  p.estimate = config.gridding.vorticity;
  // The particle and mls estimates start from ω on every particle; grid from the gridded velocity.
  p.particle_estimate = p.estimate != VorticityEstimate::Grid;
  p.need_particle_vorticity =
      p.particle_estimate && (p.need_grid_vorticity || p.need_particle_omega2);
  // The spectrum the ranks computed (Snapshot::velocity_spectrum) serves energy and spectrum.
  p.ranks_spectrum = snapshot.velocity_spectrum ? &*snapshot.velocity_spectrum : nullptr;
  p.need_velocity_grid =
      (!p.ranks_spectrum && (config.wants(Product::Energy) || config.wants(Product::Spectrum))) ||
      p.want_field_velocity ||
      (!p.particle_estimate && (p.need_grid_vorticity || p.need_particle_omega2));
  p.shepard_velocity_grid = config.gridding.velocity == VelocityGridding::Shepard;
  p.has_eddy_viscosity = snapshot.particles.eddy_viscosity.size() == snapshot.size();
  const bool asks_eddy_slice =
      config.wants(Product::Slices) && config.slice.fields.contains(SliceField::EddyViscosity);
  // The ranks answer the ν_t slice when the run has ν_t (an empty slice otherwise).
  p.eddy_slice_from_ranks = asks_eddy_slice && ranks && !ranks->slice_eddy.empty();
  p.want_eddy_slice = asks_eddy_slice && p.has_eddy_viscosity && !ranks;
  p.want_eddy_grid =
      p.want_eddy_slice || (p.grid_field(SliceField::EddyViscosity) && p.has_eddy_viscosity);
  // The node → particle map serves the nearest-particle velocity and the τ_SFS and ν_t grids.
  p.need_map =
      (p.need_velocity_grid && !p.shepard_velocity_grid) || p.want_stress_grid || p.want_eddy_grid;
  return p;
}

SpectrumProduct spectrum_product(const Snapshot& snapshot, const AnalysisConfig& config,
                                 EnergySpectrum spectrum) {
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
}

/// The products the ranks of a distributed run computed where the particles live.
void add_ranks_products(AnalysisFrame& frame, StageTimer& timed, const SnapshotPtr& snapshot_ptr,
                        const Plan& plan) {
  const Snapshot& snapshot = *snapshot_ptr;
  const AnalysisConfig& config = plan.config;
  const RanksProducts* ranks = plan.ranks;
  if (plan.ranks_spectrum) {
    // ½⟨|u'|²⟩ on the grid by Parseval (spectrum.hpp): grid_kinetic_energy to round-off.
    if (config.wants(Product::Energy))
      frame.grid_kinetic_energy =
          timed("energy", [&] { return spectrum_energy(*plan.ranks_spectrum); });
    if (config.wants(Product::Spectrum))
      frame.spectrum = timed(
          "spectrum", [&] { return spectrum_product(snapshot, config, *plan.ranks_spectrum); });
  }
  if (plan.vorticity_from_ranks)
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
  if (plan.slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::VorticitySquared, ranks->slice_omega2));
  if (plan.statistics_from_ranks) frame.subfilter = *ranks->statistics;
  if (plan.stress_slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::SubfilterStressNorm, ranks->slice_tau));
  if (plan.eddy_slice_from_ranks)
    frame.slices.push_back(ranks_slice(SliceField::EddyViscosity, ranks->slice_eddy));
  if (plan.written_by_ranks) {
    ParticlesProduct p;
    p.snapshot = snapshot_ptr;
    p.file = snapshot.ranks->request.particles.path;
    p.count = plan.written_by_ranks->count;
    for (const SliceField f : plan.written_by_ranks->fields) p.fields.push_back({f, units(f), {}});
    p.view = snapshot.ranks->view;
    frame.particles = std::move(p);
  }
  if (plan.fields_from_ranks) {
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
}

/// The products computed here from the snapshot's particles, stage by stage; each stage leaves
/// in it what a later one reuses (the node map, ω, the τ_SFS field, the grids of a field).
class LocalProducts {
 public:
  LocalProducts(const SnapshotPtr& snapshot_ptr, const Plan& plan, AnalysisFrame& frame,
                StageTimer& timed)
      : snapshot_ptr_(snapshot_ptr),
        snapshot_(*snapshot_ptr),
        plan_(plan),
        config_(plan.config),
        frame_(frame),
        timed_(timed),
        grid_(analysis_grid(snapshot_, config_)),
        particles_(snapshot_.particles),
        kernel_{snapshot_.kernel, snapshot_.support_radius},
        fit_{snapshot_.kernel, config_.gridding.fit_radius * snapshot_.support_radius} {}

  void run() {
    velocity();
    vorticity();
    subfilter_stress();
    stress_and_vorticity_slices();
    particles();
    eddy_viscosity();
    grid_fields();
  }

 private:
  /// The gridded velocity, ½⟨|u'|²⟩ and E(k) (SPEC §5).
  void velocity() {
    if (plan_.need_map)
      map_ = timed_("grid_map", [&] { return nearest_particle_map(grid_, particles_); });
    if (plan_.want_fields) fields_ = GridFieldsProduct{grid_, std::nullopt, {}};
    if (plan_.need_velocity_grid)
      velocity_ = timed_("grid_velocity", [&] {
        // The fields product keeps the velocity with its mean; the rest uses the fluctuation.
        VectorField v =
            plan_.shepard_velocity_grid
                ? shepard_velocity(grid_, particles_, kernel_, !plan_.want_field_velocity)
                : sample_velocity(*map_, particles_, !plan_.want_field_velocity);
        if (plan_.want_field_velocity) {
          fields_->velocity = v;
          remove_spatial_mean(v);
        }
        return v;
      });
    if (!plan_.ranks_spectrum && config_.wants(Product::Energy))
      frame_.grid_kinetic_energy =
          timed_("energy", [&] { return grid_kinetic_energy(*velocity_); });
    if (!plan_.ranks_spectrum && config_.wants(Product::Spectrum))
      frame_.spectrum = timed_("spectrum", [&] {
        return spectrum_product(snapshot_, config_, energy_spectrum(*velocity_));
      });
  }

  /// One neighbour list for the per-particle passes (the solver's, when the snapshot has it).
  const sim::NeighbourList& neighbour_list() {
    if (!neighbours_)
      neighbours_ = timed_("neighbours", [&] { return snapshot_neighbours(snapshot_); });
    return *neighbours_;
  }

  /// ω per particle (particle and mls estimates), ω² per particle (the particle estimate's own
  /// value, or the grid value at the nearest node) and on the grid, and ⟨ω²⟩.
  void vorticity() {
    const VorticityEstimate estimate = plan_.estimate;
    if (plan_.need_particle_vorticity) {
      omega_ = timed_("particle_vorticity", [&] {
        return estimate == VorticityEstimate::Mls
                   ? fitted_particle_vorticity(snapshot_, grid_, fit_)
                   : particle_vorticity(snapshot_, neighbour_list());
      });
      particle_vorticity_squared_ = omega_->squared_magnitude();
    }
    // ω² on the grid nodes: the whole grid, except for the mls estimate when only the slice
    // needs it (its local fits cost (R/Δl)^n per node), which fits the slice's nodes alone.
    const bool mls = estimate == VorticityEstimate::Mls;
    const bool need_whole_grid_vorticity =
        mls ? plan_.grid_field(SliceField::VorticitySquared)
            : plan_.need_grid_vorticity || (!plan_.particle_estimate && plan_.need_particle_omega2);
    if (need_whole_grid_vorticity)
      vorticity_squared_ = timed_("vorticity", [&] {
        if (mls) return fitted_vorticity_squared(grid_, particles_, fit_, *omega_, {});
        if (plan_.particle_estimate) {
          const std::span<const double> field(particle_vorticity_squared_);
          return std::move(shepard_sample(grid_, particles_, kernel_, {&field, 1}).front());
        }
        return squared_magnitude(sphles::analysis::vorticity(*velocity_));
      });
    if (config_.wants(Product::Vorticity) && !plan_.vorticity_from_ranks) {
      VorticityProduct p;
      p.estimate = estimate;
      // mls: the volume-weighted mean over the particles, Σ V ω² / Σ V (the fits are pointwise,
      // and a grid of Δl/2 would cost 2^n fits per particle); otherwise the mean over the nodes.
      p.mean_vorticity_squared = mls ? volume_weighted_mean(particles_, particle_vorticity_squared_)
                                     : mean_value(vorticity_squared_);
      p.dissipation = snapshot_.fluid.kinematic_viscosity() * p.mean_vorticity_squared;  // (4.6)
      frame_.vorticity = p;
    }
    if (!plan_.particle_estimate && plan_.need_particle_omega2) {
      const std::vector<std::size_t> node = nearest_node(grid_, particles_);
      particle_vorticity_squared_.resize(particles_.size());
      for (std::size_t i = 0; i < particles_.size(); ++i)
        particle_vorticity_squared_[i] = vorticity_squared_[node[i]];
    }
  }

  /// The implicit τ_SFS (SPEC §4) and its statistics.
  void subfilter_stress() {
    if (plan_.need_stress)
      stress_ = timed_("subfilter_stress", [&] { return implicit_subfilter_stress(snapshot_); });
    if (!plan_.want_statistics) return;
    frame_.subfilter = timed_("sfs_statistics", [&] {
      // As the ranks of a distributed run compute it (par/particle_products.hpp): maxima, an
      // exact sum, counts.
      SubfilterStatisticsProduct p;
      const std::vector<double>& norm = stress_->norm;
      p.max_norm = max_value(norm);
      p.mean_norm =
          norm.empty()
              ? 0.0
              : sim::exact_sum(norm.size(), [&](std::size_t i) { return norm[i]; }).value() /
                    static_cast<double>(norm.size());
      p.joint = bivariate_histogram(norm, particle_vorticity_squared_, p.max_norm,
                                    max_value(particle_vorticity_squared_), config_.histogram_bins,
                                    config_.histogram_bins);
      if (snapshot_.dimension() == 2)
        p.alignment = principal_direction_alignment(*stress_, particles_, config_.angle_bins,
                                                    config_.angle_threshold, p.max_norm);
      return p;
    });
  }

  void stress_and_vorticity_slices() {
    if (plan_.want_vorticity_slice && !plan_.slice_from_ranks)
      frame_.slices.push_back(timed_("slice_omega2", [&] {
        if (!vorticity_squared_.empty())
          return extract_slice(grid_, vorticity_squared_, SliceField::VorticitySquared,
                               config_.slice);
        std::vector<std::size_t> nodes;
        SliceProduct slice =
            slice_layout(grid_, SliceField::VorticitySquared, config_.slice, nodes);
        slice.values = fitted_vorticity_squared(grid_, particles_, fit_, *omega_, nodes);
        return slice;
      }));
    if (plan_.want_stress_grid)
      stress_grid_ = timed_("grid_tau_sfs", [&] { return sample_scalar(*map_, stress_->norm); });
    if (plan_.want_stress_slice && !plan_.stress_slice_from_ranks)
      frame_.slices.push_back(timed_("slice_tau_sfs", [&] {
        return extract_slice(grid_, stress_grid_, SliceField::SubfilterStressNorm, config_.slice);
      }));
  }

  void particles() {
    if (!plan_.want_particles) return;
    ParticlesProduct p;
    p.snapshot = snapshot_ptr_;
    if (plan_.particle_field(SliceField::VorticitySquared))
      p.fields.push_back({SliceField::VorticitySquared, units(SliceField::VorticitySquared),
                          particle_vorticity_squared_});
    if (plan_.particle_field(SliceField::SubfilterStressNorm))
      p.fields.push_back(
          {SliceField::SubfilterStressNorm, units(SliceField::SubfilterStressNorm), stress_->norm});
    if (plan_.particle_field(SliceField::EddyViscosity) && plan_.has_eddy_viscosity)
      p.fields.push_back({SliceField::EddyViscosity, units(SliceField::EddyViscosity),
                          snapshot_.particles.eddy_viscosity});
    if (snapshot_.view.max_points > 0)
      for (const ParticleFieldProduct& f : p.fields)
        if (f.field == snapshot_.view.field)
          p.view = select_view_points(snapshot_.particles, snapshot_.size(), f.values, f.field,
                                      view_stride(snapshot_.size(), snapshot_.view.max_points));
    frame_.particles = std::move(p);
  }

  /// ν_t of an explicit sub-filter model at the nearest particle of each node, and its slice.
  void eddy_viscosity() {
    if (plan_.want_eddy_grid)
      eddy_grid_ = timed_("grid_nu_t",
                          [&] { return sample_scalar(*map_, snapshot_.particles.eddy_viscosity); });
    if (plan_.want_eddy_slice)
      frame_.slices.push_back(timed_("slice_nu_t", [&] {
        return extract_slice(grid_, eddy_grid_, SliceField::EddyViscosity, config_.slice);
      }));
  }

  void grid_fields() {
    if (!plan_.want_fields) return;
    if (plan_.grid_field(SliceField::VorticitySquared))
      fields_->scalars.push_back({SliceField::VorticitySquared, units(SliceField::VorticitySquared),
                                  std::move(vorticity_squared_)});
    if (plan_.grid_field(SliceField::SubfilterStressNorm))
      fields_->scalars.push_back({SliceField::SubfilterStressNorm,
                                  units(SliceField::SubfilterStressNorm), std::move(stress_grid_)});
    if (plan_.grid_field(SliceField::EddyViscosity) && plan_.has_eddy_viscosity)
      fields_->scalars.push_back(
          {SliceField::EddyViscosity, units(SliceField::EddyViscosity), std::move(eddy_grid_)});
    frame_.fields = std::move(fields_);
  }

  const SnapshotPtr& snapshot_ptr_;
  const Snapshot& snapshot_;
  const Plan& plan_;
  const AnalysisConfig& config_;
  AnalysisFrame& frame_;
  StageTimer& timed_;
  const Grid grid_;
  const sim::ParticleArrays& particles_;
  const InterpolationKernel kernel_;
  const FitSettings fit_;
  std::optional<NearestParticleMap> map_;
  std::optional<VectorField> velocity_;  // mean removed (SPEC §5)
  std::optional<GridFieldsProduct> fields_;
  std::shared_ptr<const sim::NeighbourList> neighbours_;
  std::optional<ParticleVorticity> omega_;
  std::vector<double> particle_vorticity_squared_;
  std::vector<double> vorticity_squared_;
  std::optional<SubfilterStressField> stress_;
  std::vector<double> stress_grid_;  // |τ_SFS| at the nearest particle of each node
  std::vector<double> eddy_grid_;    // ν_t at the nearest particle of each node
};

}  // namespace

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

  const Plan plan = plan_frame(snapshot, config, ranks);
  add_ranks_products(frame, timed, snapshot_ptr, plan);
  // Nothing from the particles when the ranks' spectrum made energy and spectrum.
  if (plan.needs_particles()) LocalProducts(snapshot_ptr, plan, frame, timed).run();
  frame.total_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return frame;
}

}  // namespace sphles::analysis
