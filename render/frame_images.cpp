// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/frame_images.hpp"

#include "render/isosurface.hpp"
#include "render/view3d.hpp"
#include "render/vtk_window.hpp"

namespace sphles::render {

namespace {

using detail::Clock;
using detail::elapsed_ms;

const analysis::GridScalarField* grid_field(const analysis::AnalysisFrame& frame,
                                            analysis::SliceField field) {
  if (!frame.fields || frame.dimension != 3) return nullptr;
  for (const analysis::GridScalarField& f : frame.fields->scalars)
    if (f.field == field) return &f;
  return nullptr;
}

/// The particles (at most render.view3d.max_points, selected by id where the particles live:
/// analysis::ViewPoints) or the field's iso-surface on the analysis grid.
std::vector<unsigned char> render_view3d(const analysis::AnalysisFrame& frame,
                                         const View3dConfig& view, const FrameLabels& labels) {
  if (view.kind == View3dKind::Isosurface) {
    IsoField field;
    field.grid = frame.fields->grid;
    field.values = grid_field(frame, view.field)->values;
    field.field_name = detail::field_symbol(view.field);
    field.units = detail::field_units(view.field);
    if (view.slice_plane && !frame.slices.empty()) {
      field.plane_axis = frame.slices.front().normal_axis;
      field.plane_position = frame.slices.front().position;
    }
    return render_isosurface_png(field, view.colour, {view.quantile, view.level}, labels,
                                 view.width, view.height);
  }
  const analysis::ViewPoints& points = *frame.particles->view;
  ParticleCloud cloud;
  cloud.x = points.position[0];
  cloud.y = points.position[1];
  if (frame.dimension == 3) cloud.z = points.position[2];
  cloud.values = points.values;
  cloud.box_length = frame.particles->snapshot->box.length[0];
  cloud.field_name = detail::field_symbol(points.field);
  cloud.units = detail::field_units(points.field);
  return render_particles_png(cloud, view.colour, labels, view.width, view.height);
}

}  // namespace

bool has_view3d_input(const analysis::AnalysisFrame& frame, const View3dConfig& view) {
  if (view.kind == View3dKind::Isosurface) return grid_field(frame, view.field) != nullptr;
  return frame.particles && frame.particles->view && frame.particles->view->field == view.field &&
         frame.particles->snapshot;
}

std::vector<FrameImage> render_frame_images(const analysis::AnalysisFrame& frame,
                                            const RenderConfig& config,
                                            const std::string& case_name, bool include_view3d) {
  const FrameLabels labels{case_name, frame.time, frame.step};
  std::vector<FrameImage> images;
  std::vector<analysis::SliceProduct> slices;
  std::vector<ColourMapping> mappings;
  for (const analysis::SliceProduct& slice : frame.slices)
    if (config.fields.contains(slice.field)) {
      slices.push_back(slice);
      mappings.push_back(config.mapping(slice.field));
    }
  if (config.single) {
    // A single-field frame is square: the slice plus its margins at the combined frame's height.
    for (std::size_t i = 0; i < slices.size(); ++i) {
      const auto start = Clock::now();
      FrameImage image{
          std::string(analysis::slice_field_name(slices[i].field)),
          render_slice_png(slices[i], mappings[i], labels, config.height, config.height)};
      image.milliseconds = elapsed_ms(start);
      images.push_back(std::move(image));
    }
  }
  if (config.combined && !slices.empty()) {
    const auto start = Clock::now();
    FrameImage image{"combined",
                     render_slices_png(slices, mappings, labels, config.width, config.height)};
    image.milliseconds = elapsed_ms(start);
    images.push_back(std::move(image));
  }
  if (include_view3d && config.view3d.enabled && has_view3d_input(frame, config.view3d)) {
    const auto start = Clock::now();
    FrameImage image{"view3d", render_view3d(frame, config.view3d, labels)};
    image.milliseconds = elapsed_ms(start);
    images.push_back(std::move(image));
  }
  return images;
}

}  // namespace sphles::render
