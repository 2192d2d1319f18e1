// SPDX-License-Identifier: GPL-3.0-or-later
// The part of the public renderers (Renderer, ParticleRenderer) that they share: their size,
// PNG settings and timings, and the lifetime of their VTK scene. Its members are defined in
// vtk_window.hpp, away from the public headers' includes.
#pragma once

#include <memory>
#include <optional>

#include "render/frame_timings.hpp"
#include "render/png_encode.hpp"

namespace sphles::render::detail {

/// What Renderer and ParticleRenderer share: their Impl (each defines it in its .cpp file) holds
/// the off-screen window `surface` and the last frame's `timings`, and is created and destroyed
/// under the process-wide VTK scene lock. The members are instantiated in render.cpp and
/// view3d.cpp for their R.
template <class R>
class OffscreenPngRenderer {
 public:
  OffscreenPngRenderer(const OffscreenPngRenderer&) = delete;
  OffscreenPngRenderer& operator=(const OffscreenPngRenderer&) = delete;

  int width() const;
  int height() const;

  void set_compression_level(int level);  // 0..9; default Renderer::kDefaultCompressionLevel
  /// PNG encoder: a filter (default Renderer::kDefaultPngFilter) encodes the read-back pixels
  /// with libpng directly; std::nullopt uses vtkPNGWriter (WriteToMemory, libpng's adaptive row
  /// filter). Both give the same pixels; sizes and times differ (see bench/bench_render.cpp).
  void set_png_filter(std::optional<PngFilter> filter);
  const FrameTimings& last_timings() const;

 protected:
  OffscreenPngRenderer(int width, int height);
  ~OffscreenPngRenderer();

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sphles::render::detail
