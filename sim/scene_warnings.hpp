// SPDX-License-Identifier: GPL-3.0-or-later
// What makes a scene's answer meaningless although it runs: a kernel wider than the scale the
// case is about (the initial vortices, the forcing), a Mach number beyond weak compressibility,
// a viscous limit that sets the time step. Said before a run starts (the command line, run.log,
// the API's estimate and run detail, the dashboard's form), with what would change it.
#pragma once

#include <string>
#include <vector>

#include "sim/scene.hpp"

namespace sphles::sim {

struct SceneWarning {
  std::string field;    // the scene key that changes it, e.g. "particles_per_side"
  std::string message;  // why the answer is meaningless, and what would do
};

/// The largest Mach number v/c_s a weakly compressible run keeps its density fluctuations
/// (of order Ma², SPEC §2) below 10 % at.
inline constexpr double kMaxMachNumber = 0.3;

/// The warnings of a valid scene (check_scene passed), most serious first; none for a scene
/// whose answer means something.
std::vector<SceneWarning> scene_warnings(const Scene& scene);

}  // namespace sphles::sim
