// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/solver.hpp"

#include <algorithm>
#include <cmath>
#include <span>
#include <sstream>

#include "sim/case_diagnostics.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/physics/subfilter_stress.hpp"
#include "sim/reduction.hpp"

namespace sphles::sim {

namespace {

void validate(const SolverConfig& c, const ParticleArrays& p, const Exchange& exchange) {
  if (c.box.dimension != 2 && c.box.dimension != 3)
    throw std::invalid_argument("solver: dimension must be 2 or 3");
  if (p.dimension != c.box.dimension)
    throw std::invalid_argument("solver: particle and box dimensions differ");
  // A process of a distributed run may own no particle; the run as a whole must have some.
  if (exchange.sum(std::uint64_t{p.size()}) == 0)
    throw std::invalid_argument("solver: no particles");
  if (!(c.support_radius > 0.0)) throw std::invalid_argument("solver: support radius must be > 0");
  if (!(c.particle_spacing > 0.0))
    throw std::invalid_argument("solver: particle spacing must be > 0");
  if (!(c.fluid.reference_density > 0.0) || !(c.fluid.sound_speed > 0.0) ||
      !(c.fluid.dynamic_viscosity >= 0.0))
    throw std::invalid_argument("solver: invalid fluid parameters");
  if (c.scheme.type == SchemeType::ParticleShifting &&
      (!(c.scheme.shifting_mach > 0.0) || !(c.support_radius > c.particle_spacing)))
    throw std::invalid_argument(
        "solver: particle shifting needs shifting_mach > 0 and a kernel support radius larger "
        "than the particle spacing (W(Δx) > 0)");
  if (!(c.blow_up.energy_factor > 1.0) || !(c.blow_up.reference_mach >= 0.0) ||
      !(c.blow_up.reference_energy >= 0.0))
    throw std::invalid_argument(
        "solver: blow-up thresholds need energy_factor > 1, reference_mach >= 0 and "
        "reference_energy >= 0");
}

template <class KernelT>
class SphSolver final : public Simulation {
  static constexpr int Dim = KernelT::dimension;

 public:
  SphSolver(const KernelT& kernel, const SolverConfig& config, ParticleArrays initial,
            double start_time, std::uint64_t start_step, std::shared_ptr<Exchange> exchange)
      : config_(config),
        kernel_(kernel),
        search_(config.box, config.support_radius, config.neighbour_skin * config.support_radius),
        particles_(std::move(initial)),
        exchange_(std::move(exchange)),
        owned_(particles_.size()),
        time_(start_time),
        step_(start_step) {
    for (int d = 0; d < Dim; ++d) {
      particles_.acceleration[d].resize(particles_.size());
      for (double& x : particles_.position[d]) x = wrap_periodic(x, config_.box.length[d]);
    }
    particles_.volume.resize(particles_.size());
    particles_.density.resize(particles_.size());
    particles_.pressure.resize(particles_.size());
    allocate_scheme_fields();  // ṽ = v at the start: zero shift
    rebuild_neighbours();
    evaluate_acceleration(view_velocity(particles_), time_);
    update_diagnostics(0.0);
    set_reference_energy();
    check_initial_state();
  }

  /// Restart from a saved state (see restore_simulation).
  SphSolver(const KernelT& kernel, const SolverConfig& config, SolverState state,
            std::shared_ptr<Exchange> exchange)
      : config_(config),
        kernel_(kernel),
        search_(config.box, config.support_radius, config.neighbour_skin * config.support_radius),
        particles_(std::move(state.particles)),
        exchange_(std::move(exchange)),
        owned_(particles_.size()),
        time_(state.time),
        step_(state.step) {
    if (exchange_->distributed()) {
      // The halo and lists of the saving run's last rebuild: placed and built at the reference
      // positions (this process owns the particles whose reference positions lie in its part,
      // par::share_of), then every particle takes its current position.
      std::array<std::vector<double>, 3> current;
      for (int d = 0; d < Dim; ++d) {
        current[d].swap(particles_.position[d]);
        particles_.position[d] = state.list_reference_positions[d];
      }
      exchange_->build_halo(particles_);
      search_.build(view_positions(particles_), order_by_key(particles_.id), owned_);
      count_neighbours();
      std::vector<std::vector<double>*> positions;
      for (int d = 0; d < Dim; ++d) {
        std::copy(current[d].begin(), current[d].end(), particles_.position[d].begin());
        positions.push_back(&particles_.position[d]);
      }
      exchange_->refresh(positions);
    } else {
      PositionsView reference;
      reference.dimension = Dim;
      reference.size = particles_.size();
      for (int d = 0; d < Dim; ++d) reference.x[d] = state.list_reference_positions[d].data();
      search_.build(reference, order_by_key(particles_.id));
      count_neighbours();
    }
    for (int d = 0; d < Dim; ++d) predicted_velocity_[d].resize(particles_.size());
    search_.set_num_builds(state.neighbour_builds);
    allocate_scheme_fields();
    if (transport_velocity_) recompute_scheme_fields();
    update_max_acceleration();
    update_diagnostics(0.0);
    set_reference_energy();
    check_initial_state();
  }

