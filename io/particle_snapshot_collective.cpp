// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/particle_snapshot_collective.hpp"

#include <numeric>
#include <optional>
#include <string>

#include "io/checkpoint_error.hpp"
#include "io/collective_file.hpp"
#include "io/particle_snapshot_format.hpp"

namespace sphles::io {

using particle_snapshot_format::check_fields;
using particle_snapshot_format::Rows;
using particle_snapshot_format::rows_of;
using particle_snapshot_format::write_contents;

std::uint64_t particle_snapshot_size_bound(std::uint64_t particles, std::size_t fields,
                                           std::size_t metadata_bytes) {
  // id, position and velocity (3 each), mass, density, pressure and the fields: 8 bytes each per
  // particle, contiguous; a dataset's header and attributes < 4 kB; 1 % and 1 MiB of margin.
  const std::uint64_t columns = 9 + fields;
  const std::uint64_t raw = 8 * columns * particles + 4096 * (6 + fields) + 2 * metadata_bytes;
  return raw + raw / 100 + (std::uint64_t{1} << 20);
}

void write_particle_snapshot_collective(MPI_Comm comm, const std::filesystem::path& path,
                                        const sim::ParticleArrays& block, std::uint64_t first,
                                        std::uint64_t total, double time, std::uint64_t step,
                                        const std::vector<ParticleField>& extra,
                                        const SnapshotMetadata& metadata) {
  const std::string label = "snapshot '" + path.string() + "'";
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const auto fail = [&](const std::optional<std::string>& failure) {
    detail::fail_agreed(comm, path, failure);
  };
  // The blocks must tile [0, total), each in id order.
  const unsigned long long count = block.size();
  unsigned long long held = 0;
  MPI_Allreduce(&count, &held, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
  fail(detail::agree(
      comm, detail::attempt([&] {
        check_fields(extra, block.size(), label);
        if (held != total || first + count > total)
          throw CheckpointError(label + ": the processes hold " + std::to_string(held) +
                                " particles for " + std::to_string(total) + " (rank " +
                                std::to_string(rank) + " holds [" + std::to_string(first) + ", " +
                                std::to_string(first + count) + "))");
        for (std::size_t k = 0; k < block.size(); ++k)
          if (block.id[k] != first + k)
            throw CheckpointError(label + ": rank " + std::to_string(rank) + " holds id " +
                                  std::to_string(block.id[k]) + " at row " +
                                  std::to_string(first + k) + " (its block is not in id order)");
      })));
  std::vector<std::size_t> identity(block.size());
  std::iota(identity.begin(), identity.end(), std::size_t{0});
  Rows rows = rows_of(block, identity, first, total, extra);
  const std::uint64_t bound = particle_snapshot_size_bound(
      total, extra.size(), metadata.scene_json.size() + metadata.code_version.size());
  detail::write_collectively(comm, path, label, bound, [&](hid_t file, hid_t transfer) {
    rows.transfer = transfer;
    write_contents(file, rows, time, step, metadata, label);
  });
}

}  // namespace sphles::io
