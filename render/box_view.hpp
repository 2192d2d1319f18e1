// SPDX-License-Identifier: GPL-3.0-or-later
// What the 3D views (the particles, view3d.cpp; the iso-surfaces, isosurface.cpp) share: the
// frame's layout around the box, the fixed camera and the box's axis labels, so that both show
// the box at the same place, size and angle.
#pragma once

#include <array>
#include <string>

#include <vtkActor.h>
#include <vtkOutlineSource.h>
#include <vtkPolyDataMapper.h>
#include <vtkRenderWindow.h>
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

/// What a 3D view draws around its content: a full-window renderer (white, the title and the
/// colour bar) drawn first, and the scene renderer on the view rectangle with the box outline
/// and axis labels, into which the view adds its own actors.
struct BoxScene {
  vtkSmartPointer<vtkRenderer> frame = vtkSmartPointer<vtkRenderer>::New();
  vtkSmartPointer<vtkTextActor> title = make_text(VTK_TEXT_CENTERED, VTK_TEXT_TOP, kTitleFontSize);
  ColourBar bar;
  vtkSmartPointer<vtkRenderer> scene = vtkSmartPointer<vtkRenderer>::New();
  vtkSmartPointer<vtkOutlineSource> outline = vtkSmartPointer<vtkOutlineSource>::New();
  vtkSmartPointer<vtkPolyDataMapper> outline_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
  vtkSmartPointer<vtkActor> outline_actor = vtkSmartPointer<vtkActor>::New();
  std::array<EdgeLabel, 3> axis_labels;

  /// Both renderers on `window` (width x height px).
  BoxScene(vtkRenderWindow* window, int width, int height);

  /// The box [0, L]^3 (or the square at z = 0), the camera (parallel projection, the box centred
  /// in the rectangle), the axis labels, the colour bar beside the box and the title.
  void update(const Layout& layout, double length, const std::array<double, 2>& range,
              bool log_scale, const std::string& bar_title, const std::string& title_text,
              int width, int height);
};

}  // namespace sphles::render::detail
