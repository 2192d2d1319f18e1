// SPDX-License-Identifier: GPL-3.0-or-later
// Checkpoints of the spectral reference: the Fourier coefficients of the velocity, exactly, in
// HDF5 (docs/reference.md). Written atomically; a restart continues bitwise.
//   attributes: schema "sphles-reference-checkpoint-1", time, step, dimension, points_per_side,
//               scene (the run's scene JSON)
//   datasets:   modes_0 .. modes_{d-1}, shape (complex_size, 2): (Re, Im) in RealFft's layout
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "spectral/real_fft.hpp"

namespace sphles::spectral {

inline constexpr const char* kReferenceCheckpointSchema = "sphles-reference-checkpoint-1";

struct ReferenceState {
  double time = 0.0;
  std::uint64_t step = 0;
  int dimension = 3;
  int points_per_side = 0;
  std::string scene;  // JSON text
  std::array<std::vector<Complex>, 3> modes;
};

/// Writes `state` to `path` atomically; throws io::CheckpointError naming the file.
void write_reference_checkpoint(const std::filesystem::path& path, const ReferenceState& state);

/// Reads and validates a reference checkpoint; throws io::CheckpointError naming the file and
/// what is wrong (not a reference checkpoint, sizes that disagree, a non-finite value).
ReferenceState read_reference_checkpoint(const std::filesystem::path& path);

/// ref_{step:010}.h5
std::string reference_checkpoint_name(std::uint64_t step);

}  // namespace sphles::spectral
