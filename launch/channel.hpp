// SPDX-License-Identifier: GPL-3.0-or-later
// The channel between a run in the service and the rank 0 of the MPI job that holds its solver
// (docs/scaling.md, "From the service"): length-prefixed binary messages over one TCP connection.
// Message: u32 kind, u64 body length, body; bodies are remote/codec.hpp's bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "remote/codec.hpp"

namespace sphles::launch {

/// What a message is: the job's greeting, then requests from the service and one reply or
/// error to each (remote/messages.hpp, remote/codec.hpp).
enum class MessageKind : std::uint32_t {
  Hello = 1,    // rank 0 → service, first: the job's token and its rank count
  Request = 2,  // service → rank 0: a remote::Request (Finish ends the job, without reply)
  Reply = 3,    // rank 0 → service: the remote::Reply to the request
  Error = 4,    // rank 0 → service: the request failed (remote::encode_error)
};

using remote::Decoder;
using remote::Encoder;
using remote::ProtocolError;

/// The peer closed the connection or the socket failed.
class ChannelClosed : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

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
