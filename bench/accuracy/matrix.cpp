// SPDX-License-Identifier: GPL-3.0-or-later
// The matrix of cases (docs/accuracy.md): the scenes of every study, each configuration at its
// resolutions, as make_matrix gives them to run_one (accuracy.cpp measures them).
#include <functional>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "bench/accuracy/accuracy.hpp"
#include "scene/document.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::accuracy {

namespace {

using nlohmann::json;

constexpr double kStartStudyEnd = 0.3;  // the start study: t ∈ [0, 0.3] ...
constexpr double kStartStudySample =
    0.05;  // ... sampled every 0.05 (the first sample is the floor)

/// 2D Taylor-Green vortex (SPEC §6.2) as in the stability sweep: Ma = 0.1 (c_s = 10),
/// p_ref = ρ v0² = 1; Re = v0 L / ν with L = 1, ρ = 1. t ∈ [0, 2].
json tgv2d_scene(double reynolds, int n, const std::string& kernel, double dk) {
  return {{"case", "tgv2d"},
          {"particles_per_side", n},
          {"kernel", {{"type", kernel}, {"diameter_over_spacing", dk}}},
          {"fluid",
           {{"reference_density", 1.0},
            {"sound_speed", 10.0},
            {"reference_pressure", 1.0},
            {"dynamic_viscosity", 1.0 / reynolds}}},
          {"initial", {{"mass", "lattice"}}},  // the baseline rows: the thesis' start
          {"time", {{"end", 2.0}}}};
}

/// The peers' 2D Taylor-Green vortex (PySPH, DualSPHysics, SPHinXsys): Re = 100 on a unit box,
/// U = 1, c0 = 10, t = 2, i.e. ν = 2π/100 and t = 4π in the 2π box (SPEC §8), 100² particles,
/// WC4 D_K = 8Δl. `scheme`, `initial` and the background pressure vary.
json peers_scene(int n, const json& scheme, const std::string& initial_mass, double pressure,
                 double diameter_over_spacing = 8.0) {
  return {{"case", "tgv2d"},
          {"particles_per_side", n},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", diameter_over_spacing}}},
          {"fluid",
           {{"reference_density", 1.0},
            {"sound_speed", 10.0},
            {"reference_pressure", pressure},
            {"dynamic_viscosity", 2.0 * std::numbers::pi / 100.0}}},
          {"scheme", scheme},
          {"initial", {{"mass", initial_mass}}},
          {"time", {{"end", 4.0 * std::numbers::pi}}}};
}

/// 3D Taylor-Green vortex (SPEC §6.1: c_s = 5, p_ref = 6.25) at a DNS' Reynolds number, 1600 or
/// 5000 (η = 1/Re with ρ_ref = v0 = 1, L = 1), t ∈ [0, 12].
json tgv3d_scene(int n, const std::string& kernel, double dk, const std::string& model,
                 double reynolds = 5000.0) {
  return {{"case", "tgv3d"},
          {"particles_per_side", n},
          {"kernel", {{"type", kernel}, {"diameter_over_spacing", dk}}},
          {"fluid",
           {{"reference_density", 1.0},
            {"sound_speed", 5.0},
            {"reference_pressure", 6.25},
            {"dynamic_viscosity", 1.0 / reynolds}}},
          {"subfilter", {{"model", model}}},
          {"initial", {{"mass", "lattice"}}},
          {"time", {{"end", kMisfitEndTime}}}};
}

/// Kolmogorov flow (SPEC §6.3) reduced: the thesis fluid, friction, forcing χ = 1.8 m/s² and
/// forcing wavenumber k_y = 1047.2 1/m (wavelength λ = 6 mm), but 2 forcing periods (L = 12 mm
/// instead of 42 mm), WC4 with D_K = 8Δl, t ∈ [0, 1] s from rest. N = 24, 36, 48, 72 give
/// λ/D_K = 2, 3, 4, 6; the thesis' Δl = 125 µm (λ/D_K = 6) would be N = 96.
json kolmogorov_scene(int n) {
  return {{"case", "kolmogorov2d"},
          {"particles_per_side", n},
          {"box_length", 0.012},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
          {"forcing", {{"amplitude", 1.8}, {"periods", 2}}},
          {"initial", {{"mass", "lattice"}}},
          {"time", {{"end", 1.0}}}};
}

std::string number_label(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

RunSpec make_spec(std::string study, std::string config, json scene, double sample_interval) {
  const int n = scene["particles_per_side"].get<int>();
  RunSpec r;
  r.study = std::move(study);
  r.label = config + " N=" + std::to_string(n);
  r.config = std::move(config);
  r.scene = std::move(scene);
  r.sample_interval = sample_interval;
  return r;
}

/// The 2D Taylor-Green vortex (SPEC §6.2) at Re = 100 and 1000 for every kernel, D_K/Δl from 4
/// to 8 and N = 32, 64, 128.
std::vector<RunSpec> matrix_2d(bool quick) {
  std::vector<RunSpec> runs;
  // Quick: Wendland C4 and the quintic spline, D_K/Δl = 4 and 8, N = 32 and 64.
  const char* const kernels[] = {"wendland_c2", "wendland_c4", "wendland_c6", "quintic_spline"};
  for (const double reynolds : {100.0, 1000.0})
    for (const std::string kernel : kernels)
      for (const double dk : {4.0, 5.0, 6.0, 7.0, 8.0})
        for (const int n : {32, 64, 128}) {
          if (quick && (kernel == "wendland_c2" || kernel == "wendland_c6" ||
                        (dk != 4.0 && dk != 8.0) || n == 128))
            continue;
          runs.push_back(make_spec("tgv2d_re" + number_label(reynolds),
                                   kernel + " D_K/dl=" + number_label(dk),
                                   tgv2d_scene(reynolds, n, kernel, dk), 0.05));
        }
  return runs;
}

/// The 3D Taylor-Green vortex (SPEC §6.1) at the Reynolds numbers of its DNS, 5000 and 1600.
std::vector<RunSpec> matrix_3d(bool quick) {
  std::vector<RunSpec> runs;
  // WC4 with D_K = 8Δl and QS with D_K = 6Δl (SPEC Table 5.1), implicit and SMAG, at
  // Re = 5000; the implicit runs also at Re = 1600. Quick: the implicit runs at N = 24 only.
  const char* const kernels[] = {"wendland_c4", "quintic_spline"};
  const double diameters[] = {8.0, 6.0};
  for (std::size_t c = 0; c < 2; ++c)
    for (const std::string model : {"implicit", "smag"})
      for (const int n : {24, 32}) {
        if (quick && (model == "smag" || n == 32)) continue;
        const std::string kernel = kernels[c];
        for (const double reynolds : {5000.0, 1600.0}) {
          if (reynolds != 5000.0 && model != "implicit") continue;
          runs.push_back(make_spec("tgv3d_re" + number_label(reynolds),
                                   kernel + " D_K/dl=" + number_label(diameters[c]) + " " + model,
                                   tgv3d_scene(n, kernel, diameters[c], model, reynolds), 0.1));
        }
      }
  return runs;
}

/// The peers' 2D Taylor-Green vortex (SPEC §8), scheme by scheme.
std::vector<RunSpec> matrix_peers(bool quick) {
  std::vector<RunSpec> runs;
  // The peers' 2D case (SPEC §8) at 100²: the thesis model as the peers' comparison ran it
  // (p_ref = 1, lattice masses), the consistent start, the corrected viscous operator, and the
  // transport-velocity scheme at background pressures around PySPH's p_b = ρ c_s² = 100, and
  // particle shifting (Sun et al. 2019) at the δ⁺-SPH p_ref = 0 and at the thesis' p_ref = 1,
  // and with the full (Galilean-invariant) ALE correction at p_ref = 0; the TVF also with the
  // wider kernels D_K = 10Δl and 12Δl (WC4), which halve its L1 error (docs/accuracy.md), and
  // with the full ALE form of its extra stress; and the TVF at 12Δl with 3.75 times the
  // acoustic step and twice the viscous one, p_b divided by 3.75 so that p_b Δt, which sets how
  // far the background pressure moves the particles per unit time (docs/models.md), stays that
  // of p_b = 100 at the default step (the shipped scenes/tgv2d-peers.json).
  // Quick: the thesis model and TVF at p_b = 100, 50².
  struct PeersConfig {
    const char* name;
    json scheme;
    const char* initial_mass;
    double pressure;
    bool quick;
    double diameter_over_spacing = 8.0;
    json time = json::object();  // time.* keys beyond the end time (step factors)
  };
  const json thesis = {{"type", "thesis"}};
  const json corrected = {{"type", "thesis"}, {"viscous_operator", "corrected"}};
  const json tvf = {{"type", "transport_velocity"}};
  const json shifting = {{"type", "particle_shifting"}};
  const json shifting_full = {{"type", "particle_shifting"}, {"ale_correction", "full"}};
  const json tvf_full = {{"type", "transport_velocity"}, {"ale_correction", "full"}};
  const PeersConfig configs[] = {
      {"thesis p_ref=1 lattice", thesis, "lattice", 1.0, true},
      {"thesis p_ref=1 summation", thesis, "summation", 1.0, false},
      {"thesis-corrected p_ref=1 summation", corrected, "summation", 1.0, false},
      {"tvf p_b=100 summation", tvf, "summation", 100.0, true},
      {"tvf p_b=200 summation", tvf, "summation", 200.0, false},
      {"tvf p_b=100 summation D_K=10dl", tvf, "summation", 100.0, false, 10.0},
      {"tvf p_b=100 summation D_K=12dl", tvf, "summation", 100.0, false, 12.0},
      {"shifting p_ref=0 summation", shifting, "summation", 0.0, false},
      {"shifting p_ref=1 summation", shifting, "summation", 1.0, false},
      {"shifting-full p_ref=0 summation", shifting_full, "summation", 0.0, false},
      {"tvf-full p_b=100 summation", tvf_full, "summation", 100.0, false},
      {"tvf-full p_b=100 summation D_K=12dl", tvf_full, "summation", 100.0, false, 12.0},
      {"tvf p_b=26.7 summation D_K=12dl cfl=1.5",
       tvf,
       "summation",
       100.0 / 3.75,
       false,
       12.0,
       {{"cfl_acoustic", 1.5}, {"cfl_viscous", 0.25}}},
  };
  for (const PeersConfig& c : configs)
    for (const int n : {50, 100}) {
      if (quick ? (!c.quick || n != 50) : n != 100) continue;
      json scene = peers_scene(n, c.scheme, c.initial_mass, c.pressure, c.diameter_over_spacing);
      scene["time"].update(c.time);
      runs.push_back(make_spec("peers", c.name, scene, 0.1));
    }
  return runs;
}

/// The start-up error of the 2D Taylor-Green vortex.
std::vector<RunSpec> matrix_start(bool quick) {
  std::vector<RunSpec> runs;
  // The start-up error (docs/accuracy.md): the 2D TGV at Re = 100 (WC4 8Δl) to t = 0.3, sampled
  // every 0.05, at c_s = 10, 20, 40, with the thesis' lattice masses and the consistent start,
  // for the thesis model and the TVF (p_b = ρ c_s²). The velocity error at t = 0.05 is the floor
  // that acoustic waves from an inconsistent start leave. Quick: 32² and c_s = 10, 40.
  const json tvf = {{"type", "transport_velocity"}};
  for (const double sound_speed : {10.0, 20.0, 40.0})
    for (const std::string mass : {"lattice", "summation"})
      for (const bool transport : {false, true})
        for (const int n : {32, 64}) {
          if (quick && (n == 64 || sound_speed == 20.0)) continue;
          if (transport && mass == "lattice") continue;
          json scene = tgv2d_scene(100.0, n, "wendland_c4", 8.0);
          scene["fluid"]["sound_speed"] = sound_speed;
          scene["initial"]["mass"] = mass;
          scene["time"]["end"] = kStartStudyEnd;
          std::string name = std::string(transport ? "tvf" : "thesis") + " " + mass;
          if (transport) {
            scene["scheme"] = tvf;
            scene["fluid"]["reference_pressure"] = sound_speed * sound_speed;  // ρ = 1
          }
          runs.push_back(make_spec("start", name + " c_s=" + number_label(sound_speed), scene,
                                   kStartStudySample));
        }
  // The consistent start with the quintic spline (D_K = 8Δl): the kernel whose operators leave
  // the smallest floor at c_s = 10 (docs/accuracy.md).
  if (!quick)
    for (const double sound_speed : {10.0, 20.0, 40.0})
      for (const int n : {32, 64}) {
        json scene = tgv2d_scene(100.0, n, "quintic_spline", 8.0);
        scene["fluid"]["sound_speed"] = sound_speed;
        scene["initial"]["mass"] = "summation";
        scene["time"]["end"] = kStartStudyEnd;
        runs.push_back(make_spec("start", "thesis summation QS8 c_s=" + number_label(sound_speed),
                                 scene, kStartStudySample));
      }
  return runs;
}

/// Every scheme on the same cases and resolutions.
std::vector<RunSpec> matrix_schemes(bool quick) {
  std::vector<RunSpec> runs;
  // The schemes head-to-head: every scheme on the same cases and resolutions, the thesis
  // model with its own start first (the baseline rows). The TVF's background pressure is
  // p_b = ρ_ref c_s² (Adami et al. 2013; PySPH's choice); the other schemes keep each case's
  // p_ref (particle shifting: its default Ma and the conservative ALE form). The 3D case at 32³
  // was run for the thesis model, the TVF and shifting only (docs/accuracy.md). Quick: the
  // smallest resolution of each case. `tvf-3dt` is the TVF at three times the default acoustic
  // and viscous steps with p_b = ρ_ref c_s²/3, so that p_b Δt, which sets its regularisation
  // per unit time (docs/models.md), is that of `tvf`.
  enum class Pressure { Case, BulkModulus };
  struct SchemeVariant {
    const char* name;
    json scheme;
    const char* initial_mass;
    Pressure pressure;
    double step_factor = 1.0;  // times the default acoustic and viscous step factors
  };
  constexpr double kLargeStep = 3.0;
  const SchemeVariant variants[] = {
      {"thesis", {{"type", "thesis"}}, "lattice", Pressure::Case},
      {"thesis+summation", {{"type", "thesis"}}, "summation", Pressure::Case},
      {"thesis+corrected",
       {{"type", "thesis"}, {"viscous_operator", "corrected"}},
       "summation",
       Pressure::Case},
      {"tvf", {{"type", "transport_velocity"}}, "summation", Pressure::BulkModulus},
      {"shifting", {{"type", "particle_shifting"}}, "summation", Pressure::Case},
      {"tvf-3dt", {{"type", "transport_velocity"}}, "summation", Pressure::BulkModulus, kLargeStep},
  };
  struct SchemeCase {
    const char* study;
    std::vector<int> sides;
    double sample_interval;
    std::function<json(int)> scene;
  };
  const SchemeCase cases[] = {
      {"schemes_tgv2d_re100",
       {32, 64, 128},
       0.05,
       [](int n) { return tgv2d_scene(100.0, n, "wendland_c4", 8.0); }},
      {"schemes_tgv3d_re5000",
       {24, 32},
       0.1,
       [](int n) { return tgv3d_scene(n, "wendland_c4", 8.0, "implicit"); }},
      {"schemes_tgv3d_re1600",
       {24, 32},
       0.1,
       [](int n) { return tgv3d_scene(n, "wendland_c4", 8.0, "implicit", 1600.0); }},
      {"schemes_kolmogorov", {24, 36, 48}, 0.02, [](int n) { return kolmogorov_scene(n); }},
  };
  for (const SchemeCase& c : cases)
    for (const SchemeVariant& v : variants)
      for (const int n : c.sides) {
        if (quick && n != c.sides.front()) continue;
        json scene = c.scene(n);
        scene["scheme"] = v.scheme;
        scene["initial"]["mass"] = v.initial_mass;
        if (v.pressure == Pressure::BulkModulus) {
          const sim::Scene parsed = scene::parse_scene(scene);
          scene["fluid"]["reference_pressure"] = parsed.fluid.reference_density *
                                                 parsed.fluid.sound_speed *
                                                 parsed.fluid.sound_speed / v.step_factor;
        }
        if (v.step_factor != 1.0) {
          const sim::TimeStepConfig defaults;
          scene["time"]["cfl_acoustic"] = v.step_factor * defaults.cfl_acoustic;
          scene["time"]["cfl_viscous"] = v.step_factor * defaults.cfl_viscous;
        }
        runs.push_back(make_spec(c.study, v.name, scene, c.sample_interval));
      }
  return runs;
}

/// The reduced Kolmogorov flow (SPEC §6.3) at λ/D_K = 2, 3, 4, 6.
std::vector<RunSpec> matrix_kolmogorov(bool quick) {
  std::vector<RunSpec> runs;
  for (const int n : {24, 36, 48, 72}) {
    if (quick && n > 36) continue;
    runs.push_back(make_spec("kolmogorov", "wendland_c4 D_K/dl=8", kolmogorov_scene(n), 0.02));
  }
  return runs;
}

}  // namespace

std::vector<RunSpec> make_matrix(const std::string& study, bool quick) {
  if (study == "2d") return matrix_2d(quick);
  if (study == "3d") return matrix_3d(quick);
  if (study == "peers") return matrix_peers(quick);
  if (study == "start") return matrix_start(quick);
  if (study == "schemes") return matrix_schemes(quick);
  if (study == "kolmogorov") return matrix_kolmogorov(quick);
  throw std::invalid_argument("unknown study '" + study +
                              "' (2d, 3d, peers, start, schemes, kolmogorov)");
}

RunSpec with_resolution(const RunSpec& spec, int particles_per_side) {
  RunSpec r = spec;
  r.scene["particles_per_side"] = particles_per_side;
  r.label = r.config + " N=" + std::to_string(particles_per_side);
  return r;
}

}  // namespace sphles::accuracy
