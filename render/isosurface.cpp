// SPDX-License-Identifier: GPL-3.0-or-later
// The iso-surface view: VTK's flying-edges contour of the gridded field (padded by one node per
// axis with the periodic images, so the surface closes at the box's far faces), lit by the
// renderer's headlight, in the box outline with the translucent slice plane; the title, colour
// bar and axis labels of the particle view.
#include "render/isosurface.hpp"

#include <vtkActor.h>
#include <vtkDoubleArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkPlaneSource.h>
#include <vtkPointData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "render/box_view.hpp"
#include "render/vtk_window.hpp"

namespace sphles::render {

namespace {

using detail::Clock;
using detail::format_number;
using detail::kOutlineColour;

constexpr double kPlaneOpacity = 0.25;
constexpr std::array<double, 3> kPlaneColour = {0.55, 0.55, 0.6};

void validate(const IsoField& field) {
  if (field.grid.dimension != 3 || field.grid.points_per_side < 2)
    throw std::invalid_argument("render_isosurface_png: the grid must be 3D with 2 or more nodes");
  if (field.values.size() != field.grid.size())
    throw std::invalid_argument("render_isosurface_png: one value per grid node");
}

std::string quantile_text(const IsoLevel& level) {
  if (level.value) return "";
  return " (" + format_number(100.0 * level.quantile) + "th percentile)";
}

}  // namespace

double iso_value(std::span<const double> values, const IsoLevel& level) {
  if (level.value) return *level.value;
  std::vector<double> finite;
  finite.reserve(values.size());
  for (const double v : values)
    if (std::isfinite(v)) finite.push_back(v);
  if (finite.empty()) return std::nan("");
  const auto rank = static_cast<std::size_t>(std::clamp(level.quantile, 0.0, 1.0) *
                                             static_cast<double>(finite.size() - 1));
  std::nth_element(finite.begin(), finite.begin() + static_cast<std::ptrdiff_t>(rank),
                   finite.end());
  return finite[rank];
}

class IsoSurfaceRenderer : public detail::OffscreenPngRenderer<IsoSurfaceRenderer> {
 public:
  IsoSurfaceRenderer(int width, int height) : OffscreenPngRenderer(width, height) {}
  std::vector<unsigned char> render_png(const IsoField& field, const ColourMapping& mapping,
                                        const IsoLevel& level, const FrameLabels& labels);
};

template <>
struct detail::OffscreenPngRenderer<IsoSurfaceRenderer>::Impl {
  detail::OffscreenWindow surface;  // first: destroyed after the renderers and actors below
  FrameTimings timings;

  detail::BoxScene box{surface.window(), surface.width(), surface.height()};
  vtkSmartPointer<vtkImageData> image = vtkSmartPointer<vtkImageData>::New();
  vtkSmartPointer<vtkDoubleArray> nodes = vtkSmartPointer<vtkDoubleArray>::New();
  vtkSmartPointer<vtkFlyingEdges3D> contour = vtkSmartPointer<vtkFlyingEdges3D>::New();
  vtkSmartPointer<vtkPolyDataMapper> surface_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
  vtkSmartPointer<vtkActor> surface_actor = vtkSmartPointer<vtkActor>::New();
  vtkSmartPointer<vtkPlaneSource> plane = vtkSmartPointer<vtkPlaneSource>::New();
  vtkSmartPointer<vtkPolyDataMapper> plane_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
  vtkSmartPointer<vtkActor> plane_actor = vtkSmartPointer<vtkActor>::New();
  vtkSmartPointer<vtkActor> plane_edge = vtkSmartPointer<vtkActor>::New();

  Impl(int width, int height) : surface(width, height) {
    nodes->SetName("value");
    image->GetPointData()->SetScalars(nodes);
    contour->SetInputData(image);
    contour->ComputeNormalsOn();
    contour->ComputeScalarsOff();
    surface_mapper->SetInputConnection(contour->GetOutputPort());
    surface_mapper->ScalarVisibilityOff();
    surface_actor->SetMapper(surface_mapper);
    surface_actor->GetProperty()->SetSpecular(0.25);
    surface_actor->GetProperty()->SetSpecularPower(20.0);

    plane_mapper->SetInputConnection(plane->GetOutputPort());
    for (vtkActor* actor : {plane_actor.Get(), plane_edge.Get()}) {
      actor->SetMapper(plane_mapper);
      actor->GetProperty()->LightingOff();
    }
    plane_actor->GetProperty()->SetColor(kPlaneColour[0], kPlaneColour[1], kPlaneColour[2]);
    plane_actor->GetProperty()->SetOpacity(kPlaneOpacity);
    plane_edge->GetProperty()->SetRepresentationToWireframe();
    plane_edge->GetProperty()->SetColor(kOutlineColour[0], kOutlineColour[1], kOutlineColour[2]);

    box.scene->AddActor(surface_actor);
    box.scene->AddActor(plane_edge);
    box.scene->AddActor(plane_actor);  // translucent: drawn after the opaque actors
  }

