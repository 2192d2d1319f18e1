// SPDX-License-Identifier: GPL-3.0-or-later
// Headless slice rendering: colours at known pixels, log scale, determinism, no X display.
#include <gtest/gtest.h>
#include <unistd.h>
#include <vtkImageData.h>
#include <vtkPNGReader.h>
#include <vtkSmartPointer.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <thread>

#include "render/lookup_table.hpp"
#include "render/render.hpp"
#include "render/view3d.hpp"

namespace sphles::render {
namespace {

using analysis::SliceField;
using analysis::SliceProduct;

// A decoded PNG, rows bottom-up (VTK convention, as image_rect).
struct Decoded {
  int width = 0, height = 0, components = 0;
  std::vector<unsigned char> pixels;
  Rgb at(int x, int y) const {
    const std::size_t offset =
        (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + x) * components;
    return {pixels[offset], pixels[offset + 1], pixels[offset + 2]};
  }
};

Decoded decode(const std::vector<unsigned char>& png) {
  auto reader = vtkSmartPointer<vtkPNGReader>::New();
  reader->SetMemoryBuffer(png.data());
  reader->SetMemoryBufferLength(static_cast<vtkIdType>(png.size()));
  reader->Update();
  vtkImageData* image = reader->GetOutput();
  Decoded decoded;
  int* dimensions = image->GetDimensions();
  decoded.width = dimensions[0];
  decoded.height = dimensions[1];
  decoded.components = image->GetNumberOfScalarComponents();
  const auto* data = static_cast<const unsigned char*>(image->GetScalarPointer());
  decoded.pixels.assign(
      data, data + static_cast<std::size_t>(decoded.width) * decoded.height * decoded.components);
  return decoded;
}

int max_channel_difference(const Rgb& a, const Rgb& b) {
  int difference = 0;
  for (int c = 0; c < 3; ++c) difference = std::max(difference, std::abs(a[c] - b[c]));
  return difference;
}

// The colour bar, right of `rect` up to the image's right edge, shows both end colours of the
// map.
void expect_colour_bar_ends(const Decoded& image, const ImageRect& rect) {
  const Rgb low = viridis_table().front(), high = viridis_table().back();
  bool found_low = false, found_high = false;
  for (int y = rect.y; y < rect.y + rect.height; ++y) {
    for (int x = rect.x + rect.width + 1; x < image.width; ++x) {
      found_low = found_low || max_channel_difference(image.at(x, y), low) <= 1;
      found_high = found_high || max_channel_difference(image.at(x, y), high) <= 1;
    }
  }
  EXPECT_TRUE(found_low);
  EXPECT_TRUE(found_high);
}

// Index of the table colour nearest to rgb.
int nearest_table_index(const Rgb& rgb) {
  const auto& table = viridis_table();
  int best = 0;
  for (int i = 1; i < kColourCount; ++i) {
    if (max_channel_difference(table[i], rgb) < max_channel_difference(table[best], rgb)) best = i;
  }
  return best;
}

SliceProduct ramp_slice(int width, int height) {
  SliceProduct slice;
  slice.field = SliceField::VorticitySquared;
  slice.units = "1/s^2";
  slice.normal_axis = 0;
  slice.axis_u = 1;
  slice.axis_v = 2;
  slice.position = 3.14;
  slice.width = width;
  slice.height = height;
  slice.spacing = 0.1;
  slice.values.resize(static_cast<std::size_t>(width) * height);
  for (int iv = 0; iv < height; ++iv) {
    for (int iu = 0; iu < width; ++iu) {
      slice.values[iu + static_cast<std::size_t>(width) * iv] =
          static_cast<double>(iu) / (width - 1);
    }
  }
  return slice;
}

const FrameLabels kLabels{"ramp", 1.25, 42};

TEST(Render, RampHasLookupTableColoursAtKnownPixels) {
  const SliceProduct slice = ramp_slice(64, 32);
  ColourMapping mapping;
  mapping.min = 0.0;
  mapping.max = 1.0;
  constexpr int kWidth = 640, kHeight = 400;
  const Decoded image = decode(render_slice_png(slice, mapping, kLabels, kWidth, kHeight));
  ASSERT_EQ(image.width, kWidth);
  ASSERT_EQ(image.height, kHeight);
  ASSERT_GE(image.components, 3);

  const ImageRect rect = image_rect(kWidth, kHeight, slice);
  const std::array<double, 2> range{0.0, 1.0};
  const auto lookup_table = make_lookup_table(range, false);
  const int py = rect.height / 2;
  for (const double fraction : {0.1, 0.3, 0.5, 0.7, 0.9}) {
    const int px = static_cast<int>(fraction * rect.width);
    const int iu = static_cast<int>((px + 0.5) * slice.width / rect.width);
    const double value = static_cast<double>(iu) / (slice.width - 1);
    const int expected_index = colour_index(value, range, false);
    EXPECT_EQ(lookup_table->GetIndex(value), expected_index) << "value " << value;
    const Rgb expected = viridis_table()[expected_index];
    const Rgb measured = image.at(rect.x + px, rect.y + py);
    EXPECT_LE(std::abs(nearest_table_index(measured) - expected_index), 1)
        << "value " << value << " at pixel " << rect.x + px;
    EXPECT_LE(max_channel_difference(measured, expected), 2) << "value " << value;
    std::printf("value %.4f: index %d, expected (%d,%d,%d), pixel (%d,%d,%d)\n", value,
                expected_index, expected[0], expected[1], expected[2], measured[0], measured[1],
                measured[2]);
  }

  // The colour bar (right of the image) shows both end colours of the map.
  expect_colour_bar_ends(image, rect);
}

TEST(Render, LogScaleMapsDecadesToEqualSteps) {
  SliceProduct slice = ramp_slice(64, 16);
  const double band_values[4] = {1.0, 10.0, 100.0, 1000.0};
  for (int iv = 0; iv < slice.height; ++iv) {
    for (int iu = 0; iu < slice.width; ++iu) {
      slice.values[iu + static_cast<std::size_t>(slice.width) * iv] = band_values[iu / 16];
    }
  }
  ColourMapping mapping;
  mapping.log_scale = true;
  mapping.lower_percentile = 0.0;
  mapping.upper_percentile = 1.0;
  const std::array<double, 2> range = colour_range(slice.values, mapping);
  EXPECT_NEAR(range[0], 1.0, 1e-12);
  EXPECT_NEAR(range[1], 1000.0, 1e-9);

  constexpr int kWidth = 600, kHeight = 300;
  const Decoded image = decode(render_slice_png(slice, mapping, kLabels, kWidth, kHeight));
  ASSERT_EQ(image.width, kWidth);
  ASSERT_EQ(image.height, kHeight);
  const ImageRect rect = image_rect(kWidth, kHeight, slice);
  const auto lookup_table = make_lookup_table(range, true);
  int indices[4];
  for (int band = 0; band < 4; ++band) {
    const int px = static_cast<int>((band + 0.5) / 4.0 * rect.width);
    indices[band] = nearest_table_index(image.at(rect.x + px, rect.y + rect.height / 2));
    const int expected = colour_index(band_values[band], range, true);
    EXPECT_LE(std::abs(indices[band] - expected), 1) << "band " << band;
    // Interior values agree with VTK's own log-scale lookup.
    const double interior = std::pow(10.0, band + 0.5);
    EXPECT_EQ(lookup_table->GetIndex(interior), colour_index(interior, range, true));
  }
  std::printf("band indices %d %d %d %d\n", indices[0], indices[1], indices[2], indices[3]);
  const int step = indices[1] - indices[0];
  EXPECT_NEAR(step, (kColourCount - 1) / 3.0, 1.0);
  EXPECT_LE(std::abs((indices[2] - indices[1]) - step), 1);
  EXPECT_LE(std::abs((indices[3] - indices[2]) - step), 1);
}

TEST(Render, SameInputGivesIdenticalBytes) {
  SliceProduct slice = ramp_slice(128, 128);
  for (std::size_t i = 0; i < slice.values.size(); ++i) {
    slice.values[i] = 1.0 + std::sin(0.05 * static_cast<double>(i)) * std::cos(0.001 * i);
  }
  const ColourMapping mapping;
  const auto first = render_slice_png(slice, mapping, kLabels, 500, 400);
  const auto second = render_slice_png(slice, mapping, kLabels, 500, 400);
  EXPECT_EQ(first, second);
  std::printf("png %zu bytes\n", first.size());
  Renderer fresh(500, 400);  // a different context renders the same bytes too
  EXPECT_EQ(fresh.render_png(std::span(&slice, 1), std::span(&mapping, 1), kLabels), first);
}

TEST(Render, ConcurrentThreadsRenderTheSameBytes) {
  // One renderer per thread (the thread_local ones of render_slice_png), at the same time.
  const SliceProduct slice = ramp_slice(96, 64);
  const ColourMapping mapping;
  const auto reference = render_slice_png(slice, mapping, kLabels, 400, 300);
  constexpr int kThreads = 3, kFramesPerThread = 4;
  std::vector<std::vector<unsigned char>> results(kThreads * kFramesPerThread);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int f = 0; f < kFramesPerThread; ++f) {
        results[t * kFramesPerThread + f] = render_slice_png(slice, mapping, kLabels, 400, 300);
      }
    });
  }
  for (auto& thread : threads) thread.join();
  for (const auto& result : results) EXPECT_EQ(result, reference);
}

