// SPDX-License-Identifier: GPL-3.0-or-later
#include "scene/document.hpp"

#include <fstream>
#include <string>
#include <vector>

#include "scene/json_reader.hpp"
#include "scene/json_writer.hpp"
#include "scene/presets.hpp"
#include "scene/schema.hpp"
#include "sim/format.hpp"

namespace sphles::scene {

using nlohmann::json;
using namespace sim;

namespace {

// The keys of each section of the scene (docs/scenes.md), listed once: IO is an ObjectReader
// (parse_scene, S mutable) or an ObjectWriter (scene_to_json, S const).

template <class IO, class S>
void kernel_keys(IO& io, S& s) {
  io.choice("type", kKernelNames, s.kernel);
  io.number("diameter_over_spacing", s.kernel_diameter_over_spacing);
}

template <class IO, class F>
void fluid_keys(IO& io, F& f) {
  io.number("reference_density", f.reference_density);
  io.number("sound_speed", f.sound_speed);
  io.number("reference_pressure", f.reference_pressure);
  io.number("dynamic_viscosity", f.dynamic_viscosity);
}

template <class IO, class S>
void flow_keys(IO& io, S& s) {
  io.number("velocity_amplitude", s.velocity_amplitude);
  io.vector("uniform_velocity", s.uniform_velocity, static_cast<std::size_t>(s.dimension()));
}

template <class IO, class S>
void time_keys(IO& io, S& s) {
  io.number("end", s.end_time);
  io.number("cfl_acoustic", s.time_step.cfl_acoustic);
  io.number("cfl_viscous", s.time_step.cfl_viscous);
  io.number("cfl_force", s.time_step.cfl_force);
  io.number("fixed_step", s.time_step.fixed);
}

template <class IO, class B>
void blow_up_keys(IO& io, B& b) {
  io.number("energy_factor", b.energy_factor);
  io.number("reference_mach", b.reference_mach);
  io.number("reference_energy", b.reference_energy);
}

// An object, so that further keys of the scheme can join "type".
template <class IO, class C>
void scheme_keys(IO& io, C& c) {
  io.choice("type", kSchemeNames, c.type);
  // The schemes' parameters, as kSchemeParameters declares them.
  const auto parameter = [&](const auto& p) {
    if constexpr (requires { p.names; })
      io.choice(std::string(p.key), *p.names, c.*p.value);
    else
      io.number(std::string(p.key), c.*p.value);
  };
  std::apply([&](const auto&... p) { (parameter(p), ...); }, kSchemeParameters);
}

template <class IO, class M>
void subfilter_keys(IO& io, M& m) {
  io.choice("model", kSubfilterModelNames, m.model);
  // Each model's own constants, as the registry declares them.
  for_each_subfilter_constant([&](const SubfilterConstant& constant) {
    io.number(std::string(constant.key), m.*constant.value);
  });
  io.number("filter_width", m.filter_width);
}

template <class IO, class F>
void forcing_keys(IO& io, F& f) {
  io.number("amplitude", f.amplitude);
  io.integer("periods", f.periods);
  io.number("friction", f.friction);
}

template <class IO, class S>
void neighbours_keys(IO& io, S& s) {
  io.number("skin", s.neighbour_skin);
}

template <class IO, class P>
void packing_keys(IO& io, P& p) {
  io.boolean("enabled", p.enabled);
  io.boolean("cache", p.cache);
  if constexpr (IO::kReads) {
    // The cache directory is a setting of the program (--packing-cache), not of the scene: a
    // scene from a client must not choose where the server writes. Documents written before
    // hold "cache_dir": "", which is accepted and ignored.
    std::string cache_dir;
    io.string("cache_dir", cache_dir);
    if (!cache_dir.empty())
      throw_scene_error("packing.cache_dir",
                        "is not a scene key: the packing cache directory is a setting of the "
                        "program (sphles run/serve --packing-cache DIR)");
  }
  io.number("perturbation", p.perturbation);
  io.integer("max_iterations", p.max_iterations);
  io.number("tolerance", p.tolerance);
  io.integer("seed", p.seed);
}

template <class IO, class I>
void initial_keys(IO& io, I& i) {
  io.choice("mass", kInitialMassNames, i.mass);
}

template <class IO, class C>
void checkpoint_keys(IO& io, C& c) {
  io.number("every", c.every);
  io.number("every_seconds", c.every_seconds);
  io.integer("keep", c.keep);
  io.integer("compression", c.compression);
}

template <class IO, class O>
void output_keys(IO& io, O& o) {
  io.number("timeseries_every", o.timeseries_every);
  io.number("progress_every_seconds", o.progress_every_seconds);
}

/// One section: its object, its keys, then (reading) no key left unread.
template <class IO, class Keys>
void section(IO& top, const std::string& key, Keys keys) {
  IO io = top.object(key);
  keys(io);
  io.finish();
}

/// Every key of the scene below "case" and "preset", in document order; keys of one case only
/// are refused (reading) or left out (writing) for the others.
template <class IO, class S, class P>
void scene_keys(IO& top, S& s, P& policy) {
  const bool kolmogorov = s.case_type == CaseType::Kolmogorov2D;
  top.string("name", s.name);
  top.integer("particles_per_side", s.particles_per_side);
  if (kolmogorov)
    top.number("box_length", s.box_length_);
  else if constexpr (IO::kReads)
    if (top.find("box_length"))
      throw_scene_error("box_length", "is fixed at 2π for the Taylor-Green cases");
  section(top, "kernel", [&](IO& io) { kernel_keys(io, s); });
  section(top, "fluid", [&](IO& io) { fluid_keys(io, s.fluid); });
  section(top, "flow", [&](IO& io) { flow_keys(io, s); });
  section(top, "time", [&](IO& io) { time_keys(io, s); });
  section(top, "blow_up", [&](IO& io) { blow_up_keys(io, s.blow_up); });
  section(top, "scheme", [&](IO& io) { scheme_keys(io, s.scheme); });
  section(top, "subfilter", [&](IO& io) { subfilter_keys(io, s.subfilter); });
  if (kolmogorov)
    section(top, "forcing", [&](IO& io) { forcing_keys(io, s.forcing); });
  else if constexpr (IO::kReads)
    if (top.find("forcing")) throw_scene_error("forcing", "applies to case kolmogorov2d only");
  section(top, "neighbours", [&](IO& io) { neighbours_keys(io, s); });
  section(top, "packing", [&](IO& io) { packing_keys(io, s.packing); });
  section(top, "initial", [&](IO& io) { initial_keys(io, s.initial); });
  section(top, "checkpoint", [&](IO& io) { checkpoint_keys(io, policy.checkpoint); });
  section(top, "output", [&](IO& io) { output_keys(io, policy.output); });
}

/// A scheme parameter other than its default is refused by the schemes that do not take it
/// (kSchemeParameters, docs/models.md).
void check_scheme(const SchemeConfig& c) {
  const SchemeConfig defaults;
  const auto check = [&](const auto& p) {
    if (c.*p.value == defaults.*p.value || scheme_takes(c.type, p.key)) return;
    std::string why = "applies to scheme.type " + schemes_taking(p.key) + " only";
    if (!p.note.empty()) why += " (" + std::string(p.note) + ")";
    throw_scene_error("scheme." + std::string(p.key), why);
  };
  std::apply([&](const auto&... p) { (check(p), ...); }, kSchemeParameters);
}

}  // namespace

json expand_preset(const json& input) {
  const auto it = input.find("preset");
  if (!input.is_object() || it == input.end()) return input;
  if (!it->is_string()) throw_scene_error("preset", "must be a string, got " + describe_type(*it));
  json document = preset_document(it->get<std::string>());
  document.merge_patch(input);
  return document;
}

SceneAndPolicy parse_scene_and_policy(const json& input) {
  if (!input.is_object())
    throw_scene_error("(top level)", "must be an object, got " + describe_type(input));
  // A preset is the base document; the scene's own keys patch it. The preset's sections of the
  // other modules (analysis/, render/, spectral/ read them) are not the solver's to read.
  json document = expand_preset(input);
  if (input.contains("preset"))
    for (const char* section : {"analysis", "render", "reference"})
      if (!input.contains(section)) document.erase(section);
  const std::string preset = document.value("preset", std::string());
  ObjectReader top(document, "");
  CaseType type = CaseType::TaylorGreen3D;
  top.choice("case", kCaseNames, type);
  Scene s = case_defaults(type);
  s.preset = preset;
  if (!preset.empty()) s.name = preset;
  top.find("preset");
  RunPolicy policy;
  scene_keys(top, s, policy);
  top.reject_unknown();
  check_scheme(s.scheme);
  sim::check_scene(s);
  sim::check_cadence(s, "output.timeseries_every", policy.output.timeseries_every);
  sim::check_cadence(s, "checkpoint.every", policy.checkpoint.every);
  return {std::move(s), policy};
}

Scene parse_scene(const json& document) {
  return parse_scene_and_policy(document).scene;
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

json scene_to_json(const Scene& s, const RunPolicy& policy) {
  json j = json::object();
  ObjectWriter top(j);
  if (!s.preset.empty()) top.string("preset", s.preset);
  top.choice("case", kCaseNames, s.case_type);
  scene_keys(top, s, policy);
  return j;
}

}  // namespace sphles::scene
