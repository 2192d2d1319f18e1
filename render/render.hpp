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
#include "render/png_encode.hpp"

namespace sphles::render {

/// How slice values become colours. With min and max both given the range is fixed; a missing
/// bound is taken from the percentile of the finite values (for log scale: finite and > 0).
struct ColourMapping {
  bool log_scale = false;
  std::optional<double> min, max;
  double lower_percentile = 0.01;  // fraction in [0, 1]
  double upper_percentile = 0.99;  // fraction in [0, 1]
};

struct FrameLabels {
  std::string case_name;
  double time = 0.0;  // simulated time [s]
  std::uint64_t step = 0;
};

/// Number of entries of the colour map (viridis).
inline constexpr int kColourCount = 256;
using Rgb = std::array<unsigned char, 3>;

/// The 256-entry viridis table, linearly interpolated from 17 control points of the published
/// definition (matplotlib _viridis_data, every 16th entry); 8-bit RGB.
const std::array<Rgb, kColourCount>& viridis_table();

/// Value range [min, max] the mapping uses for these values (see ColourMapping). For log scale
/// both bounds are > 0. min < max always (a degenerate range is widened).
/// Throws std::invalid_argument for a log scale with a given bound <= 0.
std::array<double, 2> colour_range(std::span<const double> values, const ColourMapping& mapping);

/// Lookup-table index of a value: floor(256 t) clamped to [0, 255], t = (v - min) / (max - min),
/// or for log scale t = (log10 v - log10 min) / (log10 max - log10 min), so each decade gets
/// the same number of entries. The transform is done here (on the CPU); the vtkLookupTable the
/// scalar bar uses is set to the same range with SetScaleToLog10 and maps values identically.
/// Values below the range (and for log scale values <= 0) get index 0; NaN gets -1.
int colour_index(double value, const std::array<double, 2>& range, bool log_scale);

/// colour_index of every value (indices.size() == values.size()), with the range transform
/// hoisted out of the loop.
void colour_indices(std::span<const double> values, const std::array<double, 2>& range,
                    bool log_scale, std::span<int> indices);

/// Rectangle of a panel's image in pixels, origin at the bottom-left of the panel (VTK display
/// convention; a PNG decoded with vtkPNGReader uses the same orientation).
struct ImageRect {
  int x = 0, y = 0, width = 0, height = 0;
};
/// Where the slice image sits in a panel of the given size. Slice node (iu, iv) is drawn as the
/// cell [iu h, (iu + 1) h) x [iv h, (iv + 1) h) of the box; pixel column px shows
/// iu = floor((px - x + 0.5) * slice.width / width), likewise for rows.
ImageRect image_rect(int panel_width, int panel_height, const analysis::SliceProduct& slice);

/// Wall time of the stages of the last frame [ms].
struct FrameTimings {
  double prepare_ms = 0.0;    // colour mapping on the CPU and scene update
  double render_ms = 0.0;     // vtkRenderWindow::Render
  double read_back_ms = 0.0;  // vtkWindowToImageFilter::Update
  double encode_ms = 0.0;     // vtkPNGWriter to memory
};

/// An off-screen OSMesa context with a VTK render window of fixed size, reused across frames.
/// Not thread-safe: use one Renderer per thread (the OSMesa context is made current on the
/// calling thread at the start of every frame).
class Renderer {
 public:
  /// PNG zlib level used by default: 1 (Z_BEST_SPEED); several times faster than the default
  /// level 6 for these frames.
  static constexpr int kDefaultCompressionLevel = 1;
  /// PNG row filter used by default: none. The frames are nearest-neighbour upscaled colour
  /// fields with flat margins, so unfiltered rows compress better (long LZ77 matches) and faster
  /// than libpng's adaptive choice, which vtkPNGWriter always uses.
  static constexpr PngFilter kDefaultPngFilter = PngFilter::None;

  Renderer(int width, int height);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  int width() const;
  int height() const;

  /// Renders the slices side by side (panel i covers [i W / n, (i + 1) W / n)) and returns the
  /// PNG bytes. mappings has one entry for all panels or one per slice.
  std::vector<unsigned char> render_png(std::span<const analysis::SliceProduct> slices,
                                        std::span<const ColourMapping> mappings,
                                        const FrameLabels& labels);

  void set_compression_level(int level);  // 0..9
  /// PNG encoder: a filter (default kDefaultPngFilter) encodes the read-back pixels with libpng
  /// directly; std::nullopt uses vtkPNGWriter (WriteToMemory, libpng's adaptive row filter).
  /// Both give the same pixels; sizes and times differ (see bench/bench_render.cpp).
  void set_png_filter(std::optional<PngFilter> filter);
  const FrameTimings& last_timings() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
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
