// SPDX-License-Identifier: GPL-3.0-or-later
// JSON views of run-control objects, shared by the REST routes and the WebSocket stream
// (docs/api.md is the contract). Pure functions: no I/O, no locks beyond what Run takes.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "control/reference_jobs.hpp"
#include "control/run.hpp"

namespace sphles::server {

/// Per-run WebSocket figures reported in the run detail ("stream").
struct StreamCounters {
  std::size_t clients = 0;
  std::uint64_t dropped = 0;  // images dropped from full client queues, all clients ever
};

/// {"time","step","dt","kinetic_energy","dissipation","max_density_deviation","max_speed",...}
nlohmann::json metrics_json(const control::MetricsSample& sample);

/// Run summary: {"id","name","state","reason","case","dimension","particles_per_side","time",
/// "end_time","step","progress","steps_per_second","wall_seconds"}.
nlohmann::json run_summary_json(const control::Run& run);
nlohmann::json run_summary_json(const control::Run& run, const control::RunStatus& status,
                                const nlohmann::json& document);
/// A reference job: {"id","run","state","error","time","end_time","step","progress",
/// "points_per_side","cfl","directory","estimate":{"memory_bytes","checkpoint_bytes","steps",
/// "max_wavenumber"}}.
nlohmann::json reference_job_json(const control::ReferenceJobStatus& job);

/// Summary + {"scene","latest","changeable","counters","stream"}.
nlohmann::json run_detail_json(const control::Run& run, const StreamCounters& stream);

// The spectrum and statistics bodies: server/product_cache.hpp (serialised once per frame).

/// The JSON header of a binary image message (without the 4-byte length prefix).
nlohmann::json image_header_json(const std::string& run_id, const control::ImageEvent& image);

/// A client error or a server failure, as the JSON error body
///   {"error": {"status": 400, "message": "...", "field": "dotted.field" | null}}.
class ApiError : public std::runtime_error {
 public:
  ApiError(unsigned status, const std::string& message,
           std::optional<std::string> field = std::nullopt)
      : std::runtime_error(message), status_(status), field_(std::move(field)) {}
  unsigned status() const { return status_; }
  const std::optional<std::string>& field() const { return field_; }

 private:
  unsigned status_;
  std::optional<std::string> field_;
};

/// {"error": {"status", "message", "field"}}.
nlohmann::json error_json(const ApiError& error);

/// What an exception from run control means for a client: UnknownRunError 404, StateError 409,
/// ChangeError and sim::SceneError 400 (with the field they name), std::bad_alloc 503 (out of
/// memory: try again), anything else 500.
ApiError to_api_error(const std::exception& error);

/// Deepest nesting of arrays and objects accepted in client JSON (the library's merge patch
/// and serialisation recurse).
inline constexpr int kMaxJsonDepth = 64;

/// Parses client JSON. Throws ApiError 400 for malformed text or nesting deeper than
/// kMaxJsonDepth; `what` names the input in the message ("body", "message").
nlohmann::json parse_client_json(std::string_view text, std::string_view what = "body");

/// Serialises for the wire: invalid UTF-8 (e.g. echoed from a URL) is replaced, never thrown.
std::string dump(const nlohmann::json& value);

}  // namespace sphles::server
