// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/state.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "io/checkpoint_collective.hpp"
#include "par/messages.hpp"

namespace sphles::par {

namespace {

int checked_int(std::size_t n) {
  return mpi_count(n, "state exchange (gather fewer particles per rank)");
}

/// The per-particle arrays of a state, in a fixed order: the particle fields, then the list
/// reference positions (pointers to const for a const state).
template <class State>
auto fields_of(State& s) {
  auto fields = s.particles.double_fields();
  for (int a = 0; a < s.particles.dimension; ++a)
    fields.push_back(&s.list_reference_positions[static_cast<std::size_t>(a)]);
  return fields;
}

/// Particle i of a state as one record: its arrays (fields_of order), then the id's bits.
template <class Fields>
void pack_record(const Fields& fields, const sim::ParticleArrays& p, std::size_t i,
                 double* record) {
  for (std::size_t f = 0; f < fields.size(); ++f) record[f] = (*fields[f])[i];
  std::memcpy(&record[fields.size()], &p.id[i], sizeof(double));
}

/// Fills `s` (dimension set) with the records of `in`, in order: `records` particles, ν_t when
/// `eddy_viscosity`.
void unpack_records(const std::vector<double>& in, std::size_t stride, bool eddy_viscosity,
                    sim::SolverState& s) {
  const std::size_t records = in.size() / stride;
  s.particles.resize(records);
  if (eddy_viscosity) s.particles.eddy_viscosity.resize(records);
  for (int a = 0; a < s.particles.dimension; ++a)
    s.list_reference_positions[static_cast<std::size_t>(a)].resize(records);
  const auto to = fields_of(s);
  for (std::size_t k = 0; k < records; ++k) {
    const double* record = in.data() + k * stride;
    for (std::size_t f = 0; f < to.size(); ++f) (*to[f])[k] = record[f];
    std::memcpy(&s.particles.id[k], &record[to.size()], sizeof(double));
  }
}

/// The doubles of a record: the particle fields, the list reference positions, the id's bits.
std::size_t record_stride(int dimension, bool eddy_viscosity) {
  return static_cast<std::size_t>(3 * dimension + 4 + (eddy_viscosity ? 1 : 0) + dimension + 1);
}

/// The rank whose sub-box holds each particle's list reference position.
std::vector<int> reference_owners(const Decomposition& d, const sim::SolverState& s) {
  std::vector<int> owner(s.particles.size());
  for (std::size_t i = 0; i < owner.size(); ++i) {
    int coords[3] = {0, 0, 0};
    for (int a = 0; a < s.particles.dimension; ++a)
      coords[a] = d.coordinate_of(a, s.list_reference_positions[static_cast<std::size_t>(a)][i]);
    MPI_Cart_rank(d.comm(), coords, &owner[i]);
  }
  return owner;
}

/// A state's particles as records grouped by destination rank, in their order within each
/// group; counts and offsets in doubles, as MPI's v-collectives take them.
struct Packed {
  std::vector<double> records;
  std::vector<int> counts, offsets;
};

Packed pack_by_rank(const sim::SolverState& s, std::size_t stride, const std::vector<int>& owner,
                    int ranks) {
  const auto fields = fields_of(s);
  std::vector<std::size_t> per_rank(static_cast<std::size_t>(ranks), 0);
  for (const int r : owner) ++per_rank[static_cast<std::size_t>(r)];
  std::vector<std::size_t> next(per_rank.size(), 0);
  for (std::size_t r = 1; r < per_rank.size(); ++r) next[r] = next[r - 1] + per_rank[r - 1];
  Packed packed;
  packed.counts.resize(per_rank.size());
  packed.offsets.resize(per_rank.size());
  for (std::size_t r = 0; r < per_rank.size(); ++r) {
    packed.counts[r] = checked_int(per_rank[r] * stride);
    packed.offsets[r] = checked_int(next[r] * stride);
  }
  packed.records.resize(owner.size() * stride);
  for (std::size_t i = 0; i < owner.size(); ++i)
    pack_record(fields, s.particles, i,
                packed.records.data() + next[static_cast<std::size_t>(owner[i])]++ * stride);
  return packed;
}

/// Sends every rank its records of `packed` (all to all) and returns what this rank received, in
/// rank order, as a state with the time and counters of `like`.
sim::SolverState exchange_records(const Decomposition& d, Packed packed, std::size_t stride,
                                  bool eddy_viscosity, const sim::SolverState& like) {
  std::vector<int> receive_counts(packed.counts.size()), receive_offsets(packed.counts.size());
  MPI_Alltoall(packed.counts.data(), 1, MPI_INT, receive_counts.data(), 1, MPI_INT, d.comm());
  std::size_t received = 0;
  for (std::size_t r = 0; r < receive_counts.size(); ++r) {
    receive_offsets[r] = checked_int(received);
    received += static_cast<std::size_t>(receive_counts[r]);
  }
  std::vector<double> in(received);
  MPI_Alltoallv(packed.records.data(), packed.counts.data(), packed.offsets.data(), MPI_DOUBLE,
                in.data(), receive_counts.data(), receive_offsets.data(), MPI_DOUBLE, d.comm());
  packed = Packed{};
  sim::SolverState out;
  out.time = like.time;
  out.step = like.step;
  out.neighbour_builds = like.neighbour_builds;
  out.particles.dimension = like.particles.dimension;
  unpack_records(in, stride, eddy_viscosity, out);
  return out;
}

/// Whether any rank's state holds ν_t (a rank may hold no particles).
bool any_eddy_viscosity(const Decomposition& d, const sim::SolverState& s) {
  int mine = s.particles.eddy_viscosity.empty() ? 0 : 1, any = 0;
  MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, d.comm());
  return any != 0;
}

}  // namespace

