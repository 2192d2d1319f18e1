// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/scene.hpp"

#include "sim/json_reader.hpp"
#include "sim/scene_schema.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>

namespace sphles::sim {

using nlohmann::json;

namespace {

/// Defaults that depend on the case (SPEC §6.1 for tgv3d; tgv2d at Re = 100, Ma = 0.1).
Scene case_defaults(CaseType type) {
  Scene s;
  s.case_type = type;
  s.box_length_ = 2.0 * std::numbers::pi;
  if (type == CaseType::Kolmogorov2D) {
    // Thin-film experiment of Rivera & Wu 2000 as in SPEC §6.3: Δl = 125 µm, D_K = 1 mm.
    s.name = "kolmogorov2d";
    s.box_length_ = 0.042;
    s.particles_per_side = 336;
    s.kernel_diameter_over_spacing = 8.0;
    s.velocity_amplitude = 0.0;  // starts from rest
    s.fluid = {.reference_density = 1000.0,
               .sound_speed = 2.0,
               .reference_pressure = 400.0,
               .dynamic_viscosity = 1.6e-3};
    s.end_time = 20.0;
  } else if (type == CaseType::TaylorGreen3D) {
    s.name = "tgv3d";
    s.particles_per_side = 32;
    s.fluid = {.reference_density = 1.0,
               .sound_speed = 5.0,
               .reference_pressure = 6.25,
               .dynamic_viscosity = 1e-4};
    s.end_time = 15.0;
  } else {
    // p_ref = ρ v0² keeps the pressure positive (p0 - p_ref >= -ρ v0²/2); D_K = 12Δl gives
    // N_ngb ≈ 113 in 2D. With these, e_v stays within 2 % of the analytic decay (validation.md).
    s.name = "tgv2d";
    s.particles_per_side = 128;
    s.kernel_diameter_over_spacing = 12.0;
    s.fluid = {.reference_density = 1.0,
               .sound_speed = 10.0,
               .reference_pressure = 1.0,
               .dynamic_viscosity = 1e-2};
    s.end_time = 2.0;
  }
  return s;
}

/// Largest |∇p0| / (ρ_ref v0²) of the initial pressures. 3D (5.2): |∇p0|² / (ρ_ref v0²/8)² =
/// (2 + cos 2z)² (sin² 2x + sin² 2y) + sin² 2z (cos 2x + cos 2y)², at most 2 · 3² = 18 (z = 0,
/// |sin 2x| = |sin 2y| = 1). 2D: (ρ_ref v0²/2) (sin 2x, sin 2y), at most √2 / 2.
const double kTaylorGreen3dPressureGradient = std::sqrt(18.0) / 8.0;
const double kTaylorGreen2dPressureGradient = std::sqrt(2.0) / 2.0;

/// The keys a time-step limit depends on.
std::vector<std::string> limit_keys(const Scene& s, std::string_view limit) {
  std::vector<std::string> keys;
  if (limit == "fixed") {
    keys = {"time.fixed_step"};
  } else {
    if (s.case_type == CaseType::Kolmogorov2D) keys.push_back("box_length");
    keys.push_back("particles_per_side");
    if (limit == "acoustic") {
      keys.insert(keys.end(), {"fluid.sound_speed", "flow.velocity_amplitude",
                               "flow.uniform_velocity", "time.cfl_acoustic"});
    } else if (limit == "viscous") {
      keys.insert(keys.end(),
                  {"fluid.dynamic_viscosity", "fluid.reference_density", "time.cfl_viscous"});
    } else if (s.case_type == CaseType::Kolmogorov2D) {
      keys.insert(keys.end(), {"forcing.amplitude", "forcing.friction", "time.cfl_force"});
    } else {
      keys.insert(keys.end(), {"flow.velocity_amplitude", "time.cfl_force"});
    }
  }
  return keys;
}

/// A step below kMinTimeStepOverEndTime x time.end cannot advance the time meaningfully. The
/// message starts with the keys that set the step; the error's field is the first of them.
void check_time_resolution(const Scene& s) {
  const TimeStepEstimate e = estimate_initial_time_step(s);
  const double minimum = kMinTimeStepOverEndTime * s.end_time;
  if (e.step() >= minimum) return;
  const std::string_view limit = e.limits.binding();
  const std::vector<std::string> keys = limit_keys(s, limit);
  std::string names;  // "'a', 'b' and 'c'"
  for (std::size_t k = 0; k < keys.size(); ++k)
    names += (k == 0 ? "" : k + 1 == keys.size() ? " and " : ", ") + ("'" + keys[k] + "'");
  throw SceneError(keys.front(),
                   "scene: " + names + " give an estimated initial time step of " +
                       format_number(e.step()) + " s (" + std::string(limit) + " limit, spacing " +
                       format_number(s.particle_spacing()) + " m), below 'time.end' x " +
                       format_number(kMinTimeStepOverEndTime) + " = " + format_number(minimum) +
                       " s: t + dt would not advance meaningfully, and the run would need over " +
                       format_number(1.0 / kMinTimeStepOverEndTime) + " steps");
}

}  // namespace

std::string_view case_name(CaseType type) {
  return kCaseNames.name(type);
}

std::string_view initial_mass_name(InitialMass mass) {
  return kInitialMassNames.name(mass);
}

int case_dimension(CaseType type) {
  return type == CaseType::TaylorGreen3D ? 3 : 2;
}

double Scene::forcing_wavenumber() const {
  return 2.0 * std::numbers::pi * forcing.periods / box_length();
}
double Scene::particle_spacing() const {
  return box_length() / particles_per_side;
}
double Scene::kernel_diameter() const {
  return kernel_diameter_over_spacing * particle_spacing();
}
std::size_t Scene::num_particles() const {
  std::size_t n = 1;
  for (int d = 0; d < dimension(); ++d) n *= static_cast<std::size_t>(particles_per_side);
  return n;
}

Scene parse_scene(const json& input) {
  if (!input.is_object())
    throw_scene_error("(top level)", "must be an object, got " + describe_type(input));
  // A preset is the base document; the scene's own keys patch it.
  json document = input;
  std::string preset;
  if (const auto it = input.find("preset"); it != input.end()) {
    if (!it->is_string())
      throw_scene_error("preset", "must be a string, got " + describe_type(*it));
    preset = it->get<std::string>();
    document = preset_document(preset);
    json patch = input;
    patch.erase("preset");
    document.merge_patch(patch);
  }
  ObjectReader top(document, "");
  CaseType type = CaseType::TaylorGreen3D;
  top.choice("case", kCaseNames, type);
  Scene s = case_defaults(type);
  s.preset = preset;
  if (!preset.empty()) s.name = preset;
  top.find("preset");

  top.string("name", s.name);
  top.integer("particles_per_side", s.particles_per_side);
  if (s.case_type == CaseType::Kolmogorov2D) {
    top.number("box_length", s.box_length_);
  } else if (top.find("box_length")) {
    throw_scene_error("box_length", "is fixed at 2π for the Taylor-Green cases");
  }
  {
    ObjectReader k = top.object("kernel");
    k.choice("type", kKernelNames, s.kernel);
    k.number("diameter_over_spacing", s.kernel_diameter_over_spacing);
    k.reject_unknown();
  }
  {
    ObjectReader f = top.object("fluid");
    f.number("reference_density", s.fluid.reference_density);
    f.number("sound_speed", s.fluid.sound_speed);
    f.number("reference_pressure", s.fluid.reference_pressure);
    f.number("dynamic_viscosity", s.fluid.dynamic_viscosity);
    f.reject_unknown();
  }
  {
    ObjectReader f = top.object("flow");
    f.number("velocity_amplitude", s.velocity_amplitude);
    f.vector("uniform_velocity", s.uniform_velocity, static_cast<std::size_t>(s.dimension()));
    f.reject_unknown();
  }
  {
    ObjectReader t = top.object("time");
    t.number("end", s.end_time);
    t.number("cfl_acoustic", s.time_step.cfl_acoustic);
    t.number("cfl_viscous", s.time_step.cfl_viscous);
    t.number("cfl_force", s.time_step.cfl_force);
    t.number("fixed_step", s.time_step.fixed);
    t.reject_unknown();
  }
  {
    ObjectReader b = top.object("blow_up");
    b.number("energy_factor", s.blow_up.energy_factor);
    b.number("reference_mach", s.blow_up.reference_mach);
    b.number("reference_energy", s.blow_up.reference_energy);
    b.reject_unknown();
  }
  {
    // An object, so that further keys of the scheme can join "type".
    ObjectReader sc = top.object("scheme");
    sc.choice("type", kSchemeNames, s.scheme.type);
    sc.choice("viscous_operator", kViscousOperatorNames, s.scheme.viscous_operator);
    if (s.scheme.viscous_operator != ViscousOperator::Thesis &&
        s.scheme.type == SchemeType::TransportVelocity)
      throw_scene_error("scheme.viscous_operator",
                        "= '" + std::string(viscous_operator_name(s.scheme.viscous_operator)) +
                            "' applies to scheme.type thesis and particle_shifting only (the "
                            "transport-velocity scheme has its own viscous term)");
    const double default_mach = SchemeConfig{}.shifting_mach;
    sc.number("shifting_mach", s.scheme.shifting_mach);
    if (s.scheme.shifting_mach != default_mach && s.scheme.type != SchemeType::ParticleShifting)
      throw_scene_error("scheme.shifting_mach", "applies to scheme.type particle_shifting only");
    sc.choice("ale_correction", kAleCorrectionNames, s.scheme.ale_correction);
    if (s.scheme.ale_correction != SchemeConfig{}.ale_correction &&
        !scheme_uses_transport_velocity(s.scheme.type))
      throw_scene_error("scheme.ale_correction",
                        "applies to scheme.type transport_velocity and particle_shifting only");
    sc.reject_unknown();
  }
  {
    ObjectReader m = top.object("subfilter");
    m.choice("model", kSubfilterModelNames, s.subfilter.model);
    m.number("smagorinsky_constant", s.subfilter.smagorinsky_constant);
    m.number("sigma_constant", s.subfilter.sigma_constant);
    m.number("filter_width", s.subfilter.filter_width);
    m.reject_unknown();
  }
  if (s.case_type == CaseType::Kolmogorov2D) {
    ObjectReader f = top.object("forcing");
    f.number("amplitude", s.forcing.amplitude);
    f.integer("periods", s.forcing.periods);
    f.number("friction", s.forcing.friction);
    f.reject_unknown();
  } else if (top.find("forcing")) {
    throw_scene_error("forcing", "applies to case kolmogorov2d only");
  }
  {
    ObjectReader nb = top.object("neighbours");
    nb.number("skin", s.neighbour_skin);
    nb.reject_unknown();
  }
  {
    ObjectReader p = top.object("packing");
    p.boolean("enabled", s.packing.enabled);
    p.boolean("cache", s.packing.cache);
    // The cache directory is a setting of the program (--packing-cache), not of the scene: a
    // scene from a client must not choose where the server writes. Documents written before
    // hold "cache_dir": "", which is accepted and ignored.
    std::string cache_dir;
    p.string("cache_dir", cache_dir);
    if (!cache_dir.empty())
      throw_scene_error("packing.cache_dir",
                        "is not a scene key: the packing cache directory is a setting of the "
                        "program (sphles run/serve --packing-cache DIR)");
    p.number("perturbation", s.packing.perturbation);
    p.integer("max_iterations", s.packing.max_iterations);
    p.number("tolerance", s.packing.tolerance);
    p.integer("seed", s.packing.seed);
    p.reject_unknown();
  }
  {
    ObjectReader in = top.object("initial");
    in.choice("mass", kInitialMassNames, s.initial.mass);
    in.reject_unknown();
  }
  {
    ObjectReader c = top.object("checkpoint");
    c.number("every", s.checkpoint.every);
    c.number("every_seconds", s.checkpoint.every_seconds);
    c.integer("keep", s.checkpoint.keep);
    c.integer("compression", s.checkpoint.compression);
    c.reject_unknown();
  }
  {
    ObjectReader o = top.object("output");
    o.number("timeseries_every", s.output.timeseries_every);
    o.number("progress_every_seconds", s.output.progress_every_seconds);
    o.reject_unknown();
  }
  top.reject_unknown();

  if (s.kernel_diameter() > s.box_length()) {
    throw SceneError(
        "kernel.diameter_over_spacing",
        "scene: box length " + format_number(s.box_length()) +
            " m is smaller than the kernel diameter D_K = " + format_number(s.kernel_diameter()) +
            " m ('kernel.diameter_over_spacing' = " +
            format_number(s.kernel_diameter_over_spacing) + " x spacing " +
            format_number(s.particle_spacing()) +
            " m with 'particles_per_side' = " + std::to_string(s.particles_per_side) + ")");
  }
  check_time_resolution(s);
  check_cadence(s, "output.timeseries_every", s.output.timeseries_every);
  check_cadence(s, "checkpoint.every", s.checkpoint.every);
  return s;
}

TimeStepEstimate estimate_initial_time_step(const Scene& s) {
  TimeStepEstimate e;
  const double v0 = std::abs(s.velocity_amplitude);
  double uniform2 = 0.0;
  for (int d = 0; d < s.dimension(); ++d) uniform2 += s.uniform_velocity[d] * s.uniform_velocity[d];
  const double uniform = std::sqrt(uniform2);
  const double nu = s.fluid.kinematic_viscosity();
  e.max_speed = v0 + uniform;
  switch (s.case_type) {
    case CaseType::TaylorGreen3D:
      // max |∇p0| = ρ_ref v0² √18 / 8 for (5.2); ν∇²v = -3ν v (the modes have |k|² = 3).
      e.max_acceleration = kTaylorGreen3dPressureGradient * v0 * v0 + 3.0 * nu * v0;
      break;
    case CaseType::TaylorGreen2D:
      // p0 = p_ref + ρ_ref v0²/4 (cos 2x + cos 2y): max |∇p0| = ρ_ref v0² √2 / 2; |k|² = 2.
      e.max_acceleration = kTaylorGreen2dPressureGradient * v0 * v0 + 2.0 * nu * v0;
      break;
    case CaseType::Kolmogorov2D:
      // At rest (plus the uniform velocity): a = χ sin(k_y y) e_x - μ U.
      e.max_acceleration = std::abs(s.forcing.amplitude) + s.forcing.friction * uniform;
      break;
  }
  e.limits =
      time_step_limits(s.time_step, s.particle_spacing(), s.fluid, e.max_speed, e.max_acceleration);
  return e;
}

double min_cadence(const Scene& s) {
  return std::min(kMinCadenceOverTimeStep * estimate_initial_time_step(s).step(),
                  s.end_time / kMaxShortCadencePoints);
}

void check_cadence(const Scene& s, const std::string& field, double every) {
  if (!(every > 0.0)) return;
  const double minimum = min_cadence(s);
  if (every >= minimum) return;
  const TimeStepEstimate e = estimate_initial_time_step(s);
  throw_scene_error(
      field, "= " + format_number(every) + " s is below the smallest accepted cadence " +
                 format_number(minimum) + " s, the smaller of " +
                 format_number(kMinCadenceOverTimeStep) + " x the estimated initial time step " +
                 format_number(e.step()) + " s (" + std::string(e.limits.binding()) +
                 " limit) and 'time.end' / " + format_number(kMaxShortCadencePoints) +
                 ": every step would be cut short to land on the next of its " +
                 format_number(std::floor(s.end_time / every)) +
                 " points; use 0 (every step) or at least " + format_number(minimum) + " s");
}

json read_scene_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw SceneError(path.string(), "scene: cannot open file '" + path.string() + "'");
  try {
    return json::parse(in);
  } catch (const json::parse_error& e) {
    throw_scene_error(path.string(), std::string("is not valid JSON: ") + e.what());
  }
}