  /// The field on (M + 1)^3 nodes: the last layer of each axis is the periodic image of the
  /// first, so the surface reaches the box's faces at L.
  void fill_nodes(const IsoField& field) {
    const int m = field.grid.points_per_side;
    const int n = m + 1;
    const double h = field.grid.spacing();
    image->SetDimensions(n, n, n);
    image->SetSpacing(h, h, h);
    image->SetOrigin(0.0, 0.0, 0.0);
    nodes->SetNumberOfTuples(static_cast<vtkIdType>(n) * n * n);
    double* out = nodes->GetPointer(0);
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) *out++ = field.values[field.grid.index(i % m, j % m, k % m)];
    nodes->Modified();
    image->Modified();
  }

  void place_plane(const IsoField& field) {
    const double length = field.grid.length;
    const bool shown = field.plane_axis >= 0 && field.plane_axis < 3;
    plane_actor->SetVisibility(shown);
    plane_edge->SetVisibility(shown);
    if (!shown) return;
    const int a = field.plane_axis;
    std::array<double, 3> origin{0.0, 0.0, 0.0}, p1{}, p2{};
    origin[a] = field.plane_position;
    p1 = origin;
    p2 = origin;
    p1[(a + 1) % 3] = length;
    p2[(a + 2) % 3] = length;
    plane->SetOrigin(origin.data());
    plane->SetPoint1(p1.data());
    plane->SetPoint2(p2.data());
  }

  void update(const IsoField& field, const std::array<double, 2>& range, bool log_scale,
              double value, const IsoLevel& level, const FrameLabels& labels) {
    const double length = field.grid.length;
    const detail::Layout layout = detail::make_layout(surface.width(), surface.height(), false);
    fill_nodes(field);
    contour->SetValue(0, value);
    const int index = colour_index(value, range, log_scale);
    const Rgb& rgb = index < 0 ? detail::kNanColour : viridis_table()[index];
    surface_actor->GetProperty()->SetColor(rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0);
    surface_actor->SetVisibility(std::isfinite(value));
    place_plane(field);
    const std::string name =
        field.units.empty() ? field.field_name : field.field_name + " [" + field.units + "]";
    const int m = field.grid.points_per_side;
    const std::string title_text =
        labels.case_name + "   t = " + format_number(labels.time) + " s   step " +
        std::to_string(labels.step) + "\n" + field.field_name + " = " + format_number(value) +
        (field.units.empty() ? "" : " " + field.units) + quantile_text(level) + " on " +
        std::to_string(m) + "\u00b3 grid nodes";
    box.update(layout, length, range, log_scale, name, title_text, surface.width(),
               surface.height());
  }
};

template class detail::OffscreenPngRenderer<IsoSurfaceRenderer>;

std::vector<unsigned char> IsoSurfaceRenderer::render_png(const IsoField& field,
                                                          const ColourMapping& mapping,
                                                          const IsoLevel& level,
                                                          const FrameLabels& labels) {
  validate(field);
  Impl& impl = *impl_;
  const auto start = Clock::now();
  const std::array<double, 2> range = colour_range(field.values, mapping);
  const double value = iso_value(field.values, level);
  return impl.surface.draw_png(
      impl.timings, [&] { impl.update(field, range, mapping.log_scale, value, level, labels); },
      start);
}

std::vector<unsigned char> render_isosurface_png(const IsoField& field,
                                                 const ColourMapping& mapping,
                                                 const IsoLevel& level, const FrameLabels& labels,
                                                 int width, int height) {
  return detail::thread_local_renderer<IsoSurfaceRenderer>(width, height)
      .render_png(field, mapping, level, labels);
}

}  // namespace sphles::render
