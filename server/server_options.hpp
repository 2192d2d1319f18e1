// SPDX-License-Identifier: GPL-3.0-or-later
// The service's options: where it listens, its thread pools, and its limits (docs/api.md
// "Limits"). In a header of their own, which server/http_server.hpp includes for its users, so
// that the parts of the server (listener, HTTP sessions, connection table) read them without
// including the server that owns those parts.
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <string>

#include "server/client_queue.hpp"
#include "server/history.hpp"

namespace sphles::server {

struct ServerOptions {
  std::string address = "127.0.0.1";  // loopback unless asked otherwise
  unsigned short port = 8080;         // 0: an ephemeral port (see HttpServer::port)
  std::string token;                  // non-empty: mutating calls need it
  std::filesystem::path web_root;     // static files; need not exist
  /// Reference data (data/reference/: the 3D TGV DNS); empty: the source tree's, as built.
  std::filesystem::path reference_dir;
  /// Scene files the dashboard offers (GET /api/scenes); empty: the source tree's scenes/.
  std::filesystem::path scenes_dir;
  int io_threads = 2;
  /// Requests are handled off the I/O threads: reads (GET, HEAD) on `worker_threads`, everything
  /// else on `control_threads`. Run-control calls may block for a while (a stop waits for the
  /// step and the checkpoint; transitions of one run wait for each other), and reads never wait
  /// behind them.
  int worker_threads = 3;
  int control_threads = 3;
  /// The large reads of a run's files (time series, analysis history, log, files, archive,
  /// resolved scales: RouteInfo::bulk) are built on threads of their own, so that the health
  /// check, the run list and a run's detail never queue behind them; each peer address may
  /// have `max_bulk_reads_per_address` of them in progress or waiting, beyond which it is
  /// answered 429.
  int bulk_threads = 2;
  std::size_t max_bulk_reads_per_address = 8;  // a dashboard polls 4-5 of them at once
  std::size_t body_limit = 1u << 20;           // request bodies above: 413
  std::size_t header_limit = 16u << 10;        // request headers above: 431
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

}  // namespace sphles::server
