// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/frame_images.hpp"
#include "render/vtk_window.hpp"

#include <chrono>

#include "render/view3d.hpp"

namespace sphles::render {

namespace {
using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}
}  // namespace

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
  // The view's points (at most render.view3d.max_points, selected by id where the particles
  // live: analysis::ViewPoints).
  if (include_view3d && config.view3d.enabled && frame.particles && frame.particles->view &&
      frame.particles->view->field == config.view3d.field && frame.particles->snapshot) {
    const analysis::ViewPoints& view = *frame.particles->view;
    const auto start = Clock::now();
    ParticleCloud cloud;
    cloud.x = view.position[0];
    cloud.y = view.position[1];
    if (frame.dimension == 3) cloud.z = view.position[2];
    cloud.values = view.values;
    cloud.box_length = frame.particles->snapshot->box.length[0];
    cloud.field_name = detail::field_symbol(view.field);
    cloud.units = detail::field_units(view.field);
    FrameImage image{"view3d", render_particles_png(cloud, config.view3d.colour, labels,
                                                    config.view3d.width, config.view3d.height)};
    image.milliseconds = elapsed_ms(start);
    images.push_back(std::move(image));
  }
  return images;
}

}  // namespace sphles::render
