// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/config.hpp"

#include <array>
#include <utility>

#include "scene/document.hpp"
#include "scene/json_reader.hpp"

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

AnalysisConfig parse_analysis_config(const json* section) {
  AnalysisConfig c;
  if (!section) return c;
  scene::ObjectReader r(*section, "analysis");
  r.number("every", c.every);
  std::vector<std::string> products;
  r.strings("products", products);
  for (std::size_t k = 0; k < products.size(); ++k)
    c.products.insert(
        parse_name(kProductNames, products[k], "analysis.products[" + std::to_string(k) + "]"));
  {
    scene::ObjectReader s = r.object("slice");
    s.choice("axis", kAxisNames, c.slice.axis);
    s.number("position", c.slice.position);
    std::vector<std::string> fields;
    s.strings("fields", fields);
    if (s.find("fields")) {
      c.slice.fields.clear();
      for (std::size_t k = 0; k < fields.size(); ++k)
        c.slice.fields.insert(parse_name(kSliceFieldNames, fields[k],
                                         "analysis.slice.fields[" + std::to_string(k) + "]"));
    }
    s.reject_unknown();
  }
  {
    std::vector<std::string> fields;
    r.strings("particle_fields", fields);
    if (r.find("particle_fields")) {
      c.particle_fields.clear();
      for (std::size_t k = 0; k < fields.size(); ++k)
        c.particle_fields.insert(parse_name(kSliceFieldNames, fields[k],
                                            "analysis.particle_fields[" + std::to_string(k) + "]"));
    }
  }
  {
    std::vector<std::string> fields;
    r.strings("grid_fields", fields);
    if (r.find("grid_fields")) {
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
    }
  }
  {
    scene::ObjectReader g = r.object("gridding");
    g.choice("velocity", kVelocityGriddingNames, c.gridding.velocity);
    g.choice("vorticity", kVorticityEstimateNames, c.gridding.vorticity);
    g.number("fit_radius", c.gridding.fit_radius);
    g.reject_unknown();
  }
  r.integer("grid_points_per_spacing", c.grid_points_per_spacing);
  r.integer("histogram_bins", c.histogram_bins);
  r.integer("angle_bins", c.angle_bins);
  r.number("angle_threshold", c.angle_threshold);
  r.number("dissipation_window", c.dissipation_window);
  r.number("spectrum_length_scale", c.spectrum_length_scale);
  r.reject_unknown();
  if (!c.products.empty() && !(c.every > 0.0))
    throw_scene_error("analysis.every", "must be > 0 when products are requested, got " +
                                            sim::format_number(c.every));
  return c;
}

json analysis_config_to_json(const AnalysisConfig& c) {
  json products = json::array();
  for (const Product p : c.products) products.push_back(std::string(product_name(p)));
  json fields = json::array();
  for (const SliceField f : c.slice.fields) fields.push_back(std::string(slice_field_name(f)));
  return {{"every", c.every},
          {"products", products},
          {"slice",
           {{"axis", std::string(kAxisNames.name(c.slice.axis))},
            {"position", c.slice.position},
            {"fields", fields}}},
          {"particle_fields",
           [&] {
             json list = json::array();
             for (const SliceField f : c.particle_fields)
               list.push_back(std::string(slice_field_name(f)));
             return list;
           }()},
          {"grid_fields",
           [&] {
             json list = json::array();
             if (c.grid_velocity) list.push_back("velocity");
             for (const SliceField f : c.grid_fields)
               list.push_back(std::string(slice_field_name(f)));
             return list;
           }()},
          {"gridding",
           {{"velocity", std::string(velocity_gridding_name(c.gridding.velocity))},
            {"vorticity", std::string(vorticity_estimate_name(c.gridding.vorticity))},
            {"fit_radius", c.gridding.fit_radius}}},
          {"grid_points_per_spacing", c.grid_points_per_spacing},
          {"histogram_bins", c.histogram_bins},
          {"angle_bins", c.angle_bins},
          {"angle_threshold", c.angle_threshold},
          {"dissipation_window", c.dissipation_window},
          {"spectrum_length_scale", c.spectrum_length_scale}};
}

RunConfig parse_run_config(const json& document) {
  if (!document.is_object())
    throw_scene_error("(top level)", "must be an object, got " + scene::describe_type(document));
  json solver_part = document;
  const json* analysis = nullptr;
  json analysis_section;
  if (const auto it = document.find("analysis"); it != document.end()) {
    analysis_section = *it;
    analysis = &analysis_section;
    solver_part.erase("analysis");
  }
  RunConfig config;
  config.scene = scene::parse_scene(solver_part);
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
  json j = scene::scene_to_json(config.scene);
  j["analysis"] = analysis_config_to_json(config.analysis);
  return j;
}

}  // namespace sphles::analysis
