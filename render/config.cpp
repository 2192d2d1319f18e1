// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/config.hpp"

#include "scene/json_reader.hpp"
#include "scene/json_writer.hpp"

namespace sphles::render {

using nlohmann::json;
using sim::throw_scene_error;

namespace {

inline constexpr sim::NameTable<bool, 2> kScaleNames{{{{true, "log"}, {false, "linear"}}}};

/// The keys of a colour mapping (render.colour.FIELD, render.view3d.colour), for reading and
/// writing alike; reading, it checks the bounds against the scale and each other.
template <class IO, class M>
void mapping_keys(IO io, M& m) {
  io.choice("scale", kScaleNames, m.log_scale);
  io.optional_number("min", m.min);
  io.optional_number("max", m.max);
  io.number("lower_percentile", m.lower_percentile);
  io.number("upper_percentile", m.upper_percentile);
  io.finish();
  if constexpr (IO::kReads) {
    for (const auto& [key, bound] : {std::pair{"min", m.min}, std::pair{"max", m.max}})
      if (m.log_scale && bound && *bound <= 0.0 && io.find(key))
        throw_scene_error(io.field(key),
                          "must be > 0 for a log scale, got " + sim::format_number(*bound));
    if (m.lower_percentile >= m.upper_percentile)
      throw_scene_error(io.field("lower_percentile"), "must be below 'upper_percentile'");
    if (m.min && m.max && *m.min >= *m.max)
      throw_scene_error(io.field("min"), "must be below 'max', got " + sim::format_number(*m.min) +
                                             " >= " + sim::format_number(*m.max));
  }
}

/// "colour": a mapping per slice field named by its key.
template <class IO, class C>
void colour_keys(IO& io, C& colour) {
  IO section = io.object("colour");
  if constexpr (IO::kReads) {
    if (const json* given = io.find("colour"))
      for (const auto& [name, value] : given->items()) {
        const analysis::SliceField f =
            sim::parse_name(analysis::kSliceFieldNames, name, "render.colour." + name);
        ColourMapping mapping = default_mapping(f);
        mapping_keys(section.object(name), mapping);
        colour[f] = mapping;
      }
  } else {
    for (const auto& [f, mapping] : colour)
      mapping_keys(section.object(std::string(analysis::slice_field_name(f))), mapping);
  }
  section.finish();
}

/// Every key of the "render" section, for reading and writing alike.
template <class IO, class C>
void render_keys(IO& io, C& c) {
  io.names("fields", analysis::kSliceFieldNames, c.fields);
  io.boolean("single", c.single);
  io.boolean("combined", c.combined);
  io.boolean("save", c.save);
  io.integer("width", c.width);
  io.integer("height", c.height);
  colour_keys(io, c.colour);
  IO view = io.object("view3d");
  view.boolean("enabled", c.view3d.enabled);
  view.choice("kind", kView3dKindNames, c.view3d.kind);
  view.choice("field", analysis::kSliceFieldNames, c.view3d.field);
  view.number("every", c.view3d.every);
  view.integer("width", c.view3d.width);
  view.integer("height", c.view3d.height);
  view.integer("max_points", c.view3d.max_points);
  view.number("quantile", c.view3d.quantile);
  view.optional_number("level", c.view3d.level);
  view.boolean("slice_plane", c.view3d.slice_plane);
  mapping_keys(view.object("colour"), c.view3d.colour);
  view.finish();
  io.finish();
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
  render_keys(r, c);
  // What is drawn must be computed: slices of the analysis' slice fields, a 3D view of one of
  // its particle fields.
  if (const json* fields = r.find("fields"))
    for (std::size_t k = 0; k < fields->size(); ++k) {
      const std::string name = (*fields)[k].get<std::string>();
      const analysis::SliceField f = *analysis::kSliceFieldNames.find(name);
      if (!analysis.wants(analysis::Product::Slices) || !analysis.slice.fields.contains(f))
        throw_scene_error("render.fields[" + std::to_string(k) + "]",
                          "is " + name +
                              ", which the analysis does not compute: add \"slices\" to "
                              "'analysis.products' and " +
                              name + " to 'analysis.slice.fields'");
    }
  const View3dConfig& view = c.view3d;
  const bool isosurface = view.kind == View3dKind::Isosurface;
  if (view.enabled && isosurface &&
      (!analysis.wants(analysis::Product::Fields) || !analysis.grid_fields.contains(view.field))) {
    const std::string field(analysis::slice_field_name(view.field));
    throw_scene_error("render.view3d",
                      "draws the iso-surface of " + field +
                          " on the analysis grid, which the analysis does not compute: add "
                          "\"fields\" to 'analysis.products' and " +
                          field + " to 'analysis.grid_fields'");
  }
  if (view.enabled && !isosurface &&
      (!analysis.wants(analysis::Product::Particles) ||
       !analysis.particle_fields.contains(view.field))) {
    const std::string field(analysis::slice_field_name(view.field));
    throw_scene_error("render.view3d", "shows " + field +
                                           " per particle, which the analysis does not "
                                           "compute: add \"particles\" to 'analysis.products' "
                                           "and " +
                                           field + " to 'analysis.particle_fields'");
  }
  if (!c.single && !c.combined && !c.fields.empty())
    throw_scene_error("render.single", "and 'render.combined' are both false: no frame to draw");
  return c;
}

json render_config_to_json(const RenderConfig& c) {
  json j = json::object();
  scene::ObjectWriter w(j);
  render_keys(w, c);
  return j;
}

}  // namespace sphles::render