TEST(Render, EncodersGiveIdenticalPixels) {
  SliceProduct slice = ramp_slice(100, 80);
  for (std::size_t i = 0; i < slice.values.size(); ++i) {
    slice.values[i] = std::exp(std::sin(0.37 * static_cast<double>(i)));
  }
  ColourMapping mapping;
  mapping.log_scale = true;
  Renderer renderer(480, 360);
  const auto render = [&] {
    return renderer.render_png(std::span(&slice, 1), std::span(&mapping, 1), kLabels);
  };
  const Decoded reference = decode(render());  // default: libpng, no row filter
  renderer.set_png_filter(std::nullopt);       // vtkPNGWriter
  const Decoded vtk_writer = decode(render());
  renderer.set_png_filter(PngFilter::Paeth);
  renderer.set_compression_level(9);
  const Decoded paeth = decode(render());
  EXPECT_EQ(reference.width, 480);
  EXPECT_EQ(reference.pixels, vtk_writer.pixels);
  EXPECT_EQ(reference.pixels, paeth.pixels);
  // Not a blank frame: the image area holds many distinct colours.
  const ImageRect rect = image_rect(480, 360, slice);
  std::set<int> indices;
  for (int x = rect.x; x < rect.x + rect.width; ++x) {
    indices.insert(nearest_table_index(reference.at(x, rect.y + rect.height / 2)));
  }
  EXPECT_GT(indices.size(), 20u);
}

