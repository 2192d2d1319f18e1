// SPDX-License-Identifier: GPL-3.0-or-later
// sphles estimate: what a run would need (control/resources.hpp), without running it.
#include <omp.h>

#include <cmath>
#include <cstdio>

#include "app/commands.hpp"
#include "control/resources.hpp"
#include "control/run.hpp"
#include "control/step_time.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

namespace {

struct EstimateOptions {
  std::string scene;
  std::vector<std::string> overrides;
  bool as_json = false;
  bool time = false;
  int threads = 0;
  int ranks = 1;
};

/// "2.5 ms", "1.2 s", "3 min 20 s", "4.1 h", "2.3 days".
std::string format_duration(double seconds) {
  char text[64];
  if (seconds < 1.0)
    std::snprintf(text, sizeof text, "%.3g ms", seconds * 1e3);
  else if (seconds < 120.0)
    std::snprintf(text, sizeof text, "%.3g s", seconds);
  else if (seconds < 7200.0)
    std::snprintf(text, sizeof text, "%.0f min %.0f s", std::floor(seconds / 60.0),
                  std::fmod(seconds, 60.0));
  else if (seconds < 2.0 * 86400.0)
    std::snprintf(text, sizeof text, "%.3g h", seconds / 3600.0);
  else
    std::snprintf(text, sizeof text, "%.3g days", seconds / 86400.0);
  return text;
}

int estimate_command(const EstimateOptions& o) {
  try {
    if (o.threads > 0) omp_set_num_threads(o.threads);
    const control::RunSpec spec =
        control::parse_run_spec(load_scene_document(o.scene, o.overrides));
    print_estimate(spec, o.as_json, o.time, o.ranks);
    return kExitOk;
  } catch (const sim::SceneError& e) {
    std::fprintf(stderr, "sphles estimate: %s\n", e.what());
    return kExitUsage;
  }
}

}  // namespace

std::optional<std::string> check_machine_memory(const control::ResourceEstimate& e) {
  const double machine = static_cast<double>(control::machine_memory_bytes());
  if (machine <= 0.0) return std::nullopt;  // unknown: nothing to compare with
  return control::check_memory(e, machine, "this machine has");
}