sim::SolverState gather_state(const Decomposition& d, const sim::SolverState& local, int root) {
  const auto fields = fields_of(local);
  const std::size_t stride = fields.size() + 1;  // + the id
  const std::size_t n = local.particles.size();
  std::vector<double> out(n * stride);
  for (std::size_t i = 0; i < n; ++i) pack_record(fields, local.particles, i, &out[i * stride]);
  const int ranks = d.size();
  const bool everywhere = root == kEveryRank;
  const bool receiving = everywhere || d.rank() == root;
  int count = checked_int(out.size());
  std::vector<int> counts(static_cast<std::size_t>(ranks), 0), displacements(counts.size(), 0);
  if (everywhere)
    MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, d.comm());
  else
    MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, root, d.comm());
  std::size_t total = 0;
  for (std::size_t r = 0; r < counts.size(); ++r) {
    displacements[r] = checked_int(total);
    total += static_cast<std::size_t>(counts[r]);
  }
  std::vector<double> in(receiving ? total : 0);
  if (everywhere)
    MPI_Allgatherv(out.data(), count, MPI_DOUBLE, in.data(), counts.data(), displacements.data(),
                   MPI_DOUBLE, d.comm());
  else
    MPI_Gatherv(out.data(), count, MPI_DOUBLE, in.data(), counts.data(), displacements.data(),
                MPI_DOUBLE, root, d.comm());

  sim::SolverState whole;
  whole.time = local.time;
  whole.step = local.step;
  whole.neighbour_builds = local.neighbour_builds;
  whole.particles.dimension = local.particles.dimension;
  if (!receiving) return whole;
  unpack_records(in, stride, !local.particles.eddy_viscosity.empty(), whole);
  const std::size_t particles = whole.particles.size();
  // In id order: reorder the particles and the reference positions by one permutation.
  const std::vector<std::uint32_t> order = sim::order_by_key(whole.particles.id);
  whole.particles.reorder(order);
  std::vector<double> scratch(particles);
  for (int a = 0; a < whole.particles.dimension; ++a) {
    std::vector<double>& x = whole.list_reference_positions[static_cast<std::size_t>(a)];
    for (std::size_t k = 0; k < particles; ++k) scratch[k] = x[order[k]];
    x.swap(scratch);
  }
  return whole;
}

sim::SolverState share_of(const Decomposition& d, const sim::SolverState& whole) {
  const sim::ParticleArrays& p = whole.particles;
  const std::size_t n = p.size();
  for (int a = 0; a < p.dimension; ++a)
    if (whole.list_reference_positions[static_cast<std::size_t>(a)].size() != n)
      throw std::invalid_argument(
          "state share: list reference positions do not match the particles");
  std::vector<std::uint32_t> mine;
  for (std::size_t i = 0; i < n; ++i) {
    bool owned = true;
    for (int a = 0; a < p.dimension && owned; ++a) {
      const double x = whole.list_reference_positions[static_cast<std::size_t>(a)][i];
      owned = d.coordinate_of(a, x) == d.coords()[static_cast<std::size_t>(a)];
    }
    if (owned) mine.push_back(static_cast<std::uint32_t>(i));
  }
  sim::SolverState share;
  share.time = whole.time;
  share.step = whole.step;
  share.neighbour_builds = whole.neighbour_builds;
  share.particles.dimension = p.dimension;
  share.particles.resize(mine.size());
  if (!p.eddy_viscosity.empty()) share.particles.eddy_viscosity.resize(mine.size());
  for (int a = 0; a < p.dimension; ++a)
    share.list_reference_positions[static_cast<std::size_t>(a)].resize(mine.size());
  const auto from = fields_of(whole);
  const auto to = fields_of(share);
  for (std::size_t k = 0; k < mine.size(); ++k) {
    for (std::size_t f = 0; f < to.size(); ++f) (*to[f])[k] = (*from[f])[mine[k]];
    share.particles.id[k] = p.id[mine[k]];
  }
  return share;
}

