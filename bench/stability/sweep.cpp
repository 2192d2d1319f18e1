// SPDX-License-Identifier: GPL-3.0-or-later
#include "bench/stability/sweep.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <limits>
#include <ostream>
#include <sstream>

#include "bench/process_time.hpp"
#include "scene/document.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::stability {

namespace {

using nlohmann::json;

/// 2D Taylor-Green vortex (SPEC §6.2) at the sweep's base point: 48², Wendland C4, D_K = 8Δl,
/// Re = 100 (η = 0.01), Ma = 0.1 (c_s = 10), p_ref = ρ v0² = 1, t ∈ [0, 5].
json tgv_base() {
  return {{"case", "tgv2d"},
          {"particles_per_side", 48},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
          {"fluid",
           {{"reference_density", 1.0},
            {"sound_speed", 10.0},
            {"reference_pressure", 1.0},
            {"dynamic_viscosity", 0.01}}},
          {"time", {{"end", 5.0}}}};
}

/// Kolmogorov flow (SPEC §6.3) scaled to 48²: the thesis box, fluid and friction, D_K = 8Δl, but
/// 2 forcing periods instead of 7, so that the forcing wavelength (21 mm) spans 3 kernel
/// diameters at this resolution; t ∈ [0, 2] s.
json kolmogorov_base() {
  return {{"case", "kolmogorov2d"},
          {"particles_per_side", 48},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
          {"forcing", {{"amplitude", 1.8}, {"periods", 2}}},
          {"time", {{"end", 2.0}}}};
}

std::string number_label(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

RunSpec spec(std::string group, std::string label, json scene, double cfl = 0.4) {
  return {std::move(group), std::move(label), std::move(scene), cfl};
}

}  // namespace

std::vector<RunSpec> make_sweep(bool quick) {
  std::vector<RunSpec> runs;
  // Mach number Ma = v0 / c_s at fixed p_ref = 1.
  for (const double c : quick ? std::vector<double>{2.0, 10.0}
                              : std::vector<double>{1.5, 2.0, 3.0, 5.0, 10.0, 20.0, 40.0}) {
    json s = tgv_base();
    s["fluid"]["sound_speed"] = c;
    runs.push_back(spec("mach", "c_s=" + number_label(c), s));
  }
  // Background pressure: 0 (negative pressures in the vortex cores), ρ v0²/2 (p >= 0 exactly),
  // ρ v0², ρ c_s²/4 (the thesis' choice) and ρ c_s².
  for (const double p : quick ? std::vector<double>{0.0, 1.0}
                              : std::vector<double>{0.0, 0.25, 0.5, 1.0, 25.0, 100.0}) {
    json s = tgv_base();
    s["fluid"]["reference_pressure"] = p;
    runs.push_back(spec("p_ref", "p_ref=" + number_label(p), s));
  }
  // Acoustic CFL factor (default 0.4).
  for (const double cfl :
       quick ? std::vector<double>{0.4, 3.0}
             : std::vector<double>{0.25, 0.4, 0.8, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 8.0}) {
    runs.push_back(spec("cfl", "C_ac=" + number_label(cfl), tgv_base(), cfl));
  }
  // Kernel and D_K / Δl.
  const std::vector<std::string> kernels =
      quick
          ? std::vector<std::string>{"wendland_c4", "quintic_spline"}
          : std::vector<std::string>{"wendland_c2", "wendland_c4", "wendland_c6", "quintic_spline"};
  for (const std::string& kernel : kernels) {
    for (const double dk :
         quick ? std::vector<double>{4.0, 8.0} : std::vector<double>{4.0, 5.0, 6.0, 7.0, 8.0}) {
      json s = tgv_base();
      s["kernel"] = {{"type", kernel}, {"diameter_over_spacing", dk}};
      runs.push_back(spec("kernel", kernel + " D_K/dl=" + number_label(dk), s));
    }
  }
  // Viscosity down to zero (Re = v0 L / ν from 100 to ∞), t ∈ [0, 10].
  for (const double eta :
       quick ? std::vector<double>{0.01, 0.0} : std::vector<double>{0.01, 1e-3, 1e-4, 0.0}) {
    json s = tgv_base();
    s["fluid"]["dynamic_viscosity"] = eta;
    s["time"]["end"] = 10.0;
    runs.push_back(spec("viscosity", "eta=" + number_label(eta), s));
  }
  // Kolmogorov forcing amplitude χ [m/s²].
  for (const double chi :
       quick ? std::vector<double>{1.8} : std::vector<double>{0.2, 0.6, 1.8, 5.0, 15.0}) {
    json s = kolmogorov_base();
    s["forcing"]["amplitude"] = chi;
    runs.push_back(spec("forcing", "chi=" + number_label(chi), s));
  }
  // Long runs, t ∈ [0, 50] (t = 150 for the inviscid base case).
  if (!quick) {
    json inviscid = tgv_base();
    inviscid["fluid"]["dynamic_viscosity"] = 0.0;
    inviscid["time"]["end"] = 150.0;
    runs.push_back(spec("long", "inviscid t=150", inviscid));
    json base = tgv_base();
    base["time"]["end"] = 50.0;
    runs.push_back(spec("long", "base t=50", base));
    json spline = tgv_base();
    spline["kernel"]["type"] = "quintic_spline";
    spline["time"]["end"] = 50.0;
    runs.push_back(spec("long", "quintic_spline D_K/dl=8 t=50", spline));
    json no_pref = tgv_base();
    no_pref["fluid"]["reference_pressure"] = 0.0;
    no_pref["time"]["end"] = 50.0;
    runs.push_back(spec("long", "p_ref=0 t=50", no_pref));
    runs.push_back(spec("long", "C_ac=2 t=50", base, 2.0));
  }
  return runs;
}

namespace {

/// The run's parameters, read back from the parsed scene.
void read_parameters(RunResult& r, const sim::Scene& scene) {
  r.case_name = std::string(sim::case_name(scene.case_type));
  r.particles_per_side = scene.particles_per_side;
  r.kernel = std::string(sim::kernel_name(scene.kernel));
  r.diameter_over_spacing = scene.kernel_diameter_over_spacing;
  r.sound_speed = scene.fluid.sound_speed;
  r.reference_pressure = scene.fluid.reference_pressure;
  r.dynamic_viscosity = scene.fluid.dynamic_viscosity;
  r.forcing_amplitude =
      scene.case_type == sim::CaseType::Kolmogorov2D ? scene.forcing.amplitude : 0.0;
  r.end_time = scene.end_time;
}

/// The acoustic CFL factor `cfl` on the solver configuration, the viscous and force factors
/// scaled by the same ratio to their defaults (RunSpec::cfl).
void set_cfl(sim::TimeStepConfig& ts, double cfl) {
  const double ratio = cfl / ts.cfl_acoustic;
  ts.cfl_acoustic = cfl;
  ts.cfl_viscous *= ratio;
  ts.cfl_force *= ratio;
}

/// Expected energy: analytic decay (tgv2d), or for kolmogorov2d the laminar spin-up from rest
/// v_x = A (1 - exp(-λt)) sin(k_y y), λ = ν k_y² + μ, A = χ/λ, whose mean energy is
/// ¼ A² (1 - exp(-λt))². Its limit ¼ A² is the runaway reference of a forced run.
class ExpectedEnergy {
 public:
  explicit ExpectedEnergy(const sim::Scene& scene)
      : scene_(scene), nu_(scene.fluid.kinematic_viscosity()) {
    if (scene.case_type == sim::CaseType::Kolmogorov2D) {
      const double amplitude =
          sim::kolmogorov_laminar_velocity(scene.forcing, scene.forcing_wavenumber(), nu_,
                                           0.25 * scene.box_length() / scene.forcing.periods);
      laminar_energy_ = 0.25 * amplitude * amplitude;
    }
  }
  /// 0 for the cases without a forcing (the reference of a decaying flow is its initial energy).
  double laminar_energy() const { return laminar_energy_; }
  double operator()(double time) const {
    if (scene_.case_type == sim::CaseType::TaylorGreen2D)
      return sim::taylor_green_2d_energy(scene_.velocity_amplitude, nu_, time);
    const double k = scene_.forcing_wavenumber();
    const double growth = 1.0 - std::exp(-(nu_ * k * k + scene_.forcing.friction) * time);
    return laminar_energy_ * growth * growth;
  }