void apply_override(json& document, const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw SceneError(assignment, "--set: expected key=value, got '" + assignment + "'");
  const std::string key = assignment.substr(0, eq);
  const std::string text = assignment.substr(eq + 1);
  json value = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (value.is_discarded()) value = text;
  const std::vector<std::string> parts = dotted_keys(key);
  json* node = &document;
  std::string walked;  // the key up to `node`
  for (std::size_t k = 0; k < parts.size(); ++k) {
    const std::string& part = parts[k];
    if (part.empty()) throw SceneError(key, "--set: empty component in key '" + key + "'");
    if (!node->is_object()) throw SceneError(walked, "--set: '" + walked + "' is not an object");
    if (k + 1 == parts.size()) {
      (*node)[part] = value;
      return;
    }
    node = &(*node)[part];
    if (node->is_null()) *node = json::object();
    walked += (walked.empty() ? "" : ".") + part;
  }
}

json scene_to_json(const Scene& s) {
  json j;
  j["name"] = s.name;
  if (!s.preset.empty()) j["preset"] = s.preset;
  if (s.case_type == CaseType::Kolmogorov2D) {
    j["box_length"] = s.box_length();
    j["forcing"] = {{"amplitude", s.forcing.amplitude},
                    {"periods", s.forcing.periods},
                    {"friction", s.forcing.friction}};
  }
  j["scheme"] = {
      {"type", std::string(scheme_name(s.scheme.type))},
      {"viscous_operator", std::string(viscous_operator_name(s.scheme.viscous_operator))},
      {"shifting_mach", s.scheme.shifting_mach},
      {"ale_correction", std::string(ale_correction_name(s.scheme.ale_correction))}};
  j["subfilter"] = {{"model", std::string(subfilter_model_name(s.subfilter.model))},
                    {"smagorinsky_constant", s.subfilter.smagorinsky_constant},
                    {"sigma_constant", s.subfilter.sigma_constant},
                    {"filter_width", s.subfilter.filter_width}};
  j["case"] = std::string(case_name(s.case_type));
  j["particles_per_side"] = s.particles_per_side;
  j["kernel"] = {{"type", std::string(kernel_name(s.kernel))},
                 {"diameter_over_spacing", s.kernel_diameter_over_spacing}};
  j["fluid"] = {{"reference_density", s.fluid.reference_density},
                {"sound_speed", s.fluid.sound_speed},
                {"reference_pressure", s.fluid.reference_pressure},
                {"dynamic_viscosity", s.fluid.dynamic_viscosity}};
  j["flow"] = {
      {"velocity_amplitude", s.velocity_amplitude},
      {"uniform_velocity", std::vector<double>(s.uniform_velocity.begin(),
                                               s.uniform_velocity.begin() + s.dimension())}};
  j["time"] = {{"end", s.end_time},
               {"cfl_acoustic", s.time_step.cfl_acoustic},
               {"cfl_viscous", s.time_step.cfl_viscous},
               {"cfl_force", s.time_step.cfl_force},
               {"fixed_step", s.time_step.fixed}};
  j["blow_up"] = {{"energy_factor", s.blow_up.energy_factor},
                  {"reference_mach", s.blow_up.reference_mach},
                  {"reference_energy", s.blow_up.reference_energy}};
  j["neighbours"] = {{"skin", s.neighbour_skin}};
  j["packing"] = {
      {"enabled", s.packing.enabled},           {"cache", s.packing.cache},
      {"perturbation", s.packing.perturbation}, {"max_iterations", s.packing.max_iterations},
      {"tolerance", s.packing.tolerance},       {"seed", s.packing.seed}};
  j["initial"] = {{"mass", std::string(initial_mass_name(s.initial.mass))}};
  j["checkpoint"] = {{"every", s.checkpoint.every},
                     {"every_seconds", s.checkpoint.every_seconds},
                     {"keep", s.checkpoint.keep},
                     {"compression", s.checkpoint.compression}};
  j["output"] = {{"timeseries_every", s.output.timeseries_every},
                 {"progress_every_seconds", s.output.progress_every_seconds}};
  return j;
}

}  // namespace sphles::sim

