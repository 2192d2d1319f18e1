// SPDX-License-Identifier: GPL-3.0-or-later
// One HTTP connection of the service, after Beast's advanced-server example's http_session: reads
// a request within the limits of ServerOptions (header size, 431; body size, 413; a deadline for
// the header, then one for the body), hands it to the router on a worker pool, writes the
// response, and repeats while keep-alive; or hands the connection to a WebSocketSession on an
// upgrade. SessionContext is what every connection of one server shares, as chat-multi's
// shared_state.
#pragma once

#include <spdlog/logger.h>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/parser.hpp>
#include <boost/beast/http/string_body.hpp>
#include <chrono>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "control/run_manager.hpp"
#include "server/connection_table.hpp"
#include "server/peer_slots.hpp"
#include "server/product_cache.hpp"
#include "server/responses.hpp"
#include "server/router.hpp"
#include "server/server_options.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server {

/// What every HTTP connection of one server shares: the server owns it, and it outlives the
/// sessions (they unregister from its table and streams as they end).
struct SessionContext {
  /// The manager must outlive the context.
  SessionContext(control::RunManager& manager, ServerOptions opts);

  ServerOptions options;
  std::shared_ptr<spdlog::logger> log;  // the request log ("http")
  StreamRegistry streams;
  ProductCache products;
  ConnectionTable table;
  // Request handlers, off the I/O threads: reads on `work`, run control (which may block: a stop
  // writes a checkpoint) on `control`, so that reads never queue behind it, and the large reads
  // of a run's files on `bulk`, at most PeerSlots' per address at once.
  boost::asio::io_context work;
  boost::asio::io_context control;
  boost::asio::io_context bulk;
  PeerSlots bulk_reads;
  Router router;
};

class HttpSession : public std::enable_shared_from_this<HttpSession>, public Connection {
 public:
  HttpSession(boost::asio::ip::tcp::socket&& socket, SessionContext& server);
  ~HttpSession() override;

  /// Registers with the connection table and reads the first request.
  void start(std::string address);
  void close() override;
  void evict() override;

 private:
  using Clock = std::chrono::steady_clock;

  void close_now();
  void do_read();
  void on_header(boost::beast::error_code ec, std::size_t);
  void on_body(boost::beast::error_code ec, std::size_t);
  void on_read_error(boost::beast::error_code ec);
  void on_request();
  void upgrade(Request request);
  void send(Response response);
  void on_write(bool close, boost::beast::error_code ec, std::size_t bytes);
  void shutdown();
  void linger();
  void drain(std::size_t drained);
  void note_request();
  void log_request(unsigned status, std::size_t bytes);

  boost::beast::tcp_stream stream_;
  // The connection's strand, kept after an upgrade.
  boost::beast::tcp_stream::executor_type executor_;
  SessionContext& server_;
  std::string address_;  // the peer's
  std::string request_line_ = "-";
  Clock::time_point request_started_ = Clock::now();
  bool upgraded_ = false;
  // Of the table's pending response bytes, for the response being written.
  std::size_t reserved_ = 0;
  boost::beast::flat_buffer buffer_;
  std::optional<boost::beast::http::request_parser<boost::beast::http::string_body>> parser_;
  std::optional<Response> response_;
  std::vector<char> drain_buffer_;
};

}  // namespace sphles::server
