// The REST API of docs/api.md over run control. Request handling is independent of sockets:
// Router::handle turns one parsed request into one response and never throws, so every route and
// every malformed input can be exercised without a network (tests do both).
//
// Order of checks for a request: path (404), method (405), token for mutating calls (401),
// Content-Type of JSON bodies (415), body (400 naming the field), run id (404), state (409).
// Body size (413) and malformed HTTP (400) are rejected before routing, by the HTTP session.
#pragma once

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/http/verb.hpp>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/run_manager.hpp"
#include "server/api_json.hpp"
#include "server/static_files.hpp"

namespace sphles::server {

class StreamRegistry;

using Request = boost::beast::http::request<boost::beast::http::string_body>;
using Response = boost::beast::http::response<boost::beast::http::string_body>;

struct RouteInfo {
  boost::beast::http::verb method;
  std::string_view path;  // OpenAPI path template, e.g. "/api/runs/{id}/frames/{file}"
  bool mutating;          // needs the token when the server has one
};

struct RouterOptions {
  std::string token;  // empty: no token needed
  std::filesystem::path web_root;
};

class Router {
 public:
  Router(control::RunManager& manager, StreamRegistry& streams, RouterOptions options);

  /// One complete request → one response (keep-alive and HTTP version as the request's).
  /// Never throws: failures of run control become JSON errors, anything else a 500.
  Response handle(const Request& request) const;

  /// Every API route; each appears in server/openapi.json (tested).
  static const std::vector<RouteInfo>& routes();

  /// A WebSocket upgrade to /api/runs/{id}/stream: the run, whether the connection may send
  /// parameter changes (token in ?token= or the Authorization header), or the error to send.
  struct StreamTarget {
    std::shared_ptr<control::Run> run;
    bool authorised = false;
    std::optional<Response> error;
  };
  StreamTarget stream_target(const Request& request) const;

  struct Services;

 private:
  std::shared_ptr<Services> services_;
};

/// {"error": {...}} with the error's status, as a response to a request of this version.
Response error_response(const ApiError& error, unsigned version, bool keep_alive);

}  // namespace sphles::server
