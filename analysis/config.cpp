// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/config.hpp"

#include <array>
#include <utility>

#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene/json_writer.hpp"

namespace sphles::analysis {

using nlohmann::json;
using sim::throw_scene_error;

using sim::parse_name;

std::string_view velocity_gridding_name(VelocityGridding gridding) {
  return kVelocityGriddingNames.name(gridding);
}

std::string_view vorticity_estimate_name(VorticityEstimate estimate) {
  return kVorticityEstimateNames.name(estimate);
}

std::string_view product_name(Product product) {
  return kProductNames.name(product);
}

std::string_view slice_field_name(SliceField field) {
  return kSliceFieldNames.name(field);
}

std::string_view slice_field_units(SliceField field) {
  switch (field) {
    case SliceField::VorticitySquared:
      return "1/s^2";
    case SliceField::SubfilterStressNorm:
      return "Pa";
    case SliceField::EddyViscosity:
      return "m^2/s";
  }
  return "";
}

namespace {

/// "grid_fields": "velocity" and slice fields in one list, each at most once; present, it
/// names at least one.
template <class IO, class C>
void grid_fields_key(IO& io, C& c) {
  std::vector<std::string> fields;
  if constexpr (IO::kReads) {
    io.strings("grid_fields", fields);
    if (!io.find("grid_fields")) return;
    if (fields.empty())
      throw_scene_error("analysis.grid_fields", "is empty: it names at least one field");
    c.grid_velocity = false;
    c.grid_fields.clear();
    for (std::size_t k = 0; k < fields.size(); ++k) {
      const std::string field = "analysis.grid_fields[" + std::to_string(k) + "]";
      if (fields[k] == "velocity") {
        if (c.grid_velocity) throw_scene_error(field, "repeats 'velocity'");
        c.grid_velocity = true;
      } else if (!c.grid_fields.insert(parse_name(kSliceFieldNames, fields[k], field)).second) {
        throw_scene_error(field, "repeats '" + fields[k] + "'");
      }
    }
  } else {
    if (c.grid_velocity) fields.push_back("velocity");
    for (const SliceField f : c.grid_fields) fields.emplace_back(slice_field_name(f));
    io.strings("grid_fields", fields);
  }
}

/// Every key of the "analysis" section, for reading and writing alike.
template <class IO, class C>
void analysis_keys(IO& io, C& c) {
  io.number("every", c.every);
  io.names("products", kProductNames, c.products);
  IO slice = io.object("slice");
  slice.choice("axis", kAxisNames, c.slice.axis);
  slice.number("position", c.slice.position);
  slice.names("fields", kSliceFieldNames, c.slice.fields);
  slice.finish();
  io.names("particle_fields", kSliceFieldNames, c.particle_fields);
  grid_fields_key(io, c);
  IO gridding = io.object("gridding");
  gridding.choice("velocity", kVelocityGriddingNames, c.gridding.velocity);
  gridding.choice("vorticity", kVorticityEstimateNames, c.gridding.vorticity);
  gridding.number("fit_radius", c.gridding.fit_radius);
  gridding.finish();
  io.integer("grid_points_per_spacing", c.grid_points_per_spacing);
  io.integer("histogram_bins", c.histogram_bins);
  io.integer("angle_bins", c.angle_bins);
  io.number("angle_threshold", c.angle_threshold);
  io.number("dissipation_window", c.dissipation_window);
  io.number("spectrum_length_scale", c.spectrum_length_scale);
  io.finish();
}

}  // namespace

AnalysisConfig parse_analysis_config(const json* section) {
  AnalysisConfig c;
  if (!section) return c;
  scene::ObjectReader r(*section, "analysis");
  analysis_keys(r, c);
  if (!c.products.empty() && !(c.every > 0.0))
    throw_scene_error("analysis.every", "must be > 0 when products are requested, got " +
                                            sim::format_number(c.every));
  return c;
}

json analysis_config_to_json(const AnalysisConfig& c) {
  json j = json::object();
  scene::ObjectWriter w(j);
  analysis_keys(w, c);
  return j;
}

RunConfig parse_run_config(const json& input) {
  if (!input.is_object())
    throw_scene_error("(top level)", "must be an object, got " + scene::describe_type(input));
  // A preset's analysis section is the base of the document's (scene/presets.json).
  const json document = scene::expand_preset(input);
  json solver_part = document;
  const json* analysis = nullptr;
  json analysis_section;
  if (const auto it = document.find("analysis"); it != document.end()) {
    analysis_section = *it;
    analysis = &analysis_section;
    solver_part.erase("analysis");
  }
  RunConfig config;
  scene::SceneAndPolicy read = scene::parse_scene_and_policy(solver_part);
  config.scene = std::move(read.scene);
  config.policy = read.policy;
  config.analysis = parse_analysis_config(analysis);
  // Snapshots are taken (and every step cut short to land on them) only while products are on.
  if (config.analysis.enabled())
    sim::check_cadence(config.scene, "analysis.every", config.analysis.every);
  const bool implicit = config.scene.subfilter.model == sim::SubfilterModel::Implicit;
  if (implicit && config.analysis.wants(Product::Slices) &&
      config.analysis.slice.fields.contains(SliceField::EddyViscosity))
    throw_scene_error("analysis.slice.fields",
                      "asks for nu_t, but 'subfilter.model' is implicit (no eddy viscosity)");
  if (implicit && config.analysis.wants(Product::Particles) &&
      config.analysis.particle_fields.contains(SliceField::EddyViscosity))
    throw_scene_error("analysis.particle_fields",
                      "asks for nu_t, but 'subfilter.model' is implicit (no eddy viscosity)");
  if (implicit && config.analysis.wants(Product::Fields) &&
      config.analysis.grid_fields.contains(SliceField::EddyViscosity))
    throw_scene_error("analysis.grid_fields",
                      "asks for nu_t, but 'subfilter.model' is implicit (no eddy viscosity)");
  // The local fits of the mls estimate reach R = fit_radius H around a point; the periodic box
  // must hold the fit's ball once: 2 R <= L, i.e. fit_radius D_K <= particles_per_side.
  const AnalysisConfig& a = config.analysis;
  if (a.enabled() && a.gridding.vorticity == VorticityEstimate::Mls &&
      a.gridding.fit_radius * config.scene.kernel_diameter_over_spacing >
          config.scene.particles_per_side)
    throw_scene_error(
        "analysis.gridding.fit_radius",
        "must be at most 'particles_per_side' / "
        "'kernel.diameter_over_spacing' (" +
            sim::format_number(config.scene.particles_per_side /
                               config.scene.kernel_diameter_over_spacing) +
            ") for the mls vorticity, so that the fit fits in the periodic box, got " +
            sim::format_number(a.gridding.fit_radius));
  return config;
}

json run_config_to_json(const RunConfig& config) {
  json j = scene::scene_to_json(config.scene, config.policy);
  j["analysis"] = analysis_config_to_json(config.analysis);
  return j;
}

}  // namespace sphles::analysis