  SolverState state() const override {
    SolverState s;
    s.particles = particles_;
    s.list_reference_positions = search_.reference_positions();
    if (owned_ < particles_.size()) {  // this process' own particles, without the halo
      s.particles.truncate(owned_);
      for (std::vector<double>& x : s.list_reference_positions)
        x.resize(std::min(x.size(), owned_));
    }
    s.time = time_;
    s.step = step_;
    s.neighbour_builds = search_.num_builds();
    return s;
  }

  void step(double max_dt) override {
    const double dt = std::min(stable_time_step(), max_dt);
    if (!(dt > 0.0)) throw std::invalid_argument("solver: time step must be > 0");
    const double half_dt = 0.5 * dt;
    // Kick and drift: with v^{n+1/2}, or with the transport velocity v^{n+1/2} + δv, δv formed
    // by the scheme from the field of the last force evaluation (TVF: dt/2 ã^n, Adami et al.
    // 2013, eqs. 14-16; particle shifting: δv^n, Sun et al. 2019).
    visit_scheme(config_.scheme.type, [&](auto scheme) { kick_drift<decltype(scheme)>(dt); });
    // Every process rebuilds when a particle of any moved too far (the decision of one process).
    const bool rebuild = exchange_->any(search_.needs_rebuild(view_positions(particles_), owned_));
    if (rebuild) rebuild_neighbours();
    // Predicted end-of-step velocity for the velocity-dependent forces.
    const std::size_t n = owned_;
    VelocityView predicted;
    for (int d = 0; d < Dim; ++d) {
      const double* v = particles_.velocity[d].data();
      const double* a = particles_.acceleration[d].data();
      double* vp = predicted_velocity_[d].data();
#pragma omp parallel for schedule(static)
      for (std::size_t i = 0; i < n; ++i) vp[i] = v[i] + half_dt * a[i];
      predicted.v[d] = vp;
    }
    refresh_halo(!rebuild);
    time_ += dt;
    ++step_;
    evaluate_acceleration(predicted, time_);
    // Closing kick.
    for (int d = 0; d < Dim; ++d) {
      double* v = particles_.velocity[d].data();
      const double* a = particles_.acceleration[d].data();
#pragma omp parallel for schedule(static)
      for (std::size_t i = 0; i < n; ++i) v[i] += half_dt * a[i];
    }
    update_diagnostics(dt);
    check_blow_up();
  }

  double time() const override {
    return time_;
  }
  std::size_t owned_count() const override {
    return owned_;
  }
  std::uint64_t step_count() const override {
    return step_;
  }
  const StepDiagnostics& diagnostics() const override {
    return diagnostics_;
  }
  const ParticleArrays& particles() const override {
    return particles_;
  }
  std::shared_ptr<const NeighbourList> neighbour_list() const override {
    return search_.shared_list();
  }
  const SolverConfig& config() const override {
    return config_;
  }

  double stable_time_step() const override {
    return time_step_limits(config_.time_step, config_.particle_spacing, config_.fluid,
                            diagnostics_.max_speed, max_acceleration_)
        .step();
  }

  std::vector<double> case_diagnostics(const Scene& scene) const override {
    std::vector<ExactSum> sums = case_diagnostic_sums(scene, particles_, owned_);
    exchange_->sum(sums);
    return case_diagnostics_from_sums(scene, sums);
  }