sim::SolverState scatter_state(const Decomposition& d, const sim::SolverState& whole, int root) {
  // The shape of the state (dimension, ν_t or not), the time and the counters, from the root.
  double head[3] = {static_cast<double>(whole.particles.dimension),
                    whole.particles.eddy_viscosity.empty() ? 0.0 : 1.0, whole.time};
  MPI_Bcast(head, 3, MPI_DOUBLE, root, d.comm());
  unsigned long long counters[2] = {whole.step, whole.neighbour_builds};
  MPI_Bcast(counters, 2, MPI_UNSIGNED_LONG_LONG, root, d.comm());
  sim::SolverState share;
  share.time = head[2];
  share.step = counters[0];
  share.neighbour_builds = counters[1];
  share.particles.dimension = static_cast<int>(head[0]);
  const bool eddy_viscosity = head[1] != 0.0;

  // The root packs each rank's particles as records (fields, then the id's bits).
  const std::size_t stride = record_stride(share.particles.dimension, eddy_viscosity);
  const int ranks = d.size();
  std::vector<int> counts(static_cast<std::size_t>(ranks), 0), displacements(counts.size(), 0);
  std::vector<double> out;
  // A malformed state is refused on every rank (the others would wait in the scatter).
  int malformed = 0;
  if (d.rank() == root) {
    const auto fields = fields_of(whole);
    malformed = fields.size() + 1 != stride ? 1 : 0;
    for (const std::vector<double>* f : fields)
      if (f->size() != whole.particles.size()) malformed = 1;
  }
  MPI_Bcast(&malformed, 1, MPI_INT, root, d.comm());
  if (malformed)
    throw std::invalid_argument(
        "state scatter: the state's arrays are of unequal length or do not match its shape");
  if (d.rank() == root) {
    Packed packed = pack_by_rank(whole, stride, reference_owners(d, whole), ranks);
    out = std::move(packed.records);
    counts = std::move(packed.counts);
    displacements = std::move(packed.offsets);
  }
  int count = 0;
  MPI_Scatter(counts.data(), 1, MPI_INT, &count, 1, MPI_INT, root, d.comm());
  std::vector<double> in(static_cast<std::size_t>(count));
  MPI_Scatterv(out.data(), counts.data(), displacements.data(), MPI_DOUBLE, in.data(), count,
               MPI_DOUBLE, root, d.comm());

  unpack_records(in, stride, eddy_viscosity, share);
  return share;
}

