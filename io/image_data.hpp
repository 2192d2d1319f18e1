// SPDX-License-Identifier: GPL-3.0-or-later
// Gridded fields as VTK XML image data (.vti) and time series of them as ParaView collections
// (.pvd), so ParaView, VisIt and VTK's own readers open slices and grids directly
// (docs/analysis.md, "Slices").
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

namespace sphles::io {

/// One point array of an image: `components` values per point, points in VTK order (x fastest,
/// then y, then z).
struct ImageArray {
  std::string name;
  std::string units;
  int components = 1;
  std::vector<double> values;
};

struct ImageData {
  std::array<int, 3> dimensions{1, 1, 1};  // points per axis
  std::array<double, 3> origin{0.0, 0.0, 0.0};
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  double time = 0.0;  // [s], stored as field data "TimeValue" (ParaView's time key)
  std::vector<ImageArray> arrays;
};

/// Writes `image` to `path` atomically (a temporary in the same directory, then renamed) with
/// vtkXMLImageDataWriter: appended raw float64, zlib-compressed. Field data: TimeValue, units
/// (one "NAME [UNITS]" entry per point array), schema, code_version. Throws std::runtime_error
/// naming the file and the reason (shape mismatch, write failure).
void write_vti(const std::filesystem::path& path, const ImageData& image,
               const std::string& code_version);

struct CollectionEntry {
  double time = 0.0;
  std::string file;  // relative to the .pvd file
};

/// Writes (atomically) a ParaView data collection (.pvd) listing the files with their times.
void write_pvd(const std::filesystem::path& path, const std::vector<CollectionEntry>& entries);

}  // namespace sphles::io
