// SPDX-License-Identifier: GPL-3.0-or-later
// Renderer: OSMesa context + vtkGenericOpenGLRenderWindow, slices drawn as 2D image actors.
//
// Speed (2-core llvmpipe): the scene is 2D only. Colours are mapped on the CPU straight into an
// RGB image already scaled to its on-screen size (nearest node), so VTK draws it 1:1 through
// vtkImageMapper/vtkActor2D without colour mapping, interpolation or a camera; multisampling is
// off; the window, renderers and actors persist across frames (text textures are rebuilt only
// when their text changes); vtkWindowToImageFilter reads the back buffer without re-rendering;
// PNG uses zlib level 1 with unfiltered rows, encoded with libpng directly.
#include "render/render.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <vtkActor2D.h>
#include <vtkCoordinate.h>
#include <vtkImageData.h>
#include <vtkImageMapper.h>
#include <vtkRenderer.h>
#include <vtkTextActor.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <system_error>

#include "render/vtk_window.hpp"

namespace sphles::render {
namespace {

using detail::format_number;
using detail::kFontSize;
using detail::kNanColour;
using detail::kTitleFontSize;
using detail::make_text;
using detail::set_text;

// Panel margins [px] around the image: title above, axis labels left and below, colour bar right.
constexpr int kMarginTop = 56;
constexpr int kMarginBottom = 44;
constexpr int kMarginLeft = 64;
constexpr int kMarginRight = 130;
constexpr int kBarGap = 14;
constexpr int kBarWidth = 110;

char axis_name(int axis) {
  return axis == 0 ? 'x' : axis == 1 ? 'y' : 'z';
}

// One panel: a viewport of the window with the image, colour bar and labels.
struct Panel {
  vtkSmartPointer<vtkRenderer> renderer = vtkSmartPointer<vtkRenderer>::New();
  vtkSmartPointer<vtkImageData> image = vtkSmartPointer<vtkImageData>::New();
  vtkSmartPointer<vtkImageMapper> image_mapper = vtkSmartPointer<vtkImageMapper>::New();
  vtkSmartPointer<vtkActor2D> image_actor = vtkSmartPointer<vtkActor2D>::New();
  detail::ColourBar bar;
  vtkSmartPointer<vtkTextActor> title = make_text(VTK_TEXT_CENTERED, VTK_TEXT_TOP, kTitleFontSize);
  vtkSmartPointer<vtkTextActor> u_min = make_text(VTK_TEXT_LEFT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> u_max = make_text(VTK_TEXT_RIGHT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> u_name = make_text(VTK_TEXT_CENTERED, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> v_min = make_text(VTK_TEXT_RIGHT, VTK_TEXT_BOTTOM, kFontSize);
  vtkSmartPointer<vtkTextActor> v_max = make_text(VTK_TEXT_RIGHT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> v_name = make_text(VTK_TEXT_RIGHT, VTK_TEXT_CENTERED, kFontSize);
  std::vector<int> node_index;   // colour index per slice node
  std::vector<int> column_node;  // slice column iu per image pixel column

  Panel() {
    renderer->SetBackground(1.0, 1.0, 1.0);
    image_mapper->SetInputData(image);
    image_mapper->SetColorWindow(255.0);  // identity for 8-bit RGB: no shift, no scale
    image_mapper->SetColorLevel(127.5);
    image_actor->SetMapper(image_mapper);
    image_actor->GetPositionCoordinate()->SetCoordinateSystemToViewport();

    renderer->AddActor2D(image_actor);
    renderer->AddActor2D(bar.actor());
    for (vtkTextActor* text : {title.Get(), u_min.Get(), u_max.Get(), u_name.Get(), v_min.Get(),
                               v_max.Get(), v_name.Get()}) {
      renderer->AddActor2D(text);
    }
  }

  void update(const analysis::SliceProduct& slice, const ColourMapping& mapping,
              const FrameLabels& labels, int panel_width, int panel_height) {
    if (slice.width <= 0 || slice.height <= 0 ||
        slice.values.size() !=
            static_cast<std::size_t>(slice.width) * static_cast<std::size_t>(slice.height)) {
      throw std::invalid_argument("render: slice values do not match width x height");
    }
    const std::array<double, 2> range = colour_range(slice.values, mapping);
    const ImageRect rect = image_rect(panel_width, panel_height, slice);

    // Colour index per node, then nearest-node resampling to the on-screen image.
    node_index.resize(slice.values.size());
    colour_indices(slice.values, range, mapping.log_scale, node_index);
    column_node.resize(static_cast<std::size_t>(rect.width));
    for (int px = 0; px < rect.width; ++px) {
      column_node[px] =
          std::min(slice.width - 1, static_cast<int>((px + 0.5) * slice.width / rect.width));
    }
    int* dimensions = image->GetDimensions();
    if (dimensions[0] != rect.width || dimensions[1] != rect.height ||
        image->GetNumberOfScalarComponents() != 3) {
      image->SetDimensions(rect.width, rect.height, 1);
      image->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
    }
    auto* pixels = static_cast<unsigned char*>(image->GetScalarPointer());
    const auto& table = viridis_table();
    for (int py = 0; py < rect.height; ++py) {
      const int iv =
          std::min(slice.height - 1, static_cast<int>((py + 0.5) * slice.height / rect.height));
      const int* row = node_index.data() + static_cast<std::ptrdiff_t>(iv) * slice.width;
      unsigned char* out = pixels + static_cast<std::ptrdiff_t>(py) * rect.width * 3;
      for (int px = 0; px < rect.width; ++px) {
        const int index = row[column_node[px]];
        const Rgb& colour = index < 0 ? kNanColour : table[index];
        out[3 * px] = colour[0];
        out[3 * px + 1] = colour[1];
        out[3 * px + 2] = colour[2];
      }
    }
    image->Modified();
    image_actor->SetPosition(rect.x, rect.y);

    bar.update(range, mapping.log_scale, detail::field_label(slice.field),
               rect.x + rect.width + kBarGap, rect.y, kBarWidth, rect.height);

    const std::string title_text =
        labels.case_name + "   t = " + format_number(labels.time) + " s   step " +
        std::to_string(labels.step) + "\n" + detail::field_symbol(slice.field) + " at " +
        axis_name(slice.normal_axis) + " = " + format_number(slice.position) + " m";
    set_text(title, title_text, panel_width / 2.0, panel_height - 6.0);

    const double u_length = slice.width * slice.spacing, v_length = slice.height * slice.spacing;
    set_text(u_min, "0", rect.x, rect.y - 4.0);
    set_text(u_max, format_number(u_length), rect.x + rect.width, rect.y - 4.0);
    set_text(u_name, std::string(1, axis_name(slice.axis_u)) + " [m]", rect.x + rect.width / 2.0,
             rect.y - 4.0);
    set_text(v_min, "0", rect.x - 5.0, rect.y);
    set_text(v_max, format_number(v_length), rect.x - 5.0, rect.y + rect.height);
    set_text(v_name, std::string(1, axis_name(slice.axis_v)) + " [m]", rect.x - 5.0,
             rect.y + rect.height / 2.0);
  }
};

}  // namespace

ImageRect image_rect(int panel_width, int panel_height, const analysis::SliceProduct& slice) {
  const int available_width = std::max(1, panel_width - kMarginLeft - kMarginRight);
  const int available_height = std::max(1, panel_height - kMarginTop - kMarginBottom);
  const double aspect =
      slice.height > 0 ? static_cast<double>(slice.width) / slice.height : 1.0;  // u / v
  ImageRect rect;
  if (available_width >= aspect * available_height) {
    rect.height = available_height;
    rect.width = std::max(1, static_cast<int>(std::lround(available_height * aspect)));
  } else {
    rect.width = available_width;
    rect.height = std::max(1, static_cast<int>(std::lround(available_width / aspect)));
  }
  rect.x = kMarginLeft + (available_width - rect.width) / 2;
  rect.y = kMarginBottom + (available_height - rect.height) / 2;
  return rect;
}

template <>
struct detail::OffscreenPngRenderer<Renderer>::Impl {
  detail::OffscreenWindow surface;  // first: destroyed after the panels' renderers
  std::vector<std::unique_ptr<Panel>> panels;
  FrameTimings timings;

  Impl(int width, int height) : surface(width, height) {}

  void set_panel_count(std::size_t count) {
    if (panels.size() == count) return;
    for (const auto& panel : panels) surface.window()->RemoveRenderer(panel->renderer);
    panels.clear();
    for (std::size_t i = 0; i < count; ++i) {
      auto panel = std::make_unique<Panel>();
      panel->renderer->SetViewport(static_cast<double>(i) / count, 0.0,
                                   static_cast<double>(i + 1) / count, 1.0);
      surface.window()->AddRenderer(panel->renderer);
      panels.push_back(std::move(panel));
    }
  }
};

template class detail::OffscreenPngRenderer<Renderer>;

Renderer::Renderer(int width, int height) : OffscreenPngRenderer(width, height) {}

std::vector<unsigned char> Renderer::render_png(std::span<const analysis::SliceProduct> slices,
                                                std::span<const ColourMapping> mappings,
                                                const FrameLabels& labels) {
  if (slices.empty()) throw std::invalid_argument("render_png: no slices");
  if (mappings.size() != 1 && mappings.size() != slices.size()) {
    throw std::invalid_argument("render_png: need one mapping, or one per slice");
  }
  Impl& impl = *impl_;
  const int width = impl.surface.width(), height = impl.surface.height();
  return impl.surface.draw_png(impl.timings, [&] {
    impl.set_panel_count(slices.size());
    const int count = static_cast<int>(slices.size());
    for (int i = 0; i < count; ++i) {
      // Pixel extent of panel i, as VTK rounds the viewport [i/n, (i+1)/n).
      const int x0 = static_cast<int>(static_cast<double>(i) / count * width + 0.5);
      const int x1 = static_cast<int>(static_cast<double>(i + 1) / count * width + 0.5);
      impl.panels[i]->update(slices[i], mappings[mappings.size() == 1 ? 0 : i], labels, x1 - x0,
                             height);
    }
  });
}

std::vector<unsigned char> render_slice_png(const analysis::SliceProduct& slice,
                                            const ColourMapping& mapping, const FrameLabels& labels,
                                            int width, int height) {
  return detail::thread_local_renderer<Renderer>(width, height)
      .render_png(std::span(&slice, 1), std::span(&mapping, 1), labels);
}

std::vector<unsigned char> render_slices_png(std::span<const analysis::SliceProduct> slices,
                                             const ColourMapping& mapping,
                                             const FrameLabels& labels, int width, int height) {
  return detail::thread_local_renderer<Renderer>(width, height)
      .render_png(slices, std::span(&mapping, 1), labels);
}

std::vector<unsigned char> render_slices_png(std::span<const analysis::SliceProduct> slices,
                                             std::span<const ColourMapping> mappings,
                                             const FrameLabels& labels, int width, int height) {
  return detail::thread_local_renderer<Renderer>(width, height)
      .render_png(slices, mappings, labels);
}

void write_png_file(const std::filesystem::path& path, std::span<const unsigned char> bytes) {
  static std::atomic<unsigned> counter{0};
  std::filesystem::path temporary = path;
  temporary += ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    throw std::system_error(errno, std::generic_category(), "open " + temporary.string());
  }
  std::size_t written = 0;
  int error = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      error = errno;
      break;
    }
    written += static_cast<std::size_t>(n);
  }
  if (error == 0 && ::fsync(fd) != 0) error = errno;
  if (::close(fd) != 0 && error == 0) error = errno;
  if (error == 0 && std::rename(temporary.c_str(), path.c_str()) != 0) error = errno;
  if (error != 0) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw std::system_error(error, std::generic_category(), "write_png_file " + path.string());
  }
}

}  // namespace sphles::render
