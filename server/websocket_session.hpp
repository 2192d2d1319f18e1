// One WebSocket client of one run (/api/runs/{id}/stream), and the registry of live sessions.
//
// A session owns its socket and a ClientQueue (server/client_queue.hpp). The run's threads fill
// the queue through the run's RunFanout and wake the session with a post to its strand; the session
// serialises and writes one message at a time on that strand, so a client that reads slowly only
// ever holds one message in flight plus its bounded queue. Messages: docs/api.md.
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

namespace sphles::server {

class StreamRegistry;

class WebSocketSession : public std::enable_shared_from_this<WebSocketSession> {
 public:
  /// `stream` is the upgraded HTTP connection (its executor a strand); `workers` runs calls into
  /// the run that may take a while (parameter changes). `authorised`: the upgrade carried the
  /// token (or none is configured), so parameter messages are accepted.
  WebSocketSession(boost::beast::tcp_stream&& stream, std::shared_ptr<control::Run> run,
                   StreamRegistry& registry, boost::asio::any_io_executor workers,
                   StreamLimits limits, bool authorised);
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
  boost::asio::any_io_executor workers_;
  StreamLimits limits_;
  bool authorised_;
  std::shared_ptr<ClientQueue> queue_;
  std::shared_ptr<RunFanout> fanout_;

  // Strand-only state.
  bool started_ = false;  // hello written; queued items may follow
  bool writing_ = false;
  bool closing_ = false;     // close() was called
  bool close_sent_ = false;  // async_close issued
  bool finished_ = false;    // unregistered
  std::string out_head_;     // text message, or 4-byte length + JSON header of an image
  std::shared_ptr<const std::vector<unsigned char>> out_png_;
};

/// Live sessions per run, and the counts in run detail "stream". One mutex.
class StreamRegistry {
 public:
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
  struct Entry {
    std::string run_id;
    std::weak_ptr<WebSocketSession> session;
    std::shared_ptr<ClientQueue> queue;
  };
  mutable std::mutex mutex_;
  std::map<const WebSocketSession*, Entry> live_;
  std::map<std::string, std::uint64_t> closed_dropped_;        // per run id, of ended sessions
  std::map<std::string, std::shared_ptr<RunFanout>> fanouts_;  // per run id
};

}  // namespace sphles::server
