// SPDX-License-Identifier: GPL-3.0-or-later
// Two-panel 1200x600 frames from 256² slices: ms per frame split into CPU colour mapping and
// scene update, render (vtkRenderWindow::Render), read-back (vtkWindowToImageFilter) and PNG
// encode. Prints averages over kFrames frames after kWarmUpFrames. Then the same split for the
// 3D particle view: 32³ = 32768 particles in an 800x800 frame.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <utility>
#include <vector>

#include "render/render.hpp"
#include "render/view3d.hpp"

namespace {

using sphles::analysis::SliceField;
using sphles::analysis::SliceProduct;
using sphles::render::ColourMapping;
using sphles::render::FrameLabels;
using sphles::render::FrameTimings;
using sphles::render::ParticleCloud;
using sphles::render::ParticleRenderer;
using sphles::render::Renderer;

constexpr int kSide = 256;
constexpr int kWarmUpFrames = 2;
constexpr int kFrames = 20;
constexpr double kTwoPi = 6.283185307179586;

SliceProduct synthetic_slice(SliceField field, double phase) {
  SliceProduct slice;
  slice.field = field;
  slice.units = field == SliceField::VorticitySquared ? "1/s^2" : "Pa";
  slice.width = slice.height = kSide;
  slice.spacing = kTwoPi / kSide;
  slice.values.resize(static_cast<std::size_t>(kSide) * kSide);
  for (int iv = 0; iv < kSide; ++iv) {
    for (int iu = 0; iu < kSide; ++iu) {
      const double x = iu * slice.spacing, y = iv * slice.spacing;
      const double s = std::sin(3 * x + phase) * std::cos(5 * y) + 0.3 * std::sin(17 * x * y);
      slice.values[iu + static_cast<std::size_t>(kSide) * iv] = std::exp(4.0 * s);  // > 0
    }
  }
  return slice;
}

struct Totals {
  FrameTimings sum;
  double wall_ms = 0.0;
  std::size_t bytes = 0;
};

/// Adds one frame to `totals`: the wall time of `render_frame` (which returns the PNG bytes), the
/// renderer's split of it and the size of the PNG.
template <class R, class RenderFrame>
void add_frame(Totals& totals, const R& renderer, RenderFrame render_frame) {
  const auto start = std::chrono::steady_clock::now();
  const auto png = render_frame();
  totals.wall_ms +=
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  const FrameTimings& t = renderer.last_timings();
  totals.sum.prepare_ms += t.prepare_ms;
  totals.sum.render_ms += t.render_ms;
  totals.sum.read_back_ms += t.read_back_ms;
  totals.sum.encode_ms += t.encode_ms;
  totals.bytes += png.size();
}

Totals run(Renderer& renderer, const ColourMapping& mapping, int frames) {
  Totals totals;
  for (int frame = 0; frame < frames; ++frame) {
    const double phase = 0.1 * frame;
    const std::vector<SliceProduct> slices{
        synthetic_slice(SliceField::VorticitySquared, phase),
        synthetic_slice(SliceField::SubfilterStressNorm, -phase)};
    const FrameLabels labels{"bench", 0.01 * frame, static_cast<std::uint64_t>(100 * frame)};
    add_frame(totals, renderer,
              [&] { return renderer.render_png(slices, std::span(&mapping, 1), labels); });
  }
  return totals;
}

// A jittered 32³ lattice in a 2π box with a Taylor-Green-like vorticity magnitude per particle.
struct SyntheticCloud {
  std::vector<double> x, y, z, values;
  ParticleCloud cloud(double phase) {
    constexpr int kParticleSide = 32;
    const double spacing = kTwoPi / kParticleSide;
    x.clear();
    y.clear();
    z.clear();
    values.clear();
    for (int k = 0; k < kParticleSide; ++k) {
      for (int j = 0; j < kParticleSide; ++j) {
        for (int i = 0; i < kParticleSide; ++i) {
          const double jitter = 0.1 * std::sin(1.7 * i + 2.3 * j + 3.1 * k + phase);
          x.push_back((i + 0.5 + jitter) * spacing);
          y.push_back((j + 0.5 - jitter) * spacing);
          z.push_back((k + 0.5) * spacing);
          const double s = std::sin(x.back() + phase) * std::cos(y.back()) * std::cos(z.back());
          values.push_back(std::exp(3.0 * s));  // > 0
        }
      }
    }
    return {x, y, z, values, kTwoPi, "omega2", "1/s^2"};
  }
};

Totals run_particles(ParticleRenderer& renderer, const ColourMapping& mapping, int frames) {
  Totals totals;
  SyntheticCloud data;
  for (int frame = 0; frame < frames; ++frame) {
    const ParticleCloud cloud = data.cloud(0.1 * frame);
    const FrameLabels labels{"bench", 0.01 * frame, static_cast<std::uint64_t>(100 * frame)};
    add_frame(totals, renderer, [&] { return renderer.render_png(cloud, mapping, labels); });
  }
  return totals;
}

void print(const char* name, const Totals& totals, int frames) {
  std::printf(
      "%-31s prepare %6.2f  render %6.2f  read-back %6.2f  encode %6.2f  total %6.2f ms"
      "  (png %zu bytes)\n",
      name, totals.sum.prepare_ms / frames, totals.sum.render_ms / frames,
      totals.sum.read_back_ms / frames, totals.sum.encode_ms / frames, totals.wall_ms / frames,
      totals.bytes / static_cast<std::size_t>(frames));
}

}  // namespace

