// SPDX-License-Identifier: GPL-3.0-or-later
// A distributed run's solver state as one state in particle-id order, and one rank's share of
// such a state: what a checkpoint of N ranks holds and how M ranks restart from it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "io/checkpoint.hpp"
#include "par/decomposition.hpp"
#include "sim/solver.hpp"

namespace sphles::par {

/// Every rank's `local` state (sim::Simulation::state() of a distributed run: its owned
/// particles) combined into one state with the particles in id order, on rank `root`, or on
/// every rank with root = kEveryRank. The other ranks get the time, step and build counter with
/// no particles. Collective over d.comm().
inline constexpr int kEveryRank = -1;
sim::SolverState gather_state(const Decomposition& d, const sim::SolverState& local, int root = 0);

/// The particles of `whole` (a state of every particle, in any order) whose list reference
/// positions lie in this rank's sub-box: this rank's share, for sim::restore_simulation with a
/// par::MpiExchange over `d`. The saving run owned them there at its last list rebuild, so the
/// restarted run rebuilds that list exactly, on any rank count.
sim::SolverState share_of(const Decomposition& d, const sim::SolverState& whole);

/// The same shares sent out from one rank: `whole` is read on rank `root` only (the others pass
/// an empty state), and each rank receives the particles whose list reference positions lie in
/// its sub-box, in the order they have in `whole`, with its time, step and build counter. Every
/// rank then holds its share only, never the whole state. Collective over d.comm().
sim::SolverState scatter_state(const Decomposition& d, const sim::SolverState& whole, int root = 0);

/// The particles of ids [first, first + count) of every rank's `local` state (owned particles,
/// ids a permutation of 0..N-1), in id order on this rank: the N particles split into one block
/// per rank in rank order, the first N mod P blocks one particle longer. What a checkpoint
/// written by every rank holds on each (io::write_checkpoint_collective). Sets `first` and
/// `total` (N). Throws std::invalid_argument on every rank when the ids are not such a
/// permutation. Collective over d.comm().
sim::SolverState id_block(const Decomposition& d, const sim::SolverState& local,
                          std::uint64_t& first, std::uint64_t& total);

/// Per-particle `columns` (a value per id of `ids`, this rank's particles) of every rank moved to
/// the rank whose equal id block holds each particle (io::equal_block, as id_block), in id
/// order there: columns[c][k] belongs to the particle with id first + k. The same number of
/// columns on every rank that holds particles (the others receive that many). Throws
/// std::invalid_argument on every rank when the ids over all ranks are not a permutation of 0..N-1
/// or the columns differ. Collective over d.comm().
struct IdBlockColumns {
  std::uint64_t first = 0;
  std::uint64_t total = 0;
  std::vector<std::vector<double>> columns;
};
IdBlockColumns columns_in_id_block(const Decomposition& d, std::span<const std::uint64_t> ids,
                                   const std::vector<std::span<const double>>& columns);

/// Every particle of `state` (this rank's, any order) sent to the rank whose sub-box holds its
/// list reference position: this rank receives its share, in rank order of the senders. What
/// share_of picks from a whole state, from parts spread over the ranks. Collective.
sim::SolverState to_owners(const Decomposition& d, const sim::SolverState& state);

/// This rank's share of the checkpoint `path` (as share_of of the whole state), read by every
/// rank, each one block of the file (io::read_checkpoint_collective), then the ids checked to be
/// a permutation (id_block) and the particles moved to their owners (to_owners): no rank holds
/// more than about its share. `metadata` receives the checkpoint's. Throws io::CheckpointError on
/// every rank for a file read_checkpoint would reject. Collective.
sim::SolverState read_share(const Decomposition& d, const std::filesystem::path& path,
                            io::CheckpointMetadata* metadata = nullptr);

}  // namespace sphles::par
