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
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkImageData.h>
#include <vtkImageMapper.h>
#include <vtkPNGWriter.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkUnsignedCharArray.h>
#include <vtkWindowToImageFilter.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <system_error>

#include "render/lookup_table.hpp"
#include "render/osmesa_context.hpp"

namespace sphles::render {
namespace {

// Panel margins [px] around the image: title above, axis labels left and below, colour bar right.
constexpr int kMarginTop = 56;
constexpr int kMarginBottom = 44;
constexpr int kMarginLeft = 64;
constexpr int kMarginRight = 130;
constexpr int kBarGap = 14;
constexpr int kBarWidth = 110;
constexpr int kFontSize = 14;
constexpr int kTitleFontSize = 15;
constexpr Rgb kNanColour = {128, 128, 128};

// VTK's text rendering keeps process-wide caches (vtkFreeTypeTools, vtkTextRenderer) that are
// not documented as thread-safe: scene updates and Render of all renderers are serialised by this
// lock. Read-back and PNG encoding use per-renderer objects only and run concurrently.
std::mutex& vtk_scene_mutex() {
  static std::mutex mutex;
  return mutex;
}

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

std::string format_number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", value);
  return buffer;
}

char axis_name(int axis) {
  return axis == 0 ? 'x' : axis == 1 ? 'y' : 'z';
}

vtkSmartPointer<vtkTextActor> make_text(int justification, int vertical_justification,
                                        int font_size) {
  auto text = vtkSmartPointer<vtkTextActor>::New();
  text->SetTextScaleModeToNone();
  text->GetPositionCoordinate()->SetCoordinateSystemToViewport();
  vtkTextProperty* property = text->GetTextProperty();
  property->SetFontFamilyToArial();
  property->SetFontSize(font_size);
  property->SetColor(0.0, 0.0, 0.0);
  property->SetJustification(justification);
  property->SetVerticalJustification(vertical_justification);
  return text;
}

void set_text(vtkTextActor* actor, const std::string& text, double x, double y) {
  if (actor->GetInput() == nullptr || text != actor->GetInput()) actor->SetInput(text.c_str());
  actor->SetPosition(x, y);
}

// One panel: a viewport of the window with the image, colour bar and labels.
struct Panel {
  vtkSmartPointer<vtkRenderer> renderer = vtkSmartPointer<vtkRenderer>::New();
  vtkSmartPointer<vtkImageData> image = vtkSmartPointer<vtkImageData>::New();
  vtkSmartPointer<vtkImageMapper> image_mapper = vtkSmartPointer<vtkImageMapper>::New();
  vtkSmartPointer<vtkActor2D> image_actor = vtkSmartPointer<vtkActor2D>::New();
  vtkSmartPointer<vtkScalarBarActor> bar = vtkSmartPointer<vtkScalarBarActor>::New();
  vtkSmartPointer<vtkTextActor> title = make_text(VTK_TEXT_CENTERED, VTK_TEXT_TOP, kTitleFontSize);
  vtkSmartPointer<vtkTextActor> u_min = make_text(VTK_TEXT_LEFT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> u_max = make_text(VTK_TEXT_RIGHT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> u_name = make_text(VTK_TEXT_CENTERED, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> v_min = make_text(VTK_TEXT_RIGHT, VTK_TEXT_BOTTOM, kFontSize);
  vtkSmartPointer<vtkTextActor> v_max = make_text(VTK_TEXT_RIGHT, VTK_TEXT_TOP, kFontSize);
  vtkSmartPointer<vtkTextActor> v_name = make_text(VTK_TEXT_RIGHT, VTK_TEXT_CENTERED, kFontSize);
  std::array<double, 2> bar_range{0.0, 0.0};
  bool bar_log = false;
  std::vector<int> node_index;   // colour index per slice node
  std::vector<int> column_node;  // slice column iu per image pixel column

  Panel() {
    renderer->SetBackground(1.0, 1.0, 1.0);
    image_mapper->SetInputData(image);
    image_mapper->SetColorWindow(255.0);  // identity for 8-bit RGB: no shift, no scale
    image_mapper->SetColorLevel(127.5);
    image_actor->SetMapper(image_mapper);
    image_actor->GetPositionCoordinate()->SetCoordinateSystemToViewport();

    bar->SetOrientationToVertical();
    bar->SetMaximumNumberOfColors(kColourCount);
    bar->SetNumberOfLabels(5);
    bar->SetUnconstrainedFontSize(true);
    bar->SetBarRatio(0.3);
    bar->SetTextPad(3);
    bar->SetLabelFormat("%.3g");
    bar->GetPositionCoordinate()->SetCoordinateSystemToViewport();
    bar->GetPosition2Coordinate()->SetCoordinateSystemToViewport();
    for (vtkTextProperty* property : {bar->GetTitleTextProperty(), bar->GetLabelTextProperty()}) {
      property->SetFontFamilyToArial();
      property->SetColor(0.0, 0.0, 0.0);
      property->SetBold(false);
      property->SetItalic(false);
      property->SetShadow(false);
      property->SetFontSize(kFontSize);
    }
    bar->GetLabelTextProperty()->SetFontSize(kFontSize - 2);

    renderer->AddActor2D(image_actor);
    renderer->AddActor2D(bar);
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

    // Colour bar: rebuilt only when its range or scale changes.
    if (range != bar_range || mapping.log_scale != bar_log || bar->GetLookupTable() == nullptr) {
      bar->SetLookupTable(make_lookup_table(range, mapping.log_scale));
      bar_range = range;
      bar_log = mapping.log_scale;
    }
    const std::string bar_title =
        std::string(analysis::slice_field_name(slice.field)) + " [" + slice.units + "]";
    if (bar->GetTitle() == nullptr || bar_title != bar->GetTitle()) {
      bar->SetTitle(bar_title.c_str());
    }
    bar->SetPosition(rect.x + rect.width + kBarGap, rect.y);
    bar->SetPosition2(kBarWidth, rect.height);

    const std::string title_text =
        labels.case_name + "   t = " + format_number(labels.time) + " s   step " +
        std::to_string(labels.step) + "\n" + std::string(analysis::slice_field_name(slice.field)) +
        " at " + axis_name(slice.normal_axis) + " = " + format_number(slice.position) + " m";
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

struct Renderer::Impl {
  int width, height;
  detail::OsmesaContext context;
  vtkSmartPointer<vtkGenericOpenGLRenderWindow> window =
      vtkSmartPointer<vtkGenericOpenGLRenderWindow>::New();
  vtkSmartPointer<vtkWindowToImageFilter> read_back =
      vtkSmartPointer<vtkWindowToImageFilter>::New();
  vtkSmartPointer<vtkPNGWriter> writer = vtkSmartPointer<vtkPNGWriter>::New();
  std::vector<std::unique_ptr<Panel>> panels;
  FrameTimings timings;
  int compression_level = kDefaultCompressionLevel;
  std::optional<PngFilter> png_filter = kDefaultPngFilter;

  Impl(int w, int h) : width(w), height(h), context(w, h) {
    window->SetOwnContext(false);
    window->SetSize(width, height);
    window->SetOffScreenRendering(true);
    window->SetMultiSamples(0);
    window->SetIsDirect(true);
    window->SetSupportsOpenGL(true);
    window->SetReadyForRendering(true);
    window->SetIsCurrent(true);
    window->SetMapped(true);

    read_back->SetInput(window);
    read_back->ShouldRerenderOff();
    read_back->ReadFrontBufferOff();
    read_back->SetInputBufferTypeToRGB();

    writer->SetInputConnection(read_back->GetOutputPort());
    writer->WriteToMemoryOn();
    writer->SetCompressionLevel(kDefaultCompressionLevel);
  }

  ~Impl() {
    // VTK releases its GL objects on destruction: keep the context current until it has.
    try {
      context.make_current();
    } catch (...) {
      return;  // cannot release GL resources safely; leak them rather than crash
    }
    writer = nullptr;
    read_back = nullptr;
    panels.clear();
    window->Finalize();
    window = nullptr;
  }

  void set_panel_count(std::size_t count) {
    if (panels.size() == count) return;
    for (const auto& panel : panels) window->RemoveRenderer(panel->renderer);
    panels.clear();
    for (std::size_t i = 0; i < count; ++i) {
      auto panel = std::make_unique<Panel>();
      panel->renderer->SetViewport(static_cast<double>(i) / count, 0.0,
                                   static_cast<double>(i + 1) / count, 1.0);
      window->AddRenderer(panel->renderer);
      panels.push_back(std::move(panel));
    }
  }
};

Renderer::Renderer(int width, int height) {
  const std::lock_guard lock(vtk_scene_mutex());
  impl_ = std::make_unique<Impl>(width, height);
}
Renderer::~Renderer() {
  const std::lock_guard lock(vtk_scene_mutex());
  impl_.reset();
}
int Renderer::width() const {
  return impl_->width;
}
int Renderer::height() const {
  return impl_->height;
}
const FrameTimings& Renderer::last_timings() const {
  return impl_->timings;
}
void Renderer::set_compression_level(int level) {
  impl_->compression_level = std::clamp(level, 0, 9);
  impl_->writer->SetCompressionLevel(impl_->compression_level);
}
void Renderer::set_png_filter(std::optional<PngFilter> filter) {
  impl_->png_filter = filter;
}

std::vector<unsigned char> Renderer::render_png(std::span<const analysis::SliceProduct> slices,
                                                std::span<const ColourMapping> mappings,
                                                const FrameLabels& labels) {
  if (slices.empty()) throw std::invalid_argument("render_png: no slices");
  if (mappings.size() != 1 && mappings.size() != slices.size()) {
    throw std::invalid_argument("render_png: need one mapping, or one per slice");
  }
  Impl& impl = *impl_;
  std::unique_lock lock(vtk_scene_mutex());
  auto start = Clock::now();
  impl.context.make_current();
  impl.set_panel_count(slices.size());
  const int count = static_cast<int>(slices.size());
  for (int i = 0; i < count; ++i) {
    // Pixel extent of panel i, as VTK rounds the viewport [i/n, (i+1)/n).
    const int x0 = static_cast<int>(static_cast<double>(i) / count * impl.width + 0.5);
    const int x1 = static_cast<int>(static_cast<double>(i + 1) / count * impl.width + 0.5);
    impl.panels[i]->update(slices[i], mappings[mappings.size() == 1 ? 0 : i], labels, x1 - x0,
                           impl.height);
  }
  impl.timings.prepare_ms = elapsed_ms(start);

  start = Clock::now();
  impl.window->Render();
  impl.timings.render_ms = elapsed_ms(start);
  lock.unlock();

  start = Clock::now();
  impl.read_back->Modified();
  impl.read_back->Update();
  impl.timings.read_back_ms = elapsed_ms(start);

  start = Clock::now();
  std::vector<unsigned char> bytes;
  if (impl.png_filter) {
    vtkImageData* image = impl.read_back->GetOutput();
    int* dimensions = image->GetDimensions();
    const auto* pixels = static_cast<const unsigned char*>(image->GetScalarPointer());
    bytes = encode_png_rgb(
        std::span(pixels, static_cast<std::size_t>(dimensions[0]) * dimensions[1] * 3),
        dimensions[0], dimensions[1], impl.compression_level, *impl.png_filter);
  } else {
    impl.writer->Write();
    vtkUnsignedCharArray* result = impl.writer->GetResult();
    if (result == nullptr || result->GetNumberOfValues() == 0) {
      throw std::runtime_error("render_png: PNG encoding failed");
    }
    bytes.assign(result->GetPointer(0), result->GetPointer(0) + result->GetNumberOfValues());
  }
  impl.timings.encode_ms = elapsed_ms(start);
  return bytes;
}

namespace {

Renderer& thread_renderer(int width, int height) {
  // One renderer per thread and frame size; a few sizes at most are kept.
  constexpr std::size_t kMaxCachedRenderers = 4;
  thread_local std::vector<std::unique_ptr<Renderer>> renderers;
  for (const auto& renderer : renderers) {
    if (renderer->width() == width && renderer->height() == height) return *renderer;
  }
  if (renderers.size() >= kMaxCachedRenderers) renderers.erase(renderers.begin());
  renderers.push_back(std::make_unique<Renderer>(width, height));
  return *renderers.back();
}

}  // namespace

std::vector<unsigned char> render_slice_png(const analysis::SliceProduct& slice,
                                            const ColourMapping& mapping, const FrameLabels& labels,
                                            int width, int height) {
  return thread_renderer(width, height)
      .render_png(std::span(&slice, 1), std::span(&mapping, 1), labels);
}

std::vector<unsigned char> render_slices_png(std::span<const analysis::SliceProduct> slices,
                                             const ColourMapping& mapping,
                                             const FrameLabels& labels, int width, int height) {
  return thread_renderer(width, height).render_png(slices, std::span(&mapping, 1), labels);
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
