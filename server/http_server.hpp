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

#include <cstddef>
#include <memory>
#include <string>

#include "control/run_manager.hpp"
#include "server/server_options.hpp"

namespace sphles::server {

class Router;

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