std::optional<std::string> print_estimate(const control::RunSpec& spec, bool as_json,
                                          bool with_time, int ranks,
                                          const std::filesystem::path& packing_cache) {
  const control::ResourceEstimate e = control::estimate_resources(spec, ranks);
  const std::optional<std::string> too_big = check_machine_memory(e);
  std::optional<control::StepTimeEstimate> time;
  if (with_time && !too_big) time = control::estimate_step_time(spec, e, 10, packing_cache);
  if (as_json) {
    nlohmann::json j = control::resource_estimate_to_json(e);
    j["machine_memory_bytes"] = control::machine_memory_bytes();
    j["default_memory_limit_bytes"] = control::default_memory_limit_bytes();
    j["fits_machine_memory"] = !too_big;
    if (time) j["time"] = control::step_time_to_json(*time);
    std::puts(j.dump(2).c_str());
    return too_big;
  }
  for (const sim::SceneWarning& w : e.warnings)
    std::printf("warning (%s)         %s\n", w.field.c_str(), w.message.c_str());
  std::printf("particles            %.6g (%.4g neighbours each)\n", e.particles,
              e.neighbours_per_particle);
  std::printf("memory at the peak   %s (%s with the program itself)\n",
              control::format_bytes(e.memory_bytes).c_str(),
              control::format_bytes(e.process_peak_bytes).c_str());
  for (const control::MemoryPart& p : e.memory)
    std::printf("  %-18s %10s  %s\n", p.name.c_str(), control::format_bytes(p.bytes).c_str(),
                p.detail.c_str());
  std::printf(
      "machine memory       %s (default server limit %s)%s\n",
      control::format_bytes(static_cast<double>(control::machine_memory_bytes())).c_str(),
      control::format_bytes(static_cast<double>(control::default_memory_limit_bytes())).c_str(),
      too_big ? ": the run does NOT fit" : "");
  if (e.per_rank) {
    const control::RankEstimate& r = *e.per_rank;
    std::string grid = std::to_string(r.grid[0]);
    for (int a = 1; a < r.dimension; ++a) grid += " x " + std::to_string(r.grid[a]);
    std::printf(
        "per rank             %s at the peak on each of %d ranks (%s): %.6g owned particles, "
        "%.3g halo copies each (halo %.3g m)\n",
        control::format_bytes(r.memory_bytes).c_str(), r.ranks, grid.c_str(), r.owned,
        r.halo_per_owned, r.halo_width);
    for (const control::MemoryPart& p : r.memory)
      std::printf("  %-18s %10s  %s\n", p.name.c_str(), control::format_bytes(p.bytes).c_str(),
                  p.detail.c_str());
    std::printf("beside the ranks     %s (rank 0 under mpirun, or the service)\n",
                control::format_bytes(r.service_bytes).c_str());
    for (const control::MemoryPart& p : r.service)
      std::printf("  %-18s %10s  %s\n", p.name.c_str(), control::format_bytes(p.bytes).c_str(),
                  p.detail.c_str());
    if (!r.refusal.empty())
      std::printf("  the run would refuse this split: %s\n", r.refusal.c_str());
  }
  std::printf("checkpoint file      %s (%s on disk at once)\n",
              control::format_bytes(e.checkpoint_file_bytes).c_str(),
              control::format_bytes(e.checkpoint_disk_bytes).c_str());
  if (e.analysis_frames > 0.0)
    std::printf("analysis             %.6g frames x %s = %s\n", e.analysis_frames,
                control::format_bytes(e.analysis_frame_bytes).c_str(),
                control::format_bytes(e.analysis_disk_bytes).c_str());
  std::printf("initial time step    %.6g s (%s limit), %.6g steps to t = %g s\n",
              e.time_step.step(), std::string(e.time_step.limits.binding()).c_str(), e.steps,
              spec.scene.end_time);
  if (time) {
    std::printf(
        "time per step        %s on %d threads (measured: %d steps of %zu^%d particles in "
        "%.3g s, scaled by the particle count)\n",
        format_duration(time->seconds_per_step).c_str(), time->threads, time->calibration_steps,
        time->calibration_side, spec.scene.dimension(), time->calibration_seconds);
    if (time->frames > 0.0)
      std::printf(
          "analysis per time    %s, rendering %s (measured on the same copy, scaled by the "
          "particle count); %g analysis times\n",
          format_duration(time->analysis_seconds_per_frame).c_str(),
          format_duration(time->render_seconds_per_frame).c_str(), time->frames);
    std::printf(
        "time to the end      %s to t = %g s at the initial step (the step may shrink as the "
        "flow develops): packing %s, the solver %s%s\n",
        format_duration(time->seconds_to_end).c_str(), spec.scene.end_time,
        time->packing_seconds > 0.0 ? format_duration(time->packing_seconds).c_str()
                                    : "none (off or cached)",
        format_duration(time->solver_seconds).c_str(),
        time->frames > 0.0 ? ", the analysis and rendering beside it (the slower sets the pace)"
                           : "");
  }
  return too_big;
}

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
  estimate->add_flag("--time", o->time,
                     "also time a few steps at a small size and estimate the time per step and "
                     "to the end time on this machine");
  add_threads_option(*estimate, o->threads, "OpenMP threads of the --time calibration");
  estimate
      ->add_option("--ranks", o->ranks,
                   "also estimate what each of N MPI ranks holds (the split mpirun -n N uses)")
      ->type_name("N")
      ->check(CLI::Range(1, 1 << 24));
  estimate->callback([o, &exit_code] { exit_code = estimate_command(*o); });
}

}  // namespace sphles::app