 private:
  const sim::Scene& scene_;
  double nu_;
  double laminar_energy_ = 0.0;
};

/// One health check into the result: the extremes over the checks, and the worst
/// classification with its reason and time.
void record_health(RunResult& r, const sim::HealthReport& report, double time, bool trace) {
  if (trace)
    std::fprintf(stderr,
                 "%s | t=%.4g e_v=%.4g dev_max=%.4g dev_rms=%.4g paired=%.4g nn_min=%.3g %s\n",
                 r.spec.label.c_str(), time, report.kinetic_energy, report.density.max,
                 report.density.rms, report.pairing.paired_fraction, report.pairing.min_distance,
                 std::string(sim::classification_name(report.classification)).c_str());
  r.max_density_deviation = std::max(r.max_density_deviation, report.density.max);
  r.max_rms_density_deviation = std::max(r.max_rms_density_deviation, report.density.rms);
  r.max_paired_fraction = std::max(r.max_paired_fraction, report.pairing.paired_fraction);
  r.min_neighbour_distance = std::min(r.min_neighbour_distance, report.pairing.min_distance);
  if (report.classification > r.classification) {
    r.classification = report.classification;
    std::ostringstream reason;
    reason << report.reason << " at t = " << time;
    r.reason = reason.str();
  }
}

/// A run that ended in a BlowUpError: blown up, where and when.
void record_blow_up(RunResult& r, const sim::BlowUpError& e,
                    const ExpectedEnergy& expected_energy) {
  r.classification = sim::Classification::BlownUp;
  std::ostringstream reason;
  reason << "BlowUpError: " << e.quantity() << " = " << e.value() << " at t = " << e.time()
         << " (particle id " << e.particle_id() << ")";
  r.reason = reason.str();
  r.time_reached = e.time();
  r.steps = e.step();
  if (e.quantity() == "kinetic energy") {  // the runaway value, not the last check's
    r.final_energy = e.value();
    const double expected = expected_energy(e.time());
    r.energy_ratio = expected > 0.0 ? r.final_energy / expected : 0.0;
  }
}

}  // namespace

RunResult run_one(const RunSpec& spec, const RunOptions& options) {
  const bench::WallClock wall;
  RunResult r;
  r.spec = spec;
  json document = spec.scene;
  const sim::Scene scene = scene::parse_scene(document);
  read_parameters(r, scene);

  sim::RunSetup setup = sim::setup_run(scene, {.packing_cache_dir = options.packing_cache_dir});
  set_cfl(setup.solver.time_step, spec.cfl);
  sim::HealthThresholds thresholds = options.thresholds;
  const ExpectedEnergy expected_energy(scene);
  if (scene.case_type == sim::CaseType::Kolmogorov2D)
    thresholds.blow_up.reference_energy =
        std::max(thresholds.blow_up.reference_energy, expected_energy.laminar_energy());
  setup.solver.blow_up = thresholds.blow_up;
  const sim::PeriodicBox box = setup.solver.box;
  const double spacing = setup.solver.particle_spacing;
  const double rho_ref = setup.solver.fluid.reference_density;

  r.min_neighbour_distance = std::numeric_limits<double>::infinity();
  try {
    auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    r.initial_energy = simulation->diagnostics().kinetic_energy;
    const double reference = sim::runaway_reference_energy(
        r.initial_energy, scene.fluid.sound_speed, thresholds.blow_up);
    auto check = [&] {
      record_health(r,
                    sim::assess_health(simulation->particles(), *simulation->neighbour_list(), box,
                                       spacing, rho_ref, reference, thresholds),
                    simulation->time(), options.trace);
      r.time_reached = simulation->time();
      r.steps = simulation->step_count();
      r.final_energy = simulation->diagnostics().kinetic_energy;
      const double expected = expected_energy(r.time_reached);
      r.energy_ratio = expected > 0.0 ? r.final_energy / expected : 0.0;
    };
    check();
    const double initial_dt = simulation->stable_time_step();
    const auto step_budget =
        static_cast<std::uint64_t>(std::ceil(options.step_budget_factor * r.end_time / initial_dt));
    std::uint64_t steps = 0;
    while (!sim::reached_end(simulation->time(), r.end_time)) {
      if (steps >= step_budget) {
        std::ostringstream reason;
        reason << "time step collapsed: " << steps
               << " steps reached only t = " << simulation->time()
               << " (dt = " << simulation->stable_time_step() << ", initially " << initial_dt
               << ")";
        r.classification = sim::Classification::BlownUp;
        r.reason = reason.str();
        break;
      }
      if (wall() > options.wall_limit_seconds) {
        r.reason += (r.reason.empty() ? "" : "; ") + std::string("stopped by the wall limit");
        break;
      }
      simulation->step(r.end_time - simulation->time());
      ++steps;
      if (steps % static_cast<std::uint64_t>(options.check_every) == 0) check();
    }
    check();
  } catch (const sim::BlowUpError& e) {
    record_blow_up(r, e, expected_energy);
  }
  if (r.classification == sim::Classification::Stable && r.reason.empty())
    r.reason = "all checks within thresholds";
  r.wall_seconds = wall();
  return r;
}

void write_csv_header(std::ostream& out) {
  out << "group,label,case,particles_per_side,kernel,diameter_over_spacing,sound_speed,"
         "reference_pressure,dynamic_viscosity,cfl_acoustic,forcing_amplitude,end_time,"
         "classification,reason,time_reached,steps,max_density_deviation,"
         "max_rms_density_deviation,max_paired_fraction,min_neighbour_distance,initial_energy,"
         "final_energy,energy_ratio,wall_seconds\n";
}

void write_csv_row(std::ostream& out, const RunResult& r) {
  auto quoted = [](const std::string& text) {
    std::string q = "\"";
    for (const char c : text) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  };
  out << std::setprecision(6) << r.spec.group << ',' << quoted(r.spec.label) << ',' << r.case_name
      << ',' << r.particles_per_side << ',' << r.kernel << ',' << r.diameter_over_spacing << ','
      << r.sound_speed << ',' << r.reference_pressure << ',' << r.dynamic_viscosity << ','
      << r.spec.cfl << ',' << r.forcing_amplitude << ',' << r.end_time << ','
      << sim::classification_name(r.classification) << ',' << quoted(r.reason) << ','
      << r.time_reached << ',' << r.steps << ',' << r.max_density_deviation << ','
      << r.max_rms_density_deviation << ',' << r.max_paired_fraction << ','
      << r.min_neighbour_distance << ',' << r.initial_energy << ',' << r.final_energy << ','
      << r.energy_ratio << ',' << r.wall_seconds << '\n';
}

}  // namespace sphles::stability
