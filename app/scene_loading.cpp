#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "app/commands.hpp"
#include "io/checkpoint.hpp"
#include "io/particle_snapshot.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

nlohmann::json load_scene_document(const std::string& scene_or_preset,
                                   const std::vector<std::string>& overrides) {
  nlohmann::json document;
  const auto presets = sim::preset_names();
  const bool is_preset =
      !std::filesystem::exists(scene_or_preset) &&
      std::find(presets.begin(), presets.end(), scene_or_preset) != presets.end();
  if (is_preset)
    document = {{"preset", scene_or_preset}};
  else
    document = sim::read_scene_file(scene_or_preset);
  for (const std::string& assignment : overrides) sim::apply_override(document, assignment);
  return document;
}

analysis::RunConfig load_run_config(const std::string& scene_or_preset,
                                    const std::vector<std::string>& overrides) {
  nlohmann::json document = load_scene_document(scene_or_preset, overrides);
  document.erase("render");  // the solver and analysis sections only
  return analysis::parse_run_config(document);
}

int inspect_command(const std::vector<std::string>& args) {
  if (args.size() != 1) {
    std::fprintf(stderr, "sphles inspect: usage: sphles inspect CHECKPOINT.h5|SNAPSHOT.h5\n");
    return kExitUsage;
  }
  try {
    // The root attribute "schema" says which kind of sphles file it is.
    const std::string schema = io::hdf5_schema(args[0]);
    if (schema == io::kParticleSnapshotSchema)
      std::fputs(io::describe_particle_snapshot(args[0]).c_str(), stdout);
    else if (schema == io::kCheckpointSchema)
      std::fputs(io::describe_checkpoint(args[0]).c_str(), stdout);
    else
      throw io::CheckpointError("'" + args[0] + "': " +
                                (schema.empty() ? std::string("has no root attribute 'schema'")
                                                : "root attribute 'schema' is '" + schema + "'") +
                                ", so it is neither a sphles checkpoint ('" +
                                io::kCheckpointSchema + "') nor a particle snapshot ('" +
                                io::kParticleSnapshotSchema + "')");
    return kExitOk;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles inspect: %s\n", e.what());
    return kExitUsage;
  }
}

int presets_command(const std::vector<std::string>& args) {
  if (!args.empty()) {
    std::fprintf(stderr, "sphles presets: takes no arguments\n");
    return kExitUsage;
  }
  for (const std::string& name : sim::preset_names()) {
    const sim::Scene s = sim::parse_scene({{"preset", name}});
    std::printf("%-16s %-13s N=%d^%d  %-15s D_K/dl=%g  model=%-8s C_S=%-5g c_s=%g  p_ref=%g\n",
                name.c_str(), std::string(sim::case_name(s.case_type)).c_str(),
                s.particles_per_side, s.dimension(),
                std::string(sim::kernel_name(s.kernel)).c_str(), s.kernel_diameter_over_spacing,
                std::string(sim::subfilter_model_name(s.subfilter.model)).c_str(),
                s.subfilter.smagorinsky_constant, s.fluid.sound_speed, s.fluid.reference_pressure);
  }
  return kExitOk;
}

}  // namespace sphles::app
