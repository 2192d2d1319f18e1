// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/static_files.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <utility>

#include "server/url.hpp"

namespace sphles::server {

namespace fs = std::filesystem;

StaticFiles::StaticFiles(fs::path root) {
  std::error_code ec;
  fs::path canonical = fs::canonical(root, ec);
  root_exists_ = !ec && fs::is_directory(canonical, ec) && !ec;
  root_ = root_exists_ ? std::move(canonical) : std::move(root);
}

StaticLookup StaticFiles::lookup(std::string_view raw_path) const {
  const auto segments = path_segments(raw_path);
  if (!segments)
    return {400, "path: malformed percent-encoding or an encoded '/', '\\' or NUL", {}};
  for (const std::string& segment : *segments) {
    if (segment == "." || segment == "..")
      return {400, "path: '" + segment + "' segments are not allowed", {}};
    if (segment.front() == '.') return {404, "path: no such file", {}};
  }
  if (!root_exists_) return {404, "path: the web root " + root_.string() + " does not exist", {}};

  fs::path candidate = root_;
  for (const std::string& segment : *segments) candidate /= segment;
  std::error_code ec;
  if (fs::is_directory(candidate, ec)) candidate /= "index.html";
  const fs::path file = fs::canonical(candidate, ec);
  if (ec || !is_within(root_, file) || !fs::is_regular_file(file, ec) || ec)
    return {404, "path: no such file", {}};
  return {200, {}, file};
}

bool is_within(const fs::path& root, const fs::path& path) {
  auto r = root.begin(), p = path.begin();
  for (; r != root.end(); ++r, ++p) {
    if (r->empty() && std::next(r) == root.end()) break;  // trailing separator of the root
    if (p == path.end() || *r != *p) return false;
  }
  return true;
}

std::string_view mime_type(const fs::path& file) {
  static constexpr std::array<std::pair<std::string_view, std::string_view>, 26> kTypes{{
      {".html", "text/html; charset=utf-8"},
      {".htm", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".json", "application/json"},
      {".map", "application/json"},
      {".txt", "text/plain; charset=utf-8"},
      {".svg", "image/svg+xml"},
      {".png", "image/png"},
      {".jpg", "image/jpeg"},
      {".jpeg", "image/jpeg"},
      {".gif", "image/gif"},
      {".ico", "image/x-icon"},
      {".wasm", "application/wasm"},
      {".woff", "font/woff"},
      {".woff2", "font/woff2"},
      {".ttf", "font/ttf"},
      // What a run directory holds (GET /api/runs/{id}/files/...).
      {".csv", "text/csv; charset=utf-8"},
      {".log", "text/plain; charset=utf-8"},
      {".h5", "application/x-hdf5"},
      {".xdmf", "application/xml"},
      {".vti", "application/xml"},
      {".webm", "video/webm"},
      {".pvd", "application/xml"},
      {".npy", "application/octet-stream"},
  }};
  std::string extension = file.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const auto& [ext, type] : kTypes)
    if (ext == extension) return type;
  return "application/octet-stream";
}

}  // namespace sphles::server
