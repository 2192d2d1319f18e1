// SPDX-License-Identifier: GPL-3.0-or-later
// The REST API of docs/api.md over run control. Request handling is independent of sockets:
// Router::handle turns one parsed request into one response and never throws, so every route and
// every malformed input can be exercised without a network (tests do both).
//
// Order of checks for a request: path (404), method (405), token for mutating calls (401),
// Content-Type of JSON bodies (415), body (400 naming the field), run id (404), state (409).
// Body size (413) and malformed HTTP (400) are rejected before routing, by the HTTP session.
//
// The router holds the route table (router.cpp: every route, the index of the API) and makes
// the checks up to the token; the handlers behind it, in server/handlers/ by resource, make the
// rest, and build their answers with server/responses.hpp.
#pragma once

#include <boost/beast/http/verb.hpp>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/run_manager.hpp"
#include "server/history.hpp"
#include "server/product_cache.hpp"
#include "server/responses.hpp"

namespace sphles::server {

class StreamRegistry;
namespace handlers {
struct Services;
}

struct RouteInfo {
  boost::beast::http::verb method;
  std::string_view path;  // OpenAPI path template, e.g. "/api/runs/{id}/frames/{file}"
  bool mutating;          // needs the token when the server has one
  /// A large read of a run's files, or a movie encoded from them: made on the bulk threads
  /// under a per-address bound (ServerOptions::bulk_threads), never on the run-control pool.
  bool bulk = false;
};

struct RouterOptions {
  std::string token;  // empty: no token needed
  std::filesystem::path web_root;
  ResponseLimits limits;                // bytes of one answer, rows of one history page
  std::filesystem::path reference_dir;  // data/reference: the DNS of GET reference
  std::filesystem::path scenes_dir;     // scenes/: the scene files of GET scenes
};

class Router {
 public:
  /// `products` serialises spectra and statistics once per frame (shared with the streams).
  Router(control::RunManager& manager, StreamRegistry& streams, ProductCache& products,
         RouterOptions options);

  /// One complete request → one response (keep-alive and HTTP version as the request's).
  /// Never throws: failures of run control become JSON errors, anything else a 500.
  Response handle(const Request& request) const;

  /// Whether the request is one of a bulk route (RouteInfo::bulk; HEAD as GET): the large
  /// reads and the movies, which the bulk threads make.
  bool is_bulk(const Request& request) const;

  /// Every API route; each appears in server/openapi.json (tested).
  static const std::vector<RouteInfo>& routes();

  /// A WebSocket upgrade to /api/runs/{id}/stream: the run, whether the connection may send
  /// parameter changes (token in ?token= or the Authorization header), whether it presented the
  /// server's token (false when none is configured: such streams are "public" for admission),
  /// or the error to send: a malformed handshake (400; 426 with Sec-WebSocket-Version: 13 for
  /// another protocol version) before the path and run (404).
  struct StreamTarget {
    std::shared_ptr<control::Run> run;
    bool authorised = false;
    bool token_holder = false;
    std::optional<Response> error;
  };
  StreamTarget stream_target(const Request& request) const;

 private:
  std::shared_ptr<handlers::Services> services_;
};

}  // namespace sphles::server
