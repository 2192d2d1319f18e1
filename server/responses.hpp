// SPDX-License-Identifier: GPL-3.0-or-later
// The answers of the REST API (docs/api.md) as Beast responses, built in one place so that every
// route's answer carries the same headers: Server, the Content-Type, X-Content-Type-Options:
// nosniff on content (so that a browser never sniffs a run's file into HTML), Cache-Control:
// no-store on anything that changes while a run goes on, and keep-alive and the HTTP version as
// the request's. Errors are the JSON error body of docs/api.md ("Errors"). Also the two readers
// of request input that several routes share: a whole file within the response limit, and a
// JSON body.
#pragma once

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/status.hpp>
#include <boost/beast/http/string_body.hpp>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "server/api_json.hpp"
#include "server/byte_source.hpp"
#include "server/text_body.hpp"

namespace sphles::server {

using Request = boost::beast::http::request<boost::beast::http::string_body>;
/// Owned text, or a product's text shared with other responses (server/text_body.hpp).
using Response = boost::beast::http::response<TextBody>;

/// `body` as `content_type`, with the headers every answer carries.
Response make_response(const Request& request, boost::beast::http::status status, std::string body,
                       std::string_view content_type);

/// `body` serialised, never cached.
Response json_response(const Request& request, const nlohmann::json& body,
                       boost::beast::http::status status = boost::beast::http::status::ok);

/// 200 with JSON text written by JsonWriter (server/json_writer.hpp), never cached.
Response make_json_text(const Request& request, std::string text);

/// 200 with a PNG image, never cached (a run's latest image changes with every frame).
Response png_response(const Request& request, std::string png);

/// 200 with `source` streamed from disk as an attachment named `filename`, never cached.
Response download_response(const Request& request, std::shared_ptr<const ByteSource> source,
                           std::string_view content_type, const std::string& filename);

/// {"error": {...}} with the error's status, as a response to a request of this version.
Response error_response(const ApiError& error, unsigned version, bool keep_alive);

/// A whole file (static files, saved frames): nullopt if it cannot be read, ApiError 507 if it is
/// larger than one response may be.
std::optional<std::string> read_file(const std::filesystem::path& file, std::size_t max_bytes);

/// The JSON body of a request to a JSON route: media type application/json (or +json, RFC 6839
/// §3.1) else ApiError 415, an object of at most kMaxJsonDepth levels else ApiError 400.
nlohmann::json json_body(const Request& request);

}  // namespace sphles::server
