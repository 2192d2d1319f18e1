// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/reference.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "analysis/config.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "sim/initial_conditions.hpp"

namespace sphles::analysis {

namespace {
constexpr double kDnsMatchTolerance = 1e-9;        // relative, on ν, v0 and the box
constexpr double kTwoPi = 2.0 * std::numbers::pi;  // the Taylor-Green box [m]

bool close(double a, double b) {
  return std::abs(a - b) <= kDnsMatchTolerance * std::abs(b);
}

/// The shipped DNS of the 3D Taylor-Green vortex (data/reference/README.md), v0 = 1, L = 1.
struct DnsFile {
  double reynolds;  // V0 L / ν
  const char* file;
  const char* label;
  const char* source;
};
constexpr DnsFile kTgv3dDns[] = {
    {1600.0, kTgv3dRe1600DnsFile, "DNS, Re = 1600",
     "512³ pseudo-spectral DNS of the International Workshop on High-Order CFD Methods, case "
     "C3.5 (data/reference/README.md)"},
    {5000.0, kTgv3dDnsFile, "DNS, Re = 5000",
     "Incompact3d DNS on 1280³ nodes, Dairay, Lamballais, Laizet & Vassilicos, J. Comput. Phys. "
     "337 (2017) 252-274 (data/reference/README.md)"},
};

const DnsFile* tgv3d_dns(const sim::Scene& scene) {
  if (!close(scene.velocity_amplitude, 1.0) || !close(scene.box_length(), kTwoPi)) return nullptr;
  for (const DnsFile& d : kTgv3dDns)
    if (close(scene.fluid.kinematic_viscosity(), 1.0 / d.reynolds)) return &d;
  return nullptr;
}

double uniform_energy(const sim::Scene& scene) {
  double u2 = 0.0;
  for (double u : scene.uniform_velocity) u2 += u * u;
  return 0.5 * u2;
}
}  // namespace

DnsHistory read_dns_history(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error("cannot read the DNS reference " + file.string());
  DnsHistory h;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    double t = 0.0, e = 0.0, eps = 0.0;
    if (!(s >> t >> e >> eps))
      throw std::runtime_error("malformed line in " + file.string() + ": " + line);
    h.time.push_back(t);
    h.energy.push_back(e);
    h.dissipation.push_back(eps);
  }
  if (h.time.size() < 2) throw std::runtime_error("no data rows in " + file.string());
  return h;
}

std::optional<std::string> missing_reference(const sim::Scene& scene) {
  const double nu = scene.fluid.kinematic_viscosity();
  const double v0 = scene.velocity_amplitude;
  switch (scene.case_type) {
    case sim::CaseType::TaylorGreen2D:
      return std::nullopt;
    case sim::CaseType::TaylorGreen3D:
      if (tgv3d_dns(scene)) return std::nullopt;
      return "the DNS references are the 3D Taylor-Green vortex at Re = 1600 and Re = 5000 (v0 = "
             "1 m/s, L = 2π m, ν = 6.25e-4 or 2e-4 m²/s); this run has v0 = " +
             sim::format_number(v0) + " m/s, ν = " + sim::format_number(nu) +
             " m²/s (`sphles reference` computes one for any Re)";
    case sim::CaseType::Kolmogorov2D:
      if (scene.uniform_velocity[1] == 0.0) return std::nullopt;
      return "the Kolmogorov flow's laminar reference is a shear flow along x; this run's uniform "
             "velocity has a y component (" +
             sim::format_number(scene.uniform_velocity[1]) +
             " m/s), which advects the profile, so the laminar solution is not exact";
  }
  return "no reference history for the case " + std::string(sim::case_name(scene.case_type));
}

