// SPDX-License-Identifier: GPL-3.0-or-later
// Internal pieces shared by the slice renderer (render.cpp) and the 3D particle view (view3d.cpp):
// the off-screen window on an OSMesa context with read-back and PNG encoding, the process-wide
// VTK scene lock, text actors and the viridis colour bar. Not part of the public API.
#pragma once

#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkPNGWriter.h>
#include <vtkScalarBarActor.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>  // VTK_TEXT_* justifications for make_text
#include <vtkWindowToImageFilter.h>

#include <array>
#include <chrono>
#include <cstddef>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "analysis/config.hpp"
#include "render/colour_map.hpp"
#include "render/frame_timings.hpp"
#include "render/offscreen_png_renderer.hpp"
#include "render/osmesa_context.hpp"
#include "render/png_encode.hpp"

namespace sphles::render::detail {

inline constexpr int kFontSize = 14;
inline constexpr int kTitleFontSize = 15;
inline constexpr Rgb kNanColour = {128, 128, 128};

/// VTK's text rendering keeps process-wide caches (vtkFreeTypeTools, vtkTextRenderer) that are
/// not documented as thread-safe: construction, destruction, scene updates and Render of every
/// window are serialised by this lock. Read-back and PNG encoding use per-window objects only and
/// run concurrently.
std::mutex& vtk_scene_mutex();

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since);

/// "%.4g".
std::string format_number(double value);

/// The pictures' font on a text property: DejaVu Sans when installed, else VTK's Arial.
void set_font(vtkTextProperty* property);

/// A field's name and units as the pictures print them, in the notation of the docs (UTF-8,
/// drawn in DejaVu Sans): "ω² [s⁻²]", "|τ_SFS| [Pa]", "ν_t [m²/s]"; the ASCII names (omega2
/// [1/s^2]) without that font. The files keep the ASCII names that scripts match.
std::string field_label(analysis::SliceField field);
/// The name alone: "ω²", "|τ_SFS|", "ν_t"; the units alone: "s⁻²", "Pa", "m²/s".
std::string field_symbol(analysis::SliceField field);
std::string field_units(analysis::SliceField field);

/// Black text (set_font) at a viewport position (pixels), not scaled with the window.
vtkSmartPointer<vtkTextActor> make_text(int justification, int vertical_justification,
                                        int font_size);
/// Sets the text (only if it changed: a new text rebuilds its texture) and the position.
void set_text(vtkTextActor* actor, const std::string& text, double x, double y);

/// Vertical viridis colour bar in viewport pixel coordinates whose vtkLookupTable matches the CPU
/// mapping (make_lookup_table); the table is rebuilt only when the range or scale change.
class ColourBar {
 public:
  ColourBar();
  vtkScalarBarActor* actor() const { return actor_; }
  /// Range, scale, title and the rectangle (x, y, width, height) [px] of the bar with its labels.
  void update(const std::array<double, 2>& range, bool log_scale, const std::string& title,
              double x, double y, double width, double height);

 private:
  vtkSmartPointer<vtkScalarBarActor> actor_ = vtkSmartPointer<vtkScalarBarActor>::New();
  std::array<double, 2> range_{0.0, 0.0};
  bool log_scale_ = false;
};

/// An OSMesa context with a vtkGenericOpenGLRenderWindow of fixed size on it, a read-back filter
/// and the PNG encoders, reused across frames. Construct, destroy, update the scene and Render
/// with vtk_scene_mutex() held; read_back_png without it. The owner adds its vtkRenderers to
/// window(); they must be destroyed before this object (declare it first).
class OffscreenWindow {
 public:
  OffscreenWindow(int width, int height);
  ~OffscreenWindow();
  OffscreenWindow(const OffscreenWindow&) = delete;
  OffscreenWindow& operator=(const OffscreenWindow&) = delete;

