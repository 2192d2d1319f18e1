// SPDX-License-Identifier: GPL-3.0-or-later
// ParticleRenderer: the particles as GL points with per-point RGB from the CPU colour mapping, the
// box outline, a fixed parallel-projection camera, and the slices' title and colour bar style.
//
// Two vtkRenderers share the window: a full-window one (white background, title, colour bar)
// drawn first, and the scene one on the view rectangle (points, outline, axis labels) drawn over
// it. The camera is computed here rather than with ResetCamera, so that the box always has the
// same place and size on screen and the axis labels can be placed without a render pass.
#include "render/view3d.hpp"

#include <vtkActor.h>
#include <vtkCellArray.h>
#include <vtkFloatArray.h>
#include <vtkIdTypeArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>
#include <vtkUnsignedCharArray.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "render/box_view.hpp"
#include "render/vtk_window.hpp"

namespace sphles::render {
namespace {

using detail::Clock;
using detail::format_number;
using detail::kFontSize;
using detail::kNanColour;

using detail::Layout;
using detail::make_layout;
using detail::Vec3;

constexpr int kMinPointSize = 2, kMaxPointSize = 4;

// Screen area of the projected box [px^2]: a unit cube covers |d_x| + |d_y| + |d_z| in the
// plane normal to the view direction d, a unit square in the plane z = 0 covers |d_z|.
double projected_box_area(const Layout& layout) {
  const Vec3& d = layout.view.direction;
  const double area =
      layout.two_dimensional ? std::abs(d[2]) : std::abs(d[0]) + std::abs(d[1]) + std::abs(d[2]);
  return area * layout.pixels_per_length * layout.pixels_per_length;
}

int point_size(std::size_t particle_count, const Layout& layout) {
  if (particle_count == 0) return kMaxPointSize;
  const double spacing =
      std::sqrt(projected_box_area(layout) / static_cast<double>(particle_count));
  return std::clamp(static_cast<int>(std::lround(spacing)), kMinPointSize, kMaxPointSize);
}

void validate(const ParticleCloud& cloud) {
  const std::size_t count = cloud.values.size();
  if (cloud.x.size() != count || cloud.y.size() != count ||
      (!cloud.z.empty() && cloud.z.size() != count)) {
    throw std::invalid_argument(
        "render_particles_png: x, y, values (and z unless empty) must have one entry per "
        "particle");
  }
  if (!(cloud.box_length > 0.0) || !std::isfinite(cloud.box_length)) {
    throw std::invalid_argument("render_particles_png: box_length must be positive and finite");
  }
}

}  // namespace

ImageRect particle_view_rect(int width, int height) {
  return detail::box_view_rect(width, height);
}

int particle_point_size(std::size_t particle_count, int width, int height, bool two_dimensional) {
  return point_size(particle_count, make_layout(width, height, two_dimensional));
}

template <>
struct detail::OffscreenPngRenderer<ParticleRenderer>::Impl {
  detail::OffscreenWindow surface;  // first: destroyed after the renderers and actors below
  FrameTimings timings;

  detail::BoxScene box{surface.window(), surface.width(), surface.height()};
  vtkSmartPointer<vtkPoints> points = vtkSmartPointer<vtkPoints>::New();
  vtkSmartPointer<vtkUnsignedCharArray> colours = vtkSmartPointer<vtkUnsignedCharArray>::New();
  vtkSmartPointer<vtkPolyData> cloud = vtkSmartPointer<vtkPolyData>::New();
  vtkSmartPointer<vtkPolyDataMapper> cloud_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
  vtkSmartPointer<vtkActor> cloud_actor = vtkSmartPointer<vtkActor>::New();
  std::vector<int> indices;  // colour index per particle

  Impl(int width, int height) : surface(width, height) {
    box.scene->AutomaticLightCreationOff();

    points->SetDataTypeToFloat();
    colours->SetNumberOfComponents(3);
    colours->SetName("colour");
    cloud->SetPoints(points);
    cloud->SetVerts(vtkSmartPointer<vtkCellArray>::New());
    cloud->GetPointData()->SetScalars(colours);
    cloud_mapper->SetInputData(cloud);
    cloud_mapper->ScalarVisibilityOn();
    cloud_mapper->SetScalarModeToUsePointData();
    cloud_mapper->SetColorModeToDirectScalars();
    cloud_actor->SetMapper(cloud_mapper);
    cloud_actor->GetProperty()->LightingOff();
    cloud_actor->GetProperty()->SetRepresentationToPoints();

    box.scene->AddActor(cloud_actor);
  }

