// SPDX-License-Identifier: GPL-3.0-or-later
#include "scene/presets.hpp"

#include <stdexcept>
#include <string>
#include <vector>

#include "sim/scene.hpp"

namespace sphles::scene {

using nlohmann::json;

namespace {

/// scene/presets.json, parsed and checked once: an array of {"name", "about", "scene"}. A
/// malformed file is a defect of the build, not of a user's input.
const json& presets() {
  static const json document = [] {
    json d = json::parse(presets_text());
    if (!d.is_array()) throw std::logic_error("scene/presets.json: must be an array");
    for (const json& p : d)
      if (!p.is_object() || !p.contains("name") || !p["name"].is_string() || !p.contains("about") ||
          !p["about"].is_string() || !p.contains("scene") || !p["scene"].is_object())
        throw std::logic_error("scene/presets.json: each preset is {name, about, scene}: " +
                               p.dump());
    return d;
  }();
  return document;
}

}  // namespace

std::vector<std::string> preset_names() {
  std::vector<std::string> names;
  for (const json& p : presets()) names.push_back(p["name"].get<std::string>());
  return names;
}

json preset_document(const std::string& name) {
  for (const json& p : presets())
    if (p["name"] == name) return p["scene"];
  std::string valid;
  for (const std::string& n : preset_names()) valid += (valid.empty() ? "" : ", ") + n;
  throw sim::SceneError("preset", "scene: unknown preset '" + name + "' (valid: " + valid + ")");
}

}  // namespace sphles::scene
