// SPDX-License-Identifier: GPL-3.0-or-later
// Reference curves a run is compared with (dashboard, accuracy benchmark): the kinetic energy
// e_v(t) and its dissipation -de_v/dt of the 2D Taylor-Green vortex (analytic, SPEC §6.2), of
// the 3D Taylor-Green vortex at Re = 1600 and 5000 (the DNS shipped in data/reference/) and of
// the laminar Kolmogorov flow from rest (analytic, SPEC §6.3).
#pragma once

#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "sim/scene.hpp"

namespace sphles::analysis {

/// t, E and -dE/dt of the Incompact3d DNS file (data/reference/README.md: columns 1-3; lines
/// starting with '#' skipped). Throws std::runtime_error naming the file and the line.
struct DnsHistory {
  std::vector<double> time, energy, dissipation;
};
DnsHistory read_dns_history(const std::filesystem::path& file);

/// The DNS files' names in the reference directory: Re = 5000 (Incompact3d) and Re = 1600 (the
/// HiOCFD workshop's spectral DNS; both read by read_dns_history).
inline constexpr const char* kTgv3dDnsFile = "tgv_re5000_incompact3d_1280_dairay2017.dat";
inline constexpr const char* kTgv3dRe1600DnsFile = "tgv_re1600_spectral_512_hiocfd.gdiag";

struct ReferenceCurve {
  std::string label;                              // e.g. "DNS, Re = 5000 (Dairay et al. 2017)"
  std::string source;                             // what it is and where it comes from
  std::vector<double> time, energy, dissipation;  // [s], e_v [m²/s²], -de_v/dt [m²/s³]
};

/// Why a scene has no reference curve, or nothing when it has one (cheap: no file is read).
std::optional<std::string> missing_reference(const sim::Scene& scene);

/// The reference of a scene, if it has one: the analytic decay for tgv2d (sampled at
/// `samples` times over [0, time.end]), the DNS for tgv3d when the scene is a DNS' flow (v0 =
/// 1, L = 2π, ν = 1/1600 or 1/5000 within 1e-9 relative; up to time.end, and the DNS' t ≤ 20),
/// the laminar
/// spin-up from rest for kolmogorov2d (sampled as tgv2d; a uniform velocity along x only). A
/// uniform velocity U adds ½|U|² to e_v (decaying by the friction in the Kolmogorov flow).
/// Otherwise throws std::invalid_argument saying why there is none.
/// With `until`, the curve ends at min(until, time.end): the analytic curves are then sampled
/// over that shorter span (a dashboard showing the first seconds of a long run), the DNS cut.
ReferenceCurve reference_curve(const sim::Scene& scene, const std::filesystem::path& reference_dir,
                               int samples = 201,
                               double until = std::numeric_limits<double>::infinity());

/// The reference run of the scene's flow among `runs` (`sphles reference` run directories with
/// spectra/ and scene.json, e.g. the shipped data/reference/tgv3d_re1600_sphles_256, or the
/// service's finished reference jobs): the same case, box, viscosity, v0, uniform velocity and
/// forcing (1e-9 relative). The one with the most grid points when several match (the first by
/// path among equals); nothing when none does.
std::optional<std::filesystem::path> best_reference_run(
    const sim::Scene& scene, const std::vector<std::filesystem::path>& runs);

/// The directories directly in `reference_dir` (none if it cannot be read).
std::vector<std::filesystem::path> reference_run_directories(
    const std::filesystem::path& reference_dir);

/// best_reference_run among the run directories in `reference_dir`.
std::optional<std::filesystem::path> find_reference_run(const sim::Scene& scene,
                                                        const std::filesystem::path& reference_dir);

}  // namespace sphles::analysis
