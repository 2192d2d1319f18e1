// sphles estimate: what a run would need (control/resources.hpp), without running it.
#include <cstdio>

#include "app/commands.hpp"
#include "control/resources.hpp"
#include "control/run.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

namespace {
struct EstimateOptions {
  std::string scene;
  std::vector<std::string> overrides;
  bool as_json = false;
};

int estimate_command(const EstimateOptions& o) {
  const std::string& scene = o.scene;
  const std::vector<std::string>& overrides = o.overrides;
  const bool as_json = o.as_json;
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

}  // namespace

void add_estimate_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<EstimateOptions>();
  CLI::App* estimate = app.add_subcommand("estimate", "memory, disk and steps a run would need");
  estimate->footer(
      "Estimate the peak memory, checkpoint and analysis disk, initial time step and steps of a "
      "run without running it (control/resources.hpp).");
  estimate->add_option("scene", o->scene, "scene file (JSON) or preset name")
      ->type_name("SCENE.json|PRESET")
      ->required();
  repeatable(estimate->add_option("--set", o->overrides, "change a scene key (repeatable)"))
      ->type_name("KEY=VALUE");
  estimate->add_flag("--json", o->as_json, "print the estimate as JSON");
  estimate->callback([o, &exit_code] { exit_code = estimate_command(*o); });
}

}  // namespace sphles::app
