// SPDX-License-Identifier: GPL-3.0-or-later
// The measurements (docs/accuracy.md): one run of the matrix (matrix.cpp) stepped with its error
// taken against its reference at every sample, the errors summed up at its end, and the rows of
// the output files.
#include "bench/accuracy/accuracy.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <limits>
#include <optional>
#include <ostream>
#include <sstream>

#include "analysis/grid.hpp"
#include "analysis/products.hpp"
#include "analysis/reference.hpp"
#include "analysis/resolved_scales.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/vorticity.hpp"
#include "bench/process_time.hpp"
#include "scene/document.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::accuracy {

namespace {

/// Linear interpolation of (x, y) at t; x ascending; clamped at the ends.
double interpolate(const std::vector<double>& x, const std::vector<double>& y, double t) {
  if (t <= x.front()) return y.front();
  if (t >= x.back()) return y.back();
  const auto upper = std::upper_bound(x.begin(), x.end(), t);
  const auto k = static_cast<std::size_t>(upper - x.begin());
  const double w = (t - x[k - 1]) / (x[k] - x[k - 1]);
  return (1.0 - w) * y[k - 1] + w * y[k];
}

/// Relative L2 velocity error of the 2D Taylor-Green vortex at the particles, mass weighted:
/// sqrt(Σ M |v - v_a(x, t)|² / Σ M |v_a(x, t)|²), v_a = v0 e^(-2νt) (sin x cos y, -cos x sin y)
/// (SPEC §6.2).
double tgv2d_velocity_error(const sim::ParticleArrays& p, double v0, double nu, double time) {
  double error = 0.0, norm = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const auto [ux, uy] =
        sim::taylor_green_2d_velocity(v0, nu, time, p.position[0][i], p.position[1][i]);
    const double dx = p.velocity[0][i] - ux, dy = p.velocity[1][i] - uy;
    error += p.mass[i] * (dx * dx + dy * dy);
    norm += p.mass[i] * (ux * ux + uy * uy);
  }
  return std::sqrt(error / norm);
}

/// PySPH's L1 error of the speed (examples/taylor_green.py): mean_i | |v_i| - |v_a(x_i, t)| | /
/// mean_i |v_a(x_i, t)|, unweighted over the particles.
double tgv2d_speed_l1_error(const sim::ParticleArrays& p, double v0, double nu, double time) {
  double error = 0.0, norm = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const auto [ux, uy] =
        sim::taylor_green_2d_velocity(v0, nu, time, p.position[0][i], p.position[1][i]);
    const double exact = std::hypot(ux, uy);
    error += std::abs(std::hypot(p.velocity[0][i], p.velocity[1][i]) - exact);
    norm += exact;
  }
  return error / norm;
}

/// ν⟨ω²⟩ (4.6) with ω from the nearest-particle grid of spacing Δl/2 (SPEC §5).
double grid_viscous_dissipation(const sim::ParticleArrays& p, int particles_per_side,
                                double box_length, double nu) {
  analysis::Grid grid;
  grid.dimension = 2;
  grid.points_per_side = 2 * particles_per_side;
  grid.length = box_length;
  const analysis::NearestParticleMap map = analysis::nearest_particle_map(grid, p);
  const analysis::VectorField velocity = analysis::sample_velocity(map, p, true);
  return nu * analysis::mean_value(analysis::squared_magnitude(analysis::vorticity(velocity)));
}

/// Time average of field(sample) over samples with time >= start (trapezoidal rule).
template <typename Field>
double window_average(const std::vector<Sample>& history, double start, Field field) {
  double integral = 0.0, length = 0.0;
  for (std::size_t k = 1; k < history.size(); ++k) {
    if (history[k - 1].time < start - 1e-12) continue;
    const double dt = history[k].time - history[k - 1].time;
    integral += 0.5 * dt * (field(history[k - 1]) + field(history[k]));
    length += dt;
  }
  return length > 0.0 ? integral / length : std::numeric_limits<double>::quiet_NaN();
}