ReferenceCurve reference_curve(const sim::Scene& scene, const std::filesystem::path& reference_dir,
                               int samples, double until) {
  if (const auto why = missing_reference(scene)) throw std::invalid_argument(*why);
  if (!(until > 0.0)) throw std::invalid_argument("the reference must end at a time > 0");
  const double end = std::min(scene.end_time, until);
  const double nu = scene.fluid.kinematic_viscosity();
  const double v0 = scene.velocity_amplitude;
  const double shift = uniform_energy(scene);
  ReferenceCurve c;
  switch (scene.case_type) {
    case sim::CaseType::TaylorGreen2D: {
      // e_v(t) = v0²/4 exp(-4νt), so -de_v/dt = 4ν (e_v - ½|U|²) (SPEC §6.2).
      c.label = "analytic decay";
      c.source = "2D Taylor-Green vortex, e_v(t) = v0²/4 exp(-4νt) (SPEC §6.2)";
      const int n = std::max(samples, 2);
      for (int k = 0; k < n; ++k) {
        const double t = end * k / (n - 1);
        const double e = sim::taylor_green_2d_energy(v0, nu, t);
        c.time.push_back(t);
        c.energy.push_back(e + shift);
        c.dissipation.push_back(4.0 * nu * e);
      }
      return c;
    }
    case sim::CaseType::TaylorGreen3D: {
      const DnsFile& file = *tgv3d_dns(scene);
      const DnsHistory dns = read_dns_history(reference_dir / file.file);
      c.label = file.label;
      c.source = file.source;
      for (std::size_t k = 0; k < dns.time.size() && dns.time[k] <= end; ++k) {
        c.time.push_back(dns.time[k]);
        c.energy.push_back(dns.energy[k] + shift);
        c.dissipation.push_back(dns.dissipation[k]);
      }
      return c;
    }
    case sim::CaseType::Kolmogorov2D: {
      // From rest, v = A(t) sin(k y) e_x with A' = χ - λ A, λ = ν k² + μ (SPEC §6.3: the
      // advection of a shear flow along x vanishes, so this is exact while it stays laminar):
      // A = (χ/λ)(1 - e^{-λt}); a uniform U_x decays as U_x e^{-μt}. e_v = ¼ A² + ½ U_x²
      // e^{-2μt}, -de_v/dt = -½ A χ e^{-λt} + μ U_x² e^{-2μt} (< 0 while the forcing spins the
      // flow up; 0 in the laminar steady state).
      const double k = scene.forcing_wavenumber(), chi = scene.forcing.amplitude;
      const double mu = scene.forcing.friction, lambda = nu * k * k + mu;
      const double ux = scene.uniform_velocity[0];
      c.label = "laminar";
      c.source =
          "laminar Kolmogorov flow from rest, v = (χ/λ)(1 - exp(-λt)) sin(k_y y) e_x, "
          "λ = ν k_y² + μ (SPEC §6.3); the turbulent flow leaves it once the shear layer is "
          "unstable";
      const int n = std::max(samples, 2);
      for (int i = 0; i < n; ++i) {
        const double t = end * i / (n - 1);
        const double amplitude = chi / lambda * (1.0 - std::exp(-lambda * t));
        const double drift2 = ux * ux * std::exp(-2.0 * mu * t);
        c.time.push_back(t);
        c.energy.push_back(0.25 * amplitude * amplitude + 0.5 * drift2);
        c.dissipation.push_back(-0.5 * amplitude * chi * std::exp(-lambda * t) + mu * drift2);
      }
      return c;
    }
  }
  throw std::logic_error("missing_reference and reference_curve disagree");  // not reached
}

std::vector<std::filesystem::path> reference_run_directories(
    const std::filesystem::path& reference_dir) {
  std::vector<std::filesystem::path> directories;
  std::error_code ec;
  for (const std::filesystem::directory_entry& e :
       std::filesystem::directory_iterator(reference_dir, ec))
    if (e.is_directory(ec)) directories.push_back(e.path());
  return directories;
}

std::optional<std::filesystem::path> find_reference_run(
    const sim::Scene& scene, const std::filesystem::path& reference_dir) {
  return best_reference_run(scene, reference_run_directories(reference_dir));
}

std::optional<std::filesystem::path> best_reference_run(
    const sim::Scene& scene, const std::vector<std::filesystem::path>& runs) {
  namespace fs = std::filesystem;
  std::optional<fs::path> best;
  int best_points = 0;
  for (const fs::path& dir : runs) {
    if (!fs::exists(dir / "scene.json") || !fs::exists(dir / "spectra" / "index.csv")) continue;
    try {
      nlohmann::json document = scene::read_scene_file(dir / "scene.json");
      const int points =
          document.value("reference", nlohmann::json::object()).value("points_per_side", 0);
      document.erase("reference");
      document.erase("render");
      const sim::Scene r = parse_run_config(document).scene;
      const bool same = r.case_type == scene.case_type &&
                        close(r.box_length(), scene.box_length()) &&
                        close(r.fluid.kinematic_viscosity(), scene.fluid.kinematic_viscosity()) &&
                        close(r.velocity_amplitude, scene.velocity_amplitude) &&
                        r.uniform_velocity == scene.uniform_velocity &&
                        (scene.case_type != sim::CaseType::Kolmogorov2D ||
                         (close(r.forcing.amplitude, scene.forcing.amplitude) &&
                          r.forcing.periods == scene.forcing.periods &&
                          close(r.forcing.friction, scene.forcing.friction)));
      if (same && (points > best_points || (points == best_points && best && dir < *best))) {
        best = dir;
        best_points = points;
      }
    } catch (const std::exception&) {
      continue;  // not a reference run of this version's scenes
    }
  }
  return best;
}

}  // namespace sphles::analysis