TEST(Render, WorksWithoutDisplay) {
  unsetenv("DISPLAY");
  ASSERT_EQ(std::getenv("DISPLAY"), nullptr);
  const SliceProduct slice = ramp_slice(32, 32);
  const auto png = render_slice_png(slice, ColourMapping{}, kLabels, 320, 240);
  ASSERT_GT(png.size(), 8u);
  const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  EXPECT_TRUE(std::equal(std::begin(signature), std::end(signature), png.begin()));
  const Decoded image = decode(png);
  EXPECT_EQ(image.width, 320);
  EXPECT_EQ(image.height, 240);
}

TEST(Render, TwoPanelFrameShowsBothSlices) {
  SliceProduct left = ramp_slice(64, 64);
  SliceProduct right = ramp_slice(64, 64);
  right.field = SliceField::SubfilterStressNorm;
  right.units = "Pa";
  for (double& v : right.values) v = 1.0 - v;  // reversed ramp
  ColourMapping mapping;
  mapping.min = 0.0;
  mapping.max = 1.0;
  const std::vector<SliceProduct> slices{left, right};
  const Decoded image = decode(render_slices_png(slices, mapping, kLabels));
  ASSERT_EQ(image.width, 1200);
  ASSERT_EQ(image.height, 600);
  const ImageRect rect = image_rect(600, 600, left);
  const int y = rect.y + rect.height / 2;
  // Leftmost image column: value 0 on the left panel, value 1 on the right panel.
  EXPECT_LE(max_channel_difference(image.at(rect.x + 1, y), viridis_table().front()), 2);
  EXPECT_LE(max_channel_difference(image.at(600 + rect.x + 1, y), viridis_table().back()), 2);
}

