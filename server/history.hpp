// SPDX-License-Identifier: GPL-3.0-or-later
// The run's growing CSV files as JSON pages: timeseries.csv (GET /api/runs/{id}/timeseries) and
// frames/index.csv (GET /api/runs/{id}/frames). Files are read in chunks, never whole, so any
// length can be served; an answer is bounded in rows (`limit`, at most ResponseLimits::max_rows)
// and bytes (ResponseLimits::max_bytes), and a history that does not fit one answer is paged
// (`since_step` + `limit`: the answer says whether more rows follow and where to continue) or
// decimated (`max_points`: first and last rows kept). What cannot be served is an ApiError (507
// naming the limit), never an empty 200.
//
// `since_step` is efficient: a SeriesIndex per file (steps at byte offsets, extended by the bytes
// appended since the last request) lets a page start near its first row and stop at its last.
#pragma once

#include <cstdint>
#include <filesystem>
#include <list>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace sphles::server {

/// Bounds of one answer (ServerOptions::responses).
struct ResponseLimits {
  std::size_t max_bytes = 128u << 20;  // one response body or stream message; beyond: 507
  std::size_t max_rows = 1u << 20;     // rows of one time series or frames answer; `limit` ≤ this
};

/// What a client asks of a history: rows with step > since_step, then at most `limit` of them,
/// or the whole rest decimated to at most `max_points` rows (not both).
struct HistoryQuery {
  std::optional<std::uint64_t> since_step;
  std::optional<std::size_t> limit;
  std::optional<std::size_t> max_points;
};

/// Where in a time-series file its rows are, so that a page need not read from the start. One per
/// file (by inode), shared by requests; thread-safe.
class SeriesIndexCache {
 public:
  struct Index;
  /// The index of `file`, brought up to the file's current end. nullptr if the file does not
  /// exist. Throws ApiError 500 if it exists but cannot be read.
  std::shared_ptr<const Index> update(const std::filesystem::path& file);

  static constexpr std::size_t kMaxFiles = 64;  // least recently used out beyond

 private:
  std::mutex mutex_;
  std::list<std::pair<std::filesystem::path, std::shared_ptr<Index>>> files_;  // newest first
};

/// The body of GET timeseries: {"columns","data","more","next_since_step","stride"}. Throws
/// ApiError 400 (bad query, naming the parameter), 507 (beyond the limits) or 500 (I/O).
std::string timeseries_answer(const std::filesystem::path& file, const HistoryQuery& query,
                              const ResponseLimits& limits, SeriesIndexCache& cache);

/// The body of GET frames ([{"time","step","field","file","url"}]) and whether rows with a later
/// step follow (paging with `limit`: a page never splits a step). `url_base` + file = url.
struct FramesPage {
  std::string body;
  bool more = false;
  std::optional<std::uint64_t> last_step;
};
FramesPage frames_answer(const std::filesystem::path& index_file, const std::string& url_base,
                         const HistoryQuery& query, const ResponseLimits& limits);

}  // namespace sphles::server
