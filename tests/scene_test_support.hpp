// SPDX-License-Identifier: GPL-3.0-or-later
// Shared by the tests of scene keys: what parsing a document says about it.
#pragma once

#include <string>

#include "scene/document.hpp"

namespace sphles::sim::testing {

/// The message of the SceneError that parsing `doc` throws; empty when it parses.
inline std::string scene_error(const nlohmann::json& doc) {
  try {
    scene::parse_scene(doc);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

}  // namespace sphles::sim::testing
