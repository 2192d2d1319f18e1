// SPDX-License-Identifier: GPL-3.0-or-later
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <set>

#include "app/commands.hpp"
#include "control/scene_schema.hpp"
#include "io/checkpoint.hpp"
#include "io/particle_snapshot.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene/presets.hpp"
#include "server/openapi.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

nlohmann::json load_scene_document(const std::string& scene_or_preset,
                                   const std::vector<std::string>& overrides) {
  nlohmann::json document;
  const auto presets = scene::preset_names();
  const bool is_preset =
      !std::filesystem::exists(scene_or_preset) &&
      std::find(presets.begin(), presets.end(), scene_or_preset) != presets.end();
  const bool looks_like_file = scene_or_preset.find('/') != std::string::npos ||
                               std::filesystem::path(scene_or_preset).has_extension();
  if (is_preset) {
    document = {{"preset", scene_or_preset}};
  } else if (!std::filesystem::exists(scene_or_preset) && !looks_like_file) {
    // Neither a file nor a preset: say so, and which preset it may be a typo of.
    const std::optional<std::string> near =
        scene::closest_key(scene_or_preset, std::set<std::string>(presets.begin(), presets.end()));
    throw sim::SceneError(scene_or_preset,
                          "'" + scene_or_preset + "' is neither a scene file nor a preset" +
                              (near ? "; did you mean '" + *near + "'?" : std::string()) +
                              " (see 'sphles presets')");
  } else {
    document = scene::read_scene_file(scene_or_preset);
  }
  for (const std::string& assignment : overrides) scene::apply_override(document, assignment);
  return document;
}

analysis::RunConfig load_run_config(const std::string& scene_or_preset,
                                    const std::vector<std::string>& overrides) {
  nlohmann::json document = load_scene_document(scene_or_preset, overrides);
  document.erase("render");     // the solver and analysis sections only
  document.erase("reference");  // the spectral reference's (sphles reference)
  return analysis::parse_run_config(document);
}

namespace {

int inspect_command(const std::string& file) {
  const std::vector<std::string> args{file};
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

int presets_command() {
  for (const std::string& name : scene::preset_names()) {
    const sim::Scene s = scene::parse_scene({{"preset", name}});
    std::printf("%-16s %-13s N=%d^%d  %-15s D_K/dl=%g  model=%-8s C_S=%-5g c_s=%g  p_ref=%g\n",
                name.c_str(), std::string(sim::case_name(s.case_type)).c_str(),
                s.particles_per_side, s.dimension(),
                std::string(sim::kernel_name(s.kernel)).c_str(), s.kernel_diameter_over_spacing,
                std::string(sim::subfilter_model_name(s.subfilter.model)).c_str(),
                s.subfilter.smagorinsky_constant, s.fluid.sound_speed, s.fluid.reference_pressure);
  }
  return kExitOk;
}

}  // namespace

void add_inspect_command(CLI::App& app, int& exit_code) {
  auto file = std::make_shared<std::string>();
  CLI::App* inspect =
      app.add_subcommand("inspect", "validate a checkpoint or snapshot and describe it");
  inspect->footer(
      "Validate a checkpoint or a particle snapshot and print what it holds (exit 2 if it is "
      "not valid; docs/checkpoints.md).");
  inspect->add_option("file", *file, "an HDF5 file sphles wrote")
      ->type_name("CHECKPOINT.h5|SNAPSHOT.h5")
      ->required();
  inspect->callback([file, &exit_code] { exit_code = inspect_command(*file); });
}

void add_presets_command(CLI::App& app, int& exit_code) {
  app.add_subcommand("presets", "list the presets (the thesis cases, kolmogorov2d)")
      ->footer(
          "The 21 Taylor-Green cases of the thesis and kolmogorov2d; run one by name, "
          "scaled down with --set particles_per_side=N.")
      ->callback([&exit_code] { exit_code = presets_command(); });
}

void add_schema_command(CLI::App& app, int& exit_code) {
  auto which = std::make_shared<std::string>("scene");
  CLI::App* schema = app.add_subcommand(
      "schema",
      "print the scene's JSON Schema (or the scene patch's, the API's OpenAPI or the stream's "
      "AsyncAPI document)");
  schema->footer(
      "The scene schema is the one declaration of every scene key: type, bounds, default, "
      "description, and whether a running run may change it (x-live, x-fixed); the same "
      "document as GET /api/schema/scene (docs/scenes.md).");
  schema->add_option("document", *which, "which document")
      ->check(CLI::IsMember({"scene", "patch", "openapi", "asyncapi"}))
      ->type_name("scene|patch|openapi|asyncapi");
  schema->callback([which, &exit_code] {
    if (*which == "openapi")
      std::printf("%s\n", server::served_openapi_document().c_str());
    else if (*which == "asyncapi")
      std::printf("%s\n", server::served_asyncapi_document().c_str());
    else
      std::printf("%s\n",
                  (*which == "patch" ? control::scene_patch_schema() : control::scene_schema())
                      .dump(2)
                      .c_str());
    exit_code = kExitOk;
  });
}

}  // namespace sphles::app
