// SPDX-License-Identifier: GPL-3.0-or-later
// The "render" section of a scene: which images a run produces from its analysis frames and how
// they are colour-mapped (docs/rendering.md). Rendering is off unless the section asks for it.
#pragma once

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>

#include "analysis/config.hpp"
#include "render/render.hpp"

namespace sphles::render {

/// Log scale between the 1st and 99th percentiles.
inline ColourMapping log_mapping() {
  ColourMapping mapping;
  mapping.log_scale = true;
  return mapping;
}

/// What a 3D view draws: the particles coloured by a per-particle field, or the iso-surface of
/// a gridded field (the analysis' "fields" product).
enum class View3dKind { Particles, Isosurface };
inline constexpr sim::NameTable<View3dKind, 2> kView3dKindNames{
    {{{View3dKind::Particles, "particles"}, {View3dKind::Isosurface, "isosurface"}}}};

/// A 3D view at a lower cadence than slices.
struct View3dConfig {
  bool enabled = false;
  View3dKind kind = View3dKind::Particles;
  analysis::SliceField field = analysis::SliceField::VorticitySquared;
  double every = 0.0;  // simulated time between 3D views [s]; 0 = with every analysis frame
  int width = 800, height = 800;
  ColourMapping colour = log_mapping();
  /// At most this many particles are drawn: every k-th by id, k = ceil(N / max_points)
  /// (analysis::view_stride); only those are sent from the ranks of a distributed run.
  std::int64_t max_points = 1'000'000;
  /// Iso-surfaces: the level as a quantile of the field's grid values, or a value [the field's
  /// units] when given; and whether the slice plane (analysis.slice) is drawn.
  double quantile = 0.9;
  std::optional<double> level;
  bool slice_plane = true;
};

struct RenderConfig {
  /// Slice fields rendered (each must be a slice field of the analysis section).
  std::set<analysis::SliceField> fields;
  bool single = true;              // one frame per field: frames/{field}_t{t}.png
  bool combined = true;            // all fields side by side: frames/combined_t{t}.png
  bool save = true;                // write the image series; false: images only for live viewers
  int width = 1200, height = 600;  // of a combined frame; single frames are height x height
  std::map<analysis::SliceField, ColourMapping> colour;  // per field; default: log, percentiles
  View3dConfig view3d;

  bool enabled() const { return !fields.empty() || view3d.enabled; }
  const ColourMapping& mapping(analysis::SliceField field) const;
};

/// Default mapping of a field: log scale between the 1st and 99th percentiles.
ColourMapping default_mapping(analysis::SliceField field);

/// Parses the "render" object (missing: rendering off). Checks it against the analysis section:
/// rendered slice fields must be computed there, a 3D view needs the "particles" product with its
/// field. Throws sim::SceneError naming the field, e.g. "scene: 'render.width' must be ...".
RenderConfig parse_render_config(const nlohmann::json* section,
                                 const analysis::AnalysisConfig& analysis);
nlohmann::json render_config_to_json(const RenderConfig& config);

}  // namespace sphles::render
