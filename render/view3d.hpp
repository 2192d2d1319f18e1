// SPDX-License-Identifier: GPL-3.0-or-later
// 3D view of the particles coloured by a per-particle field, at its own cadence
// `render.view3d.every` (docs/rendering.md), headless like the slices (render/render.hpp).
//
// Colours come from the same CPU mapping as the slices (colour_range, colour_indices,
// viridis_table, NaN grey) and are given to VTK as per-point RGB, so a value has the same colour
// in a slice and in a 3D view; the colour bar uses the matching vtkLookupTable.
//
// Threading as for Renderer: a ParticleRenderer is used from one thread at a time;
// render_particles_png keeps one thread_local ParticleRenderer per frame size. Scene updates and
// Render share the slices' process-wide VTK lock; read-back and encoding run in parallel.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "render/render.hpp"

namespace sphles::render {

/// Particles of a periodic box as points coloured by a per-particle field (positions in [0, L)).
struct ParticleCloud {
  std::span<const double> x, y, z;  // z may be empty for 2D (then drawn in the plane z = 0)
  std::span<const double> values;   // one per particle
  double box_length = 0.0;          // [m]
  std::string field_name, units;    // for the colour bar title, e.g. "omega2", "1/s^2"
};

/// Where the box is drawn in a frame of width x height [px], origin bottom-left (as image_rect).
/// The box is fitted inside this rectangle with room for its axis labels, and the box centre
/// (L/2, L/2, L/2), or (L/2, L/2, 0) in 2D, projects to the rectangle's centre. The colour bar is
/// to its right, the title above.
ImageRect particle_view_rect(int width, int height);

/// Side of the square drawn per particle [px]: the projected box area per particle, rounded and
/// clamped to [2, 4], so a full box looks filled and particles stay distinguishable (32^3
/// particles in an 800 x 800 frame: 3 px).
int particle_point_size(std::size_t particle_count, int width, int height, bool two_dimensional);

/// An off-screen 3D particle view of fixed size, reused across frames (like Renderer). The camera
/// is fixed: parallel projection, 3D clouds seen from azimuth 30° (about z, from the -y side) and
/// elevation 20° with z up; 2D clouds from above (x right, y up). Not thread-safe: one per
/// thread.
class ParticleRenderer : public detail::OffscreenPngRenderer<ParticleRenderer> {
 public:
  ParticleRenderer(int width, int height);

  /// The cloud inside the box outline, with colour bar, title and axis labels, as PNG bytes.
  /// Throws std::invalid_argument for mismatched spans or a non-positive (or non-finite) box.
  std::vector<unsigned char> render_png(const ParticleCloud& cloud, const ColourMapping& mapping,
                                        const FrameLabels& labels);
};

/// Oblique 3D view of the cloud inside the box outline, with colour bar, title (case, time, step,
/// field) and axis labels; PNG of width x height. One thread_local renderer per size, like
/// render_slices_png. Throws std::invalid_argument for mismatched spans or a non-positive box.
std::vector<unsigned char> render_particles_png(const ParticleCloud& cloud,
                                                const ColourMapping& mapping,
                                                const FrameLabels& labels, int width = 800,
                                                int height = 800);

}  // namespace sphles::render
