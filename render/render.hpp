// SPDX-License-Identifier: GPL-3.0-or-later
// Headless rendering of analysis slices to PNG (SPEC §5 "frames"), without an X server.
//
// Debian 12's VTK 9.1 is built for GLX only, so this library creates its own OSMesa context
// (software, llvmpipe), hands it to a vtkGenericOpenGLRenderWindow and routes GLEW's entry-point
// loader to OSMesa (see render/gl_loader.cpp and docs/rendering.md).
//
// Threading: a Renderer owns one OSMesa context and is used from one thread at a time; make one
// renderer per thread. The free functions render_slice_png / render_slices_png keep one
// thread_local Renderer per frame size, so they are safe to call from several threads at once.
// VTK's text rendering caches are process-wide, so the scene update and Render of all renderers
// are serialised by one mutex; read-back and PNG encoding run in parallel.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "analysis/products.hpp"
#include "render/colour_map.hpp"
#include "render/frame_timings.hpp"
#include "render/offscreen_png_renderer.hpp"
#include "render/png_encode.hpp"

namespace sphles::render {

struct FrameLabels {
  std::string case_name;
  double time = 0.0;  // simulated time [s]
  std::uint64_t step = 0;
};

/// Rectangle of a panel's image in pixels, origin at the bottom-left of the panel (VTK display
/// convention; a PNG decoded with vtkPNGReader uses the same orientation).
struct ImageRect {
  int x = 0, y = 0, width = 0, height = 0;
};
/// Where the slice image sits in a panel of the given size. Slice node (iu, iv) is drawn as the
/// cell [iu h, (iu + 1) h) x [iv h, (iv + 1) h) of the box; pixel column px shows
/// iu = floor((px - x + 0.5) * slice.width / width), likewise for rows.
ImageRect image_rect(int panel_width, int panel_height, const analysis::SliceProduct& slice);

/// An off-screen OSMesa context with a VTK render window of fixed size, reused across frames.
/// Not thread-safe: use one Renderer per thread (the OSMesa context is made current on the
/// calling thread at the start of every frame).
class Renderer : public detail::OffscreenPngRenderer<Renderer> {
 public:
  /// PNG zlib level and row filter used by default (png_encode.hpp).
  static constexpr int kDefaultCompressionLevel = kDefaultPngCompressionLevel;
  static constexpr PngFilter kDefaultPngFilter = render::kDefaultPngFilter;

  Renderer(int width, int height);

  /// Renders the slices side by side (panel i covers [i W / n, (i + 1) W / n)) and returns the
  /// PNG bytes. mappings has one entry for all panels or one per slice.
  std::vector<unsigned char> render_png(std::span<const analysis::SliceProduct> slices,
                                        std::span<const ColourMapping> mappings,
                                        const FrameLabels& labels);
};

/// One slice as a PNG of width x height pixels (thread_local Renderer per size).
std::vector<unsigned char> render_slice_png(const analysis::SliceProduct& slice,
                                            const ColourMapping& mapping, const FrameLabels& labels,
                                            int width, int height);

/// Slices side by side (typically two fields in a 1200 x 600 frame), one mapping for all.
std::vector<unsigned char> render_slices_png(std::span<const analysis::SliceProduct> slices,
                                             const ColourMapping& mapping,
                                             const FrameLabels& labels, int width = 1200,
                                             int height = 600);
/// The same with one mapping per slice.
std::vector<unsigned char> render_slices_png(std::span<const analysis::SliceProduct> slices,
                                             std::span<const ColourMapping> mappings,
                                             const FrameLabels& labels, int width, int height);

/// Writes bytes to path atomically: to "<path>.tmp.<pid>.<n>" first, then renames over path.
/// Throws std::runtime_error on failure (the temporary is removed).
void write_png_file(const std::filesystem::path& path, std::span<const unsigned char> bytes);

}  // namespace sphles::render