TEST(ColourRange, PercentilesIgnoreOutlier) {
  std::vector<double> values(10000);
  for (std::size_t i = 0; i < values.size(); ++i) {
    values[i] = static_cast<double>(i) / (values.size() - 1);
  }
  values[1234] = 1e9;  // one huge outlier
  values[4321] = std::numeric_limits<double>::quiet_NaN();
  const std::array<double, 2> range = colour_range(values, ColourMapping{});
  EXPECT_NEAR(range[1], 0.99, 0.002);
  EXPECT_NEAR(range[0], 0.01, 0.002);
  EXPECT_LT(range[1], 1.0);
  std::printf("auto range [%.6f, %.6f]\n", range[0], range[1]);
}

TEST(ColourRange, FixedBoundsAndDegenerateData) {
  const std::vector<double> constant(100, 5.0);
  ColourMapping mapping;
  auto range = colour_range(constant, mapping);
  EXPECT_LT(range[0], 5.0);
  EXPECT_GT(range[1], 5.0);
  mapping.min = -2.0;
  mapping.max = 3.0;
  range = colour_range(constant, mapping);
  EXPECT_EQ(range[0], -2.0);
  EXPECT_EQ(range[1], 3.0);
  mapping.log_scale = true;
  EXPECT_THROW(colour_range(constant, mapping), std::invalid_argument);
  EXPECT_EQ(colour_index(std::numeric_limits<double>::quiet_NaN(), {0.0, 1.0}, false), -1);
  EXPECT_EQ(colour_index(-1.0, {1.0, 10.0}, true), 0);
  EXPECT_EQ(colour_index(2.0, {0.0, 1.0}, false), kColourCount - 1);
}

TEST(ColourRange, IndicesMatchVtkLookupTable) {
  // 1000 values spread over the range [1e-2, 1e2]: the CPU mapping and the vtkLookupTable the
  // scalar bar draws agree, in linear and in log scale.
  std::vector<double> values;
  for (int i = 0; i < 1000; ++i) values.push_back(std::pow(10.0, -1.999 + 0.003997 * i));
  std::vector<int> indices(values.size());
  const std::array<double, 2> range{1e-2, 1e2};
  for (const bool log_scale : {false, true}) {
    colour_indices(values, range, log_scale, indices);
    const auto lookup_table = make_lookup_table(range, log_scale);
    int mismatches = 0;
    for (std::size_t i = 0; i < values.size(); ++i) {
      mismatches += indices[i] != lookup_table->GetIndex(values[i]);
      EXPECT_EQ(indices[i], colour_index(values[i], range, log_scale));
    }
    EXPECT_EQ(mismatches, 0) << "log " << log_scale;
  }
  EXPECT_EQ(indices.front(), 0);
  EXPECT_EQ(indices.back(), kColourCount - 1);
}

TEST(Viridis, EndsMatchPublishedDefinition) {
  const auto& table = viridis_table();
  // #440154 and #fde725: the first and last entries of matplotlib's viridis.
  EXPECT_EQ(table.front(), (Rgb{0x44, 0x01, 0x54}));
  EXPECT_EQ(table.back(), (Rgb{0xfd, 0xe7, 0x25}));
  // #21918c: entry 128.
  EXPECT_LE(max_channel_difference(table[128], Rgb{0x21, 0x91, 0x8c}), 1);
}

TEST(WritePngFile, WritesAtomicallyWithoutLeftovers) {
  const auto directory =
      std::filesystem::temp_directory_path() / ("sphles_render_" + std::to_string(::getpid()));
  std::filesystem::create_directories(directory);
  const auto path = directory / "frame.png";
  const std::vector<unsigned char> bytes{1, 2, 3, 4, 5};
  write_png_file(path, bytes);
  write_png_file(path, bytes);  // replaces
  std::ifstream in(path, std::ios::binary);
  const std::vector<unsigned char> read((std::istreambuf_iterator<char>(in)), {});
  EXPECT_EQ(read, bytes);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(directory), {}), 1);
  EXPECT_THROW(write_png_file(directory / "missing" / "frame.png", bytes), std::system_error);
  std::filesystem::remove_all(directory);
}

