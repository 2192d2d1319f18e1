// SPDX-License-Identifier: GPL-3.0-or-later
// Scene documents of a run: the sections of every module read into one RunSpec by their readers,
// which apply the scene schema, and written back in full.
#include "control/run.hpp"
#include "render/config.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"

namespace sphles::control {

using nlohmann::json;

RunSpec parse_run_spec(const json& input) {
  if (!input.is_object())
    sim::throw_scene_error("(top level)", "must be an object, got " + scene::describe_type(input));
  // A preset's render and reference sections are the base of the document's too.
  const json document = scene::expand_preset(input);
  json rest = document;
  json render_section;
  const bool has_render = document.contains("render");
  if (has_render) {
    render_section = document.at("render");
    rest.erase("render");
  }
  rest.erase("reference");
  RunSpec spec;
  analysis::RunConfig run = analysis::parse_run_config(rest);
  spec.scene = std::move(run.scene);
  spec.policy = run.policy;
  spec.analysis = std::move(run.analysis);
  spec.render = render::parse_render_config(has_render ? &render_section : nullptr, spec.analysis);
  spec.reference = spectral::parse_reference_config(document);
  if (spec.render.view3d.enabled && spec.render.view3d.kind == render::View3dKind::Isosurface &&
      spec.scene.dimension() != 3)
    sim::throw_scene_error("render.view3d.kind",
                           "is isosurface, which needs a 3D case; a 2D case draws its "
                           "particles (kind \"particles\") or its slices");
  // The readers are the document's one validation: every key, type, bound, name and array rule
  // of the schema, with their own messages (SceneSchema.TheReadersEnforceEveryKeywordOfTheSchema
  // walks the schema to check it).
  return spec;
}

json run_spec_to_json(const RunSpec& spec) {
  json j = analysis::run_config_to_json({spec.scene, spec.analysis, spec.policy});
  j["render"] = render::render_config_to_json(spec.render);
  j["reference"] = spectral::reference_config_to_json(spec.reference);
  return j;
}

}  // namespace sphles::control