void finish_tgv2d(RunResult& r) {
  double error = 0.0, norm = 0.0, velocity = 0.0;
  for (const Sample& s : r.history) {
    error += (s.kinetic_energy - s.reference_energy) * (s.kinetic_energy - s.reference_energy);
    norm += s.reference_energy * s.reference_energy;
    velocity += s.velocity_error * s.velocity_error;
  }
  r.energy_error = std::sqrt(error / norm);
  r.velocity_error_rms = std::sqrt(velocity / static_cast<double>(r.history.size()));
  r.velocity_error_end = r.history.back().velocity_error;
  r.speed_l1_error_end = r.history.back().speed_l1_error;
  r.energy_error_end = r.history.back().kinetic_energy / r.history.back().reference_energy - 1.0;
}

/// "k:ratio" of every shell (NaN ratios as "-"), separated by spaces.
std::string shell_ratio_list(const std::vector<double>& shell, const std::vector<double>& ratio) {
  std::ostringstream out;
  out << std::setprecision(3);
  for (std::size_t p = 0; p < shell.size(); ++p) {
    if (p > 0) out << ' ';
    out << shell[p] << ':';
    if (std::isnan(ratio[p]))
      out << '-';
    else
      out << ratio[p];
  }
  return out.str();
}

/// The resolved-scale errors (SPEC §9) of the run's spectra against the reference run's over
/// t ∈ [0, 12], and E_res of both at the samples taken at the spectrum times.
void finish_resolved(RunResult& r, const std::vector<analysis::ShellSpectrum>& spectra,
                     const std::vector<analysis::ShellSpectrum>& reference) {
  const analysis::ResolvedHistory h =
      analysis::resolved_history(spectra, reference, 0.0, kMisfitEndTime);
  r.resolved_misfit = h.l2_misfit;
  r.resolved_max_error = h.max_relative_error;
  const analysis::ResolvedHistory window =
      analysis::resolved_history(spectra, reference, kShellWindowStart, kShellWindowEnd);
  r.shell_ratios_window = shell_ratio_list(window.mean_shell, window.mean_shell_ratio);
  if (!h.flux.empty()) {
    r.resolved_flux_peak_time = h.flux_peak_time;
    r.reference_resolved_flux_peak_time = h.reference_flux_peak_time;
  }
  for (const analysis::ResolvedScales& s : h.samples) {
    if (std::abs(s.time - 8.0) < 1e-6) r.shell_ratios_t8 = shell_ratio_list(s.shell, s.shell_ratio);
    if (std::abs(s.time - 9.0) < 1e-6) r.shell_ratios_t9 = shell_ratio_list(s.shell, s.shell_ratio);
    for (Sample& sample : r.history)
      if (std::abs(sample.time - s.time) < 1e-9) {
        sample.resolved_energy = s.resolved_energy;
        sample.reference_resolved_energy = s.reference_resolved_energy;
      }
  }
}

void finish_tgv3d(RunResult& r, const analysis::ReferenceCurve* dns) {
  std::vector<Sample>& h = r.history;
  const std::size_t n = h.size();
  // ε = -de_v/dt (5.4) by centred differences of the recorded samples, one-sided at both ends.
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t lo = k == 0 ? 0 : k - 1, hi = k + 1 == n ? n - 1 : k + 1;
    h[k].dissipation =
        hi > lo ? -(h[hi].kinetic_energy - h[lo].kinetic_energy) / (h[hi].time - h[lo].time) : 0.0;
  }
  r.peak_dissipation = -1.0;
  for (const Sample& s : h)
    if (s.time <= kMisfitEndTime + 1e-9 && s.dissipation > r.peak_dissipation) {
      r.peak_dissipation = s.dissipation;
      r.peak_time = s.time;
    }
  if (r.status != "completed" || dns == nullptr) {
    r.energy_misfit = r.dissipation_misfit = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  std::vector<double> t(n), e(n), eps(n);
  for (std::size_t k = 0; k < n; ++k) {
    t[k] = h[k].time;
    e[k] = h[k].kinetic_energy;
    eps[k] = h[k].dissipation;
  }
  // Relative L2 misfit on the DNS time grid (Δt = 0.02) over t ∈ [0, 12], the run's history
  // interpolated linearly.
  double de = 0.0, ne = 0.0, dd = 0.0, nd = 0.0;
  for (std::size_t k = 0; k < dns->time.size(); ++k) {
    if (dns->time[k] > kMisfitEndTime + 1e-9) break;
    const double se = interpolate(t, e, dns->time[k]);
    const double sd = interpolate(t, eps, dns->time[k]);
    de += (se - dns->energy[k]) * (se - dns->energy[k]);
    ne += dns->energy[k] * dns->energy[k];
    dd += (sd - dns->dissipation[k]) * (sd - dns->dissipation[k]);
    nd += dns->dissipation[k] * dns->dissipation[k];
  }
  r.energy_misfit = std::sqrt(de / ne);
  r.dissipation_misfit = std::sqrt(dd / nd);
}

