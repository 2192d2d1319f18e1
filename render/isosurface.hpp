// SPDX-License-Identifier: GPL-3.0-or-later
// 3D view of a gridded field's iso-surface (render.view3d.kind = "isosurface",
// docs/rendering.md): the surface where the field crosses one level, lit and in the colour bar's
// colour of that level, inside the box outline, with the slice plane drawn translucent; the
// camera, layout and labels of the particle view (box_view.hpp). Threading as for the particle
// view: one thread_local renderer per frame size, the process-wide VTK lock around the scene.
#pragma once

#include <optional>
#include <span>
#include <string>
#include <vector>

#include "analysis/grid_shape.hpp"
#include "render/render.hpp"

namespace sphles::render {

/// A scalar field on the analysis grid of a periodic 3D box: node (i, j, k) at (i, j, k) h,
/// value index i + M (j + M k).
struct IsoField {
  analysis::Grid grid;
  std::span<const double> values;
  std::string field_name, units;  // for the title and colour bar, e.g. "ω²", "s⁻²"
  int plane_axis = -1;            // the slice plane drawn (0 x, 1 y, 2 z); none when < 0
  double plane_position = 0.0;    // [m]
};

/// Where the surface is drawn: `value` when given, else the `quantile` of the field's finite
/// values (0.9: the surface encloses the strongest tenth of the grid nodes).
struct IsoLevel {
  double quantile = 0.9;
  std::optional<double> value;
};

/// The level of IsoLevel over `values`; NaN when no value is finite.
double iso_value(std::span<const double> values, const IsoLevel& level);

/// The iso-surface view as a PNG of width x height. Throws std::invalid_argument when the grid
/// is not 3D or the values are not one per node.
std::vector<unsigned char> render_isosurface_png(const IsoField& field,
                                                 const ColourMapping& mapping,
                                                 const IsoLevel& level, const FrameLabels& labels,
                                                 int width = 800, int height = 800);

}  // namespace sphles::render
