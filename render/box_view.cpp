// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/box_view.hpp"

#include <vtkCamera.h>
#include <vtkProperty.h>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace sphles::render::detail {

namespace {

constexpr double kLabelOffset = 16.0;  // label anchor beyond its edge [px]
constexpr double kAzimuthDegrees = 30.0;
constexpr double kElevationDegrees = 20.0;

double dot(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

View make_view(bool two_dimensional) {
  if (two_dimensional) return {{0.0, 0.0, 1.0}, {1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}};
  const double azimuth = kAzimuthDegrees * std::numbers::pi / 180.0;
  const double elevation = kElevationDegrees * std::numbers::pi / 180.0;
  const double ca = std::cos(azimuth), sa = std::sin(azimuth);
  const double ce = std::cos(elevation), se = std::sin(elevation);
  // Azimuth 0 looks along +y from the -y side with z up; positive azimuth moves the camera
  // towards +x. right = z x direction, up = direction x right.
  return {{sa * ce, -ca * ce, se}, {ca, sa, 0.0}, {-sa * se, ca * se, ce}};
}

}  // namespace

ImageRect box_view_rect(int width, int height) {
  ImageRect rect;
  rect.x = kBoxMarginLeft;
  rect.y = kBoxMarginBottom;
  rect.width = std::max(1, width - kBoxMarginLeft - kBoxMarginRight);
  rect.height = std::max(1, height - kBoxMarginTop - kBoxMarginBottom);
  return rect;
}

std::array<double, 2> Layout::project(const Vec3& p) const {
  return {0.5 * rect.width + pixels_per_length * dot(p, view.right),
          0.5 * rect.height + pixels_per_length * dot(p, view.up)};
}

Layout make_layout(int width, int height, bool two_dimensional) {
  Layout layout;
  layout.rect = box_view_rect(width, height);
  layout.view = make_view(two_dimensional);
  layout.two_dimensional = two_dimensional;
  // Half extents of the projected box (unit side, centred), over its corners.
  double half_u = 0.0, half_v = 0.0;
  const double half_z = two_dimensional ? 0.0 : 0.5;
  for (const double cx : {-0.5, 0.5}) {
    for (const double cy : {-0.5, 0.5}) {
      for (const double cz : {-half_z, half_z}) {
        const Vec3 corner{cx, cy, cz};
        half_u = std::max(half_u, std::abs(dot(corner, layout.view.right)));
        half_v = std::max(half_v, std::abs(dot(corner, layout.view.up)));
      }
    }
  }
  const double inner_width = std::max(1, layout.rect.width - 2 * kLabelRoomX);
  const double inner_height = std::max(1, layout.rect.height - 2 * kLabelRoomY);
  layout.pixels_per_length = std::min(inner_width / (2.0 * half_u), inner_height / (2.0 * half_v));
  return layout;
}

void EdgeLabel::place(const std::string& text, const Layout& layout, const Vec3& from,
                      const Vec3& to) {
  const Vec3 middle{0.5 * (from[0] + to[0]), 0.5 * (from[1] + to[1]), 0.5 * (from[2] + to[2])};
  const auto anchor = layout.project(middle);
  const auto centre = layout.project({0.0, 0.0, 0.0});
  double out_x = anchor[0] - centre[0], out_y = anchor[1] - centre[1];
  const double norm = std::hypot(out_x, out_y);
  if (norm > 0.0) {
    out_x /= norm;
    out_y /= norm;
  }
  vtkTextProperty* property = actor->GetTextProperty();
  property->SetJustification(out_x > 0.5    ? VTK_TEXT_LEFT
                             : out_x < -0.5 ? VTK_TEXT_RIGHT
                                            : VTK_TEXT_CENTERED);
  property->SetVerticalJustification(out_y > 0.5    ? VTK_TEXT_BOTTOM
                                     : out_y < -0.5 ? VTK_TEXT_TOP
                                                    : VTK_TEXT_CENTERED);
  set_text(actor, text, std::round(anchor[0] + kLabelOffset * out_x),
           std::round(anchor[1] + kLabelOffset * out_y));
}

namespace {

void place_camera(vtkRenderer* scene, const Layout& layout, double length) {
  const bool flat = layout.two_dimensional;
  const Vec3 centre{0.5 * length, 0.5 * length, flat ? 0.0 : 0.5 * length};
  const double distance = 4.0 * length;
  const View& view = layout.view;
  vtkCamera* camera = scene->GetActiveCamera();
  camera->ParallelProjectionOn();
  camera->SetFocalPoint(centre[0], centre[1], centre[2]);
  camera->SetPosition(centre[0] + distance * view.direction[0],
                      centre[1] + distance * view.direction[1],
                      centre[2] + distance * view.direction[2]);
  camera->SetViewUp(view.up[0], view.up[1], view.up[2]);
  camera->SetParallelScale(0.5 * layout.rect.height / layout.pixels_per_length * length);
  camera->SetClippingRange(distance - length, distance + length);
}

void place_axis_labels(std::array<EdgeLabel, 3>& labels, const Layout& layout) {
  // In units of L, relative to the box centre.
  if (layout.two_dimensional) {
    labels[0].place("x [m]", layout, {-0.5, -0.5, 0.0}, {0.5, -0.5, 0.0});
    labels[1].place("y [m]", layout, {-0.5, -0.5, 0.0}, {-0.5, 0.5, 0.0});
    labels[2].actor->VisibilityOff();
  } else {
    labels[0].place("x [m]", layout, {-0.5, -0.5, -0.5}, {0.5, -0.5, -0.5});
    labels[1].place("y [m]", layout, {0.5, -0.5, -0.5}, {0.5, 0.5, -0.5});
    labels[2].place("z [m]", layout, {-0.5, -0.5, -0.5}, {-0.5, -0.5, 0.5});
    labels[2].actor->VisibilityOn();
  }
}

}  // namespace

BoxScene::BoxScene(vtkRenderWindow* window, int width, int height) {
  frame->SetBackground(1.0, 1.0, 1.0);
  frame->AddActor2D(title);
  frame->AddActor2D(bar.actor());
  const ImageRect rect = box_view_rect(width, height);
  scene->SetViewport(static_cast<double>(rect.x) / width, static_cast<double>(rect.y) / height,
                     static_cast<double>(rect.x + rect.width) / width,
                     static_cast<double>(rect.y + rect.height) / height);
  scene->SetBackground(1.0, 1.0, 1.0);
  outline_mapper->SetInputConnection(outline->GetOutputPort());
  outline_mapper->ScalarVisibilityOff();
  outline_actor->SetMapper(outline_mapper);
  outline_actor->GetProperty()->LightingOff();
  outline_actor->GetProperty()->SetColor(kOutlineColour[0], kOutlineColour[1], kOutlineColour[2]);
  outline_actor->GetProperty()->SetLineWidth(1.0);
  scene->AddActor(outline_actor);
  for (const EdgeLabel& label : axis_labels) scene->AddActor2D(label.actor);
  window->AddRenderer(frame);  // drawn first; the scene clears only its viewport
  window->AddRenderer(scene);
}

void BoxScene::update(const Layout& layout, double length, const std::array<double, 2>& range,
                      bool log_scale, const std::string& bar_title, const std::string& title_text,
                      int width, int height) {
  outline->SetBounds(0.0, length, 0.0, length, 0.0, layout.two_dimensional ? 0.0 : length);
  place_camera(scene, layout, length);
  place_axis_labels(axis_labels, layout);
  const ImageRect& rect = layout.rect;
  bar.update(range, log_scale, bar_title, rect.x + rect.width + kBoxBarGap, rect.y + kLabelRoomY,
             kBoxBarWidth, rect.height - 2 * kLabelRoomY);
  set_text(title, title_text, width / 2.0, height - 6.0);
}

}  // namespace sphles::render::detail
