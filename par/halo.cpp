// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/halo.hpp"

#include <cstring>
#include <limits>
#include <string>
#include <unordered_set>

namespace sphles::par {

namespace {

/// Makes the field set the same on every rank: ν_t is there on all ranks when it is on one (a
/// rank without particles has no values of it).
void agree_on_fields(const Decomposition& d, sim::ParticleArrays& p) {
  int has = p.eddy_viscosity.empty() ? 0 : 1;
  int any = 0;
  MPI_Allreduce(&has, &any, 1, MPI_INT, MPI_MAX, d.comm());
  if (any && p.eddy_viscosity.size() != p.size()) p.eddy_viscosity.resize(p.size(), 0.0);
}

int checked_count(std::size_t n) {
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::length_error("halo exchange: a message of " + std::to_string(n) +
                            " doubles exceeds MPI's int count");
  return static_cast<int>(n);
}

/// Sends `out` to rank `to` and receives what rank `from` sends with the same tag into `in`.
void send_receive(MPI_Comm comm, const std::vector<double>& out, int to, std::vector<double>& in,
                  int from, int tag) {
  unsigned long long out_count = out.size(), in_count = 0;
  MPI_Sendrecv(&out_count, 1, MPI_UNSIGNED_LONG_LONG, to, tag, &in_count, 1, MPI_UNSIGNED_LONG_LONG,
               from, tag, comm, MPI_STATUS_IGNORE);
  in.resize(static_cast<std::size_t>(in_count));
  MPI_Sendrecv(out.data(), checked_count(out.size()), MPI_DOUBLE, to, tag + 1, in.data(),
               checked_count(in.size()), MPI_DOUBLE, from, tag + 1, comm, MPI_STATUS_IGNORE);
}

double id_bits(std::uint64_t id) {
  double bits;
  std::memcpy(&bits, &id, sizeof bits);
  return bits;
}
std::uint64_t id_of(double bits) {
  std::uint64_t id;
  std::memcpy(&id, &bits, sizeof id);
  return id;
}

/// Whole particles as one message: per particle every field of `fields`, then the id's bits;
/// the position along `axis` (fields[axis]) gets `shift` added.
void pack(const std::vector<std::vector<double>*>& fields, const sim::ParticleArrays& p,
          std::span<const std::uint32_t> indices, int axis, double shift,
          std::vector<double>& out) {
  const std::size_t stride = fields.size() + 1;
  out.resize(indices.size() * stride);
  for (std::size_t k = 0; k < indices.size(); ++k) {
    double* record = out.data() + k * stride;
    const std::uint32_t i = indices[k];
    for (std::size_t f = 0; f < fields.size(); ++f) record[f] = (*fields[f])[i];
    record[axis] += shift;
    record[fields.size()] = id_bits(p.id[i]);
  }
}

/// Appends the particles of a message made by pack. With `present` (the ids already here), a
/// particle already present is skipped; the appended records' numbers go to `kept`.
void append(const std::vector<std::vector<double>*>& fields, sim::ParticleArrays& p,
            const std::vector<double>& in, std::unordered_set<std::uint64_t>* present = nullptr,
            std::vector<std::uint32_t>* kept = nullptr) {
  const std::size_t stride = fields.size() + 1;
  const std::size_t count = in.size() / stride;
  for (std::size_t k = 0; k < count; ++k) {
    const double* record = in.data() + k * stride;
    const std::uint64_t id = id_of(record[fields.size()]);
    if (present && !present->insert(id).second) continue;
    for (std::size_t f = 0; f < fields.size(); ++f) fields[f]->push_back(record[f]);
    p.id.push_back(id);
    if (kept) kept->push_back(static_cast<std::uint32_t>(k));
  }
}

constexpr int kHaloTag = 100;
constexpr int kUpdateTag = 200;
constexpr int kMigrateTag = 300;

}  // namespace

Halo Halo::build(const Decomposition& d, sim::ParticleArrays& p, HaloPositions positions) {
  // A particle outside the sub-box would be sent to the wrong ranks or not at all: refuse on
  // every rank (migrate first).
  std::uint64_t outside = 0, first_outside = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (!d.owns(p, i) && outside++ == 0) first_outside = p.id[i];
  unsigned long long mine = outside, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, d.comm());
  if (all > 0)
    throw std::invalid_argument(
        "halo: " + std::to_string(all) + " particle(s) lie outside their rank's sub-box" +
        (outside ? " (here id " + std::to_string(first_outside) + ")" : std::string()) +
        "; migrate them first");
  agree_on_fields(d, p);
  Halo halo;
  halo.owned_ = p.size();
  const double width = d.halo_width();
  const bool wrapped = positions == HaloPositions::Wrapped;
  std::unordered_set<std::uint64_t> present;
  if (wrapped) present.insert(p.id.begin(), p.id.end());
  std::vector<double> out, in;
  for (int a = 0; a < d.dimension(); ++a) {
    const auto axis = static_cast<std::size_t>(a);
    const double length = d.box().length[axis];
    const int n = d.dims()[axis];
    const int c = d.coords()[axis];
    if (wrapped && n == 1) continue;
    // Candidates: owned particles and the halo of the earlier axes (edges, corners).
    const std::size_t candidates = p.size();
    const std::vector<double>& x = p.position[axis];
    Stage down, up;  // to the rank below (particles near the lower face), to the rank above
    down.axis = up.axis = a;
    down.to = up.from = d.neighbour(a, -1);
    down.from = up.to = d.neighbour(a, +1);
    down.tag = kHaloTag + 4 * a;
    up.tag = down.tag + 2;
    if (!wrapped) {
      down.shift = c == 0 ? length : 0.0;     // across the periodic face at 0
      up.shift = c == n - 1 ? -length : 0.0;  // across the periodic face at L
    }
    const double low = d.lower(a) + width, high = d.upper(a) - width;
    for (std::size_t i = 0; i < candidates; ++i) {
      if (x[i] < low) down.send.push_back(static_cast<std::uint32_t>(i));
      if (x[i] >= high) up.send.push_back(static_cast<std::uint32_t>(i));
    }
    for (Stage* stage : {&down, &up}) {
      const auto fields = p.double_fields();
      pack(fields, p, stage->send, a, stage->shift, out);
      halo.bytes_sent_ += out.size() * sizeof(double);
      send_receive(d.comm(), out, stage->to, in, stage->from, stage->tag);
      stage->receive_begin = p.size();
      stage->deduplicated = wrapped;
      if (wrapped)
        append(fields, p, in, &present, &stage->kept);
      else
        append(fields, p, in);
      stage->receive_count = p.size() - stage->receive_begin;
      halo.stages_.push_back(std::move(*stage));
    }
  }
  halo.received_ = p.size() - halo.owned_;
  return halo;
}

