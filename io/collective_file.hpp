// SPDX-License-Identifier: GPL-3.0-or-later
// What every file written by all processes of a distributed run through MPI-IO shares (checkpoints,
// particle snapshots): failures agreed across the processes, the room checked and reserved before
// HDF5 touches the disk, the file made under a temporary name and renamed.
#pragma once

#include <hdf5.h>
#include <mpi.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

namespace sphles::io::detail {

/// The processes of a communicator, in its rank order, without its topology: what every MPI-IO
/// file of sphles is opened with. Open MPI 4.1's OMPIO (Debian 12's 4.1.4) can lose a process'
/// part of a collective write through a Cartesian communicator (open-mpi/ompi#12718, fixed in
/// later releases): a particle snapshot of 3 or 4 ranks came back with one rank's rows of some
/// dataset unwritten in about half the runs; through a plain communicator, never
/// (DistributedParticleProducts tests). Collective (MPI_Comm_split).
struct PlainCommunicator {
  MPI_Comm comm = MPI_COMM_NULL;
  explicit PlainCommunicator(MPI_Comm from);
  ~PlainCommunicator();
  PlainCommunicator(const PlainCommunicator&) = delete;
  PlainCommunicator& operator=(const PlainCommunicator&) = delete;
};

/// The failure of any process, agreed: the lowest failing rank's message on every process, or
/// none. Collective.
std::optional<std::string> agree(MPI_Comm comm, const std::optional<std::string>& failure);

/// Runs `step`, returning what it threw (or none).
template <class Step>
std::optional<std::string> attempt(Step&& step) {
  try {
    step();
    return std::nullopt;
  } catch (const std::exception& e) {
    return std::string(e.what());
  }
}

/// Throws CheckpointError with the agreed failure (after rank 0 removed `path`'s temporary), if
/// any. Collective when `failure` comes from agree().
void fail_agreed(MPI_Comm comm, const std::filesystem::path& path,
                 const std::optional<std::string>& failure);

/// Makes the HDF5 file `path` from every process of `comm`: checks every process' file-size
/// limit and (rank 0) the file system's free space against `bound` bytes, creates NAME.tmp.PID
/// (rank 0's PID) through MPI-IO, reserves its blocks, calls `contents(file, transfer)` on
/// every process (`transfer`: collective data transfer properties), closes it and renames it
/// over `path`. Takes the HDF5 library lock. Any process' failure throws CheckpointError on every
/// process with the lowest failing rank's message, removes the temporary and leaves `path` as it
/// was. Collective.
void write_collectively(MPI_Comm comm, const std::filesystem::path& path, const std::string& label,
                        std::uint64_t bound,
                        const std::function<void(hid_t file, hid_t transfer)>& contents);

}  // namespace sphles::io::detail
