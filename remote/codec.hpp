// SPDX-License-Identifier: GPL-3.0-or-later
// The bytes a request to a solver elsewhere, and its reply, travel as (remote/messages.hpp): the
// same for every transport (an MPI broadcast to the ranks, a TCP connection to a job). Doubles
// travel as their bits, so a state sent and received is bitwise the state that was sent
// (restarts and live changes stay exact); every value is little-endian as on the machines
// sphles runs on (x86-64, aarch64).
//
// encode(Encoder&, const T&) and decode(Decoder&, T&) are one overload set over every value that
// crosses; a message is the sequence of its fields (its static fields(), remote/messages.hpp),
// so it needs no codec of its own.
#pragma once

#include <cstddef>
#include <cstdint>
#include <exception>
#include <span>
#include <stdexcept>
#include <string>
#include <tuple>
#include <variant>
#include <vector>

#include "analysis/snapshot.hpp"
#include "analysis/spectrum.hpp"
#include "io/checkpoint.hpp"
#include "sim/packing.hpp"
#include "sim/solver.hpp"

namespace sphles::remote {

/// A message that is truncated, malformed or of an unexpected kind.
class ProtocolError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Encoder {
 public:
  void u64(std::uint64_t value);
  void f64(double value);
  void string(const std::string& text);
  void doubles(std::span<const double> values);
  void u64s(std::span<const std::uint64_t> values);
  const std::vector<std::byte>& bytes() const { return bytes_; }

 private:
  void raw(const void* data, std::size_t size);
  std::vector<std::byte> bytes_;
};

class Decoder {
 public:
  explicit Decoder(std::span<const std::byte> bytes) : bytes_(bytes) {}
  std::uint64_t u64();
  double f64();
  std::string string();
  std::vector<double> doubles();
  std::vector<std::uint64_t> u64s();
  /// Throws ProtocolError unless every byte was read.
  void finish() const;

 private:
  void raw(void* data, std::size_t size);
  std::size_t count(std::size_t element_size);  // a length prefix, checked against what is left
  std::span<const std::byte> bytes_;
  std::size_t at_ = 0;
};

/// A solver's progress after a request.
struct SolverStatus {
  double time = 0.0;
  std::uint64_t step = 0;
  double stable_time_step = 0.0;
  sim::StepDiagnostics diagnostics;
};

// The values that cross. Decoding refuses what does not fit its type (a dimension other than 2
// or 3, counts and bins beyond int, an unknown field code) with ProtocolError.
void encode(Encoder& e, std::monostate);
void decode(Decoder& d, std::monostate&);
void encode(Encoder& e, std::uint64_t value);
void decode(Decoder& d, std::uint64_t& value);
void encode(Encoder& e, double value);
void decode(Decoder& d, double& value);
void encode(Encoder& e, const std::string& text);
void decode(Decoder& d, std::string& text);
void encode(Encoder& e, const std::vector<double>& values);
void decode(Decoder& d, std::vector<double>& values);
void encode(Encoder& e, const sim::ParticleArrays& p);
void decode(Decoder& d, sim::ParticleArrays& p);
void encode(Encoder& e, const sim::SolverState& s);
void decode(Decoder& d, sim::SolverState& s);
void encode(Encoder& e, const sim::StepDiagnostics& g);
void decode(Decoder& d, sim::StepDiagnostics& g);
void encode(Encoder& e, const sim::PackingReport& r);
void decode(Decoder& d, sim::PackingReport& r);
void encode(Encoder& e, const SolverStatus& s);
void decode(Decoder& d, SolverStatus& s);
void encode(Encoder& e, const io::CheckpointMetadata& m);
void decode(Decoder& d, io::CheckpointMetadata& m);
void encode(Encoder& e, const analysis::EnergySpectrum& s);
void decode(Decoder& d, analysis::EnergySpectrum& s);
void encode(Encoder& e, const analysis::RanksRequest& r);
void decode(Decoder& d, analysis::RanksRequest& r);
void encode(Encoder& e, const analysis::RanksProducts& p);
void decode(Decoder& d, analysis::RanksProducts& p);

/// A message: its fields in order (T::fields(message) ties them).
template <class T>
concept Message = requires(T& m) {
  T::fields(m);
};

template <Message T>
void encode(Encoder& e, const T& message) {
  std::apply([&](const auto&... field) { (encode(e, field), ...); }, T::fields(message));
}
template <Message T>
void decode(Decoder& d, T& message) {
  std::apply([&](auto&... field) { (decode(d, field), ...); }, T::fields(message));
}

/// One of several messages: its index, then its fields.
template <class... T>
void encode(Encoder& e, const std::variant<T...>& v) {
  e.u64(v.index());
  std::visit([&](const auto& message) { encode(e, message); }, v);
}
template <class... T>
void decode(Decoder& d, std::variant<T...>& v) {
  const std::uint64_t index = d.u64();
  if (index >= sizeof...(T))
    throw ProtocolError("remote: unknown message kind " + std::to_string(index));
  // Default-construct the alternative the index names, then read its fields into it.
  std::size_t k = 0;
  ((k++ == index ? (v.template emplace<T>(), true) : false) || ...);
  std::visit([&](auto& message) { decode(d, message); }, v);
}

/// The value `bytes` holds, all of them.
template <class T>
T decode_all(std::span<const std::byte> bytes) {
  Decoder d(bytes);
  T value{};
  decode(d, value);
  d.finish();
  return value;
}

/// An exception on the solver's side, and back: a sim::BlowUpError keeps its facts,
/// std::invalid_argument (a state that does not fit the scene) and io::CheckpointError their
/// types, anything else becomes a sim::SimulationError with the same text.
void encode_error(Encoder& e, const std::exception& error);
[[noreturn]] void throw_error(Decoder& d);

}  // namespace sphles::remote
