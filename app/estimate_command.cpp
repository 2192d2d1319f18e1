// sphles estimate: what a run would need (control/resources.hpp), without running it.
#include <cstdio>

#include "app/commands.hpp"
#include "control/resources.hpp"
#include "control/run.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

int estimate_command(const std::vector<std::string>& args) {
  std::string scene;
  std::vector<std::string> overrides;
  bool as_json = false;
  for (std::size_t k = 0; k < args.size(); ++k) {
    if (args[k] == "--set" && k + 1 < args.size()) {
      overrides.push_back(args[++k]);
    } else if (args[k] == "--json") {
      as_json = true;
    } else if (scene.empty() && !args[k].empty() && args[k][0] != '-') {
      scene = args[k];
    } else {
      std::fprintf(stderr,
                   "sphles estimate: usage: sphles estimate SCENE.json|PRESET [--set key=value "
                   "...] [--json]\n");
      return kExitUsage;
    }
  }
  if (scene.empty()) {
    std::fprintf(stderr, "sphles estimate: a scene file or preset is required\n");
    return kExitUsage;
  }
  try {
    const control::RunSpec spec = control::parse_run_spec(load_scene_document(scene, overrides));
    const control::ResourceEstimate e = control::estimate_resources(spec);
    if (as_json) {
      nlohmann::json j = control::resource_estimate_to_json(e);
      j["machine_memory_bytes"] = control::machine_memory_bytes();
      j["default_memory_limit_bytes"] = control::default_memory_limit_bytes();
      std::puts(j.dump(2).c_str());
      return kExitOk;
    }
    std::printf("particles            %.6g (%.4g neighbours each)\n", e.particles,
                e.neighbours_per_particle);
    std::printf("memory at the peak   %s\n", control::format_bytes(e.memory_bytes).c_str());
    for (const control::MemoryPart& p : e.memory)
      std::printf("  %-18s %10s  %s\n", p.name.c_str(), control::format_bytes(p.bytes).c_str(),
                  p.detail.c_str());
    std::printf(
        "machine memory       %s (default server limit %s)\n",
        control::format_bytes(static_cast<double>(control::machine_memory_bytes())).c_str(),
        control::format_bytes(static_cast<double>(control::default_memory_limit_bytes())).c_str());
    std::printf("checkpoint file      %s (%s on disk at once)\n",
                control::format_bytes(e.checkpoint_file_bytes).c_str(),
                control::format_bytes(e.checkpoint_disk_bytes).c_str());
    if (e.analysis_frames > 0.0)
      std::printf("analysis             %.6g frames x %s = %s\n", e.analysis_frames,
                  control::format_bytes(e.analysis_frame_bytes).c_str(),
                  control::format_bytes(e.analysis_disk_bytes).c_str());
    std::printf("initial time step    %.6g s (%s limit), %.6g steps to t = %g s\n",
                e.time_step.step(), std::string(e.time_step.limits.binding()).c_str(), e.steps,
                spec.run.scene.end_time);
    return kExitOk;
  } catch (const sim::SceneError& e) {
    std::fprintf(stderr, "sphles estimate: %s\n", e.what());
    return kExitUsage;
  }
}

}  // namespace sphles::app
