// SPDX-License-Identifier: GPL-3.0-or-later
// The layout of a particle snapshot file (docs/analysis.md): its attributes and datasets, written
// by one process (particle_snapshot.cpp) or every process of a distributed run through MPI-IO
// (particle_snapshot_collective.cpp). Internal to io.
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include "io/particle_snapshot_data.hpp"
#include "sim/particles.hpp"

namespace sphles::io::particle_snapshot_format {

/// Rows [first, first + count) of a snapshot's datasets of `total` rows, in id order, and the
/// data transfer properties they are written with (collective for MPI-IO).
struct Rows {
  int dimension = 3;
  hsize_t first = 0;
  hsize_t total = 0;
  hid_t transfer = H5P_DEFAULT;
  std::vector<std::uint64_t> id;
  std::vector<double> position, velocity;  // count x 3 (z = 0 in 2D)
  std::vector<double> mass, density, pressure;
  std::vector<ParticleField> extra;
  hsize_t count() const { return id.size(); }
};

/// The rows of the particles p[row_of[k]], k = 0, 1, ..., with ids first, first + 1, ...
Rows rows_of(const sim::ParticleArrays& p, const std::vector<std::size_t>& row_of,
             std::uint64_t first, std::uint64_t total, const std::vector<ParticleField>& extra);

/// The whole snapshot under `root`: its attributes, then the datasets with `rows`. Every
/// process of a collective write makes the same calls with the same attribute values.
void write_contents(hid_t root, const Rows& rows, double time, std::uint64_t step,
                    const SnapshotMetadata& metadata, const std::string& label);

/// Throws CheckpointError unless every extra field has a value per particle.
void check_fields(const std::vector<ParticleField>& extra, std::size_t n, const std::string& label);

}  // namespace sphles::io::particle_snapshot_format
