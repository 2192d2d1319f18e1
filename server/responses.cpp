// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/responses.hpp"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <system_error>
#include <utility>

namespace sphles::server {

namespace http = boost::beast::http;
namespace fs = std::filesystem;

namespace {

constexpr unsigned kStatusUnavailable = 503;
constexpr const char* kRetryAfterSeconds = "1";

}  // namespace

Response make_response(const Request& request, http::status status, std::string body,
                       std::string_view content_type) {
  Response res{status, request.version()};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, content_type);
  res.set("X-Content-Type-Options", "nosniff");
  res.keep_alive(request.keep_alive());
  res.body() = std::move(body);
  res.prepare_payload();
  return res;
}

Response json_response(const Request& request, const nlohmann::json& body, http::status status) {
  Response res = make_response(request, status, dump(body), "application/json");
  res.set(http::field::cache_control, "no-store");
  return res;
}

Response make_json_text(const Request& request, std::string text) {
  Response res = make_response(request, http::status::ok, std::move(text), "application/json");
  res.set(http::field::cache_control, "no-store");
  return res;
}

Response png_response(const Request& request, std::string png) {
  Response res = make_response(request, http::status::ok, std::move(png), "image/png");
  res.set(http::field::cache_control, "no-store");
  return res;
}

Response download_response(const Request& request, std::shared_ptr<const ByteSource> source,
                           std::string_view content_type, const std::string& filename) {
  Response res{http::status::ok, request.version()};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, content_type);
  res.set(http::field::content_disposition, "attachment; filename=\"" + filename + "\"");
  res.set(http::field::cache_control, "no-store");
  res.set("X-Content-Type-Options", "nosniff");
  res.keep_alive(request.keep_alive());
  res.body().stream(std::move(source));
  res.prepare_payload();
  return res;
}

Response error_response(const ApiError& error, unsigned version, bool keep_alive) {
  Response res{static_cast<http::status>(error.status()), version};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, "application/json");
  res.set(http::field::cache_control, "no-store");
  // A 503 is a passing condition (memory, a full server): say when to ask again.
  if (error.status() == kStatusUnavailable) res.set(http::field::retry_after, kRetryAfterSeconds);
  res.keep_alive(keep_alive);
  res.body() = dump(error_json(error));
  res.prepare_payload();
  return res;
}

std::optional<std::string> read_file(const fs::path& file, std::size_t max_bytes) {
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  if (ec) return std::nullopt;
  if (size > max_bytes)
    throw ApiError(507, file.filename().string() + " has " + std::to_string(size) +
                            " bytes, more than the server's response limit of " +
                            std::to_string(max_bytes) + " bytes");
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  std::string content(static_cast<std::size_t>(size), '\0');
  in.read(content.data(), static_cast<std::streamsize>(size));
  content.resize(static_cast<std::size_t>(in.gcount()));
  return content;
}

nlohmann::json json_body(const Request& request) {
  if (request.body().empty()) throw ApiError(400, "body: a JSON object is required");
  std::string type(request[http::field::content_type]);
  type = type.substr(0, type.find(';'));
  std::transform(type.begin(), type.end(), type.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  while (!type.empty() && type.back() == ' ') type.pop_back();
  const bool json = type == "application/json" ||
                    (type.size() > 5 && type.compare(type.size() - 5, 5, "+json") == 0);
  if (!json)
    throw ApiError(415, "Content-Type must be application/json (got '" + type + "')",
                   "Content-Type");
  nlohmann::json body = parse_client_json(request.body());
  if (!body.is_object()) throw ApiError(400, "body: must be a JSON object");
  return body;
}

}  // namespace sphles::server