namespace sphles::sim {

namespace {

/// The glass start: the packing's random displacement [Δl] and the residual it stops at (a glass
/// has no force-free state to converge to; 0.003 is reached in about 300 iterations at 32³).
constexpr double kGlassPerturbation = 0.45;
constexpr double kGlassTolerance = 0.003;

/// One row of SPEC Table 5.1.
struct ThesisCase {
  int number;
  const char* kernel;
  int particles_per_side;
  double diameter_over_spacing;
  const char* model;
  double smagorinsky_constant;
  double reference_pressure;  // 0: the default ρ c_s²/4 = 6.25
  double sound_speed;         // 0: the default 5
  double uniform_velocity_z;
};

constexpr ThesisCase kThesisCases[] = {
    {1, "quintic_spline", 128, 6, "implicit", 0.15, 0, 0, 0},
    {2, "quintic_spline", 192, 6, "implicit", 0.15, 0, 0, 0},
    {3, "quintic_spline", 256, 6, "implicit", 0.15, 0, 0, 0},
    {4, "quintic_spline", 512, 6, "implicit", 0.15, 0, 0, 0},
    {5, "wendland_c4", 256, 4, "implicit", 0.15, 0, 0, 0},
    {6, "wendland_c4", 256, 6, "implicit", 0.15, 0, 0, 0},
    {7, "wendland_c4", 256, 8, "implicit", 0.15, 0, 0, 0},
    {8, "wendland_c4", 128, 8, "implicit", 0.15, 0, 0, 0},
    {9, "wendland_c4", 192, 8, "implicit", 0.15, 0, 0, 0},
    {10, "wendland_c4", 256, 8, "implicit", 0.15, 0, 0, 0},
    {11, "wendland_c4", 512, 8, "implicit", 0.15, 0, 0, 0},
    {12, "wendland_c4", 128, 8, "smag", 0.15, 0, 0, 0},
    {13, "wendland_c4", 192, 8, "smag", 0.15, 0, 0, 0},
    {14, "wendland_c4", 256, 8, "smag", 0.15, 0, 0, 0},
    {15, "wendland_c4", 512, 8, "smag", 0.15, 0, 0, 0},
    {16, "wendland_c4", 256, 8, "sigma", 0.15, 0, 0, 0},
    {17, "wendland_c4", 256, 8, "smag_mcg", 0.15, 0, 0, 0},
    {18, "wendland_c4", 256, 8, "smag", 0.075, 0, 0, 0},
    {19, "wendland_c4", 256, 8, "smag", 0.3, 0, 0, 0},
    {20, "wendland_c4", 256, 8, "implicit", 0.15, 68, 0, 0},
    {21, "wendland_c4", 256, 8, "implicit", 0.15, 68, 16.5, std::numbers::pi},
};

}  // namespace

std::vector<std::string> preset_names() {
  std::vector<std::string> names;
  names.push_back("tgv2d");
  names.push_back("tgv3d");
  names.push_back("tgv3d-re1600");
  for (const ThesisCase& c : kThesisCases) names.push_back("tgv3d-case" + std::to_string(c.number));
  names.push_back("kolmogorov2d");
  return names;
}

json preset_document(const std::string& name) {
  // Small cases for a laptop or a live demo: 2D Taylor-Green at Re = 100 (SPEC §6.2, the
  // validation setting of docs/validation.md at 64²) and the 3D vortex of SPEC §6.1 at 32³.
  if (name == "tgv2d")
    return {{"case", "tgv2d"},
            {"particles_per_side", 64},
            {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
            {"fluid",
             {{"reference_density", 1.0},
              {"dynamic_viscosity", 0.01},
              {"sound_speed", 10.0},
              {"reference_pressure", 1.0}}},
            {"time", {{"end", 2.0}}}};
  if (name == "tgv3d")
    return {{"case", "tgv3d"},
            {"particles_per_side", 32},
            {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
            {"fluid",
             {{"reference_density", 1.0},
              {"dynamic_viscosity", 1e-4},
              {"sound_speed", 5.0},
              {"reference_pressure", 6.25}}},
            {"time", {{"end", 15.0}}}};
  // The 3D vortex at the community's Re = 1600, whose spectral reference sphles ships
  // (data/reference/), from a glass: the lattice displaced by up to 0.45Δl before the packing,
  // which relaxes it into an isotropic arrangement. From the near-lattice of the default 0.05Δl
  // the strained lattice rearranges at t ≈ 0.8 and the resolved scales lose 17 % of their energy
  // by t = 2 at 32³, much of it to particle-scale motion (docs/accuracy.md, "The start").
  if (name == "tgv3d-re1600") {
    json document = preset_document("tgv3d");
    document["fluid"]["dynamic_viscosity"] = 1.0 / 1600.0;
    document["packing"] = {{"perturbation", kGlassPerturbation}, {"tolerance", kGlassTolerance}};
    return document;
  }
  if (name == "kolmogorov2d") return {{"case", "kolmogorov2d"}, {"forcing", {{"amplitude", 1.8}}}};
  for (const ThesisCase& c : kThesisCases) {
    if (name != "tgv3d-case" + std::to_string(c.number)) continue;
    json fluid = {{"reference_density", 1.0}, {"dynamic_viscosity", 1e-4}};
    fluid["sound_speed"] = c.sound_speed > 0.0 ? c.sound_speed : 5.0;
    fluid["reference_pressure"] = c.reference_pressure > 0.0 ? c.reference_pressure : 6.25;
    return {{"case", "tgv3d"},
            {"particles_per_side", c.particles_per_side},
            {"kernel", {{"type", c.kernel}, {"diameter_over_spacing", c.diameter_over_spacing}}},
            {"fluid", fluid},
            {"flow", {{"uniform_velocity", {0.0, 0.0, c.uniform_velocity_z}}}},
            {"subfilter", {{"model", c.model}, {"smagorinsky_constant", c.smagorinsky_constant}}},
            {"initial", {{"mass", "lattice"}}},  // the thesis' M0 = ρ0 Δl³ (SPEC §6.1)
            {"time", {{"end", 15.0}}}};
  }
  std::string valid;
  for (const std::string& n : preset_names()) valid += (valid.empty() ? "" : ", ") + n;
  throw SceneError("preset", "scene: unknown preset '" + name + "' (valid: " + valid + ")");
}

}  // namespace sphles::sim
