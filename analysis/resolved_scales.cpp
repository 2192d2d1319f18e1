// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/resolved_scales.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include "analysis/writer.hpp"
#include "sim/kernels.hpp"

namespace sphles::analysis {

namespace {

// A shell counts as at or below a wavenumber when its centre is, up to round-off of k_p = pΔk.
constexpr double kShellTolerance = 1e-9;
// A reference shell holding less than this fraction of the reference's energy counts as empty:
// round-off of the transforms (10⁻³⁰ of the energy) rather than flow.
constexpr double kEmptyShell = 1e-12;

ShellSpectrum blend(const ShellSpectrum& a, const ShellSpectrum& b, double time) {
  ShellSpectrum s = a;
  s.time = time;
  const double w = (time - a.time) / (b.time - a.time);
  const std::size_t shells = std::min(a.energy.size(), b.energy.size());
  s.wavenumber.resize(shells);
  s.energy.resize(shells);
  for (std::size_t p = 0; p < shells; ++p) s.energy[p] = (1.0 - w) * a.energy[p] + w * b.energy[p];
  return s;
}

}  // namespace

std::vector<ShellSpectrum> read_run_spectra(const std::filesystem::path& run_directory) {
  const std::filesystem::path index = run_directory / "spectra" / "index.csv";
  if (!std::filesystem::exists(index))
    throw std::runtime_error("'" + run_directory.string() +
                             "' has no spectra (spectra/index.csv): run it with the analysis "
                             "product \"spectrum\"");
  std::vector<ShellSpectrum> out;
  for (const auto& row : read_index(index)) {
    if (row.size() < 3) continue;  // a row being appended
    ShellSpectrum s;
    s.time = index_number(row, "t", index);
    s.delta_k = index_number(row, "delta_k", index);
    s.kernel_wavenumber = index_number(row, "k_kernel", index);
    const std::filesystem::path file = run_directory / "spectra" / row.at("file");
    std::ifstream in(file);
    if (!in) throw std::runtime_error("'" + file.string() + "' cannot be read");
    std::string line;
    std::getline(in, line);  // k,E,...
    while (std::getline(in, line)) {
      std::stringstream cells(line);
      std::string k, e;
      std::getline(cells, k, ',');
      std::getline(cells, e, ',');
      try {
        s.wavenumber.push_back(std::stod(k));
        s.energy.push_back(std::stod(e));
      } catch (const std::exception&) {
        throw std::runtime_error("'" + file.string() + "': malformed row '" + line + "'");
      }
    }
    out.push_back(std::move(s));
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const ShellSpectrum& a, const ShellSpectrum& b) { return a.time < b.time; });
  return out;
}

ShellSpectrum shell_spectrum(double time, const EnergySpectrum& spectrum,
                             double kernel_wavenumber) {
  return {time, spectrum.delta_k, kernel_wavenumber, spectrum.wavenumber, spectrum.energy};
}

ShellSpectrum spectrum_at(const std::vector<ShellSpectrum>& reference, double time) {
  if (reference.empty()) return {};
  const double spacing = reference.size() > 1 ? (reference.back().time - reference.front().time) /
                                                    static_cast<double>(reference.size() - 1)
                                              : 1.0;
  const double tolerance = 1e-6 * spacing;
  for (const ShellSpectrum& s : reference)
    if (std::abs(s.time - time) <= tolerance) return s;
  for (std::size_t i = 1; i < reference.size(); ++i)
    if (reference[i - 1].time < time && time < reference[i].time)
      return blend(reference[i - 1], reference[i], time);
  return {};
}

ResolvedScales resolved_scales(const ShellSpectrum& run, const ShellSpectrum& reference,
                               double kernel_wavenumber) {
  if (std::abs(run.delta_k - reference.delta_k) > 1e-12 * run.delta_k)
    throw std::invalid_argument("the run's shells (delta_k " + std::to_string(run.delta_k) +
                                ") and the reference's (" + std::to_string(reference.delta_k) +
                                ") differ: not the same box");
  ResolvedScales r;
  r.time = run.time;
  r.kernel_wavenumber = kernel_wavenumber;
  r.sph_wavenumber = 0.5 * kernel_wavenumber;
  const double dk = run.delta_k;
  auto sums = [&](const ShellSpectrum& s, double& resolved, double& above) {
    resolved = above = 0.0;
    for (std::size_t p = 0; p < s.energy.size(); ++p) {
      const double k = s.wavenumber[p];
      if (k <= r.sph_wavenumber * (1.0 + kShellTolerance)) resolved += s.energy[p] * dk;
      if (k > kernel_wavenumber * (1.0 + kShellTolerance)) above += s.energy[p] * dk;
    }
  };
  sums(run, r.resolved_energy, r.energy_above_kernel);
  sums(reference, r.reference_resolved_energy, r.reference_energy_above_kernel);
  double reference_total = 0.0;
  for (double e : reference.energy) reference_total += e * dk;
  r.reference_energy = reference_total;
  for (std::size_t p = 1; p < run.energy.size(); ++p) {
    const double k = run.wavenumber[p];
    if (k > kernel_wavenumber * (1.0 + kShellTolerance)) break;
    r.shell.push_back(k);
    const double ref = p < reference.energy.size() ? reference.energy[p] : 0.0;
    r.shell_energy.push_back(run.energy[p]);
    r.reference_shell_energy.push_back(ref);
    // A shell the reference leaves empty (the Taylor-Green vortex's odd shells early on) has
    // no ratio.
    r.shell_ratio.push_back(ref * dk > kEmptyShell * reference_total
                                ? run.energy[p] / ref
                                : std::numeric_limits<double>::quiet_NaN());
  }
  return r;
}

