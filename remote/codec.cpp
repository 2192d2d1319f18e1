// SPDX-License-Identifier: GPL-3.0-or-later
#include "remote/codec.hpp"

#include <bit>
#include <cstring>
#include <limits>

namespace sphles::remote {

static_assert(std::endian::native == std::endian::little,
              "remote messages carry values in the byte order of little-endian machines");

void Encoder::raw(const void* data, std::size_t size) {
  const auto* begin = static_cast<const std::byte*>(data);
  bytes_.insert(bytes_.end(), begin, begin + size);
}
void Encoder::u64(std::uint64_t value) {
  raw(&value, sizeof value);
}
void Encoder::f64(double value) {
  raw(&value, sizeof value);
}
void Encoder::string(const std::string& text) {
  u64(text.size());
  raw(text.data(), text.size());
}
void Encoder::doubles(std::span<const double> values) {
  u64(values.size());
  raw(values.data(), values.size_bytes());
}
void Encoder::u64s(std::span<const std::uint64_t> values) {
  u64(values.size());
  raw(values.data(), values.size_bytes());
}

void Decoder::raw(void* data, std::size_t size) {
  if (size > bytes_.size() - at_)
    throw ProtocolError("remote: message truncated (" + std::to_string(size) +
                        " bytes needed at offset " + std::to_string(at_) + " of " +
                        std::to_string(bytes_.size()) + ")");
  if (size > 0) std::memcpy(data, bytes_.data() + at_, size);
  at_ += size;
}
std::size_t Decoder::count(std::size_t element_size) {
  const std::uint64_t n = u64();
  if (n > (bytes_.size() - at_) / element_size)
    throw ProtocolError("remote: a length of " + std::to_string(n) + " exceeds the message (" +
                        std::to_string(bytes_.size() - at_) + " bytes left)");
  return static_cast<std::size_t>(n);
}
std::uint64_t Decoder::u64() {
  std::uint64_t value = 0;
  raw(&value, sizeof value);
  return value;
}
double Decoder::f64() {
  double value = 0.0;
  raw(&value, sizeof value);
  return value;
}
std::string Decoder::string() {
  std::string text(count(1), '\0');
  raw(text.data(), text.size());
  return text;
}
std::vector<double> Decoder::doubles() {
  std::vector<double> values(count(sizeof(double)));
  raw(values.data(), values.size() * sizeof(double));
  return values;
}
std::vector<std::uint64_t> Decoder::u64s() {
  std::vector<std::uint64_t> values(count(sizeof(std::uint64_t)));
  raw(values.data(), values.size() * sizeof(std::uint64_t));
  return values;
}
void Decoder::finish() const {
  if (at_ != bytes_.size())
    throw ProtocolError("remote: " + std::to_string(bytes_.size() - at_) +
                        " unread bytes at the end of a message");
}

namespace {

/// The arrays of a particle set in the order they travel (explicit, so that arrays a fresh set
/// leaves empty travel empty).
template <class Particles>
auto travelling_arrays(Particles& p) {
  std::vector<decltype(&p.mass)> arrays;
  for (int a = 0; a < p.dimension; ++a) arrays.push_back(&p.position[static_cast<std::size_t>(a)]);
  for (int a = 0; a < p.dimension; ++a) arrays.push_back(&p.velocity[static_cast<std::size_t>(a)]);
  for (int a = 0; a < p.dimension; ++a)
    arrays.push_back(&p.acceleration[static_cast<std::size_t>(a)]);
  for (auto* f : {&p.mass, &p.volume, &p.density, &p.pressure, &p.eddy_viscosity})
    arrays.push_back(f);
  return arrays;
}

int checked_dimension(std::uint64_t dimension) {
  if (dimension != 2 && dimension != 3)
    throw ProtocolError("remote: particle dimension " + std::to_string(dimension) +
                        " is neither 2 nor 3");
  return static_cast<int>(dimension);
}

}  // namespace

void encode(Encoder& e, const sim::ParticleArrays& p) {
  e.u64(static_cast<std::uint64_t>(p.dimension));
  for (const std::vector<double>* array : travelling_arrays(p)) e.doubles(*array);
  e.u64s(p.id);
}

void decode(Decoder& d, sim::ParticleArrays& p) {
  p = sim::ParticleArrays{};
  p.dimension = checked_dimension(d.u64());
  for (std::vector<double>* array : travelling_arrays(p)) *array = d.doubles();
  p.id = d.u64s();
}

void encode(Encoder& e, const sim::SolverState& s) {
  encode(e, s.particles);
  for (int a = 0; a < s.particles.dimension; ++a)
    e.doubles(s.list_reference_positions[static_cast<std::size_t>(a)]);
  e.f64(s.time);
  e.u64(s.step);
  e.u64(s.neighbour_builds);
}

void decode(Decoder& d, sim::SolverState& s) {
  s = sim::SolverState{};
  decode(d, s.particles);
  for (int a = 0; a < s.particles.dimension; ++a)
    s.list_reference_positions[static_cast<std::size_t>(a)] = d.doubles();
  s.time = d.f64();
  s.step = d.u64();
  s.neighbour_builds = d.u64();
}

void encode(Encoder& e, const sim::StepDiagnostics& g) {
  e.f64(g.time);
  e.u64(g.step);
  for (const double v : {g.dt, g.kinetic_energy, g.max_density_deviation, g.max_speed, g.total_mass,
                         g.momentum[0], g.momentum[1], g.momentum[2]})
    e.f64(v);
  e.u64(g.neighbour_builds);
  e.f64(g.mean_neighbours);
}

void decode(Decoder& d, sim::StepDiagnostics& g) {
  g = sim::StepDiagnostics{};
  g.time = d.f64();
  g.step = d.u64();
  for (double* v : {&g.dt, &g.kinetic_energy, &g.max_density_deviation, &g.max_speed, &g.total_mass,
                    &g.momentum[0], &g.momentum[1], &g.momentum[2]})
    *v = d.f64();
  g.neighbour_builds = static_cast<std::size_t>(d.u64());
  g.mean_neighbours = d.f64();
}

namespace {

/// A small non-negative integer of a request (a count of points or bins, an axis).
int small_int(Decoder& d, const char* what) {
  const std::uint64_t v = d.u64();
  if (v > static_cast<std::uint64_t>(std::numeric_limits<int>::max()))
    throw ProtocolError(std::string("particle products: ") + what + " out of range");
  return static_cast<int>(v);
}

// The request's flags, one bit each.
constexpr std::uint64_t kVorticity = 1, kSliceOmega2 = 2, kSliceTau = 4, kStatistics = 8,
                        kSliceEddy = 16;
// The particle snapshot's fields, one bit each; the grid fields', one bit each.
constexpr std::uint64_t kParticleOmega2 = 1, kParticleTau = 2, kParticleEddy = 4;
constexpr std::uint64_t kFieldsVelocity = 1, kFieldsOmega2 = 2, kFieldsTau = 4, kFieldsEddy = 8;

void encode(Encoder& e, const analysis::Histogram2D& h) {
  e.u64(static_cast<std::uint64_t>(h.bins_x));
  e.u64(static_cast<std::uint64_t>(h.bins_y));
  e.u64s(h.counts);
  e.u64(h.total);
}

analysis::SliceField field_from_code(std::uint64_t code) {
  if (code > static_cast<std::uint64_t>(analysis::SliceField::EddyViscosity))
    throw ProtocolError("particle products: unknown particle field " + std::to_string(code));
  return static_cast<analysis::SliceField>(code);
}

analysis::SliceField decode_field(Decoder& d) {
  return field_from_code(d.u64());
}

analysis::Histogram2D decode_histogram(Decoder& d) {
  analysis::Histogram2D h;
  h.bins_x = small_int(d, "histogram bins");
  h.bins_y = small_int(d, "histogram bins");
  h.counts = d.u64s();
  h.total = d.u64();
  return h;
}

}  // namespace

void encode(Encoder& e, const analysis::RanksRequest& r) {
  e.u64(static_cast<std::uint64_t>(r.points_per_side));
  e.f64(r.fit_radius);
  e.u64((r.vorticity ? kVorticity : 0) | (r.slice_omega2 ? kSliceOmega2 : 0) |
        (r.slice_tau ? kSliceTau : 0) | (r.statistics ? kStatistics : 0) |
        (r.slice_eddy ? kSliceEddy : 0));
  e.u64(static_cast<std::uint64_t>(r.slice_axis));
  e.f64(r.slice_position);
  e.u64(static_cast<std::uint64_t>(r.histogram_bins));
  e.u64(static_cast<std::uint64_t>(r.angle_bins));
  e.f64(r.angle_threshold);
  e.string(r.particles.path);
  e.u64((r.particles.omega2 ? kParticleOmega2 : 0) | (r.particles.tau ? kParticleTau : 0) |
        (r.particles.eddy ? kParticleEddy : 0));
  e.f64(r.particles.time);
  e.u64(r.particles.step);
  e.string(r.particles.metadata.scene_json);
  e.string(r.particles.metadata.code_version);
  e.u64((r.fields.velocity ? kFieldsVelocity : 0) | (r.fields.omega2 ? kFieldsOmega2 : 0) |
        (r.fields.tau ? kFieldsTau : 0) | (r.fields.eddy ? kFieldsEddy : 0));
  e.u64(r.view.max_points);
  e.u64(static_cast<std::uint64_t>(r.view.field));
}

void decode(Decoder& d, analysis::RanksRequest& r) {
  r = analysis::RanksRequest{};
  r.points_per_side = small_int(d, "points per side");
  r.fit_radius = d.f64();
  const std::uint64_t flags = d.u64();
  r.vorticity = (flags & kVorticity) != 0;
  r.slice_omega2 = (flags & kSliceOmega2) != 0;
  r.slice_tau = (flags & kSliceTau) != 0;
  r.slice_eddy = (flags & kSliceEddy) != 0;
  r.statistics = (flags & kStatistics) != 0;
  r.slice_axis = small_int(d, "slice axis");
  if (r.slice_axis > 2) throw ProtocolError("particle products: slice axis out of range");
  r.slice_position = d.f64();
  r.histogram_bins = small_int(d, "histogram bins");
  r.angle_bins = small_int(d, "angle bins");
  r.angle_threshold = d.f64();
  r.particles.path = d.string();
  const std::uint64_t fields = d.u64();
  r.particles.omega2 = (fields & kParticleOmega2) != 0;
  r.particles.tau = (fields & kParticleTau) != 0;
  r.particles.eddy = (fields & kParticleEddy) != 0;
  r.particles.time = d.f64();
  r.particles.step = d.u64();
  r.particles.metadata.scene_json = d.string();
  r.particles.metadata.code_version = d.string();
  const std::uint64_t grid = d.u64();
  r.fields.velocity = (grid & kFieldsVelocity) != 0;
  r.fields.omega2 = (grid & kFieldsOmega2) != 0;
  r.fields.tau = (grid & kFieldsTau) != 0;
  r.fields.eddy = (grid & kFieldsEddy) != 0;
  r.view.max_points = d.u64();
  r.view.field = decode_field(d);
}

void encode(Encoder& e, const analysis::RanksProducts& p) {
  encode(e, p.request);
  e.f64(p.mean_vorticity_squared);
  e.doubles(p.slice_omega2);
  e.doubles(p.slice_tau);
  e.doubles(p.slice_eddy);
  for (const std::vector<double>& c : p.fields_velocity) e.doubles(c);
  e.doubles(p.fields_omega2);
  e.doubles(p.fields_tau);
  e.doubles(p.fields_eddy);
  e.u64(p.particles ? 1 : 0);
  if (p.particles) {
    e.u64(p.particles->count);
    std::vector<std::uint64_t> fields;
    for (const analysis::SliceField f : p.particles->fields)
      fields.push_back(static_cast<std::uint64_t>(f));
    e.u64s(fields);
  }
  e.u64(p.view ? 1 : 0);
  if (p.view) {
    e.u64(static_cast<std::uint64_t>(p.view->field));
    e.u64(p.view->stride);
    for (const std::vector<double>& x : p.view->position) e.doubles(x);
    e.doubles(p.view->values);
  }
  e.u64(p.statistics ? 1 : 0);
  if (!p.statistics) return;
  const analysis::SubfilterStatisticsProduct& s = *p.statistics;
  e.f64(s.max_norm);
  e.f64(s.mean_norm);
  encode(e, s.joint);
  e.u64(s.alignment ? 1 : 0);
  if (!s.alignment) return;
  e.u64(static_cast<std::uint64_t>(s.alignment->bins));
  e.f64(s.alignment->threshold);
  e.u64s(s.alignment->counts);
  e.u64(s.alignment->total);
}

void decode(Decoder& d, analysis::RanksProducts& p) {
  p = analysis::RanksProducts{};
  decode(d, p.request);
  p.mean_vorticity_squared = d.f64();
  p.slice_omega2 = d.doubles();
  p.slice_tau = d.doubles();
  p.slice_eddy = d.doubles();
  for (std::vector<double>& c : p.fields_velocity) c = d.doubles();
  p.fields_omega2 = d.doubles();
  p.fields_tau = d.doubles();
  p.fields_eddy = d.doubles();
  if (d.u64() != 0) {
    analysis::WrittenParticles& w = p.particles.emplace();
    w.count = d.u64();
    for (const std::uint64_t f : d.u64s()) w.fields.push_back(field_from_code(f));
  }
  if (d.u64() != 0) {
    analysis::ViewPoints& v = p.view.emplace();
    v.field = decode_field(d);
    v.stride = d.u64();
    for (std::vector<double>& x : v.position) x = d.doubles();
    v.values = d.doubles();
  }
  if (d.u64() == 0) return;
  analysis::SubfilterStatisticsProduct& s = p.statistics.emplace();
  s.max_norm = d.f64();
  s.mean_norm = d.f64();
  s.joint = decode_histogram(d);
  if (d.u64() == 0) return;
  analysis::AngleHistogram& a = s.alignment.emplace();
  a.bins = small_int(d, "angle bins");
  a.threshold = d.f64();
  a.counts = d.u64s();
  a.total = d.u64();
}

void encode(Encoder& e, const SolverStatus& s) {
  e.f64(s.time);
  e.u64(s.step);
  e.f64(s.stable_time_step);
  encode(e, s.diagnostics);
}

void decode(Decoder& d, SolverStatus& s) {
  s.time = d.f64();
  s.step = d.u64();
  s.stable_time_step = d.f64();
  decode(d, s.diagnostics);
}

void encode(Encoder&, std::monostate) {}
void decode(Decoder&, std::monostate&) {}
void encode(Encoder& e, std::uint64_t value) {
  e.u64(value);
}
void decode(Decoder& d, std::uint64_t& value) {
  value = d.u64();
}
void encode(Encoder& e, double value) {
  e.f64(value);
}
void decode(Decoder& d, double& value) {
  value = d.f64();
}
void encode(Encoder& e, const std::string& text) {
  e.string(text);
}
void decode(Decoder& d, std::string& text) {
  text = d.string();
}
void encode(Encoder& e, const std::vector<double>& values) {
  e.doubles(values);
}
void decode(Decoder& d, std::vector<double>& values) {
  values = d.doubles();
}

void encode(Encoder& e, const sim::PackingReport& r) {
  e.u64(static_cast<std::uint64_t>(r.iterations));
  e.f64(r.initial_residual);
  e.f64(r.final_residual);
  e.u64(r.converged ? 1 : 0);
  e.u64(r.from_cache ? 1 : 0);
  e.string(r.cache_file);
}

void decode(Decoder& d, sim::PackingReport& r) {
  const std::uint64_t iterations = d.u64();
  if (iterations > static_cast<std::uint64_t>(std::numeric_limits<int>::max()))
    throw ProtocolError("a packing report of " + std::to_string(iterations) + " iterations");
  r.iterations = static_cast<int>(iterations);
  r.initial_residual = d.f64();
  r.final_residual = d.f64();
  r.converged = d.u64() != 0;
  r.from_cache = d.u64() != 0;
  r.cache_file = d.string();
}

void encode(Encoder& e, const io::CheckpointMetadata& m) {
  e.string(m.scene_json);
  e.string(m.code_version);
  e.string(m.packing);
}

void decode(Decoder& d, io::CheckpointMetadata& m) {
  m.scene_json = d.string();
  m.code_version = d.string();
  m.packing = d.string();
}

void encode(Encoder& e, const analysis::EnergySpectrum& s) {
  e.f64(s.delta_k);
  e.doubles(s.wavenumber);
  e.doubles(s.energy);
  e.doubles(s.k2_energy);
}

void decode(Decoder& d, analysis::EnergySpectrum& s) {
  s.delta_k = d.f64();
  s.wavenumber = d.doubles();
  s.energy = d.doubles();
  s.k2_energy = d.doubles();
}

namespace {
enum class ErrorType : std::uint64_t { Other = 0, BlowUp = 1, InvalidArgument = 2, Checkpoint = 3 };
}

void encode_error(Encoder& e, const std::exception& error) {
  if (const auto* blow_up = dynamic_cast<const sim::BlowUpError*>(&error)) {
    e.u64(static_cast<std::uint64_t>(ErrorType::BlowUp));
    e.string(blow_up->what());
    e.f64(blow_up->time());
    e.u64(blow_up->step());
    e.string(blow_up->quantity());
    e.f64(blow_up->value());
    e.u64(blow_up->particle_id());
    return;
  }
  const bool invalid = dynamic_cast<const std::invalid_argument*>(&error) != nullptr;
  const bool checkpoint = dynamic_cast<const io::CheckpointError*>(&error) != nullptr;
  e.u64(static_cast<std::uint64_t>(invalid      ? ErrorType::InvalidArgument
                                   : checkpoint ? ErrorType::Checkpoint
                                                : ErrorType::Other));
  e.string(error.what());
}

void throw_error(Decoder& d) {
  const std::uint64_t type = d.u64();
  std::string what = d.string();
  if (type == static_cast<std::uint64_t>(ErrorType::BlowUp)) {
    const double time = d.f64();
    const std::uint64_t step = d.u64();
    std::string quantity = d.string();
    const double value = d.f64();
    const std::uint64_t particle = d.u64();
    throw sim::BlowUpError(what, time, step, std::move(quantity), value, particle);
  }
  if (type == static_cast<std::uint64_t>(ErrorType::InvalidArgument))
    throw std::invalid_argument(what);
  if (type == static_cast<std::uint64_t>(ErrorType::Checkpoint)) throw io::CheckpointError(what);
  throw sim::SimulationError(what);
}

}  // namespace sphles::remote
