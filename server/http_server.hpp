// The sphles service: one port, HTTP/1.1 (REST API, static web/ files) and WebSocket streams,
// asynchronous (Boost.Beast on an io_context with a small thread pool). Request handlers that
// call into run control run on a separate worker pool, because some of them block (stopping a run
// writes a checkpoint); the I/O threads only parse, route and write.
//
// Limits, all at the call site in http_server.cpp: request body (413), header size, request
// timeout, connections; per-client WebSocket queues (server/client_queue.hpp).
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "control/run_manager.hpp"
#include "server/client_queue.hpp"

namespace sphles::server {

class Router;

struct ServerOptions {
  std::string address = "127.0.0.1";  // loopback unless asked otherwise
  unsigned short port = 8080;         // 0: an ephemeral port (see HttpServer::port)
  std::string token;                  // non-empty: mutating calls need it
  std::filesystem::path web_root;     // static files; need not exist
  int io_threads = 2;
  int worker_threads = 3;
  std::size_t body_limit = 1u << 20;     // request bodies above: 413
  std::size_t header_limit = 16u << 10;  // request headers above: 431
  std::chrono::seconds request_timeout{30};
  std::size_t max_connections = 512;  // further connections are closed at once
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
  /// the reason if it cannot listen.
  void start();
  unsigned short port() const;  // the bound port (also after port 0)
  std::string url() const;      // "http://HOST:PORT/"

  /// Closes the listening socket; open connections continue.
  void stop_accepting();
  /// Stops accepting, closes every WebSocket ("going away") and HTTP connection, waits for
  /// requests in progress, joins the threads. Runs are not touched (RunManager::shutdown does
  /// that). Idempotent.
  void stop();

  std::size_t connections() const;  // open HTTP connections plus WebSocket sessions
  const Router& router() const;

  struct Impl;  // opaque (http_server.cpp): keeps Boost out of this header

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sphles::server
