// SPDX-License-Identifier: GPL-3.0-or-later
// sphles compare RUN REF: a run's resolved scales against a reference (SPEC §9).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "analysis/reference.hpp"
#include "analysis/resolved_scales.hpp"
#include "analysis/writer.hpp"
#include "app/commands.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "sim/kernels.hpp"

namespace sphles::app {

namespace {

struct CompareOptions {
  std::string run, reference;
  double from = 0.0, to = 1e300;
  std::string filter = "none";  // "kernel": the reference filtered by the run's kernel
  bool json = false;
};

/// sqrt(Σ (e_v - E_ref)² / Σ E_ref²) over the run's time series rows in [from, to] that the
/// reference's time series covers (E_ref linear between its rows); NaN without such rows.
double total_energy_misfit(const std::filesystem::path& run, const std::filesystem::path& reference,
                           double from, double to) {
  const auto rows = analysis::read_index(run / "timeseries.csv");
  const auto ref = analysis::read_index(reference / "timeseries.csv");
  std::vector<double> rt, re;
  for (const auto& r : ref)
    if (r.contains("t") && r.contains("E")) {
      rt.push_back(std::stod(r.at("t")));
      re.push_back(std::stod(r.at("E")));
    }
  double num = 0.0, den = 0.0;
  for (const auto& r : rows) {
    if (!r.contains("t") || !r.contains("e_v")) continue;
    const double t = std::stod(r.at("t"));
    if (t < from || t > to || rt.size() < 2 || t < rt.front() || t > rt.back()) continue;
    const std::size_t i =
        static_cast<std::size_t>(std::lower_bound(rt.begin(), rt.end(), t) - rt.begin());
    const double e =
        i == 0 ? re[0] : re[i - 1] + (re[i] - re[i - 1]) * (t - rt[i - 1]) / (rt[i] - rt[i - 1]);
    const double d = std::stod(r.at("e_v")) - e;
    num += d * d;
    den += e * e;
  }
  return den > 0.0 ? std::sqrt(num / den) : std::numeric_limits<double>::quiet_NaN();
}

int compare_command(CompareOptions o) {
  try {
    const bool filtered = o.filter == "kernel";
    // The run's scene, read when the default reference or the kernel filter needs it.
    sim::Scene scene;
    if (o.reference.empty() || filtered) {
      nlohmann::json document = scene::read_scene_file(std::filesystem::path(o.run) / "scene.json");
      document.erase("reference");
      document.erase("render");
      scene = analysis::parse_run_config(document).scene;
    }
    if (o.reference.empty()) {
      // The shipped reference of the run's flow (data/reference/).
      const auto found = analysis::find_reference_run(scene, SPHLES_REFERENCE_DIR);
      if (!found)
        throw std::runtime_error("no shipped reference matches the flow of '" + o.run + "' (case " +
                                 std::string(sim::case_name(scene.case_type)) +
                                 ", nu = " + sim::format_number(scene.fluid.kinematic_viscosity()) +
                                 "): compute one with `sphles reference " + o.run +
                                 "/scene.json` and give its "
                                 "directory as REF");
      o.reference = found->string();
    }
    const auto run = analysis::read_run_spectra(o.run);
    const auto ref = filtered
                         ? analysis::kernel_filtered(analysis::read_run_spectra(o.reference), scene)
                         : analysis::read_run_spectra(o.reference);
    const analysis::ResolvedHistory h = analysis::resolved_history(run, ref, o.from, o.to);
    if (h.samples.empty())
      throw std::runtime_error("no time of '" + o.run + "' in [" + std::to_string(o.from) + ", " +
                               std::to_string(o.to) + "] lies within the reference's times");
    if (o.json) {
      nlohmann::json out = analysis::resolved_history_to_json(h);
      out["filter"] = o.filter;
      std::printf("%s\n", out.dump(2).c_str());
      return kExitOk;
    }
    const auto& first = h.samples.front();
    std::printf("%s against %s%s: k_kern = %g, k_SPH = %g (SPEC §9)\n", o.run.c_str(),
                o.reference.c_str(), filtered ? " filtered by the run's kernel" : "",
                first.kernel_wavenumber, first.sph_wavenumber);
    if (filtered) {
      std::printf("the reference's E(k) times W(k)^2 of %s at D_K = %g:",
                  std::string(sim::kernel_name(scene.kernel)).c_str(), scene.kernel_diameter());
      const std::vector<double> transfer = analysis::kernel_transfer_squared(scene, first.shell);
      for (std::size_t p = 0; p < first.shell.size(); ++p)
        std::printf(" %g: %.3f", first.shell[p], transfer[p]);
      std::printf("\n");
    }
    std::printf("%8s %11s %11s %7s %11s %11s  E(k)/E_ref(k) at k =", "t", "E_res", "E_res,ref",
                "ratio", ">k_kern", ">k_kern,ref");
    for (double k : first.shell) std::printf(" %5g", k);
    std::printf("\n");
    for (const auto& s : h.samples) {
      std::printf("%8.3f %11.5e %11.5e %7.3f %11.4e %11.4e  %20s", s.time, s.resolved_energy,
                  s.reference_resolved_energy, s.resolved_energy / s.reference_resolved_energy,
                  s.energy_above_kernel, s.reference_energy_above_kernel, "");
      for (double r : s.shell_ratio)
        std::isnan(r) ? std::printf("     -") : std::printf(" %5.2f", r);
      std::printf("\n");
    }
    std::printf("%8s %77s", "mean", "");
    for (double r : h.mean_shell_ratio)
      std::isnan(r) ? std::printf("     -") : std::printf(" %5.2f", r);
    std::printf("  (each shell over the %zu times)\n", h.samples.size());
    std::printf("E_res misfit: L2 %.2f %%, max %.2f %% over %zu times\n", 100.0 * h.l2_misfit,
                100.0 * h.max_relative_error, h.samples.size());
    if (!h.flux.empty())
      std::printf("-dE_res/dt peak: %.5g at t = %.3f (reference %.5g at t = %.3f)\n", h.flux_peak,
                  h.flux_peak_time, h.reference_flux_peak, h.reference_flux_peak_time);
    // The secondary measure beside it: the particles' e_v against the reference's E.
    const double misfit = total_energy_misfit(o.run, o.reference, o.from, o.to);
    if (std::isfinite(misfit))
      std::printf("e_v against E (secondary): L2 misfit %.2f %%\n", 100.0 * misfit);
    return kExitOk;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles compare: %s\n", e.what());
    return kExitUsage;
  }
}

}  // namespace

void add_compare_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<CompareOptions>();
  CLI::App* cmd = app.add_subcommand(
      "compare", "a run's resolved scales against a reference run (E_res, shells, noise)");
  cmd->footer(
      "At the run's spectra times: the resolved energy E_res = sum of E(k) over k <= k_SPH = "
      "k_kern/2, the shell ratios E(k)/E_ref(k) up to k_kern, the energy above k_kern, and over "
      "time the misfit of E_res and the peak of -dE_res/dt, and each shell's energy summed over "
      "the times compared over the reference's (SPEC §9; docs/reference.md). REF is a "
      "`sphles reference` run directory of the same flow; without it, the one shipped in "
      "data/reference/ for the run's case and Reynolds number.");
  cmd->add_option("run", o->run, "run directory with spectra/")->required()->type_name("RUN");
  cmd->add_option("reference", o->reference,
                  "reference run directory (default: the shipped one of the run's flow)")
      ->type_name("REF");
  cmd->add_option("--from", o->from, "first time compared")->type_name("T");
  cmd->add_option("--to", o->to, "last time compared")->type_name("T");
  cmd->add_option("--filter", o->filter,
                  "none: the reference as computed; kernel: its E(k) times W(k)^2 of the run's "
                  "kernel, the spectrum a perfect SPH-LES of that kernel would carry")
      ->check(CLI::IsMember({"none", "kernel"}))
      ->type_name("none|kernel");
  cmd->add_flag("--json", o->json, "print JSON instead of a table");
  cmd->callback([o, &exit_code] { exit_code = compare_command(*o); });
}

}  // namespace sphles::app