IdBlockColumns columns_in_id_block(const Decomposition& d, std::span<const std::uint64_t> ids,
                                   const std::vector<std::span<const double>>& columns) {
  const unsigned long long n = ids.size();
  unsigned long long all = 0;
  MPI_Allreduce(&n, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, d.comm());
  IdBlockColumns block;
  block.total = all;
  const io::Block mine = io::equal_block(block.total, d.rank(), d.size());
  block.first = mine.first;
  // The same columns on every rank that holds particles (one that holds none may lack a field,
  // e.g. ν_t), each a value per particle: the largest and smallest count among those ranks.
  const int own = static_cast<int>(columns.size());
  int shape[2] = {n > 0 ? own : 0, n > 0 ? -own : -std::numeric_limits<int>::max()};
  MPI_Allreduce(MPI_IN_PLACE, shape, 2, MPI_INT, MPI_MAX, d.comm());
  const std::size_t width = all > 0 ? static_cast<std::size_t>(shape[0]) : columns.size();
  int bad = all > 0 && shape[0] != -shape[1] ? 1 : 0;
  for (const std::span<const double> c : columns)
    if (c.size() != ids.size()) bad = 1;
  const std::size_t stride = width + 1;  // + the id's bits
  std::vector<int> owner(ids.size());
  for (std::size_t i = 0; i < ids.size() && !bad; ++i) {
    if (ids[i] >= block.total)
      bad = 1;
    else
      owner[i] = io::equal_block_rank(ids[i], block.total, d.size());
  }
  int any_bad = 0;
  MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, d.comm());
  if (any_bad)
    throw std::invalid_argument("id block: particle ids are not below the particle count " +
                                std::to_string(block.total) + ", or a rank's fields differ");
  // Records grouped by destination rank, in their order within each group.
  const auto ranks = static_cast<std::size_t>(d.size());
  std::vector<std::size_t> next(ranks + 1, 0);
  for (const int r : owner) ++next[static_cast<std::size_t>(r) + 1];
  for (std::size_t r = 1; r <= ranks; ++r) next[r] += next[r - 1];
  std::vector<int> counts(ranks), offsets(ranks);
  for (std::size_t r = 0; r < ranks; ++r) {
    counts[r] = checked_int((next[r + 1] - next[r]) * stride);
    offsets[r] = checked_int(next[r] * stride);
  }
  std::vector<double> out(ids.size() * stride);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    double* record = out.data() + next[static_cast<std::size_t>(owner[i])]++ * stride;
    for (std::size_t c = 0; c < width; ++c) record[c] = columns[c][i];
    std::memcpy(&record[width], &ids[i], sizeof(double));
  }
  std::vector<int> receive_counts(ranks), receive_offsets(ranks);
  MPI_Alltoall(counts.data(), 1, MPI_INT, receive_counts.data(), 1, MPI_INT, d.comm());
  std::size_t received = 0;
  for (std::size_t r = 0; r < ranks; ++r) {
    receive_offsets[r] = checked_int(received);
    received += static_cast<std::size_t>(receive_counts[r]);
  }
  std::vector<double> in(received);
  MPI_Alltoallv(out.data(), counts.data(), offsets.data(), MPI_DOUBLE, in.data(),
                receive_counts.data(), receive_offsets.data(), MPI_DOUBLE, d.comm());
  out = {};
  // In id order: record k at position id - first; each id exactly once.
  const std::size_t records = received / stride;
  block.columns.assign(width, std::vector<double>(mine.count));
  std::vector<char> seen(mine.count, 0);
  bad = records == mine.count ? 0 : 1;
  for (std::size_t k = 0; k < records && !bad; ++k) {
    const double* record = in.data() + k * stride;
    std::uint64_t id = 0;
    std::memcpy(&id, &record[width], sizeof(double));
    const std::uint64_t at = id - block.first;
    if (at >= mine.count || seen[at]) {
      bad = 1;
      break;
    }
    seen[at] = 1;
    for (std::size_t c = 0; c < width; ++c) block.columns[c][at] = record[c];
  }
  MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, d.comm());
  if (any_bad)
    throw std::invalid_argument("id block: particle ids are not a permutation of 0.." +
                                std::to_string(block.total == 0 ? 0 : block.total - 1));
  return block;
}

sim::SolverState id_block(const Decomposition& d, const sim::SolverState& local,
                          std::uint64_t& first, std::uint64_t& total) {
  std::vector<std::span<const double>> fields;
  for (const std::vector<double>* f : fields_of(local)) fields.emplace_back(*f);
  IdBlockColumns block = columns_in_id_block(d, local.particles.id, fields);
  first = block.first;
  total = block.total;
  // The shape of the state: ν_t when any rank's particles have it (a rank may hold none).
  const bool eddy_viscosity = any_eddy_viscosity(d, local);
  sim::SolverState out;
  out.time = local.time;
  out.step = local.step;
  out.neighbour_builds = local.neighbour_builds;
  out.particles.dimension = local.particles.dimension;
  const std::size_t count = block.columns.empty() ? 0 : block.columns[0].size();
  out.particles.resize(count);
  if (eddy_viscosity) out.particles.eddy_viscosity.resize(count);
  for (int a = 0; a < out.particles.dimension; ++a)
    out.list_reference_positions[static_cast<std::size_t>(a)].resize(count);
  const auto to = fields_of(out);
  if (to.size() != block.columns.size())
    throw std::invalid_argument("id block: a rank's fields differ");
  for (std::size_t f = 0; f < to.size(); ++f) to[f]->swap(block.columns[f]);
  std::iota(out.particles.id.begin(), out.particles.id.end(), first);
  return out;
}

sim::SolverState to_owners(const Decomposition& d, const sim::SolverState& state) {
  const bool eddy_viscosity = any_eddy_viscosity(d, state);
  const std::size_t stride = record_stride(state.particles.dimension, eddy_viscosity);
  return exchange_records(d, pack_by_rank(state, stride, reference_owners(d, state), d.size()),
                          stride, eddy_viscosity, state);
}

sim::SolverState read_share(const Decomposition& d, const std::filesystem::path& path,
                            io::CheckpointMetadata* metadata) {
  std::uint64_t first = 0, total = 0;
  io::Checkpoint c = io::read_checkpoint_collective(d.comm(), path, first);
  if (metadata) *metadata = c.metadata;
  sim::SolverState block;
  try {
    block = id_block(d, c.state, first, total);  // checks the ids' permutation
  } catch (const std::invalid_argument& e) {
    throw io::CheckpointError("checkpoint '" + path.string() +
                              "': dataset 'particles/id': " + e.what());
  }
  c = io::Checkpoint{};
  return to_owners(d, block);
}

}  // namespace sphles::par