int main() {
  const auto start = std::chrono::steady_clock::now();
  Renderer renderer(1200, 600);
  ColourMapping mapping;
  mapping.log_scale = true;
  const Totals first = run(renderer, mapping, 1);
  std::printf(
      "context + first frame: %.1f ms (render %.1f ms)\n",
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
      first.sum.render_ms);
  run(renderer, mapping, kWarmUpFrames - 1);
  std::printf("two-panel 1200x600, 256^2 slices, log scale, mean of %d frames:\n", kFrames);
  print("default (libpng, level 1, none)", run(renderer, mapping, kFrames), kFrames);
  renderer.set_png_filter(std::nullopt);
  for (const int level : {Renderer::kDefaultCompressionLevel, 0, 3, 6}) {
    renderer.set_compression_level(level);
    char name[64];
    std::snprintf(name, sizeof name, "vtkPNGWriter level %d", level);
    print(name, run(renderer, mapping, kFrames), kFrames);
  }
  // libpng directly with a fixed row filter instead of vtkPNGWriter's adaptive choice.
  for (const auto& [name, filter] :
       {std::pair{"libpng level 1, filter none", sphles::render::PngFilter::None},
        std::pair{"libpng level 1, filter sub", sphles::render::PngFilter::Sub},
        std::pair{"libpng level 1, filter up", sphles::render::PngFilter::Up},
        std::pair{"libpng level 1, adaptive", sphles::render::PngFilter::Adaptive}}) {
    renderer.set_compression_level(Renderer::kDefaultCompressionLevel);
    renderer.set_png_filter(filter);
    print(name, run(renderer, mapping, kFrames), kFrames);
  }
  renderer.set_png_filter(Renderer::kDefaultPngFilter);
  // A fixed range keeps the colour bar unchanged between frames (no bar rebuild).
  ColourMapping fixed = mapping;
  fixed.min = 1e-2;
  fixed.max = 1e2;
  renderer.set_compression_level(Renderer::kDefaultCompressionLevel);
  print("default, fixed colour range", run(renderer, fixed, kFrames), kFrames);
  // SPHLES_BENCH_RENDER_PNG=path writes one frame for inspection.
  if (const char* path = std::getenv("SPHLES_BENCH_RENDER_PNG")) {
    renderer.set_compression_level(Renderer::kDefaultCompressionLevel);
    const std::vector<SliceProduct> slices{synthetic_slice(SliceField::VorticitySquared, 0.0),
                                           synthetic_slice(SliceField::SubfilterStressNorm, 0.0)};
    sphles::render::write_png_file(
        path, renderer.render_png(slices, std::span(&mapping, 1), FrameLabels{"bench", 1.5, 150}));
  }

  // 3D particle view.
  const auto particles_start = std::chrono::steady_clock::now();
  ParticleRenderer particles(800, 800);
  const Totals first_view = run_particles(particles, mapping, 1);
  std::printf(
      "3D view: context + first frame: %.1f ms (render %.1f ms)\n",
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - particles_start)
          .count(),
      first_view.sum.render_ms);
  run_particles(particles, mapping, kWarmUpFrames - 1);
  std::printf("3D view 800x800, 32^3 = 32768 particles, log scale, mean of %d frames:\n", kFrames);
  print("default (libpng, level 1, none)", run_particles(particles, mapping, kFrames), kFrames);
  print("default, fixed colour range", run_particles(particles, fixed, kFrames), kFrames);
  // SPHLES_BENCH_VIEW3D_PNG=path writes one 3D view for inspection.
  if (const char* path = std::getenv("SPHLES_BENCH_VIEW3D_PNG")) {
    SyntheticCloud data;
    sphles::render::write_png_file(
        path, particles.render_png(data.cloud(0.0), mapping, FrameLabels{"bench", 1.5, 150}));
  }
  return 0;
}
