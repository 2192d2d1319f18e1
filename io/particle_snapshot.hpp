// SPDX-License-Identifier: GPL-3.0-or-later
// Particle snapshots for tools outside sphles: one HDF5 file per snapshot plus an XDMF file
// describing the time series, so ParaView and VisIt open the series directly, and h5py reads
// every dataset with its units (docs/checkpoints.md, "Snapshots").
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "io/particle_snapshot_data.hpp"
#include "sim/particles.hpp"

namespace sphles::io {

/// Writes `path` atomically. Rows are in id order (row k holds the particle with id k, so the
/// same row is the same particle in every snapshot of a run); the ids must be a permutation of
/// 0..N-1. Datasets: id (N, uint64), position (N x 3, z = 0 in 2D), velocity (N x 3), mass,
/// density, pressure and the extra fields (N), each with a "units" attribute. Root attributes:
/// schema, schema_version, code_version, time, time_units, step, dimension, num_particles, scene.
/// Throws CheckpointError naming the file and the reason.
void write_particle_snapshot(const std::filesystem::path& path,
                             const sim::ParticleArrays& particles, double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const SnapshotMetadata& metadata);

struct SnapshotEntry {
  std::string file;  // relative to the XDMF file
  double time = 0.0;
  std::size_t count = 0;
  std::vector<std::string> scalars;  // scalar datasets besides mass, density, pressure
};

/// Writes (atomically) an XDMF 3 temporal collection of polyvertex grids over the entries: one
/// vertex cell per particle (connectivity: the `id` dataset, 0..N-1 in row order), so ParaView's
/// Xdmf3 reader draws the points with its default representation.
void write_xdmf_series(const std::filesystem::path& path,
                       const std::vector<SnapshotEntry>& entries);

/// A human-readable listing of a particle snapshot (for `sphles inspect`): attributes, datasets
/// with shape and units, id order check, e_v. Throws CheckpointError naming the file.
std::string describe_particle_snapshot(const std::filesystem::path& path);

/// Everything a particle snapshot holds, read back (tests, tools): the root attributes as text
/// (numbers with 17 digits) and each dataset's values in row order (read as doubles: ids are
/// exact below 2^53; position and velocity row by row, 3 per row) with its units.
struct ParticleSnapshotContents {
  std::map<std::string, std::string> attributes;
  struct Dataset {
    std::vector<double> values;
    std::string units;
    bool operator==(const Dataset&) const = default;
  };
  std::map<std::string, Dataset> datasets;
};
/// Throws CheckpointError naming the file when it is not a particle snapshot or a dataset
/// cannot be read.
ParticleSnapshotContents read_particle_snapshot(const std::filesystem::path& path);

/// The value of the root attribute "schema" of an HDF5 file ("" when it has none). Throws
/// CheckpointError when the file is not HDF5.
std::string hdf5_schema(const std::filesystem::path& path);

}  // namespace sphles::io
