// SPDX-License-Identifier: GPL-3.0-or-later
// A checkpoint written by every process of a distributed run into one file (docs/checkpoints.md),
// through MPI-IO (HDF5 built for MPI). No process holds more than its own particles.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <filesystem>

#include "io/checkpoint.hpp"

namespace sphles::io {

/// Writes the checkpoint `path` from every process of `comm`: this process' `part` holds the
/// particles [first, first + part.particles.size()) of the `total` particles in id order (its
/// list reference positions beside them), the parts of all processes covering [0, total) once;
/// time, step, build counter, metadata and options the same on every process. The file is the
/// one write_checkpoint writes for the whole state in id order (same datasets, chunks,
/// checksums and attributes), so read_checkpoint and every reader take it alike.
///
/// Atomic like write_checkpoint: the processes write NAME.tmp.PID (rank 0's PID) in the target
/// directory, rank 0 fsyncs it and renames it over `path`. Before any HDF5 call touches the disk,
/// the room for the file is checked: every process' file-size limit (RLIMIT_FSIZE) and the file
/// system's free space, and the temporary's blocks are reserved (fallocate), since HDF5 1.10
/// cannot survive a failed write to disk (io/hdf5_file.hpp). Every failure throws
/// CheckpointError on every process with the same message (the lowest failing rank's), removes
/// the temporary and leaves `path` as it was. Collective over `comm`.
/// Returns the shape of the whole checkpoint (for its XDMF side file).
CheckpointShape write_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                            const sim::SolverState& part, std::uint64_t first,
                                            std::uint64_t total, const CheckpointMetadata& metadata,
                                            const CheckpointWriteOptions& options = {});

/// Particles [first, first + count) of `total`: process `rank`'s block of `ranks` equal blocks in
/// rank order, the first total mod ranks blocks one particle longer.
struct Block {
  std::uint64_t first = 0;
  std::uint64_t count = 0;
};
Block equal_block(std::uint64_t total, int rank, int ranks);
/// The rank whose equal_block of `total` holds particle `id` (id < total).
int equal_block_rank(std::uint64_t id, std::uint64_t total, int ranks);

/// Reads the checkpoint `path` on every process of `comm`, each its equal_block of the stored
/// particles (collective MPI-IO reads), validated as read_checkpoint validates (attributes,
/// checksums, every value, ids below the count) but for the ids' permutation, which needs all
/// blocks (par::id_block checks it). Every process gets the metadata, time and counters. Any
/// process' failure throws CheckpointError on every process with the lowest failing rank's
/// message. Sets `first` to this process' block start. Collective over `comm`.
Checkpoint read_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                      std::uint64_t& first);

/// The bytes write_checkpoint_collective reserves for a checkpoint of `particles` particles: the
/// datasets uncompressed, their checksums and chunk index, the attributes, and a margin.
std::uint64_t checkpoint_size_bound(int dimension, std::uint64_t particles, bool eddy_viscosity,
                                    std::size_t metadata_bytes);

}  // namespace sphles::io
