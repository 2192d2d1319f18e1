// SPDX-License-Identifier: GPL-3.0-or-later
// The built-in presets (docs/models.md): scene documents a run can start from by name.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace sphles::scene {

/// Names of the built-in presets: tgv2d (64², Re = 100), tgv3d (32³), tgv3d-re1600,
/// tgv3d-case1 ... tgv3d-case21 (SPEC Table 5.1), kolmogorov2d.
std::vector<std::string> preset_names();

/// The scene document of a preset; throws sim::SceneError for an unknown name.
nlohmann::json preset_document(const std::string& name);

}  // namespace sphles::scene