  int width() const { return width_; }
  int height() const { return height_; }
  vtkGenericOpenGLRenderWindow* window() const { return window_; }
  /// Makes the OSMesa context current on the calling thread (at the start of every frame).
  void make_current() { context_.make_current(); }

  void set_compression_level(int level);  // clamped to 0..9
  /// A filter: libpng directly with that row filter; std::nullopt: vtkPNGWriter (adaptive).
  void set_png_filter(std::optional<PngFilter> filter) { png_filter_ = filter; }

  /// Reads back the frame rendered last (without re-rendering) and encodes it as PNG; sets
  /// timings.read_back_ms and timings.encode_ms.
  std::vector<unsigned char> read_back_png(FrameTimings& timings);

  /// One frame: under vtk_scene_mutex() makes the context current, runs `update` (the scene's
  /// changes) and renders; then reads back and encodes without the lock. timings.prepare_ms
  /// counts from `start` (the CPU work a renderer does before taking the lock), or from the
  /// lock's taking when none is given.
  template <class Update>
  std::vector<unsigned char> draw_png(FrameTimings& timings, Update&& update,
                                      std::optional<Clock::time_point> start = std::nullopt) {
    std::unique_lock lock(vtk_scene_mutex());
    const Clock::time_point from = start.value_or(Clock::now());
    make_current();
    update();
    timings.prepare_ms = elapsed_ms(from);
    const auto rendering = Clock::now();
    window_->Render();
    timings.render_ms = elapsed_ms(rendering);
    lock.unlock();
    return read_back_png(timings);
  }

 private:
  int width_, height_;
  OsmesaContext context_;
  vtkSmartPointer<vtkGenericOpenGLRenderWindow> window_ =
      vtkSmartPointer<vtkGenericOpenGLRenderWindow>::New();
  vtkSmartPointer<vtkWindowToImageFilter> read_back_ =
      vtkSmartPointer<vtkWindowToImageFilter>::New();
  vtkSmartPointer<vtkPNGWriter> writer_ = vtkSmartPointer<vtkPNGWriter>::New();
  int compression_level_ = kDefaultPngCompressionLevel;
  std::optional<PngFilter> png_filter_ = kDefaultPngFilter;
};

/// The calling thread's renderer (Renderer, ParticleRenderer) of this frame size, created on
/// first use; a few sizes at most are kept per thread and type.
template <class R>
R& thread_local_renderer(int width, int height) {
  constexpr std::size_t kMaxCachedRenderers = 4;
  thread_local std::vector<std::unique_ptr<R>> renderers;
  for (const auto& renderer : renderers) {
    if (renderer->width() == width && renderer->height() == height) return *renderer;
  }
  if (renderers.size() >= kMaxCachedRenderers) renderers.erase(renderers.begin());
  renderers.push_back(std::make_unique<R>(width, height));
  return *renderers.back();
}

// The members OffscreenPngRenderer<R> shares, for the explicit instantiation after R's Impl
// (render.cpp, view3d.cpp).
template <class R>
OffscreenPngRenderer<R>::OffscreenPngRenderer(int width, int height) {
  const std::lock_guard lock(vtk_scene_mutex());
  impl_ = std::make_unique<Impl>(width, height);
}
template <class R>
OffscreenPngRenderer<R>::~OffscreenPngRenderer() {
  const std::lock_guard lock(vtk_scene_mutex());
  impl_.reset();
}
template <class R>
int OffscreenPngRenderer<R>::width() const {
  return impl_->surface.width();
}
template <class R>
int OffscreenPngRenderer<R>::height() const {
  return impl_->surface.height();
}
template <class R>
const FrameTimings& OffscreenPngRenderer<R>::last_timings() const {
  return impl_->timings;
}
template <class R>
void OffscreenPngRenderer<R>::set_compression_level(int level) {
  impl_->surface.set_compression_level(level);
}
template <class R>
void OffscreenPngRenderer<R>::set_png_filter(std::optional<PngFilter> filter) {
  impl_->surface.set_png_filter(filter);
}

}  // namespace sphles::render::detail