// 3D particle view.

// Particles on an n^3 lattice filling the cube [lo, hi)^3 (in units of the box length).
struct ParticleBlock {
  std::vector<double> x, y, z, values;
  ParticleBlock(int n, double lo, double hi, double length, double value) {
    const double spacing = (hi - lo) / n * length;
    for (int k = 0; k < n; ++k) {
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          x.push_back(lo * length + (i + 0.5) * spacing);
          y.push_back(lo * length + (j + 0.5) * spacing);
          z.push_back(lo * length + (k + 0.5) * spacing);
          values.push_back(value);
        }
      }
    }
  }
  ParticleCloud cloud(double length) const { return {x, y, z, values, length, "omega2", "1/s^2"}; }
};

constexpr double kBox = 6.283185307179586;

TEST(View3d, CentreOfBlockHasTheSlicesColourForItsValue) {
  ColourMapping mapping;
  mapping.min = 0.0;
  mapping.max = 1.0;
  const double value = 0.3;
  const ParticleBlock block(24, 0.35, 0.65, kBox, value);
  constexpr int kWidth = 640, kHeight = 560;
  const Decoded image =
      decode(render_particles_png(block.cloud(kBox), mapping, kLabels, kWidth, kHeight));
  ASSERT_EQ(image.width, kWidth);
  ASSERT_EQ(image.height, kHeight);
  ASSERT_GE(image.components, 3);

  const ImageRect rect = particle_view_rect(kWidth, kHeight);
  const int expected_index = colour_index(value, {0.0, 1.0}, false);
  const Rgb expected = viridis_table()[expected_index];
  const Rgb centre = image.at(rect.x + rect.width / 2, rect.y + rect.height / 2);
  std::printf("centre pixel (%d,%d,%d), expected index %d (%d,%d,%d)\n", centre[0], centre[1],
              centre[2], expected_index, expected[0], expected[1], expected[2]);
  EXPECT_LE(std::abs(nearest_table_index(centre) - expected_index), 1);
  EXPECT_LE(max_channel_difference(centre, expected), 2);

  // The same value in a slice with the same mapping has the same colour.
  SliceProduct uniform = ramp_slice(16, 16);
  std::fill(uniform.values.begin(), uniform.values.end(), value);
  const Decoded slice_image = decode(render_slice_png(uniform, mapping, kLabels, 400, 300));
  const ImageRect slice_rect = image_rect(400, 300, uniform);
  EXPECT_EQ(
      slice_image.at(slice_rect.x + slice_rect.width / 2, slice_rect.y + slice_rect.height / 2),
      centre);

  // Outside the block's projection (a corner of the view rectangle) the background is white.
  EXPECT_EQ(image.at(rect.x + 3, rect.y + 3), (Rgb{255, 255, 255}));

  // The colour bar, right of the view rectangle, shows both end colours of the map.
  expect_colour_bar_ends(image, rect);
}

TEST(View3d, LogScaleAndNanUseTheSlicesMapping) {
  ColourMapping mapping;
  mapping.log_scale = true;
  mapping.min = 1.0;
  mapping.max = 1000.0;
  constexpr int kSize = 500;
  const ImageRect rect = particle_view_rect(kSize, kSize);
  const int cx = rect.x + rect.width / 2, cy = rect.y + rect.height / 2;

  const ParticleBlock block(16, 0.4, 0.6, 1.0, 10.0);  // one decade of three: index 85
  const Rgb decade =
      decode(render_particles_png(block.cloud(1.0), mapping, kLabels, kSize, kSize)).at(cx, cy);
  const int expected_index = colour_index(10.0, {1.0, 1000.0}, true);
  EXPECT_NEAR(expected_index, kColourCount / 3, 1);
  EXPECT_LE(std::abs(nearest_table_index(decade) - expected_index), 1);
  EXPECT_LE(max_channel_difference(decade, viridis_table()[expected_index]), 2);

  ParticleBlock nan_block = block;
  std::fill(nan_block.values.begin(), nan_block.values.end(),
            std::numeric_limits<double>::quiet_NaN());
  const Rgb nan =
      decode(render_particles_png(nan_block.cloud(1.0), mapping, kLabels, kSize, kSize)).at(cx, cy);
  EXPECT_LE(max_channel_difference(nan, Rgb{128, 128, 128}), 1);
}

