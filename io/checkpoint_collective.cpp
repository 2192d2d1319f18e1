// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/checkpoint_collective.hpp"

#include <hdf5.h>

#include <algorithm>
#include <optional>
#include <string>

#include "io/checkpoint_format.hpp"
#include "io/collective_file.hpp"
#include "io/hdf5_file.hpp"

namespace sphles::io {

using checkpoint_format::check_gzip_level;
using checkpoint_format::chunk_entries;
using checkpoint_format::Header;
using checkpoint_format::read_header;
using checkpoint_format::read_particles;
using checkpoint_format::write_contents;
using detail::agree;
using detail::attempt;
using detail::Handle;

std::uint64_t checkpoint_size_bound(int dimension, std::uint64_t particles, bool eddy_viscosity,
                                    std::size_t metadata_bytes) {
  // Per particle: position, velocity, acceleration and list reference per axis, mass, volume,
  // density, pressure, id (8 bytes each), ν_t when the run has it.
  const std::uint64_t datasets =
      4 * static_cast<std::uint64_t>(dimension) + 5 + (eddy_viscosity ? 1 : 0);
  // Chunks are allocated whole, the last one too (chunk_entries keeps that waste below one entry
  // per chunk); compressed chunks are no larger than that.
  const std::uint64_t chunk = chunk_entries(particles);
  const std::uint64_t chunks = chunk == 0 ? 0 : (particles + chunk - 1) / chunk;
  // A chunk's checksum (4 B) and index entry (< 64 B), a dataset's header and attributes (< 4 kB);
  // gzip can grow incompressible data by < 0.1 %: 1 % and 1 MiB of margin.
  const std::uint64_t raw =
      datasets * (8 * chunk * chunks + 64 * chunks + 4096) + 2 * metadata_bytes;
  return raw + raw / 100 + (std::uint64_t{1} << 20);
}

CheckpointShape write_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                            const sim::SolverState& part, std::uint64_t first,
                                            std::uint64_t total, const CheckpointMetadata& metadata,
                                            const CheckpointWriteOptions& options) {
  check_gzip_level(options);
  const std::string label = "checkpoint '" + path.string() + "'";
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const auto fail = [&](const std::optional<std::string>& failure) {
    detail::fail_agreed(comm, path, failure);
  };

  // The parts must tile [0, total).
  const unsigned long long count = part.particles.size();
  unsigned long long held = 0;
  MPI_Allreduce(&count, &held, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
  fail(agree(comm, held == total && first + count <= total
                       ? std::nullopt
                       : std::optional<std::string>(
                             label + ": the processes hold " + std::to_string(held) +
                             " particles for a checkpoint of " + std::to_string(total) + " (rank " +
                             std::to_string(rank) + " holds [" + std::to_string(first) + ", " +
                             std::to_string(first + count) + "))")));

  // Whether the run has ν_t: a process may hold no particles.
  const int mine = part.particles.eddy_viscosity.empty() ? 0 : 1;
  int eddy_viscosity = 0;
  MPI_Allreduce(&mine, &eddy_viscosity, 1, MPI_INT, MPI_MAX, comm);
  fail(agree(comm, part.particles.eddy_viscosity.size() == (eddy_viscosity ? count : 0)
                       ? std::nullopt
                       : std::optional<std::string>(label + ": rank " + std::to_string(rank) +
                                                    " has no eddy viscosity for its particles")));

  const std::uint64_t bound = checkpoint_size_bound(
      part.particles.dimension, total, eddy_viscosity != 0,
      metadata.scene_json.size() + metadata.code_version.size() + metadata.packing.size());
  detail::write_collectively(comm, path, label, bound, [&](hid_t file, hid_t transfer) {
    write_contents(
        file, part, metadata, options, label,
        {static_cast<hsize_t>(first), static_cast<hsize_t>(total), transfer, eddy_viscosity != 0});
  });
  return {part.particles.dimension, total, part.time, eddy_viscosity != 0};
}

Block equal_block(std::uint64_t total, int rank, int ranks) {
  const auto r = static_cast<std::uint64_t>(rank);
  const auto p = static_cast<std::uint64_t>(ranks);
  const std::uint64_t base = total / p, longer = total % p;
  const std::uint64_t first = r * base + std::min(r, longer);
  return {first, base + (r < longer ? 1 : 0)};
}

int equal_block_rank(std::uint64_t id, std::uint64_t total, int ranks) {
  const auto p = static_cast<std::uint64_t>(ranks);
  const std::uint64_t base = total / p, longer = total % p;
  const std::uint64_t split = longer * (base + 1);  // ids below it lie in the longer blocks
  return static_cast<int>(id < split ? id / (base + 1) : longer + (id - split) / base);
}

Checkpoint read_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                      std::uint64_t& first) {
  const std::string file = path.string();
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const auto fail = [](const std::optional<std::string>& failure) {
    if (failure) throw CheckpointError(*failure);
  };
  const std::lock_guard lock(hdf5_library_mutex());
  detail::silence_hdf5();
  // Every process sees the file before any opens it (the open is collective).
  fail(agree(comm, attempt([&] {
               if (!std::filesystem::exists(path))
                 throw CheckpointError("checkpoint '" + file + "': file does not exist");
               if (H5Fis_hdf5(file.c_str()) <= 0)
                 throw CheckpointError("checkpoint '" + file +
                                       "': not a readable HDF5 file (truncated or corrupted)");
             })));
  const detail::PlainCommunicator plain(comm);  // (collective_file.hpp: why)
  const Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  const Handle transfer(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  const bool properties = access.valid() && transfer.valid() &&
                          H5Pset_fapl_mpio(access.get(), plain.comm, MPI_INFO_NULL) >= 0 &&
                          H5Pset_dxpl_mpio(transfer.get(), H5FD_MPIO_COLLECTIVE) >= 0;
  fail(agree(comm, properties ? std::nullopt
                              : std::optional<std::string>(
                                    "checkpoint '" + file +
                                    "': cannot set up the MPI-IO file access properties")));
  const Handle h5(H5Fopen(file.c_str(), H5F_ACC_RDONLY, access.get()), H5Fclose);
  fail(agree(comm, h5.valid() ? std::nullopt
                              : std::optional<std::string>(
                                    "checkpoint '" + file +
                                    "': not a readable HDF5 file (truncated or corrupted)")));
  Header h;
  fail(agree(comm, attempt([&] { h = read_header(h5.get(), file); })));
  const Block block = equal_block(h.count, rank, size);
  first = block.first;
  fail(agree(comm, attempt([&] {
               read_particles(h5.get(), h,
                              {static_cast<hsize_t>(block.first), static_cast<hsize_t>(block.count),
                               transfer.get()},
                              file);
             })));
  return std::move(h.checkpoint);
}

}  // namespace sphles::io