  // Colour index per particle and the range: CPU only, done before taking the VTK lock.
  std::array<double, 2> map_colours(const ParticleCloud& input, const ColourMapping& mapping) {
    const std::array<double, 2> range = colour_range(input.values, mapping);
    indices.resize(input.values.size());
    colour_indices(input.values, range, mapping.log_scale, indices);
    return range;
  }

  void update(const ParticleCloud& input, const std::array<double, 2>& range, bool log_scale,
              const FrameLabels& labels) {
    const std::size_t count = input.values.size();
    const bool two_dimensional = input.z.empty();
    const double length = input.box_length;
    const Layout layout = make_layout(surface.width(), surface.height(), two_dimensional);

    // Positions, and one vertex cell per particle (rebuilt only when the count changes).
    points->SetNumberOfPoints(static_cast<vtkIdType>(count));
    float* xyz = vtkFloatArray::SafeDownCast(points->GetData())->GetPointer(0);
    for (std::size_t i = 0; i < count; ++i) {
      xyz[3 * i] = static_cast<float>(input.x[i]);
      xyz[3 * i + 1] = static_cast<float>(input.y[i]);
      xyz[3 * i + 2] = two_dimensional ? 0.0f : static_cast<float>(input.z[i]);
    }
    points->Modified();
    if (cloud->GetVerts()->GetNumberOfCells() != static_cast<vtkIdType>(count)) {
      auto connectivity = vtkSmartPointer<vtkIdTypeArray>::New();
      connectivity->SetNumberOfValues(static_cast<vtkIdType>(count));
      for (vtkIdType i = 0; i < static_cast<vtkIdType>(count); ++i) connectivity->SetValue(i, i);
      auto verts = vtkSmartPointer<vtkCellArray>::New();
      verts->SetData(1, connectivity);
      cloud->SetVerts(verts);
    }

    // Colours: the slices' CPU mapping, as RGB per point.
    colours->SetNumberOfTuples(static_cast<vtkIdType>(count));
    unsigned char* rgb = colours->GetPointer(0);
    const auto& table = viridis_table();
    for (std::size_t i = 0; i < count; ++i) {
      const Rgb& colour = indices[i] < 0 ? kNanColour : table[indices[i]];
      rgb[3 * i] = colour[0];
      rgb[3 * i + 1] = colour[1];
      rgb[3 * i + 2] = colour[2];
    }
    colours->Modified();
    cloud->Modified();
    cloud_actor->GetProperty()->SetPointSize(static_cast<float>(point_size(count, layout)));

    const std::string bar_title =
        input.units.empty() ? input.field_name : input.field_name + " [" + input.units + "]";
    const std::string title_text = labels.case_name + "   t = " + format_number(labels.time) +
                                   " s   step " + std::to_string(labels.step) + "\n" +
                                   input.field_name + " on " + std::to_string(count) +
                                   " particles, box " + format_number(length) + " m";
    box.update(layout, length, range, log_scale, bar_title, title_text, surface.width(),
               surface.height());
  }
};

template class detail::OffscreenPngRenderer<ParticleRenderer>;

ParticleRenderer::ParticleRenderer(int width, int height) : OffscreenPngRenderer(width, height) {}

std::vector<unsigned char> ParticleRenderer::render_png(const ParticleCloud& cloud,
                                                        const ColourMapping& mapping,
                                                        const FrameLabels& labels) {
  validate(cloud);
  Impl& impl = *impl_;
  const auto start = Clock::now();
  const std::array<double, 2> range = impl.map_colours(cloud, mapping);
  return impl.surface.draw_png(
      impl.timings, [&] { impl.update(cloud, range, mapping.log_scale, labels); }, start);
}

std::vector<unsigned char> render_particles_png(const ParticleCloud& cloud,
                                                const ColourMapping& mapping,
                                                const FrameLabels& labels, int width, int height) {
  return detail::thread_local_renderer<ParticleRenderer>(width, height)
      .render_png(cloud, mapping, labels);
}

}  // namespace sphles::render
