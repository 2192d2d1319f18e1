// SPDX-License-Identifier: GPL-3.0-or-later
// The iso-surface view (render/isosurface.hpp) of analytic fields: a sphere's drawn area grows
// as its radius squared, the level is the quantile asked for, and bad input is refused.
#include "render/isosurface.hpp"

#include <gtest/gtest.h>
#include <vtkImageData.h>
#include <vtkPNGReader.h>
#include <vtkSmartPointer.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace {

using sphles::analysis::Grid;
using sphles::render::IsoField;
using sphles::render::IsoLevel;

constexpr int kNodes = 32;
constexpr double kLength = 1.0;

/// f = |x - c|² on the grid: its iso-surface at R² is the sphere of radius R around the centre.
std::vector<double> distance_squared() {
  const Grid grid{3, kNodes, kLength};
  std::vector<double> values(grid.size());
  const double h = grid.spacing(), c = 0.5 * kLength;
  for (int k = 0; k < kNodes; ++k)
    for (int j = 0; j < kNodes; ++j)
      for (int i = 0; i < kNodes; ++i)
        values[grid.index(i, j, k)] =
            std::pow(i * h - c, 2) + std::pow(j * h - c, 2) + std::pow(k * h - c, 2);
  return values;
}

/// Pixels of the picture that are neither white, grey (outline, plane, text) nor in the colour
/// bar: the lit surface.
int surface_pixels(const std::vector<unsigned char>& png, int bar_from_x) {
  auto reader = vtkSmartPointer<vtkPNGReader>::New();
  reader->SetMemoryBuffer(png.data());
  reader->SetMemoryBufferLength(static_cast<vtkIdType>(png.size()));
  reader->Update();
  vtkImageData* image = reader->GetOutput();
  const int* size = image->GetDimensions();
  const int components = image->GetNumberOfScalarComponents();
  const auto* data = static_cast<const unsigned char*>(image->GetScalarPointer());
  int count = 0;
  for (int y = 0; y < size[1]; ++y)
    for (int x = 0; x < bar_from_x; ++x) {
      const unsigned char* p = data + (static_cast<std::size_t>(y) * size[0] + x) * components;
      const int spread = std::max({p[0], p[1], p[2]}) - std::min({p[0], p[1], p[2]});
      count += spread > 40 ? 1 : 0;  // coloured, not a shade of grey
    }
  return count;
}

TEST(IsoSurface, ASpheresDrawnAreaGrowsAsItsRadiusSquared) {
  const std::vector<double> values = distance_squared();
  IsoField field{Grid{3, kNodes, kLength}, values, "r\u00b2", "m\u00b2", 0, 0.5};
  sphles::render::ColourMapping linear;
  linear.log_scale = false;
  std::vector<int> areas;
  for (const double radius : {0.15, 0.3}) {
    IsoLevel level;
    level.value = radius * radius;
    const auto png =
        sphles::render::render_isosurface_png(field, linear, level, {"sphere", 1.0, 10}, 400, 400);
    areas.push_back(surface_pixels(png, 400 - 130));
  }
  ASSERT_GT(areas[0], 100) << "the small sphere is drawn";
  const double ratio = static_cast<double>(areas[1]) / areas[0];
  EXPECT_GT(ratio, 3.4) << areas[0] << " -> " << areas[1];  // (0.3 / 0.15)² = 4
  EXPECT_LT(ratio, 4.6) << areas[0] << " -> " << areas[1];
}

TEST(IsoSurface, TheLevelIsTheQuantileUnlessGivenAndNaNsAreLeftOut) {
  std::vector<double> values(100);
  std::iota(values.begin(), values.end(), 0.0);
  values.push_back(std::nan(""));
  EXPECT_DOUBLE_EQ(sphles::render::iso_value(values, {0.9, std::nullopt}), 89.0);
  EXPECT_DOUBLE_EQ(sphles::render::iso_value(values, {0.5, std::nullopt}), 49.0);
  EXPECT_DOUBLE_EQ(sphles::render::iso_value(values, {0.9, 7.5}), 7.5);
  const std::vector<double> none{std::nan("")};
  EXPECT_TRUE(std::isnan(sphles::render::iso_value(none, {})));
}

TEST(IsoSurface, A2DGridOrAWrongCountIsRefused) {
  const std::vector<double> flat(16 * 16, 1.0);
  const IsoField two_d{Grid{2, 16, kLength}, flat, "w", "", -1, 0.0};
  EXPECT_THROW(sphles::render::render_isosurface_png(two_d, {}, {}, {"x", 0.0, 0}, 200, 200),
               std::invalid_argument);
  const IsoField short_field{Grid{3, 16, kLength}, flat, "w", "", -1, 0.0};
  EXPECT_THROW(sphles::render::render_isosurface_png(short_field, {}, {}, {"x", 0.0, 0}, 200, 200),
               std::invalid_argument);
}

}  // namespace
