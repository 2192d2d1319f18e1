// SPDX-License-Identifier: GPL-3.0-or-later
// Shared by the tests that parse scene documents: a common scene, and what parsing a document
// says about it.
#pragma once

#include <string>

#include "scene/document.hpp"

namespace sphles::sim::testing {

/// 2D Taylor-Green vortex (SPEC §6.2) at Re = 100 (η = 0.01, v0 = 1), Ma = 0.1 (c_s = 10),
/// p_ref = 1, Wendland C4, t ∈ [0, end_time].
inline nlohmann::json taylor_green_2d_scene(int per_side, double diameter_over_spacing,
                                            double end_time) {
  return {{"case", "tgv2d"},
          {"particles_per_side", per_side},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", diameter_over_spacing}}},
          {"fluid",
           {{"reference_density", 1.0},
            {"dynamic_viscosity", 0.01},
            {"sound_speed", 10.0},
            {"reference_pressure", 1.0}}},
          {"time", {{"end", end_time}}}};
}

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
