// SPDX-License-Identifier: GPL-3.0-or-later
// The analysis' part of a run's resource estimate (control/resources.cpp): what analyse() holds
// at its peak, what an analysis frame carries, what the writer buffers and what a frame writes,
// from the scene and the analysis configuration alone; and the sizes of the stored types that
// both parts count in. Private to run control.
#pragma once

#include <cstddef>
#include <cstdint>

#include "analysis/config.hpp"
#include "sim/scene.hpp"

namespace sphles::control {

inline constexpr double kDouble = sizeof(double);
inline constexpr double kIndex = sizeof(std::uint32_t);  // NeighbourList::indices, grid maps
inline constexpr double kSize = sizeof(std::size_t);     // NeighbourList::offsets, cell starts
inline constexpr double kId = sizeof(std::uint64_t);

/// HDF5 per dataset and per file (object headers, chunk index, checksums), an upper bound
/// for the files sphles writes (measured against real checkpoints,
/// tests/control/test_resources.cpp).
inline constexpr double kHdf5BytesPerDataset = 4096.0;
inline constexpr double kHdf5BytesPerFile = 8192.0;

/// The analysis thread's memory and disk per frame (analysis/pipeline.cpp, products.cpp,
/// writer.cpp).
struct AnalysisModel {
  double work_bytes = 0.0;   // peak inside analyse(), frame included
  double frame_bytes = 0.0;  // the products a frame carries
  double writer_bytes = 0.0;
  double file_bytes = 0.0;  // written per frame
  double grid_points = 0.0;
};

/// The model of the analysis that `c` configures for the scene `s`.
AnalysisModel analysis_model(const sim::Scene& s, const analysis::AnalysisConfig& c);

}  // namespace sphles::control