 private:
  /// The opening kick v^{n+1/2} = v^n + dt/2 a^n and the drift x^{n+1} = x^n + dt (v^{n+1/2} +
  /// δv), δv = 0 or Scheme::drift_shift of SchemeFields::drift_source (stored in
  /// transport_shift for the force evaluation of the step).
  template <class Scheme>
  void kick_drift(double dt) {
    const double half_dt = 0.5 * dt;
    const std::size_t n = owned_;
    for (int d = 0; d < Dim; ++d) {
      double* v = particles_.velocity[d].data();
      double* x = particles_.position[d].data();
      const double* a = particles_.acceleration[d].data();
      const double length = config_.box.length[d];
      if constexpr (Scheme::transport_velocity) {
        const double* source = fields_.drift_source[d].data();
        double* shift = fields_.transport_shift[d].data();
#pragma omp parallel for schedule(static)
        for (std::size_t i = 0; i < n; ++i) {
          v[i] += half_dt * a[i];
          shift[i] = Scheme::drift_shift(dt, source[i]);
          x[i] = wrap_periodic(x[i] + dt * (v[i] + shift[i]), length);
        }
      } else {
#pragma omp parallel for schedule(static)
        for (std::size_t i = 0; i < n; ++i) {
          v[i] += half_dt * a[i];
          x[i] = wrap_periodic(x[i] + dt * v[i], length);
        }
      }
    }
  }

  /// Lists (and, distributed, the particles each process owns and its halo) for the current
  /// positions. The shift of the step being taken follows its particles (the drift source is
  /// rewritten before use).
  void rebuild_neighbours() {
    std::vector<std::vector<double>*> carried;
    if (transport_velocity_)
      for (int d = 0; d < Dim; ++d) carried.push_back(&fields_.transport_shift[d]);
    if (exchange_->distributed()) {
      particles_.truncate(owned_);  // drop the halo: migrate and reorder owned particles only
      for (std::vector<double>* values : carried) values->resize(owned_);
      exchange_->migrate(particles_, carried);
    }
    const auto order = search_.locality_order(view_positions(particles_));
    particles_.reorder(order);
    for (std::vector<double>* values : carried) reorder_array(*values, order);
    owned_ = particles_.size();
    exchange_->build_halo(particles_);
    for (int d = 0; d < Dim; ++d) {
      predicted_velocity_[d].resize(particles_.size());
      if (transport_velocity_) {
        fields_.transport_shift[d].resize(particles_.size());
        fields_.drift_source[d].resize(particles_.size());
      }
    }
    // Lists for the owned particles, neighbours within a cell in id order: a particle's list,
    // and so every sum over it, does not depend on where the particles sit in the arrays or on
    // which process holds them (par/).
    search_.build(view_positions(particles_), order_by_key(particles_.id), owned_);
    count_neighbours();
  }

  /// The mean list length over every process' owned particles, for the diagnostics: it changes
  /// only when the lists are built.
  void count_neighbours() {
    mean_neighbours_ = static_cast<double>(exchange_->sum(search_.list().num_entries())) /
                       static_cast<double>(exchange_->sum(std::uint64_t{owned_}));
  }

  /// Before a force evaluation: the halo copies take their owners' positions (unless a rebuild
  /// just placed them), predicted velocities and transport shifts.
  void refresh_halo(bool positions) {
    if (!exchange_->distributed()) return;
    std::vector<std::vector<double>*> fields;
    for (int d = 0; d < Dim; ++d) {
      if (positions) fields.push_back(&particles_.position[d]);
      fields.push_back(&predicted_velocity_[d]);
      if (transport_velocity_) fields.push_back(&fields_.transport_shift[d]);
    }
    exchange_->refresh(fields);
  }

  void reorder_array(std::vector<double>& values, std::span<const std::uint32_t> order) {
    scratch_.resize(values.size());
    for (std::size_t k = 0; k < order.size(); ++k) scratch_[k] = values[order[k]];
    values.swap(scratch_);
  }

