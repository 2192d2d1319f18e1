// SPDX-License-Identifier: GPL-3.0-or-later
// The scene document (docs/scenes.md): a scene is JSON, read section by section into the plain
// sim::Scene and written back with every default filled in. Keys, types and bounds come from the
// scene schema (scene/schema.hpp); unknown keys, wrong types and out-of-range values raise
// sim::SceneError naming the field and the reason.
#pragma once

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "scene/run_policy.hpp"
#include "sim/scene.hpp"

namespace sphles::scene {

/// A scene read in full: the solver's sections and when the run writes.
struct SceneAndPolicy {
  sim::Scene scene;
  RunPolicy policy;
};

/// Parses and validates a scene; throws sim::SceneError. A "preset" key starts from that preset's
/// document (scene/presets.hpp), and the other keys override it (JSON merge patch).
SceneAndPolicy parse_scene_and_policy(const nlohmann::json& document);

/// The document with its "preset" expanded: the preset's document (every section of it:
/// solver, analysis, render, reference) patched by the document's own keys (RFC 7396), the
/// "preset" key kept; the document itself when it names none. Idempotent, so each reader of a
/// section may call it.
nlohmann::json expand_preset(const nlohmann::json& document);
/// The same checks; the run policy is validated and left out (a solver's own reader).
sim::Scene parse_scene(const nlohmann::json& document);

/// Reads a JSON file; throws sim::SceneError naming the file on I/O or syntax errors.
nlohmann::json read_scene_file(const std::filesystem::path& path);

/// Applies "dotted.key=value" to a scene document. The value is parsed as JSON when it is valid
/// JSON, otherwise taken as a string. Throws sim::SceneError on a malformed assignment.
void apply_override(nlohmann::json& document, const std::string& assignment);

/// The complete scene with every default filled in (written next to each run's output).
nlohmann::json scene_to_json(const sim::Scene& scene, const RunPolicy& policy = {});

}  // namespace sphles::scene
