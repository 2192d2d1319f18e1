// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/router.hpp"

#include <algorithm>
#include <cctype>
#include <exception>
#include <map>
#include <utility>

#include "server/auth.hpp"
#include "server/handlers/handlers.hpp"
#include "server/url.hpp"

namespace sphles::server {

namespace http = boost::beast::http;
using handlers::Context;
using handlers::Handler;
using handlers::Services;

namespace {

constexpr const char* kWebSocketVersion = "13";

struct Route {
  RouteInfo info;
  Handler handler;
  bool json_body = false;  // needs Content-Type: application/json and a JSON body
};

/// Every route of the API (docs/api.md "Routes"). server/handlers/handlers.hpp declares the
/// handlers and says which file of server/handlers/ holds each resource's.
const std::vector<Route>& route_table() {
  using V = http::verb;
  using M = control::RunManager;
  using R = control::ReferenceJobs;
  using namespace handlers;
  static const std::vector<Route> table = {
      {{V::get, "/api/health", false}, health},
      {{V::get, "/api/openapi.json", false}, openapi},
      {{V::get, "/api/asyncapi.json", false}, asyncapi},
      {{V::get, "/api/presets", false}, presets},
      {{V::get, "/api/scenes", false}, scene_files},
      {{V::get, "/api/schema/scene", false}, scene_schema},
      {{V::get, "/api/runs", false}, list_runs},
      {{V::post, "/api/runs", true}, create_run, true},
      {{V::post, "/api/estimate", true}, estimate_run, true},
      {{V::get, "/api/runs/{id}", false}, get_run},
      {{V::delete_, "/api/runs/{id}", true}, delete_run},
      {{V::post, "/api/runs/{id}/start", true}, transition<&M::start>},
      {{V::post, "/api/runs/{id}/pause", true}, transition<&M::pause>},
      {{V::post, "/api/runs/{id}/resume", true}, transition<&M::resume>},
      {{V::post, "/api/runs/{id}/stop", true}, stop_run},
      {{V::patch, "/api/runs/{id}/parameters", true}, change_parameters, true},
      {{V::get, "/api/runs/{id}/timeseries", false, true}, timeseries},
      {{V::get, "/api/runs/{id}/log", false, true}, run_log},
      {{V::get, "/api/runs/{id}/analysis", false, true}, analysis_history},
      {{V::get, "/api/runs/{id}/reference", false}, reference},
      {{V::get, "/api/runs/{id}/resolved", false, true}, resolved},
      {{V::get, "/api/runs/{id}/files", false}, list_files},
      {{V::get, "/api/runs/{id}/files/{name}", false, true}, get_file},
      {{V::get, "/api/runs/{id}/files/{dir}/{name}", false, true}, get_file},
      {{V::get, "/api/runs/{id}/archive", false, true}, get_archive},
      {{V::post, "/api/runs/{id}/movies", true, true}, make_movie, true},
      {{V::get, "/api/runs/{id}/spectrum", false}, spectrum},
      {{V::get, "/api/runs/{id}/statistics", false}, statistics},
      {{V::get, "/api/runs/{id}/images/{field}", false}, latest_image},
      {{V::get, "/api/runs/{id}/frames", false}, list_frames},
      {{V::get, "/api/runs/{id}/frames/{file}", false}, get_frame},
      {{V::get, "/api/runs/{id}/stream", false}, stream_without_upgrade},
      {{V::get, "/api/references", false}, list_references},
      {{V::post, "/api/references", true}, create_reference, true},
      {{V::get, "/api/references/{id}", false}, get_reference},
      {{V::delete_, "/api/references/{id}", true}, delete_reference},
      {{V::post, "/api/references/{id}/stop", true}, reference_transition<&R::stop>},
      {{V::post, "/api/references/{id}/resume", true}, reference_transition<&R::resume>},
  };
  return table;
}

/// Matches decoded segments against a template; fills the {...} values.
bool match(std::string_view pattern, const std::vector<std::string>& segments,
           std::vector<std::string>& params) {
  std::vector<std::string> values;
  std::size_t index = 0;
  std::size_t start = 1;  // skip the leading '/'
  while (start <= pattern.size()) {
    std::size_t end = pattern.find('/', start);
    if (end == std::string_view::npos) end = pattern.size();
    const std::string_view part = pattern.substr(start, end - start);
    if (index >= segments.size()) return false;
    if (!part.empty() && part.front() == '{')
      values.push_back(segments[index]);
    else if (part != segments[index])
      return false;
    ++index;
    start = end + 1;
  }
  if (index != segments.size()) return false;
  params = std::move(values);
  return true;
}

/// The Allow header of a 405 (RFC 9110 §10.2.1): every method with a route for the path, HEAD
/// wherever GET is.
std::string allowed_methods(const std::vector<std::string>& segments) {
  std::string allow;
  std::vector<std::string> unused;
  for (const Route& r : route_table()) {
    if (!match(r.info.path, segments, unused)) continue;
    if (!allow.empty()) allow += ", ";
    allow += std::string(http::to_string(r.info.method));
    if (r.info.method == http::verb::get) allow += ", HEAD";
  }
  return allow;
}

/// 401 with the challenge of RFC 6750 §3 when a mutating route lacks the server's token.
std::optional<Response> refuse_without_token(const Services& s, const Request& request) {
  const std::optional<std::string_view> bearer = bearer_token(request[http::field::authorization]);
  if (authorised(s.token, bearer)) return std::nullopt;
  Response res = error_response(
      ApiError(401, "this call needs the server's token: Authorization: Bearer TOKEN",
               "Authorization"),
      request.version(), request.keep_alive());
  res.set(http::field::www_authenticate, "Bearer");
  return res;
}

/// The checks of router.hpp up to the token, then the route's handler (which checks the rest).
Response dispatch(const Services& s, const Request& request) {
  const std::optional<Target> target = split_target(request.target());
  if (!target) throw ApiError(400, "request target must be a path starting with '/'", "target");
  const std::optional<std::vector<std::string>> segments = path_segments(target->path);
  if (!segments)
    throw ApiError(400, "path: malformed percent-encoding or an encoded '/', '\\' or NUL", "path");
  if (segments->empty() || (*segments)[0] != "api")
    return handlers::serve_static(s, request, target->path);

  const http::verb method =
      request.method() == http::verb::head ? http::verb::get : request.method();
  bool path_known = false;
  for (const Route& route : route_table()) {
    std::vector<std::string> params;
    if (!match(route.info.path, *segments, params)) continue;
    path_known = true;
    if (route.info.method != method) continue;
    if (route.info.mutating)
      if (std::optional<Response> refusal = refuse_without_token(s, request)) return *refusal;
    std::optional<std::map<std::string, std::string>> query = parse_query(target->query);
    if (!query) throw ApiError(400, "query: malformed percent-encoding", "query");
    return route.handler(s, Context{request, std::move(params), std::move(*query)});
  }
  if (!path_known) throw ApiError(404, "no API route " + std::string(target->path), "path");
  Response res = error_response(ApiError(405,
                                         "method " + std::string(request.method_string()) +
                                             " is not allowed on " + std::string(target->path),
                                         "method"),
                                request.version(), request.keep_alive());
  res.set(http::field::allow, allowed_methods(*segments));
  return res;
}

/// What Beast's accept would decline, as the documented JSON error (Beast answers in plain
/// text): RFC 6455 §4.2.1. The caller has checked is_upgrade (GET, HTTP/1.1, Connection: Upgrade,
/// Upgrade: websocket).
std::optional<ApiError> handshake_error(const Request& request, bool& wrong_version) {
  wrong_version = false;
  if (request[http::field::host].empty())
    return ApiError(400, "WebSocket handshake: the Host header is missing", "Host");
  const std::string_view key = request[http::field::sec_websocket_key];
  if (key.empty())
    return ApiError(400, "WebSocket handshake: the Sec-WebSocket-Key header is missing",
                    "Sec-WebSocket-Key");
  // base64 of a 16-byte nonce: 22 base64 characters and "==".
  constexpr std::size_t kKeyLength = 24, kKeyCharacters = 22;
  const auto base64 = [](unsigned char ch) { return std::isalnum(ch) || ch == '+' || ch == '/'; };
  if (key.size() != kKeyLength || key.substr(kKeyCharacters) != "==" ||
      !std::all_of(key.begin(), key.begin() + kKeyCharacters, base64))
    return ApiError(400,
                    "WebSocket handshake: Sec-WebSocket-Key must be the base64 of 16 bytes "
                    "(24 characters ending in '==')",
                    "Sec-WebSocket-Key");
  const std::string_view version = request[http::field::sec_websocket_version];
  if (version.empty())
    return ApiError(400, "WebSocket handshake: the Sec-WebSocket-Version header is missing (13)",
                    "Sec-WebSocket-Version");
  if (version != kWebSocketVersion) {
    wrong_version = true;
    return ApiError(426,
                    "WebSocket handshake: protocol version '" + std::string(version) +
                        "' is not supported; this server speaks " + kWebSocketVersion,
                    "Sec-WebSocket-Version");
  }
  return std::nullopt;
}

}  // namespace

Router::Router(control::RunManager& manager, StreamRegistry& streams, ProductCache& products,
               RouterOptions options)
    : services_(new Services{manager,
                             streams,
                             products,
                             options.token,
                             options.limits,
                             options.reference_dir,
                             options.scenes_dir,
                             StaticFiles(options.web_root),
                             {},
                             {}}) {
  try {
    services_->presets = dump(control::RunManager::presets());
  } catch (const std::exception&) {
    // Served per request instead (and the error reported there).
  }
}

bool Router::is_bulk(const Request& request) const {
  const std::optional<Target> target = split_target(request.target());
  const auto segments = target ? path_segments(target->path) : std::nullopt;
  if (!segments) return false;
  const http::verb method =
      request.method() == http::verb::head ? http::verb::get : request.method();
  std::vector<std::string> unused;
  for (const Route& r : route_table())
    if (r.info.bulk && r.info.method == method && match(r.info.path, *segments, unused))
      return true;
  return false;
}

const std::vector<RouteInfo>& Router::routes() {
  static const std::vector<RouteInfo> infos = [] {
    std::vector<RouteInfo> v;
    for (const Route& r : route_table()) v.push_back(r.info);
    return v;
  }();
  return infos;
}

Response Router::handle(const Request& request) const {
  Response res;
  try {
    res = dispatch(*services_, request);
  } catch (const std::exception& e) {
    // Out of memory here throws on (std::bad_alloc): the caller closes the connection.
    res = error_response(to_api_error(e), request.version(), request.keep_alive());
  }
  if (request.method() == http::verb::head) {
    // Same header as GET, no body.
    const std::size_t size = res.body().size();
    res.body().clear();
    res.content_length(size);
  }
  return res;
}

Router::StreamTarget Router::stream_target(const Request& request) const {
  StreamTarget t;
  const auto fail = [&](const ApiError& e) {
    t.error = error_response(e, request.version(), false);
    return t;
  };
  bool wrong_version = false;
  if (const std::optional<ApiError> bad = handshake_error(request, wrong_version)) {
    fail(*bad);
    if (wrong_version) t.error->set(http::field::sec_websocket_version, kWebSocketVersion);
    return t;
  }
  const std::optional<Target> target = split_target(request.target());
  const auto segments = target ? path_segments(target->path) : std::nullopt;
  std::vector<std::string> params;
  if (!segments || !match("/api/runs/{id}/stream", *segments, params))
    return fail(ApiError(404, "WebSocket endpoints are /api/runs/{id}/stream only", "path"));
  const auto query = parse_query(target->query);
  if (!query) return fail(ApiError(400, "query: malformed percent-encoding", "query"));
  try {
    t.run = services_->manager.get(params[0]);
  } catch (const std::exception& e) {
    return fail(to_api_error(e));
  }
  std::optional<std::string_view> query_token;
  if (const auto it = query->find("token"); it != query->end()) query_token = it->second;
  const std::optional<std::string_view> header_token =
      bearer_token(request[http::field::authorization]);
  t.authorised = authorised(services_->token, header_token, query_token);
  t.token_holder = !services_->token.empty() && t.authorised;
  return t;
}

}  // namespace sphles::server