  void allocate_scheme_fields() {
    fields_.scheme = config_.scheme;
    transport_velocity_ = scheme_uses_transport_velocity(config_.scheme.type);
    if (!transport_velocity_) return;
    fields_.shifting = shifting_parameters(
        config_.scheme.shifting_mach * config_.fluid.sound_speed, config_.support_radius,
        kernel_.value(config_.particle_spacing), config_.scheme.ale_correction);
    for (int d = 0; d < Dim; ++d) {
      fields_.drift_source[d].assign(particles_.size(), 0.0);
      fields_.transport_shift[d].assign(particles_.size(), 0.0);
    }
  }

  /// On restore: the drift source of the saving run's last force evaluation (TVF ã^n, particle
  /// shifting δv^n), by the same passes on the same positions and list (bitwise equal: both
  /// depend on neither velocity nor shift). The density
  /// pass rewrites V, ρ, p with the values they have; a^n is kept as stored.
  void recompute_scheme_fields() {
    const std::array<std::vector<double>, 3> stored = particles_.acceleration;
    visit_scheme(config_.scheme.type, [&](auto scheme) {
      decltype(scheme)::template evaluate<Dim>(kernel_, config_.box, search_.list(), config_.fluid,
                                               view_velocity(particles_), fields_, particles_,
                                               *exchange_);
    });
    particles_.acceleration = stored;
  }

  /// One force evaluation: the scheme's passes (the single dispatch per evaluation), then an
  /// explicit sub-filter model and the external acceleration.
  void evaluate_acceleration(const VelocityView& velocity, double time) {
    visit_scheme(config_.scheme.type, [&](auto scheme) {
      decltype(scheme)::template evaluate<Dim>(kernel_, config_.box, search_.list(), config_.fluid,
                                               velocity, fields_, particles_, *exchange_);
    });
    if (config_.subfilter.model != SubfilterModel::Implicit) add_subfilter_force(velocity);
    if (config_.external) config_.external(time, particles_, velocity, particles_.acceleration);
    update_max_acceleration();
  }

  void update_max_acceleration() {
    max_acceleration_ = exchange_->max(parallel_max(owned_, [&](std::size_t i) {
      double a2 = 0.0;
      for (int d = 0; d < Dim; ++d)
        a2 += particles_.acceleration[d][i] * particles_.acceleration[d][i];
      return a2;
    }));
    max_acceleration_ = std::sqrt(max_acceleration_);
  }

  /// Explicit model: gradient (A.20), ν_t (A.21/A.22), then force (A.18) or (A.23).
  void add_subfilter_force(const VelocityView& velocity) {
    const InteractionList& list = fields_.interactions;  // this evaluation's pairs
    velocity_gradient_pass<Dim>(kernel_, config_.box, list, velocity, particles_, gradient_);
    std::vector<double>& nu_t = particles_.eddy_viscosity;
    nu_t.resize(particles_.size());
    const double kernel_diameter = 2.0 * config_.support_radius;
    const auto n = static_cast<std::ptrdiff_t>(owned_);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i)
      nu_t[static_cast<std::size_t>(i)] = eddy_viscosity(config_.subfilter, kernel_diameter,
                                                         gradient_[static_cast<std::size_t>(i)]);
    if (exchange_->distributed()) refresh_subfilter_fields();
    visit_subfilter_model(config_.subfilter.model, [&](auto model) {
      if constexpr (decltype(model)::force == SubfilterForce::Central)
        subfilter_mcg_pass<Dim>(kernel_, config_.box, list, velocity, nu_t, particles_);
      else if constexpr (decltype(model)::force == SubfilterForce::Divergence)
        subfilter_divergence_pass<Dim>(kernel_, config_.box, list, gradient_, nu_t, particles_);
    });
  }

  /// The exchange point of the explicit models: the neighbours' J (the divergence form builds
  /// τ_j of it, A.19) and ν_t (both forms), through a flat copy of J.
  void refresh_subfilter_fields() {
    constexpr std::size_t kValues = 9;  // a VelocityGradient
    std::vector<double>& flat = scratch_;
    flat.resize(kValues * particles_.size());
    for (std::size_t i = 0; i < owned_; ++i)
      for (std::size_t a = 0; a < 3; ++a)
        for (std::size_t b = 0; b < 3; ++b) flat[kValues * i + 3 * a + b] = gradient_[i][a][b];
    std::vector<double>* fields[] = {&flat, &particles_.eddy_viscosity};
    exchange_->refresh(fields);
    for (std::size_t i = owned_; i < particles_.size(); ++i)
      for (std::size_t a = 0; a < 3; ++a)
        for (std::size_t b = 0; b < 3; ++b) gradient_[i][a][b] = flat[kValues * i + 3 * a + b];
  }