TEST(View3d, TwoDimensionalCloudIsDrawnInThePlane) {
  // A 100 x 100 particle lattice with the value x / L, no z: seen from above, colours increase
  // from left to right through the centre.
  constexpr int kSide = 100;
  std::vector<double> x, y, values;
  for (int j = 0; j < kSide; ++j) {
    for (int i = 0; i < kSide; ++i) {
      x.push_back((i + 0.5) / kSide);
      y.push_back((j + 0.5) / kSide);
      values.push_back(x.back());
    }
  }
  ColourMapping mapping;
  mapping.min = 0.0;
  mapping.max = 1.0;
  const ParticleCloud cloud{x, y, {}, values, 1.0, "x", ""};
  constexpr int kSize = 600;
  const Decoded image = decode(render_particles_png(cloud, mapping, kLabels, kSize, kSize));
  ASSERT_EQ(image.width, kSize);
  const ImageRect rect = particle_view_rect(kSize, kSize);
  const int cx = rect.x + rect.width / 2, cy = rect.y + rect.height / 2;
  const int centre = nearest_table_index(image.at(cx, cy));
  EXPECT_LE(std::abs(centre - colour_index(0.5, {0.0, 1.0}, false)), 3);
  // Particles are 2-4 px squares on a ~4 px lattice: find the nearest coloured pixel.
  const auto index_near = [&](int px) {
    for (int d = 0; d < 4; ++d) {
      for (const int x_px : {px + d, px - d}) {
        const Rgb rgb = image.at(x_px, cy);
        if (rgb != Rgb{255, 255, 255}) return nearest_table_index(rgb);
      }
    }
    return -1;
  };
  const int left = index_near(cx - 100), right = index_near(cx + 100);
  std::printf("2D: indices %d | %d | %d\n", left, centre, right);
  EXPECT_GE(left, 0);
  EXPECT_LT(left, centre);
  EXPECT_GT(right, centre);
}

TEST(View3d, SameInputGivesIdenticalBytes) {
  std::vector<double> x, y, z, values;
  for (int i = 0; i < 4096; ++i) {
    x.push_back(std::fmod(0.6180339887 * i, 1.0) * kBox);
    y.push_back(std::fmod(0.7548776662 * i, 1.0) * kBox);
    z.push_back(std::fmod(0.5698402910 * i, 1.0) * kBox);
    values.push_back(std::exp(std::sin(0.37 * i)));
  }
  const ParticleCloud cloud{x, y, z, values, kBox, "omega2", "1/s^2"};
  ColourMapping mapping;
  mapping.log_scale = true;
  const auto first = render_particles_png(cloud, mapping, kLabels, 480, 400);
  const auto second = render_particles_png(cloud, mapping, kLabels, 480, 400);
  EXPECT_EQ(first, second);
  std::printf("png %zu bytes\n", first.size());
  ParticleRenderer fresh(480, 400);  // another context renders the same bytes
  EXPECT_EQ(fresh.render_png(cloud, mapping, kLabels), first);
  // Not a blank frame: the points show many colours.
  const Decoded image = decode(first);
  std::set<int> indices;
  for (int y_px = 0; y_px < image.height; ++y_px) {
    for (int x_px = 0; x_px < image.width / 2; ++x_px) {
      indices.insert(nearest_table_index(image.at(x_px, y_px)));
    }
  }
  EXPECT_GT(indices.size(), 50u);
}

