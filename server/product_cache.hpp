// SPDX-License-Identifier: GPL-3.0-or-later
// The serialised spectrum and statistics of analysis frames, built once per frame on first use
// and shared read-only by every GET /spectrum, GET /statistics and every WebSocket client of the
// run (each used to serialise the frame again, and a 10⁸-bin histogram took 3 GB each time).
//
// The text is written without an nlohmann document (server/json_writer.hpp) and is never larger
// than the server's response limit: a frame whose product would be larger answers ApiError 507
// (remembered for that frame, so it is not tried again); running out of memory while building
// answers 503 (not remembered: the next reader tries again). Entries hold frames only weakly and
// go when their frame does (at most kMaxFrames entries, least recently used out first).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "analysis/products.hpp"
#include "server/api_json.hpp"

namespace sphles::server {

enum class Product { spectrum, statistics };

class ProductCache {
 public:
  explicit ProductCache(std::size_t max_bytes);

  /// The JSON body of GET /api/runs/{id}/spectrum (or /statistics) for `frame`, or nullptr if
  /// the frame has no such product. Throws ApiError 507 (too large) or 503 (out of memory).
  /// Concurrent callers for the same frame wait for one serialisation.
  std::shared_ptr<const std::string> get(
      const std::shared_ptr<const analysis::AnalysisFrame>& frame, Product product);

  std::size_t max_bytes() const { return max_bytes_; }
  std::size_t entries() const;

  static constexpr std::size_t kMaxFrames = 16;

 private:
  struct Slot {
    std::mutex mutex;  // held while the text is built
    std::shared_ptr<const std::string> text;
    std::optional<ApiError> error;  // too large: the same answer for every later reader
  };
  struct Entry {
    std::weak_ptr<const analysis::AnalysisFrame> frame;
    std::array<std::shared_ptr<Slot>, 2> slots;
    std::uint64_t used = 0;
  };
  std::shared_ptr<Slot> slot(const std::shared_ptr<const analysis::AnalysisFrame>& frame,
                             Product product);

  const std::size_t max_bytes_;
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;
  std::uint64_t clock_ = 0;
};

/// The bodies themselves (what the cache stores), at most `max_bytes` long: ApiError 507 beyond.
std::string spectrum_text(const analysis::AnalysisFrame& frame, std::size_t max_bytes);
std::string statistics_text(const analysis::AnalysisFrame& frame, std::size_t max_bytes);

}  // namespace sphles::server
