// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/handlers/handlers.hpp"

#include <charconv>
#include <utility>

#include "analysis/reference.hpp"

namespace sphles::server::handlers {

namespace fs = std::filesystem;

std::shared_ptr<control::Run> find_run(const Services& s, const std::string& id) {
  return s.manager.get(id);  // throws UnknownRunError → 404
}

std::uint64_t query_unsigned(const Context& c, const std::string& name, std::uint64_t fallback) {
  const auto it = c.query.find(name);
  if (it == c.query.end()) return fallback;
  std::uint64_t value = 0;
  const std::string& text = it->second;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size())
    throw ApiError(400, "'" + name + "' must be a non-negative integer", name);
  return value;
}

HistoryQuery history_query(const Services& s, const Context& c, bool decimation) {
  HistoryQuery q;
  if (c.query.contains("since_step")) q.since_step = query_unsigned(c, "since_step", 0);
  const std::uint64_t max_rows = s.limits.max_rows;
  const auto bounded = [&](const std::string& name, std::uint64_t min) -> std::size_t {
    const std::uint64_t v = query_unsigned(c, name, 0);
    if (v < min || v > max_rows)
      throw ApiError(400,
                     "'" + name + "' must be an integer in [" + std::to_string(min) + ", " +
                         std::to_string(max_rows) + "] (the server's rows per answer)",
                     name);
    return static_cast<std::size_t>(v);
  };
  if (c.query.contains("limit")) q.limit = bounded("limit", 1);
  if (decimation && c.query.contains("max_points")) {
    constexpr std::uint64_t kMinPoints = 2;  // the first row and the last
    q.max_points = bounded("max_points", kMinPoints);
    if (q.limit)
      throw ApiError(400, "give either 'limit' (a page) or 'max_points' (decimated), not both",
                     "max_points");
  }
  return q;
}

std::optional<fs::path> reference_run_of(const Services& s, const sim::Scene& scene) {
  std::vector<fs::path> runs = analysis::reference_run_directories(s.reference_dir);
  for (fs::path& job : s.manager.references().done_directories()) runs.push_back(std::move(job));
  return analysis::best_reference_run(scene, runs);
}

}  // namespace sphles::server::handlers