TEST(View3d, ConcurrentWithSlicesRendersTheSameBytes) {
  // 3D views and slices from several threads at once (thread_local renderers, one VTK lock).
  const ParticleBlock block(12, 0.2, 0.8, kBox, 0.0);
  ParticleBlock ramp = block;
  for (std::size_t i = 0; i < ramp.values.size(); ++i) ramp.values[i] = ramp.x[i] + ramp.z[i];
  const ParticleCloud cloud = ramp.cloud(kBox);
  const SliceProduct slice = ramp_slice(64, 48);
  const ColourMapping mapping;
  const auto view_reference = render_particles_png(cloud, mapping, kLabels, 360, 300);
  const auto slice_reference = render_slice_png(slice, mapping, kLabels, 400, 300);
  constexpr int kThreads = 3, kFramesPerThread = 3;
  std::vector<std::vector<unsigned char>> views(kThreads * kFramesPerThread),
      slices(kThreads * kFramesPerThread);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int f = 0; f < kFramesPerThread; ++f) {
        views[t * kFramesPerThread + f] = render_particles_png(cloud, mapping, kLabels, 360, 300);
        slices[t * kFramesPerThread + f] = render_slice_png(slice, mapping, kLabels, 400, 300);
      }
    });
  }
  for (auto& thread : threads) thread.join();
  for (const auto& view : views) EXPECT_EQ(view, view_reference);
  for (const auto& result : slices) EXPECT_EQ(result, slice_reference);
}

TEST(View3d, MismatchedSpansOrBadBoxThrow) {
  const std::vector<double> three{0.1, 0.2, 0.3}, two{0.1, 0.2};
  const ColourMapping mapping;
  const auto render = [&](const ParticleCloud& cloud) {
    return render_particles_png(cloud, mapping, kLabels, 200, 200);
  };
  EXPECT_THROW(render({two, three, three, three, 1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, two, three, three, 1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, three, two, three, 1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, three, three, two, 1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, three, {}, two, 1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, three, three, three, 0.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(render({three, three, three, three, -1.0, "f", ""}), std::invalid_argument);
  EXPECT_THROW(
      render({three, three, three, three, std::numeric_limits<double>::quiet_NaN(), "f", ""}),
      std::invalid_argument);
  EXPECT_NO_THROW(render({three, three, three, three, 1.0, "f", ""}));
  EXPECT_NO_THROW(render({three, three, {}, three, 1.0, "f", ""}));
  EXPECT_NO_THROW(render({{}, {}, {}, {}, 1.0, "f", ""}));  // empty box
}

TEST(View3d, WorksWithoutDisplayAndDrawsTheBoxOutline) {
  unsetenv("DISPLAY");
  ASSERT_EQ(std::getenv("DISPLAY"), nullptr);
  const ParticleBlock block(8, 0.45, 0.55, 2.0, 0.5);
  const auto png = render_particles_png(block.cloud(2.0), ColourMapping{}, kLabels, 320, 240);
  ASSERT_GT(png.size(), 8u);
  const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  EXPECT_TRUE(std::equal(std::begin(signature), std::end(signature), png.begin()));
  const Decoded image = decode(png);
  EXPECT_EQ(image.width, 320);
  EXPECT_EQ(image.height, 240);
  // Dark grey outline pixels (0.3 of full scale) inside the view rectangle.
  const ImageRect rect = particle_view_rect(320, 240);
  int outline = 0;
  for (int y = rect.y; y < rect.y + rect.height; ++y) {
    for (int x = rect.x; x < rect.x + rect.width; ++x) {
      outline += max_channel_difference(image.at(x, y), Rgb{77, 77, 77}) <= 3;
    }
  }
  EXPECT_GT(outline, 100);
}

TEST(View3d, PointSizeFollowsProjectedDensity) {
  EXPECT_EQ(particle_point_size(32768, 800, 800, false), 3);
  EXPECT_EQ(particle_point_size(0, 800, 800, false), 4);
  EXPECT_EQ(particle_point_size(512, 800, 800, false), 4);
  EXPECT_EQ(particle_point_size(2097152, 800, 800, false), 2);  // 128^3
  EXPECT_EQ(particle_point_size(65536, 800, 800, true), 2);     // 256^2 in 2D
}

}  // namespace
}  // namespace sphles::render