void finish_kolmogorov(RunResult& r) {
  const std::vector<Sample>& h = r.history;
  const double start = 0.5 * r.end_time;
  r.mean_u_rms = window_average(h, start, [](const Sample& s) { return s.u_rms; });
  r.mean_energy_injection =
      window_average(h, start, [](const Sample& s) { return s.energy_injection; });
  r.mean_viscous_dissipation =
      window_average(h, start, [](const Sample& s) { return s.viscous_dissipation; });
  r.mean_film_dissipation =
      window_average(h, start, [](const Sample& s) { return s.film_dissipation; });
  const auto first =
      std::find_if(h.begin(), h.end(), [&](const Sample& s) { return s.time >= start - 1e-12; });
  if (first == h.end() || first->time >= h.back().time) {  // stopped before the window
    r.mean_energy_change = r.budget_imbalance = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  r.mean_energy_change =
      (h.back().kinetic_energy - first->kinetic_energy) / (h.back().time - first->time);
  // Budget (4.3) with the storage term: de_v/dt = ε_inj - ε_v - ε_film - ε_numerical.
  r.budget_imbalance = (r.mean_energy_injection - r.mean_viscous_dissipation -
                        r.mean_film_dissipation - r.mean_energy_change) /
                       r.mean_energy_injection;
}

}  // namespace

