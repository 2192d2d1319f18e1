// SPDX-License-Identifier: GPL-3.0-or-later
// What a particle snapshot holds besides the particles (extra fields, metadata) and its schema;
// the functions that write and read it are in particle_snapshot.hpp and
// particle_snapshot_collective.hpp.
#pragma once

#include <string>
#include <vector>

namespace sphles::io {

inline constexpr const char* kParticleSnapshotSchema = "sphles-particles";
/// Version 2: rows in id order with an `id` dataset, schema and code version attributes.
inline constexpr int kParticleSnapshotSchemaVersion = 2;

/// An extra per-particle scalar (τ_SFS norm, ν_t, ω², ...).
struct ParticleField {
  std::string name;
  std::string units;
  std::vector<double> values;  // in the particle arrays' order
};

struct SnapshotMetadata {
  std::string scene_json = "{}";  // the run configuration, JSON text
  std::string code_version = "unknown";
  bool operator==(const SnapshotMetadata&) const = default;
};

}  // namespace sphles::io
