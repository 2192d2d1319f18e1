// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/setup.hpp"

#include <mpi.h>
#include <unistd.h>

#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

#include "io/checkpoint_collective.hpp"
#include "par/exchange.hpp"
#include "par/messages.hpp"
#include "par/reduce.hpp"
#include "par/state.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/neighbour_search.hpp"

namespace sphles::par {

namespace {

/// The sum modulo 2^64 of every rank's `mine` (a checksum's parts).
std::uint64_t summed(const Decomposition& d, std::uint64_t mine) {
  allreduce_counts(d, std::span<std::uint64_t>(&mine, 1));
  return mine;
}

/// The lattice points of this rank's sub-box.
sim::ParticleArrays lattice_share(const Decomposition& d, const sim::Scene& scene) {
  return sim::make_lattice(d.box(), scene.particles_per_side, [&d](int axis, double x) {
    return d.coordinate_of(axis, x) == d.coords()[static_cast<std::size_t>(axis)];
  });
}

/// This rank's block of the cached packing `f` (io::equal_block of the ids) when every rank read
/// its block and the blocks' checksums add up to the file's; else nothing, on every rank.
std::optional<sim::ParticleArrays> read_cached_block(const Decomposition& d,
                                                     const sim::PackingCacheFile& f) {
  const io::Block mine = io::equal_block(f.count, d.rank(), d.size());
  std::optional<sim::PackingCacheBlock> block =
      sim::read_packing_cache_block(f, mine.first, mine.count);
  if (!on_every_rank(d, block.has_value())) return std::nullopt;
  if (!on_every_rank(d, f.key_hash + summed(d, block->checksum_part) == block->stored))
    return std::nullopt;
  return std::move(block->particles);
}

/// The packing cache `f` written by every rank, each its block of ids [first, first + size) in
/// id order, into a temporary file that rank 0 renames when every write succeeded (else removes:
/// the cache is an optimisation, so a failure is not an error).
void write_cached_blocks(const Decomposition& d, const sim::PackingCacheFile& f,
                         const sim::ParticleArrays& block, std::uint64_t first) {
  std::string temporary;
  if (d.rank() == 0) {
    std::error_code ec;
    std::filesystem::create_directories(f.path.parent_path(), ec);
    temporary = f.path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  }
  broadcast_string(d.comm(), temporary);
  MPI_File file;
  const int opened = MPI_File_open(d.comm(), temporary.c_str(), MPI_MODE_CREATE | MPI_MODE_WRONLY,
                                   MPI_INFO_NULL, &file);
  if (!on_every_rank(d, opened == MPI_SUCCESS)) {
    if (opened == MPI_SUCCESS) MPI_File_close(&file);
    if (d.rank() == 0) std::filesystem::remove(temporary);
    return;
  }
  bool written = true;
  std::uint64_t part = 0;
  for (int a = 0; a < f.dimension; ++a) {
    part += f.checksum(a, first, block.position[a]);
    written =
        MPI_File_write_at_all(file, static_cast<MPI_Offset>(f.offset(a, first)),
                              block.position[a].data(), mpi_count(block.size(), "packing cache"),
                              MPI_DOUBLE, MPI_STATUS_IGNORE) == MPI_SUCCESS &&
        written;
  }
  const std::uint64_t checksum = f.key_hash + summed(d, part);
  if (d.rank() == 0) {
    written =
        MPI_File_write_at(file, 0, f.header.data(), mpi_count(f.header.size(), "packing cache"),
                          MPI_CHAR, MPI_STATUS_IGNORE) == MPI_SUCCESS &&
        MPI_File_write_at(file, static_cast<MPI_Offset>(f.checksum_offset()), &checksum, 1,
                          MPI_UINT64_T, MPI_STATUS_IGNORE) == MPI_SUCCESS &&
        written;
  }
  written = MPI_File_close(&file) == MPI_SUCCESS && written;
  written = on_every_rank(d, written);
  if (d.rank() == 0) {
    std::error_code ec;
    if (written) std::filesystem::rename(temporary, f.path, ec);
    if (!written || ec) std::filesystem::remove(temporary, ec);
  }
}

}  // namespace

sim::ParticleArrays set_up_share(const Decomposition& d, const sim::Scene& scene,
                                 const sim::SolverConfig& config, const sim::SetupOptions& options,
                                 sim::PackingReport& report) {
  report = sim::PackingReport{};
  sim::SolverState state;
  if (!scene.packing.enabled) {
    state.particles = lattice_share(d, scene);
  } else {
    const double packing_radius = sim::packing_list_radius(config.box, config.support_radius);
    if (d.halo_width() < packing_radius)
      throw std::invalid_argument("set-up: the ranks' halo (" + std::to_string(d.halo_width()) +
                                  " m) is narrower than the packing's list radius (" +
                                  std::to_string(packing_radius) + " m)");
    const sim::PackingCacheFile f = sim::packing_cache_file(scene, options);
    std::optional<sim::ParticleArrays> cached;
    if (!f.path.empty()) cached = read_cached_block(d, f);
    if (cached) {
      report.from_cache = true;
      report.converged = true;
      state.particles = std::move(*cached);
    } else {
      state.particles = lattice_share(d, scene);
      MpiExchange exchange(d);
      report = sim::relax_particles(scene.packing, config.box, scene.kernel, config.support_radius,
                                    config.particle_spacing, state.particles, exchange,
                                    options.cancelled);
      if (!f.path.empty()) {
        state.list_reference_positions = state.particles.position;  // id_block carries them
        std::uint64_t first = 0, total = 0;
        const sim::SolverState block = id_block(d, state, first, total);
        write_cached_blocks(d, f, block.particles, first);
      }
    }
    report.cache_file = f.path.string();
  }
  // Each particle to the rank whose sub-box holds it, as the solver's first rebuild expects.
  state.list_reference_positions = state.particles.position;
  state = to_owners(d, state);
  MpiExchange exchange(d);
  sim::set_case_fields(scene, config, state.particles, exchange);
  return std::move(state.particles);
}

}  // namespace sphles::par