RunResult run_one(const RunSpec& spec, const RunOptions& options) {
  const bench::WallClock wall;
  RunResult r;
  r.spec = spec;
  const sim::Scene scene = scene::parse_scene(spec.scene);
  r.case_name = std::string(sim::case_name(scene.case_type));
  r.particles_per_side = scene.particles_per_side;
  r.particles = scene.num_particles();
  r.kernel = std::string(sim::kernel_name(scene.kernel));
  r.diameter_over_spacing = scene.kernel_diameter_over_spacing;
  r.subfilter = std::string(sim::subfilter_model_name(scene.subfilter.model));
  r.dynamic_viscosity = scene.fluid.dynamic_viscosity;
  r.end_time = scene.end_time;
  const bool tgv2d = scene.case_type == sim::CaseType::TaylorGreen2D;
  const bool tgv3d = scene.case_type == sim::CaseType::TaylorGreen3D;
  const bool kolmogorov = scene.case_type == sim::CaseType::Kolmogorov2D;
  const double nu = scene.fluid.kinematic_viscosity();
  // The 3D TGV's references: the DNS' E(t) where one exists at the run's Re, and the spectra of
  // the `sphles reference` run of the flow.
  std::optional<analysis::ReferenceCurve> dns;
  std::vector<analysis::ShellSpectrum> reference_spectra, spectra;
  analysis::AnalysisConfig spectrum_config;
  spectrum_config.products = {analysis::Product::Spectrum};
  if (tgv3d) {
    if (!analysis::missing_reference(scene))
      dns = analysis::reference_curve(scene, options.reference_dir);
    if (const auto run = analysis::find_reference_run(scene, options.reference_dir)) {
      r.resolved_reference = run->filename().string();
      reference_spectra = analysis::read_run_spectra(*run);
    }
  }
  const bool resolved = !reference_spectra.empty();

  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));

  auto sample = [&] {
    Sample s;
    s.time = simulation->time();
    s.kinetic_energy = simulation->diagnostics().kinetic_energy;
    const sim::ParticleArrays& p = simulation->particles();
    if (tgv2d) {
      s.reference_energy = sim::taylor_green_2d_energy(scene.velocity_amplitude, nu, s.time);
      s.velocity_error = tgv2d_velocity_error(p, scene.velocity_amplitude, nu, s.time);
      s.speed_l1_error = tgv2d_speed_l1_error(p, scene.velocity_amplitude, nu, s.time);
    } else if (tgv3d) {
      if (dns) s.reference_energy = interpolate(dns->time, dns->energy, s.time);
    } else if (kolmogorov) {
      const std::vector<double> d = sim::case_diagnostics(scene, p);  // (4.3)
      s.energy_injection = d[0];
      s.film_dissipation = d[1];
      s.u_rms = d[2];
      s.viscous_dissipation =
          grid_viscous_dissipation(p, scene.particles_per_side, scene.box_length(), nu);
    }
    if (options.trace)
      std::fprintf(stderr, "%s | t=%.4g e_v=%.6g ref=%.6g verr=%.4g eps_v=%.4g wall=%.1f\n",
                   spec.label.c_str(), s.time, s.kinetic_energy, s.reference_energy,
                   s.velocity_error, s.viscous_dissipation, wall());
    r.history.push_back(s);
  };

  // The run's spectrum as `sphles run` writes it (analysis grid Δl/2, SPEC §5).
  auto take_spectrum = [&] {
    const analysis::AnalysisFrame frame =
        analysis::analyse(*analysis::make_snapshot(*simulation, spectrum_config), spectrum_config);
    spectra.push_back(analysis::shell_spectrum(simulation->time(), frame.spectrum->spectrum,
                                               frame.spectrum->kernel_wavenumber));
  };

  sample();
  if (resolved) take_spectrum();
  try {
    sim::Cadence samples(spec.sample_interval, simulation->time());
    sim::Cadence spectrum_times(resolved ? options.spectrum_interval : 0.0, simulation->time());
    while (!sim::reached_end(simulation->time(), r.end_time)) {
      if (wall() > options.wall_limit_seconds) {
        r.status = "wall_limit";
        break;
      }
      const double t = simulation->time();
      const auto step_start = std::chrono::steady_clock::now();
      const double cpu_start = bench::process_cpu_seconds();
      simulation->step(samples.limit_step(t, spectrum_times.limit_step(t, r.end_time - t)));
      r.cpu_seconds += bench::process_cpu_seconds() - cpu_start;
      r.wall_seconds +=
          std::chrono::duration<double>(std::chrono::steady_clock::now() - step_start).count();
      // On the fixed grid k · interval, and at the end.
      const bool at_end = sim::reached_end(simulation->time(), r.end_time);
      const bool spectrum_due = spectrum_times.take(simulation->time()) || (resolved && at_end);
      const bool sample_due = samples.take(simulation->time()) || at_end;
      if (spectrum_due) take_spectrum();
      if (spectrum_due || sample_due) sample();
    }
  } catch (const sim::BlowUpError& e) {
    r.status = "blown_up";
  }
  r.time_reached = simulation->time();
  r.steps = simulation->step_count();
  r.final_energy = r.history.back().kinetic_energy;
  if (tgv2d) finish_tgv2d(r);
  if (tgv3d) finish_tgv3d(r, dns ? &*dns : nullptr);
  if (resolved) finish_resolved(r, spectra, reference_spectra);
  if (kolmogorov) finish_kolmogorov(r);
  r.total_wall_seconds = wall();
  return r;
}

namespace {

std::string optional_number(bool applies, double value) {
  if (!applies) return "";
  std::ostringstream s;
  s << std::setprecision(6) << value;
  return s.str();
}

}  // namespace

