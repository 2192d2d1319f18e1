// SPDX-License-Identifier: GPL-3.0-or-later
// Request-target parsing shared by the routes and the static files: split path and query,
// percent-decode strictly. Every function rejects rather than guesses: a malformed escape, an
// encoded NUL or an encoded '/' inside a path segment is an error (HTTP 400), never a file name.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace sphles::server {

/// "%41b+c" → "Ab+c" (or "Ab c" with plus_as_space, for queries). nullopt for a truncated or
/// non-hex escape.
std::optional<std::string> percent_decode(std::string_view text, bool plus_as_space = false);

struct Target {
  std::string_view path;   // raw, still encoded; starts with '/'
  std::string_view query;  // after '?', without the fragment
};

/// Splits an origin-form request target ("/a/b?x=1"). nullopt for any other form (absolute
/// URLs, "*", empty, or not starting with '/').
std::optional<Target> split_target(std::string_view target);

/// Decoded path segments, empty segments dropped: "/api//runs/%61" → {"api", "runs", "a"}.
/// nullopt if a segment is malformed or decodes to something containing '/', '\\' or NUL.
std::optional<std::vector<std::string>> path_segments(std::string_view path);

/// Decoded query parameters (the last of repeated keys wins). nullopt if malformed.
std::optional<std::map<std::string, std::string>> parse_query(std::string_view query);

/// The request target as a log may show it: the value of every `token` query parameter is
/// replaced by "***" (a WebSocket URL carries the server's token there).
std::string loggable_target(std::string_view target);

}  // namespace sphles::server