std::size_t Halo::update(const Decomposition& d,
                         std::span<std::vector<double>* const> fields) const {
  // Values per particle of each field, and where each field's values start in a record.
  const std::size_t particles = owned_ + received_;
  std::vector<std::size_t> values(fields.size()), start(fields.size() + 1, 0);
  for (std::size_t f = 0; f < fields.size(); ++f) {
    const std::size_t size = fields[f]->size();
    if (particles == 0 ? size != 0 : size % particles != 0)
      throw std::logic_error("halo update: a field of " + std::to_string(size) +
                             " values does not hold the same number for each of the " +
                             std::to_string(particles) + " particles");
    values[f] = particles == 0 ? 0 : size / particles;
    start[f + 1] = start[f] + values[f];
  }
  const std::size_t width = start.back();
  // Copies record r's values of particle i from (or into) the fields.
  const auto gather = [&](std::size_t i, double* record) {
    for (std::size_t f = 0; f < fields.size(); ++f)
      for (std::size_t v = 0; v < values[f]; ++v)
        record[start[f] + v] = (*fields[f])[i * values[f] + v];
  };
  const auto scatter = [&](std::size_t i, const double* record) {
    for (std::size_t f = 0; f < fields.size(); ++f)
      for (std::size_t v = 0; v < values[f]; ++v)
        (*fields[f])[i * values[f] + v] = record[start[f] + v];
  };
  std::vector<double> out, in;
  std::size_t bytes = 0;
  for (const Stage& stage : stages_) {
    out.resize(stage.send.size() * width);
    bytes += out.size() * sizeof(double);
    for (std::size_t k = 0; k < stage.send.size(); ++k)
      gather(stage.send[k], out.data() + k * width);
    send_receive(d.comm(), out, stage.to, in, stage.from, kUpdateTag + stage.tag);
    const std::size_t records = width > 0 ? in.size() / width : 0;
    const bool fits = stage.deduplicated ? stage.kept.empty() || stage.kept.back() < records
                                         : width == 0 || records == stage.receive_count;
    if (!fits)
      throw std::logic_error("halo update: the neighbour sent " + std::to_string(records) +
                             " records for " + std::to_string(stage.receive_count) +
                             " halo particles");
    for (std::size_t k = 0; k < stage.receive_count; ++k) {
      const std::size_t record = stage.deduplicated ? stage.kept[k] : k;
      scatter(stage.receive_begin + k, in.data() + record * width);
    }
  }
  return bytes;
}