void write_summary_header(std::ostream& out) {
  out << "study,config,label,case,particles_per_side,particles,kernel,diameter_over_spacing,"
         "subfilter,dynamic_viscosity,end_time,status,time_reached,steps,wall_seconds,"
         "cpu_seconds,total_wall_seconds,energy_error,velocity_error_end,velocity_error_rms,"
         "energy_misfit,dissipation_misfit,peak_dissipation,peak_time,final_energy,mean_u_rms,"
         "mean_energy_injection,mean_viscous_dissipation,mean_film_dissipation,"
         "mean_energy_change,budget_imbalance,energy_error_end,speed_l1_error_end,"
         "resolved_reference,resolved_misfit,resolved_max_error,shell_ratios_t8,shell_ratios_t9,"
         "shell_ratios_window,resolved_flux_peak_time,reference_resolved_flux_peak_time\n";
}

void write_summary_row(std::ostream& out, const RunResult& r) {
  const bool t2 = r.case_name == "tgv2d", t3 = r.case_name == "tgv3d",
             kf = r.case_name == "kolmogorov2d";
  out << std::setprecision(6) << r.spec.study << ',' << r.spec.config << ',' << r.spec.label << ','
      << r.case_name << ',' << r.particles_per_side << ',' << r.particles << ',' << r.kernel << ','
      << r.diameter_over_spacing << ',' << r.subfilter << ',' << r.dynamic_viscosity << ','
      << r.end_time << ',' << r.status << ',' << r.time_reached << ',' << r.steps << ','
      << r.wall_seconds << ',' << r.cpu_seconds << ',' << r.total_wall_seconds << ','
      << optional_number(t2, r.energy_error) << ',' << optional_number(t2, r.velocity_error_end)
      << ',' << optional_number(t2, r.velocity_error_rms) << ','
      << optional_number(t3, r.energy_misfit) << ',' << optional_number(t3, r.dissipation_misfit)
      << ',' << optional_number(t3, r.peak_dissipation) << ',' << optional_number(t3, r.peak_time)
      << ',' << r.final_energy << ',' << optional_number(kf, r.mean_u_rms) << ','
      << optional_number(kf, r.mean_energy_injection) << ','
      << optional_number(kf, r.mean_viscous_dissipation) << ','
      << optional_number(kf, r.mean_film_dissipation) << ','
      << optional_number(kf, r.mean_energy_change) << ',' << optional_number(kf, r.budget_imbalance)
      << ',' << optional_number(t2, r.energy_error_end) << ','
      << optional_number(t2, r.speed_l1_error_end) << ',' << r.resolved_reference << ','
      << optional_number(t3, r.resolved_misfit) << ',' << optional_number(t3, r.resolved_max_error)
      << ',' << r.shell_ratios_t8 << ',' << r.shell_ratios_t9 << ',' << r.shell_ratios_window << ','
      << optional_number(t3, r.resolved_flux_peak_time) << ','
      << optional_number(t3, r.reference_resolved_flux_peak_time) << '\n';
}

void write_history_header(std::ostream& out) {
  out << "study,label,time,kinetic_energy,reference_energy,velocity_error,dissipation,"
         "energy_injection,viscous_dissipation,film_dissipation,u_rms,speed_l1_error,"
         "resolved_energy,reference_resolved_energy\n";
}

void write_history_rows(std::ostream& out, const RunResult& r) {
  out << std::setprecision(6);
  for (const Sample& s : r.history)
    out << r.spec.study << ',' << r.spec.label << ',' << s.time << ',' << s.kinetic_energy << ','
        << s.reference_energy << ',' << s.velocity_error << ',' << s.dissipation << ','
        << s.energy_injection << ',' << s.viscous_dissipation << ',' << s.film_dissipation << ','
        << s.u_rms << ',' << s.speed_l1_error << ','
        << optional_number(!std::isnan(s.resolved_energy), s.resolved_energy) << ','
        << optional_number(!std::isnan(s.reference_resolved_energy), s.reference_resolved_energy)
        << '\n';
}

}  // namespace sphles::accuracy
