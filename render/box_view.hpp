// SPDX-License-Identifier: GPL-3.0-or-later
// What the 3D views (the particles, view3d.cpp; the iso-surfaces, isosurface.cpp) share: the
// frame's layout around the box, the fixed camera and the box's axis labels, so that both show
// the box at the same place, size and angle.
#pragma once

#include <array>
#include <string>

#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>

#include "render/render.hpp"
#include "render/vtk_window.hpp"

namespace sphles::render::detail {

// Frame layout [px]: title above the view rectangle, colour bar to its right; the box is fitted
// kLabelRoomX / kLabelRoomY inside the rectangle, leaving room for the axis labels around it.
inline constexpr int kBoxMarginTop = 56;
inline constexpr int kBoxMarginBottom = 12;
inline constexpr int kBoxMarginLeft = 12;
inline constexpr int kBoxMarginRight = 130;
inline constexpr int kBoxBarGap = 14;
inline constexpr int kBoxBarWidth = 110;
inline constexpr int kLabelRoomX = 60;  // "z [m]" beside a vertical edge
inline constexpr int kLabelRoomY = 36;
inline constexpr std::array<double, 3> kOutlineColour = {0.3, 0.3, 0.3};

using Vec3 = std::array<double, 3>;

// Unit vectors of the fixed camera: from the focal point to the camera, and screen right and up.
struct View {
  Vec3 direction, right, up;
};

// Where the box lands on screen: the view rectangle, the scale and the screen projection.
struct Layout {
  ImageRect rect;
  View view;
  bool two_dimensional = false;
  double pixels_per_length = 1.0;  // screen pixels per box length L

  // Pixel position in the view rectangle of the point p (in units of L, relative to the box
  // centre).
  std::array<double, 2> project(const Vec3& p) const;
};

/// The view rectangle of a frame (render::particle_view_rect): the margins above removed.
ImageRect box_view_rect(int width, int height);

/// 3D boxes seen from azimuth 30° (about z, from the -y side) and elevation 20° with z up;
/// 2D boxes from above (x right, y up); the box fitted inside box_view_rect.
Layout make_layout(int width, int height, bool two_dimensional);

// An edge label: text anchored beyond the middle of an edge, away from the centre.
struct EdgeLabel {
  vtkSmartPointer<vtkTextActor> actor = make_text(VTK_TEXT_CENTERED, VTK_TEXT_CENTERED, kFontSize);
  void place(const std::string& text, const Layout& layout, const Vec3& from, const Vec3& to);
};

/// The scene renderer's viewport on the layout's rectangle, white.
void set_scene_viewport(vtkRenderer* scene, int width, int height);
/// Parallel projection, the box [0, L]^3 (or the square at z = 0) centred in the rectangle.
void place_camera(vtkRenderer* scene, const Layout& layout, double length);
/// "x [m]", "y [m]" (and "z [m]") beside three silhouette edges.
void place_axis_labels(std::array<EdgeLabel, 3>& labels, const Layout& layout);

}  // namespace sphles::render::detail
