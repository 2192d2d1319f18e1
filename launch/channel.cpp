// SPDX-License-Identifier: GPL-3.0-or-later
#include "launch/channel.hpp"

#include <array>
#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <chrono>
#include <cstring>
#include <optional>

namespace sphles::launch {

namespace asio = boost::asio;
using asio::ip::tcp;

namespace {
constexpr std::size_t kHeaderBytes = sizeof(std::uint32_t) + sizeof(std::uint64_t);
/// Larger bodies are refused as corrupt: 2^40 bytes is about 7·10⁹ particles' state.
constexpr std::uint64_t kMaxBody = std::uint64_t{1} << 40;
}  // namespace

struct Channel::Impl {
  asio::io_context context;
  tcp::socket socket{context};
  std::optional<tcp::acceptor> acceptor;

  /// Runs the context until `done`, calling `check` every poll interval.
  void run_until(const bool& done, const std::function<void()>& check, double poll_seconds) {
    const auto poll = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(poll_seconds));
    context.restart();
    while (!done) {
      if (check) {
        context.run_for(poll);
        if (!done) check();
      } else {
        context.run_one();
      }
    }
  }
};

Channel::Channel() : impl_(std::make_unique<Impl>()) {}

Channel::~Channel() {
  boost::system::error_code ignored;
  impl_->socket.close(ignored);
}

unsigned short Channel::listen(const std::string& address) {
  const tcp::endpoint endpoint(asio::ip::make_address(address), 0);
  impl_->acceptor.emplace(impl_->context, endpoint);
  return impl_->acceptor->local_endpoint().port();
}

void Channel::accept(const std::function<void()>& check, double poll_seconds) {
  if (!impl_->acceptor) throw std::logic_error("Channel::accept before listen");
  bool done = false;
  boost::system::error_code error;
  impl_->acceptor->async_accept(impl_->socket, [&](const boost::system::error_code& e) {
    error = e;
    done = true;
  });
  try {
    impl_->run_until(done, check, poll_seconds);
  } catch (...) {
    impl_->acceptor->cancel();
    impl_->context.restart();
    impl_->context.run();  // the cancelled handler, before `done` and `error` go out of scope
    throw;
  }
  impl_->acceptor.reset();  // one connection: nobody else may connect afterwards
  if (error) throw ChannelClosed("job channel: accepting the job's connection: " + error.message());
  impl_->socket.set_option(tcp::no_delay(true));
}

void Channel::connect(const std::string& host, unsigned short port) {
  tcp::resolver resolver(impl_->context);
  asio::connect(impl_->socket, resolver.resolve(host, std::to_string(port)));
  impl_->socket.set_option(tcp::no_delay(true));
}

void Channel::send(MessageKind kind, const Encoder& body) {
  std::array<std::byte, kHeaderBytes> header{};
  const auto k = static_cast<std::uint32_t>(kind);
  const std::uint64_t size = body.bytes().size();
  std::memcpy(header.data(), &k, sizeof k);
  std::memcpy(header.data() + sizeof k, &size, sizeof size);
  const std::array<asio::const_buffer, 2> buffers{asio::buffer(header), asio::buffer(body.bytes())};
  boost::system::error_code error;
  asio::write(impl_->socket, buffers, error);
  if (error) throw ChannelClosed("job channel: sending: " + error.message());
}

void Channel::send(MessageKind kind) {
  send(kind, Encoder{});
}

Message Channel::receive(const std::function<void()>& check, double poll_seconds) {
  Impl& s = *impl_;
  std::array<std::byte, kHeaderBytes> header{};
  Message message;
  bool done = false;
  boost::system::error_code error;
  asio::async_read(s.socket, asio::buffer(header),
                   [&](const boost::system::error_code& e, std::size_t) {
                     if (e) {
                       error = e;
                       done = true;
                       return;
                     }
                     std::uint32_t kind = 0;
                     std::uint64_t size = 0;
                     std::memcpy(&kind, header.data(), sizeof kind);
                     std::memcpy(&size, header.data() + sizeof kind, sizeof size);
                     if (size > kMaxBody) {
                       error = asio::error::message_size;
                       done = true;
                       return;
                     }
                     message.kind = static_cast<MessageKind>(kind);
                     message.body.resize(static_cast<std::size_t>(size));
                     asio::async_read(s.socket, asio::buffer(message.body),
                                      [&](const boost::system::error_code& e2, std::size_t) {
                                        error = e2;
                                        done = true;
                                      });
                   });
  try {
    s.run_until(done, check, poll_seconds);
  } catch (...) {
    // Give up: the connection is no longer in step with the messages; close it.
    boost::system::error_code ignored;
    s.socket.close(ignored);
    s.context.restart();
    s.context.run();
    throw;
  }
  if (error == asio::error::message_size) throw ProtocolError("job channel: message too large");
  if (error == asio::error::eof) throw ChannelClosed("the job's rank 0 closed its connection");
  if (error) throw ChannelClosed("job channel: " + error.message());
  return message;
}

}  // namespace sphles::launch
