// SPDX-License-Identifier: GPL-3.0-or-later
// A particle snapshot written by every process of a distributed run into one file, through MPI-IO
// (HDF5 built for MPI): no process holds more than its own particles.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <filesystem>
#include <vector>

#include "io/particle_snapshot.hpp"

namespace sphles::io {

/// Writes the particle snapshot `path` from every process of `comm`: this process' `block`
/// holds the particles with ids [first, first + block.size()) of the `total` in id order (its
/// `extra` fields' values beside them, in the same order), the blocks of all processes
/// covering [0, total) once (io::equal_block's split, or any other); time, step, the extra
/// fields' names and units and the metadata the same on every process. The file is the one
/// write_particle_snapshot writes for all particles (same datasets, attributes and values).
/// Atomic and checked for room like write_checkpoint_collective; every failure throws
/// CheckpointError on every process with the same message and leaves `path` as it was.
/// Collective over `comm`.
void write_particle_snapshot_collective(MPI_Comm comm, const std::filesystem::path& path,
                                        const sim::ParticleArrays& block, std::uint64_t first,
                                        std::uint64_t total, double time, std::uint64_t step,
                                        const std::vector<ParticleField>& extra,
                                        const SnapshotMetadata& metadata);

/// The bytes write_particle_snapshot_collective reserves for `particles` particles with `fields`
/// extra fields and `metadata_bytes` of metadata.
std::uint64_t particle_snapshot_size_bound(std::uint64_t particles, std::size_t fields,
                                           std::size_t metadata_bytes);

}  // namespace sphles::io
