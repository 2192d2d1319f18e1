// SPDX-License-Identifier: GPL-3.0-or-later
// The channel between a run in the service and the rank 0 of the MPI job that holds its solver
// (docs/scaling.md, "From the service"): length-prefixed binary messages over one TCP connection,
// and the codec of the solver values that cross it. Doubles travel as their bits, so a state sent
// and received is bitwise the state that was sent (restarts and live changes stay exact).
//
// Message: u32 kind, u64 body length, body. Bodies are built by Encoder and read by Decoder;
// every value is little-endian as on the machines sphles runs on (x86-64, aarch64).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/snapshot.hpp"
#include "sim/solver.hpp"

namespace sphles::launch {

/// What a message is. Requests go from the service to rank 0; each gets one reply.
enum class MessageKind : std::uint32_t {
  Hello = 1,    // rank 0 → service, first: the job's token and its rank count
  Make = 2,     // scene JSON + particles of a fresh start → Status
  Restore = 3,  // scene JSON + solver state → Status
  Step = 4,     // max_dt → Status
  State = 5,    // → SolverState
  Finish = 6,   // the job ends (no reply)
  Status = 7,   // time, step, stable time step, diagnostics
  SolverState = 8,
  Error = 9,             // a request failed on the job: what, and the blow-up facts if it was one
  CaseDiagnostics = 10,  // scene JSON → Values (Simulation::case_diagnostics)
  Values = 11,
  Spectrum = 12,  // points per side → Values (Δk, then wavenumbers, energies, k² energies)
  ParticleProducts = 13,  // analysis::RanksRequest → Values (analysis::RanksProducts)
  WriteCheckpoint = 14,   // file, scene JSON, code version, packing, gzip level → Status
  RestoreFile = 15,       // scene JSON + checkpoint file, read by the job's ranks → Status
  Change = 16,            // scene JSON: the job's solver continued on its ranks → Status
  SetUp = 17,  // scene JSON + packing cache directory: a new run made by the job's ranks →
               // Status followed by the packing's report
};

/// A message that is truncated, malformed or of an unexpected kind.
class ProtocolError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The peer closed the connection or the socket failed.
class ChannelClosed : public std::runtime_error {
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

void encode(Encoder& e, const sim::ParticleArrays& p);
sim::ParticleArrays decode_particles(Decoder& d);
void encode(Encoder& e, const sim::SolverState& s);
sim::SolverState decode_state(Decoder& d);
void encode(Encoder& e, const sim::StepDiagnostics& diagnostics);
sim::StepDiagnostics decode_diagnostics(Decoder& d);

/// The ParticleProducts request and its reply (analysis/snapshot.hpp). Decoding refuses
/// counts and bins that do not fit their types.
void encode(Encoder& e, const analysis::RanksRequest& request);
analysis::RanksRequest decode_ranks_request(Decoder& d);
void encode(Encoder& e, const analysis::RanksProducts& products);
analysis::RanksProducts decode_ranks_products(Decoder& d);

/// A solver's progress after a request: what the Status message carries.
struct SolverStatus {
  double time = 0.0;
  std::uint64_t step = 0;
  double stable_time_step = 0.0;
  sim::StepDiagnostics diagnostics;
};
void encode(Encoder& e, const SolverStatus& status);
SolverStatus decode_status(Decoder& d);

/// An exception on the job's side as a message body, and back: a sim::BlowUpError keeps its
/// facts, std::invalid_argument (a state that does not fit the scene) its type, anything else
/// becomes a sim::SimulationError with the same text.
void encode_error(Encoder& e, const std::exception& error);
[[noreturn]] void throw_error(Decoder& d);

struct Message {
  MessageKind kind{};
  std::vector<std::byte> body;
};

/// One end of the connection. Blocking, one thread at a time.
class Channel {
 public:
  Channel();
  ~Channel();
  Channel(const Channel&) = delete;
  Channel& operator=(const Channel&) = delete;

  /// The service's end: listens on `address` (an IP address), on a port the system picks;
  /// returns the port.
  unsigned short listen(const std::string& address);
  /// Waits for the job to connect, calling `check` every `poll_seconds` (it throws to give up:
  /// the job ended, the time ran out).
  void accept(const std::function<void()>& check, double poll_seconds);
  /// The job's end.
  void connect(const std::string& host, unsigned short port);

  void send(MessageKind kind, const Encoder& body);
  void send(MessageKind kind);
  /// The next message; while waiting, `check` (if given) is called every `poll_seconds` and may
  /// throw to give up. Throws ChannelClosed when the peer has gone.
  Message receive(const std::function<void()>& check = {}, double poll_seconds = 0.2);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sphles::launch