ResolvedHistory resolved_history(const std::vector<ShellSpectrum>& run,
                                 const std::vector<ShellSpectrum>& reference, double t_min,
                                 double t_max) {
  ResolvedHistory h;
  for (const ShellSpectrum& s : run) {
    if (s.time < t_min || s.time > t_max) continue;
    const ShellSpectrum ref = spectrum_at(reference, s.time);
    if (ref.energy.empty()) continue;
    h.samples.push_back(resolved_scales(s, ref, s.kernel_wavenumber));
  }
  double num = 0.0, den = 0.0;
  bool any = false;
  for (const ResolvedScales& r : h.samples) {
    if (!(r.reference_resolved_energy > kEmptyShell * r.reference_energy)) continue;
    any = true;
    const double d = r.resolved_energy - r.reference_resolved_energy;
    num += d * d;
    den += r.reference_resolved_energy * r.reference_resolved_energy;
    h.max_relative_error = std::max(
        h.max_relative_error, std::abs(r.resolved_energy / r.reference_resolved_energy - 1.0));
  }
  if (!any) h.max_relative_error = std::numeric_limits<double>::quiet_NaN();
  h.l2_misfit = any ? std::sqrt(num / den) : std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 1; i + 1 < h.samples.size(); ++i) {
    const ResolvedScales &a = h.samples[i - 1], &b = h.samples[i + 1];
    const double dt = b.time - a.time;
    h.flux_time.push_back(h.samples[i].time);
    h.flux.push_back(-(b.resolved_energy - a.resolved_energy) / dt);
    h.reference_flux.push_back(-(b.reference_resolved_energy - a.reference_resolved_energy) / dt);
  }
  for (const ResolvedScales& r : h.samples)
    if (r.shell.size() > h.mean_shell.size()) h.mean_shell = r.shell;
  for (std::size_t p = 0; p < h.mean_shell.size(); ++p) {
    double run_sum = 0.0, reference_sum = 0.0;
    for (const ResolvedScales& r : h.samples)
      if (p < r.shell_ratio.size() && !std::isnan(r.shell_ratio[p])) {
        run_sum += r.shell_energy[p];
        reference_sum += r.reference_shell_energy[p];
      }
    h.mean_shell_ratio.push_back(reference_sum > 0.0 ? run_sum / reference_sum
                                                     : std::numeric_limits<double>::quiet_NaN());
  }
  if (!h.flux.empty()) {
    const auto peak = std::max_element(h.flux.begin(), h.flux.end()) - h.flux.begin();
    const auto ref_peak = std::max_element(h.reference_flux.begin(), h.reference_flux.end()) -
                          h.reference_flux.begin();
    h.flux_peak_time = h.flux_time[peak];
    h.flux_peak = h.flux[peak];
    h.reference_flux_peak_time = h.flux_time[ref_peak];
    h.reference_flux_peak = h.reference_flux[ref_peak];
  }
  return h;
}

namespace {

nlohmann::json ratios_or_null(const std::vector<double>& ratios) {
  nlohmann::json out = nlohmann::json::array();
  for (double r : ratios) out.push_back(std::isnan(r) ? nlohmann::json() : nlohmann::json(r));
  return out;
}

}  // namespace

std::vector<double> kernel_transfer_squared(const sim::Scene& scene,
                                            const std::vector<double>& wavenumbers) {
  std::vector<double> out;
  for (double k : wavenumbers) {
    const double w =
        sim::kernel_transfer(scene.kernel, scene.dimension(), 0.5 * scene.kernel_diameter(), k);
    out.push_back(w * w);
  }
  return out;
}

std::vector<ShellSpectrum> kernel_filtered(std::vector<ShellSpectrum> reference,
                                           const sim::Scene& run_scene) {
  // The same shells at every time: the factors once, for the spectrum with the most shells.
  const ShellSpectrum* widest = nullptr;
  for (const ShellSpectrum& s : reference)
    if (!widest || s.wavenumber.size() > widest->wavenumber.size()) widest = &s;
  const std::vector<double> transfer =
      widest ? kernel_transfer_squared(run_scene, widest->wavenumber) : std::vector<double>{};
  for (ShellSpectrum& s : reference)
    for (std::size_t p = 0; p < s.energy.size(); ++p) s.energy[p] *= transfer[p];
  return reference;
}

nlohmann::json resolved_history_to_json(const ResolvedHistory& h) {
  nlohmann::json samples = nlohmann::json::array();
  for (const ResolvedScales& s : h.samples) {
    const nlohmann::json ratios = ratios_or_null(s.shell_ratio);
    samples.push_back({{"t", s.time},
                       {"k_kernel", s.kernel_wavenumber},
                       {"k_sph", s.sph_wavenumber},
                       {"resolved_energy", s.resolved_energy},
                       {"reference_resolved_energy", s.reference_resolved_energy},
                       {"energy_above_kernel", s.energy_above_kernel},
                       {"reference_energy_above_kernel", s.reference_energy_above_kernel},
                       {"reference_energy", s.reference_energy},
                       {"shell", s.shell},
                       {"shell_ratio", ratios}});
  }
  return {{"samples", samples},
          {"resolved_energy_l2_misfit", h.l2_misfit},
          {"resolved_energy_max_relative_error", h.max_relative_error},
          {"flux", {{"t", h.flux_time}, {"run", h.flux}, {"reference", h.reference_flux}}},
          {"flux_peak", {{"t", h.flux_peak_time}, {"value", h.flux_peak}}},
          {"reference_flux_peak",
           {{"t", h.reference_flux_peak_time}, {"value", h.reference_flux_peak}}},
          {"mean_shell_ratio",
           {{"shell", h.mean_shell}, {"ratio", ratios_or_null(h.mean_shell_ratio)}}}};
}

}  // namespace sphles::analysis
