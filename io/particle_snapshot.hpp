// Particle snapshots for tools outside sphles: one HDF5 file per snapshot plus an XDMF file
// describing the time series, so ParaView and VisIt open the series directly
// (docs/checkpoints.md, "Snapshots").
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "sim/particles.hpp"

namespace sphles::io {

/// An extra per-particle scalar (τ_SFS norm, ν_t, ω², ...).
struct ParticleField {
  std::string name;
  std::string units;
  std::vector<double> values;
};

/// Writes `path` atomically with datasets position (N x 3, z = 0 in 2D), velocity (N x 3),
/// mass, density, pressure and the extra fields (N), each with a "units" attribute, and root
/// attributes time, step, dimension, scene (JSON).
void write_particle_snapshot(const std::filesystem::path& path,
                             const sim::ParticleArrays& particles, double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const std::string& scene_json);

struct SnapshotEntry {
  std::string file;  // relative to the XDMF file
  double time = 0.0;
  std::size_t count = 0;
  std::vector<std::string> scalars;  // scalar datasets besides mass, density, pressure
};

/// Writes (atomically) an XDMF 3 temporal collection of polyvertex grids over the entries.
void write_xdmf_series(const std::filesystem::path& path,
                       const std::vector<SnapshotEntry>& entries);

}  // namespace sphles::io