std::size_t migrate(const Decomposition& d, sim::ParticleArrays& p,
                    std::span<std::vector<double>* const> carried) {
  agree_on_fields(d, p);
  for (const std::vector<double>* values : carried)
    if (values->size() != p.size())
      throw std::invalid_argument("migration: a carried field has " +
                                  std::to_string(values->size()) + " values for " +
                                  std::to_string(p.size()) + " particles");
  std::size_t sent = 0;
  std::vector<double> out_down, out_up, in;
  for (int a = 0; a < d.dimension(); ++a) {
    const auto axis = static_cast<std::size_t>(a);
    const double length = d.box().length[axis];
    const int n = d.dims()[axis];
    const int c = d.coords()[axis];
    std::vector<std::uint32_t> keep, down, up;
    int too_far = 0;
    std::uint64_t far_id = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      double& x = p.position[axis][i];
      x = sim::wrap_periodic(x, length);
      const int owner = d.coordinate_of(a, x);
      if (owner == c) {
        keep.push_back(static_cast<std::uint32_t>(i));
      } else if (owner == (c + n - 1) % n) {
        down.push_back(static_cast<std::uint32_t>(i));
      } else if (owner == (c + 1) % n) {
        up.push_back(static_cast<std::uint32_t>(i));
      } else if (!too_far) {
        too_far = 1;
        far_id = p.id[i];
      }
    }
    int any_far = 0;
    MPI_Allreduce(&too_far, &any_far, 1, MPI_INT, MPI_MAX, d.comm());
    if (any_far)
      throw MigrationError(
          std::string("migration: a particle") +
          (too_far ? " (id " + std::to_string(far_id) + ")" : std::string(" of another rank")) +
          " moved more than one sub-box along axis " + std::to_string(a) +
          " since the last migration");
    auto fields = p.double_fields();
    fields.insert(fields.end(), carried.begin(), carried.end());
    // A periodic wrap is already in the positions, so nothing is shifted.
    pack(fields, p, down, a, 0.0, out_down);
    pack(fields, p, up, a, 0.0, out_up);
    sent += down.size() + up.size();
    // Keep the rest in order (keep is increasing, so the copy never overwrites a later source).
    for (std::vector<double>* f : fields) {
      for (std::size_t k = 0; k < keep.size(); ++k) (*f)[k] = (*f)[keep[k]];
      f->resize(keep.size());
    }
    for (std::size_t k = 0; k < keep.size(); ++k) p.id[k] = p.id[keep[k]];
    p.id.resize(keep.size());
    const int tag = kMigrateTag + 4 * a;
    send_receive(d.comm(), out_down, d.neighbour(a, -1), in, d.neighbour(a, +1), tag);
    append(fields, p, in);
    send_receive(d.comm(), out_up, d.neighbour(a, +1), in, d.neighbour(a, -1), tag + 2);
    append(fields, p, in);
  }
  return sent;
}

}  // namespace sphles::par