  /// Sums are exact (ExactSum), so they are the same bits however the particles are ordered
  /// and split over threads and processes.
  void update_diagnostics(double dt) {
    const ParticleArrays& p = particles_;
    const std::size_t n = owned_;
    StepDiagnostics& diag = diagnostics_;
    diag.time = time_;
    diag.step = step_;
    diag.dt = dt;
    // Σ M, Σ M v², Σ M v_d.
    std::array<ExactSum, 2 + Dim> sums = exact_sums<2 + Dim>(n, [&](std::size_t i, auto& term) {
      double v2 = 0.0;
      for (int d = 0; d < Dim; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
      term[0] = p.mass[i];
      term[1] = p.mass[i] * v2;
      for (int d = 0; d < Dim; ++d) term[2 + d] = p.mass[i] * p.velocity[d][i];
    });
    exchange_->sum(sums);
    diag.total_mass = sums[0].value();
    diag.kinetic_energy = 0.5 * sums[1].value() / diag.total_mass;  // (5.3)
    for (int d = 0; d < 3; ++d) diag.momentum[d] = d < Dim ? sums[2 + d].value() : 0.0;
    const double rho_ref = config_.fluid.reference_density;
    diag.max_density_deviation = exchange_->max(
        parallel_max(n, [&](std::size_t i) { return std::abs(p.density[i] - rho_ref) / rho_ref; }));
    diag.max_speed = std::sqrt(exchange_->max(parallel_max(n, [&](std::size_t i) {
      double v2 = 0.0;
      for (int d = 0; d < Dim; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
      return v2;
    })));
    diag.neighbour_builds = search_.num_builds();
    diag.mean_neighbours = mean_neighbours_;
  }

  /// Reference of the runaway test, from the energy of the state the solver starts from.
  void set_reference_energy() {
    reference_energy_ = runaway_reference_energy(diagnostics_.kinetic_energy,
                                                 config_.fluid.sound_speed, config_.blow_up);
  }

  /// A state the solver starts from (initial or restored) is scanned once in full: a NaN
  /// position, for example, drops out of every pair (distance comparisons are false) and would
  /// never reach the e_v sum. During a run positions only change through velocities, which
  /// check_blow_up covers.
  void check_initial_state() const {
    if (exchange_->any(find_non_finite(particles_).has_value())) report_non_finite();
    check_blow_up();
  }

  /// Blow-up test on figures update_diagnostics already has, so it costs a few comparisons: a
  /// single non-finite velocity or mass makes the e_v sum non-finite, a non-finite density or
  /// pressure makes the accelerations (hence the velocities of the closing kick) non-finite
  /// within the same step; parallel_max skips NaN, so the maxima only add the inf cases. Only
  /// when the test fires is the state scanned to name the particle.
  void check_blow_up() const {
    const StepDiagnostics& diag = diagnostics_;
    const bool finite = std::isfinite(diag.kinetic_energy) && std::isfinite(max_acceleration_) &&
                        std::isfinite(diag.max_density_deviation);
    if (!finite) report_non_finite();
    if (is_energy_runaway(diag.kinetic_energy, reference_energy_, config_.blow_up))
      report_runaway();
  }

  [[noreturn]] void report_non_finite() const {
    const ParticleArrays& p = particles_;
    std::ostringstream msg;
    msg << "solver: blow-up, non-finite state at t = " << time_ << " (step " << step_ << ")";
    if (const auto bad = find_non_finite(p)) {
      msg << ": " << bad->field << " = " << bad->value << ", first at particle id " << bad->id
          << ", position (";
      for (int d = 0; d < Dim; ++d) msg << (d ? ", " : "") << p.position[d][bad->index];
      msg << "), density " << p.density[bad->index];
      throw BlowUpError(msg.str(), time_, step_, bad->field, bad->value, bad->id);
    }
    // Every value finite but a sum overflowed: name the fastest particle.
    const std::size_t i = fastest_particle(p);
    msg << ": kinetic energy e_v = " << diagnostics_.kinetic_energy
        << " (overflow), fastest particle id " << p.id[i];
    throw BlowUpError(msg.str(), time_, step_, "kinetic energy", diagnostics_.kinetic_energy,
                      p.id[i]);
  }

  [[noreturn]] void report_runaway() const {
    const ParticleArrays& p = particles_;
    const std::size_t i = fastest_particle(p);
    double v2 = 0.0;
    for (int d = 0; d < Dim; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
    std::ostringstream msg;
    msg << "solver: blow-up, runaway kinetic energy at t = " << time_ << " (step " << step_
        << "): e_v = " << diagnostics_.kinetic_energy << " m^2/s^2 > "
        << config_.blow_up.energy_factor << " x reference " << reference_energy_
        << " m^2/s^2; fastest particle id " << p.id[i] << ", |v| = " << std::sqrt(v2)
        << " m/s, density " << p.density[i];
    throw BlowUpError(msg.str(), time_, step_, "kinetic energy", diagnostics_.kinetic_energy,
                      p.id[i]);
  }

  SolverConfig config_;
  KernelT kernel_;
  VerletNeighbourSearch search_;
  ParticleArrays particles_;            // owned particles at [0, owned_), then the halo copies
  std::shared_ptr<Exchange> exchange_;  // the other processes (LocalExchange: none)
  std::size_t owned_;
  std::array<std::vector<double>, 3> predicted_velocity_;
  SchemeFields fields_;                     // the scheme's fields (empty for the thesis model)
  bool transport_velocity_ = false;         // particles drift with v + δv (SchemeFields)
  std::vector<double> scratch_;             // reorder buffer of the scheme's fields
  std::vector<VelocityGradient> gradient_;  // scratch of the explicit sub-filter model
  double time_;
  std::uint64_t step_;
  double max_acceleration_ = 0.0;
  double reference_energy_ = 0.0;
  double mean_neighbours_ = 0.0;  // of the current lists (count_neighbours)  // E_ref of the
                                  // runaway test (BlowUpThresholds)
  StepDiagnostics diagnostics_;
};

}  // namespace

std::string_view viscous_operator_name(ViscousOperator op) {
  return kViscousOperatorNames.name(op);
}

std::unique_ptr<Simulation> restore_simulation(const SolverConfig& config, SolverState state,
                                               std::shared_ptr<Exchange> exchange) {
  if (!exchange) exchange = std::make_shared<LocalExchange>();
  validate(config, state.particles, *exchange);
  const std::size_t n = state.particles.size();
  const ParticleArrays& p = state.particles;
  bool complete =
      p.volume.size() == n && p.density.size() == n && p.pressure.size() == n && p.id.size() == n;
  for (int d = 0; d < p.dimension; ++d)
    complete = complete && p.position[d].size() == n && p.velocity[d].size() == n &&
               p.acceleration[d].size() == n;
  for (int d = 0; d < p.dimension; ++d)
    complete = complete && state.list_reference_positions[d].size() == n;
  // Every process throws when one has a bad share (the others would wait for it).
  if (exchange->any(!complete))
    throw std::invalid_argument("solver: restart state has arrays of unequal length");
  return with_kernel(config.kernel, config.box.dimension, config.support_radius,
                     [&](const auto& kernel) -> std::unique_ptr<Simulation> {
                       using KernelT = std::decay_t<decltype(kernel)>;
                       return std::make_unique<SphSolver<KernelT>>(kernel, config, std::move(state),
                                                                   std::move(exchange));
                     });
}

std::unique_ptr<Simulation> make_simulation(const SolverConfig& config, ParticleArrays initial,
                                            double start_time, std::uint64_t start_step,
                                            std::shared_ptr<Exchange> exchange) {
  if (!exchange) exchange = std::make_shared<LocalExchange>();
  validate(config, initial, *exchange);
  return with_kernel(config.kernel, config.box.dimension, config.support_radius,
                     [&](const auto& kernel) -> std::unique_ptr<Simulation> {
                       using KernelT = std::decay_t<decltype(kernel)>;
                       return std::make_unique<SphSolver<KernelT>>(kernel, config,
                                                                   std::move(initial), start_time,
                                                                   start_step, std::move(exchange));
                     });
}

}  // namespace sphles::sim
