// SPDX-License-Identifier: GPL-3.0-or-later
// One WebSocket client of one run (/api/runs/{id}/stream), and the registry of live sessions.
//
// A session owns its socket and a ClientQueue (server/client_queue.hpp). The run's threads fill
// the queue through the run's RunFanout and wake the session with a post to its strand; the session
// serialises and writes one message at a time on that strand, so a client that reads slowly only
// ever holds one message in flight plus its bounded queue. Spectra and statistics are not
// serialised per client: every client sends the frame's one shared text (server/product_cache.hpp).
// Messages: docs/api.md.
//
// Admission (StreamRegistry::admit, before the handshake): streams opened without the server's
// token ("public"; every stream when no token is configured) are capped in total and per peer
// address below the server's connection cap, so that read-only clients can never take the places
// the token holder's calls and streams need.
#pragma once

#include <boost/asio/any_io_executor.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "control/run.hpp"
#include "server/api_json.hpp"
#include "server/client_queue.hpp"
#include "server/product_cache.hpp"

namespace sphles::server {

class StreamRegistry;

/// Caps on public WebSocket streams (ServerOptions); a stream beyond one is declined with 503.
struct StreamQuota {
  std::size_t max_public = 256;             // all public streams
  std::size_t max_public_per_address = 32;  // public streams of one peer address
};

/// A stream's place in the registry's counts, from admission (before the handshake) until the
/// session ends. Move-only; releases the place when destroyed.
class StreamTicket {
 public:
  StreamTicket() = default;
  StreamTicket(StreamRegistry* registry, std::string address, bool public_stream)
      : registry_(registry), address_(std::move(address)), public_(public_stream) {}
  StreamTicket(StreamTicket&& other) noexcept { *this = std::move(other); }
  StreamTicket& operator=(StreamTicket&& other) noexcept;
  StreamTicket(const StreamTicket&) = delete;
  StreamTicket& operator=(const StreamTicket&) = delete;
  ~StreamTicket() { release(); }
  void release() noexcept;

 private:
  StreamRegistry* registry_ = nullptr;
  std::string address_;
  bool public_ = false;
};

class WebSocketSession : public std::enable_shared_from_this<WebSocketSession> {
 public:
  /// `stream` is the upgraded HTTP connection (its executor a strand); `workers` runs calls into
  /// the run that may take a while (parameter changes). `authorised`: the upgrade carried the
  /// token (or none is configured), so parameter messages are accepted. `ticket`: the place
  /// StreamRegistry::admit gave this stream.
  WebSocketSession(boost::beast::tcp_stream&& stream, std::shared_ptr<control::Run> run,
                   StreamRegistry& registry, ProductCache& products,
                   boost::asio::any_io_executor workers, StreamLimits limits, bool authorised,
                   StreamTicket ticket);
  ~WebSocketSession();
  WebSocketSession(const WebSocketSession&) = delete;
  WebSocketSession& operator=(const WebSocketSession&) = delete;

  /// Completes the upgrade, sends {"type":"hello"}, then streams until either side closes.
  void start(boost::beast::http::request<boost::beast::http::string_body> upgrade);

  /// Any thread: stops queueing and closes with "going away" once the message in flight is out.
  void close();

  const std::shared_ptr<control::Run>& run() const { return run_; }
  const std::shared_ptr<ClientQueue>& queue() const { return queue_; }

 private:
  void on_accept(boost::beast::error_code ec);
  void on_wake();
  void send_next();
  void on_write(boost::beast::error_code ec, std::size_t bytes);
  void write_out();  // out_head_ then out_png_ or out_shared_, as one message
  /// A frame's shared text as a message {"type":"spectrum"|"statistics", ...body}.
  void set_product(const std::shared_ptr<const analysis::AnalysisFrame>& frame, Product product,
                   const char* type);
  void abort();  // after a failure that leaves the strand state unknown: close the socket
  void do_close();
  void do_read();
  void on_read(boost::beast::error_code ec, std::size_t bytes);
  void handle_message(const std::string& text);
  void reply_error(const ApiError& error);
  void finish();  // unregisters; idempotent

  boost::beast::websocket::stream<boost::beast::tcp_stream> ws_;
  boost::beast::flat_buffer in_;
  std::shared_ptr<control::Run> run_;
  StreamRegistry& registry_;
  ProductCache& products_;
  boost::asio::any_io_executor workers_;
  StreamLimits limits_;
  bool authorised_;
  std::shared_ptr<ClientQueue> queue_;
  std::shared_ptr<RunFanout> fanout_;
  StreamTicket ticket_;

  // Strand-only state.
  bool started_ = false;  // hello written; queued items may follow
  bool writing_ = false;
  bool closing_ = false;     // close() was called
  bool close_sent_ = false;  // async_close issued
  bool finished_ = false;    // unregistered
  std::string out_head_;     // text message, or 4-byte length + JSON header of an image
  std::shared_ptr<const std::vector<unsigned char>> out_png_;
  std::shared_ptr<const std::string> out_shared_;  // a product's body after its first byte
};

/// Live sessions per run, the counts in run detail "stream", and admission. One mutex.
class StreamRegistry {
 public:
  explicit StreamRegistry(StreamQuota quota = {}) : quota_(quota) {}

  /// A place for a new stream from `address` (before its handshake). A public stream (no token)
  /// beyond the quota throws ApiError 503 naming the limit; token holders' streams are counted
  /// but not capped here (the server's connection cap applies).
  StreamTicket admit(const std::string& address, bool public_stream);
  /// Streams holding a ticket: handshaking or live.
  std::size_t admitted() const;

  void add(const std::shared_ptr<WebSocketSession>& session);
  /// Adds the session's dropped images to its run's total; idempotent.
  void remove(const WebSocketSession& session);
  StreamCounters counters(const std::string& run_id) const;
  std::size_t size() const;
  /// The run's fan-out observer, registered with the run on first use (once per run).
  std::shared_ptr<RunFanout> fanout(const std::shared_ptr<control::Run>& run);
  /// Every session: queue closed (no producer posts any more), close frame requested. Safe from
  /// any thread; call before the I/O context goes away.
  void close_all();

 private:
  friend class StreamTicket;
  void release(const std::string& address, bool public_stream) noexcept;

  struct Entry {
    std::string run_id;
    std::weak_ptr<WebSocketSession> session;
    std::shared_ptr<ClientQueue> queue;
  };
  mutable std::mutex mutex_;
  std::map<const WebSocketSession*, Entry> live_;
  std::map<std::string, std::uint64_t> closed_dropped_;        // per run id, of ended sessions
  std::map<std::string, std::shared_ptr<RunFanout>> fanouts_;  // per run id
  StreamQuota quota_;
  std::size_t admitted_ = 0, public_ = 0;
  std::map<std::string, std::size_t> public_by_address_;
};

}  // namespace sphles::server
