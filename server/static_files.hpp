// SPDX-License-Identifier: GPL-3.0-or-later
// The web/ directory as static files. A URL path is decoded strictly (server/url.hpp), every
// segment is checked ('..', '.', hidden names), and the file is canonicalised and must lie inside
// the canonical web root, so neither encoded traversal nor symbolic links leave it.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace sphles::server {

struct StaticLookup {
  unsigned status = 200;  // 200, 400 (malformed or traversal) or 404
  std::string message;    // why, if status != 200
  std::filesystem::path file;
};

class StaticFiles {
 public:
  /// `root` need not exist (then every lookup is a 404 that says so).
  explicit StaticFiles(std::filesystem::path root);

  /// Resolves the raw (still percent-encoded) path of a request target; "/" and directories
  /// map to their index.html.
  StaticLookup lookup(std::string_view raw_path) const;

  const std::filesystem::path& root() const { return root_; }

 private:
  std::filesystem::path root_;  // canonical, or as given if it does not exist
  bool root_exists_ = false;
};

/// Content-Type by file extension (text types with charset=utf-8); application/octet-stream
/// for unknown extensions.
std::string_view mime_type(const std::filesystem::path& file);

/// True if `path` is `root` or lies below it (both canonical), compared by components.
bool is_within(const std::filesystem::path& root, const std::filesystem::path& path);

}  // namespace sphles::server
