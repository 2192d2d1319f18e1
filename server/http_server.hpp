// SPDX-License-Identifier: GPL-3.0-or-later
// The sphles service: one port, HTTP/1.1 (REST API, static web/ files) and WebSocket streams,
// asynchronous (Boost.Beast on an io_context with a small thread pool). Request handlers that
// call into run control run on a separate worker pool, because some of them block (stopping a run
// writes a checkpoint); the I/O threads only parse, route and write.
//
// Limits (ServerOptions, docs/api.md "Limits"): request header (431) and body (413) sizes; a
// deadline for a request's header (slowloris) apart from the body/response timeout; response
// size (507) and unsent response bytes (503); connections in total and per peer address, where a
// newcomer evicts the least valuable HTTP connection (lingering, then idle or slowest reading)
// rather than being refused; WebSocket streams without the token, in total and per address, kept
// below the connection cap so that the token holder always gets in; per-client WebSocket queues
// (server/client_queue.hpp). No exception from a handler ends the process: the I/O and worker
// threads catch and carry on, and running out of memory answers 503.
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "control/run_manager.hpp"
#include "server/client_queue.hpp"
#include "server/history.hpp"

namespace sphles::server {

class Router;

struct ServerOptions {
  std::string address = "127.0.0.1";  // loopback unless asked otherwise
  unsigned short port = 8080;         // 0: an ephemeral port (see HttpServer::port)
  std::string token;                  // non-empty: mutating calls need it
  std::filesystem::path web_root;     // static files; need not exist
  /// Reference data (data/reference/: the 3D TGV DNS); empty: the source tree's, as built.
  std::filesystem::path reference_dir;
  int io_threads = 2;
  /// Requests are handled off the I/O threads: reads (GET, HEAD) on `worker_threads`, everything
  /// else on `control_threads`. Run-control calls may block for a while (a stop waits for the
  /// step and the checkpoint; transitions of one run wait for each other), and reads never wait
  /// behind them.
  int worker_threads = 3;
  int control_threads = 3;
  std::size_t body_limit = 1u << 20;     // request bodies above: 413
  std::size_t header_limit = 16u << 10;  // request headers above: 431
  /// A request's header must be complete this long after the connection was ready for it
  /// (accepted, or its previous response sent), or the connection closes: idle keep-alive
  /// connections and slowloris clients (a byte now and then) both end here.
  std::chrono::seconds header_timeout{10};
  std::chrono::seconds request_timeout{30};  // to receive a body, and to send a response
  /// Open sockets, HTTP and WebSocket. When full, a newcomer evicts the least valuable HTTP
  /// connection (lingering after its last response, then the one waiting longest for or reading
  /// its current request); only if every connection is busy is it refused (503, then closed).
  std::size_t max_connections = 512;
  /// HTTP connections of one peer address; a newcomer beyond evicts that address's least
  /// valuable connection the same way.
  std::size_t max_connections_per_address = 64;
  /// WebSocket streams opened without the server's token (every stream when none is
  /// configured), in total and per peer address; beyond, the upgrade is declined with 503. The
  /// rest of max_connections stays for API calls and the token holder's streams.
  std::size_t max_public_streams = 256;
  std::size_t max_public_streams_per_address = 32;
  /// Response bodies built and not yet sent, all connections together (a shared product counts
  /// once, in ProductCache); a response beyond is replaced by a 503.
  std::size_t max_pending_response_bytes = 512u << 20;
  ResponseLimits responses;  // one response's bytes (507 beyond), one history page's rows
  StreamLimits stream;
};

class HttpServer {
 public:
  /// The manager must outlive the server.
  HttpServer(control::RunManager& manager, ServerOptions options);
  ~HttpServer();  // stop()
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  /// Binds, listens and starts the threads. Throws std::runtime_error naming the address and
  /// the reason if it cannot listen, std::invalid_argument if max_public_streams is not below
  /// max_connections.
  void start();
  unsigned short port() const;  // the bound port (also after port 0)
  std::string url() const;      // "http://HOST:PORT/"

  /// Closes the listening socket; open connections continue.
  void stop_accepting();
  /// Stops accepting, closes every WebSocket ("going away") and HTTP connection, waits for
  /// requests in progress, joins the threads. Runs are not touched (RunManager::shutdown does
  /// that). Idempotent.
  void stop();

  std::size_t connections() const;  // open HTTP connections plus WebSocket streams
  const Router& router() const;

  struct Impl;  // opaque (http_server.cpp): keeps Boost out of this header

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sphles::server
