// SPDX-License-Identifier: GPL-3.0-or-later
// What a checkpoint holds (the solver state and its metadata) and how it is written; the
// functions that write and read it are in checkpoint.hpp and checkpoint_collective.hpp.
#pragma once

#include <string>

#include "sim/solver.hpp"

namespace sphles::io {

inline constexpr const char* kCheckpointSchema = "sphles-checkpoint";
inline constexpr int kCheckpointSchemaVersion = 1;

struct CheckpointMetadata {
  std::string scene_json;  // the complete run configuration (scene + analysis), JSON text
  std::string code_version;
  std::string packing;  // provenance of the initial positions, free text
};

struct Checkpoint {
  sim::SolverState state;
  CheckpointMetadata metadata;
};

struct CheckpointWriteOptions {
  int gzip_level = 0;  // 0 = no compression; 1-9 = gzip with byte shuffle
};

}  // namespace sphles::io
