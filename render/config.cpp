// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/config.hpp"

#include "scene/json_reader.hpp"

namespace sphles::render {

using nlohmann::json;
using sim::throw_scene_error;

namespace {

ColourMapping parse_mapping(scene::ObjectReader r, ColourMapping mapping) {
  std::string scale = mapping.log_scale ? "log" : "linear";
  r.string("scale", scale);
  if (scale != "log" && scale != "linear")
    throw_scene_error(r.field("scale"), "must be one of log, linear, got '" + scale + "'");
  mapping.log_scale = scale == "log";
  // null clears a fixed bound (back to the percentile), as a JSON merge patch would.
  for (const char* key : {"min", "max"}) {
    std::optional<double>& bound = std::string(key) == "min" ? mapping.min : mapping.max;
    const json* value = r.find(key);
    if (value && value->is_null()) {
      bound.reset();
    } else if (value) {
      double x = 0.0;
      r.number(key, x);
      if (mapping.log_scale && x <= 0.0)
        throw_scene_error(r.field(key),
                          "must be > 0 for a log scale, got " + sim::format_number(x));
      bound = x;
    }
  }
  r.number("lower_percentile", mapping.lower_percentile);
  r.number("upper_percentile", mapping.upper_percentile);
  r.reject_unknown();
  if (mapping.lower_percentile >= mapping.upper_percentile)
    throw_scene_error(r.field("lower_percentile"), "must be below 'upper_percentile'");
  if (mapping.min && mapping.max && *mapping.min >= *mapping.max)
    throw_scene_error(r.field("min"), "must be below 'max', got " +
                                          sim::format_number(*mapping.min) +
                                          " >= " + sim::format_number(*mapping.max));
  return mapping;
}

json mapping_to_json(const ColourMapping& m) {
  json j = {{"scale", m.log_scale ? "log" : "linear"},
            {"lower_percentile", m.lower_percentile},
            {"upper_percentile", m.upper_percentile}};
  j["min"] = m.min ? json(*m.min) : json(nullptr);
  j["max"] = m.max ? json(*m.max) : json(nullptr);
  return j;
}

void read_size(scene::ObjectReader& r, int& width, int& height) {
  r.integer("width", width);
  r.integer("height", height);
}

}  // namespace

ColourMapping default_mapping(analysis::SliceField) {
  return log_mapping();
}

const ColourMapping& RenderConfig::mapping(analysis::SliceField field) const {
  static const ColourMapping kDefault = default_mapping(analysis::SliceField::VorticitySquared);
  const auto it = colour.find(field);
  return it == colour.end() ? kDefault : it->second;
}

RenderConfig parse_render_config(const json* section, const analysis::AnalysisConfig& analysis) {
  RenderConfig c;
  if (!section) return c;
  scene::ObjectReader r(*section, "render");
  std::vector<std::string> fields;
  r.strings("fields", fields);
  for (std::size_t k = 0; k < fields.size(); ++k) {
    const std::string field = "render.fields[" + std::to_string(k) + "]";
    const analysis::SliceField f = sim::parse_name(analysis::kSliceFieldNames, fields[k], field);
    if (!analysis.wants(analysis::Product::Slices) || !analysis.slice.fields.contains(f))
      throw_scene_error(field, "is " + fields[k] +
                                   ", which the analysis does not compute: add \"slices\" to "
                                   "'analysis.products' and " +
                                   fields[k] + " to 'analysis.slice.fields'");
    c.fields.insert(f);
  }
  r.boolean("single", c.single);
  r.boolean("combined", c.combined);
  r.boolean("save", c.save);
  read_size(r, c.width, c.height);
  {
    scene::ObjectReader colour = r.object("colour");
    const json* colours = section->contains("colour") ? &section->at("colour") : nullptr;
    if (colours)
      for (const auto& [name, value] : colours->items()) {
        const analysis::SliceField f =
            sim::parse_name(analysis::kSliceFieldNames, name, "render.colour." + name);
        c.colour[f] = parse_mapping(colour.object(name), default_mapping(f));
      }
    colour.reject_unknown();
  }
  {
    scene::ObjectReader v = r.object("view3d");
    View3dConfig& view = c.view3d;
    v.boolean("enabled", view.enabled);
    std::string field(analysis::slice_field_name(view.field));
    v.string("field", field);
    view.field = sim::parse_name(analysis::kSliceFieldNames, field, "render.view3d.field");
    v.number("every", view.every);
    read_size(v, view.width, view.height);
    v.integer("max_points", view.max_points);
    view.colour = parse_mapping(v.object("colour"), view.colour);
    v.reject_unknown();
    if (view.enabled && (!analysis.wants(analysis::Product::Particles) ||
                         !analysis.particle_fields.contains(view.field)))
      throw_scene_error("render.view3d",
                        "shows " + field +
                            " per particle, which the analysis does not compute: add "
                            "\"particles\" to 'analysis.products' and " +
                            field + " to 'analysis.particle_fields'");
  }
  r.reject_unknown();
  if (!c.single && !c.combined && !c.fields.empty())
    throw_scene_error("render.single", "and 'render.combined' are both false: no frame to draw");
  return c;
}

json render_config_to_json(const RenderConfig& c) {
  json fields = json::array();
  for (const analysis::SliceField f : c.fields) fields.push_back(analysis::slice_field_name(f));
  json colour = json::object();
  for (const auto& [f, m] : c.colour)
    colour[std::string(analysis::slice_field_name(f))] = mapping_to_json(m);
  return {{"fields", fields},
          {"single", c.single},
          {"combined", c.combined},
          {"save", c.save},
          {"width", c.width},
          {"height", c.height},
          {"colour", colour},
          {"view3d",
           {{"enabled", c.view3d.enabled},
            {"field", analysis::slice_field_name(c.view3d.field)},
            {"every", c.view3d.every},
            {"width", c.view3d.width},
            {"height", c.view3d.height},
            {"max_points", c.view3d.max_points},
            {"colour", mapping_to_json(c.view3d.colour)}}}};
}

}  // namespace sphles::render
