// SPDX-License-Identifier: GPL-3.0-or-later
// The handlers of the REST API (docs/api.md), internal to server/: what they share with the
// router (Services, Context, Handler), the helpers several resources use, and every handler's
// declaration. server/router.cpp's route table says which path and method reaches each one.
// The definitions are grouped by resource:
//
//   service.cpp      the service itself: health, the OpenAPI and AsyncAPI documents, the scene
//                    schema, the presets, and the web/ files (the dashboard)
//   runs.cpp         runs: list, create, estimate, get, transitions, delete, parameters
//   run_history.cpp  what a run has computed so far: time series, analysis history, reference
//                    curve, resolved scales, log, latest spectrum and statistics
//   run_files.cpp    a run's pictures and files: latest image, frames, files, archive
//   references.cpp   reference jobs (control/reference_jobs.hpp)
//
// A handler runs on a worker thread, may throw (Router::handle turns any exception into the
// JSON error, ApiError with its own status), and only reads the services.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/run_manager.hpp"
#include "server/history.hpp"
#include "server/responses.hpp"
#include "server/static_files.hpp"

namespace sphles::server {

class ProductCache;
class StreamRegistry;

namespace handlers {

/// What a Router holds for its handlers: run control, the streams and products it shares with
/// the WebSocket sessions, the server's options, and caches.
struct Services {
  control::RunManager& manager;
  StreamRegistry& streams;
  ProductCache& products;
  std::string token;  // empty: no token needed
  ResponseLimits limits;
  std::filesystem::path reference_dir;  // data/reference: the DNS of GET reference
  std::filesystem::path scenes_dir;     // scenes/: the scene files of GET scenes
  StaticFiles web;
  std::string presets;  // RunManager::presets(), serialised once
  mutable SeriesIndexCache series;
};

/// One request as its route matched it.
struct Context {
  const Request& request;
  std::vector<std::string> params;  // values of the {...} segments, in order
  std::map<std::string, std::string> query;
};

using Handler = Response (*)(const Services&, const Context&);

// --- shared by several resources (handlers.cpp) ----------------------------------------------

/// The run `id`; control::UnknownRunError (404) if there is none.
std::shared_ptr<control::Run> find_run(const Services& s, const std::string& id);

/// The query parameter `name` as a non-negative integer, `fallback` if absent; ApiError 400
/// naming it otherwise.
std::uint64_t query_unsigned(const Context& c, const std::string& name, std::uint64_t fallback);

/// since_step, limit and (time series only) max_points of a history request; `limit` and
/// `max_points` at most the server's row limit.
HistoryQuery history_query(const Services& s, const Context& c, bool decimation);

/// The reference run of the scene's flow in the server's reference data or among its finished
/// reference jobs: the one with the most grid points.
std::optional<std::filesystem::path> reference_run_of(const Services& s, const sim::Scene& scene);

// --- service.cpp -----------------------------------------------------------------------------

Response health(const Services& s, const Context& c);
Response openapi(const Services& s, const Context& c);
Response asyncapi(const Services& s, const Context& c);
Response scene_schema(const Services& s, const Context& c);
Response presets(const Services& s, const Context& c);
/// GET /api/scenes: the scene files of the scenes directory, read at each request.
Response scene_files(const Services& s, const Context& c);
/// A file of web/ for a path outside /api (GET and HEAD only, else 405 with Allow).
Response serve_static(const Services& s, const Request& request, std::string_view path);

// --- runs.cpp --------------------------------------------------------------------------------

Response list_runs(const Services& s, const Context& c);
Response create_run(const Services& s, const Context& c);
Response estimate_run(const Services& s, const Context& c);
Response get_run(const Services& s, const Context& c);
Response delete_run(const Services& s, const Context& c);
Response change_parameters(const Services& s, const Context& c);
/// GET stream without an Upgrade: 426 naming the upgrade (RFC 9110 §15.5.22), 404 if no run.
Response stream_without_upgrade(const Services& s, const Context& c);

/// POST /api/runs/{id}/ACTION: the transition, then the run's summary.
template <void (control::RunManager::*Action)(const std::string&)>
Response transition(const Services& s, const Context& c) {
  const std::string& id = c.params[0];
  (s.manager.*Action)(id);
  return json_response(c.request, run_summary_json(*find_run(s, id)));
}

/// POST /api/runs/{id}/stop: 200 with the stopped run's summary, 202 with the summary of a run
/// still stopping (its solver's step outlasted the stop's grace period, or a stop was under
/// way already).
Response stop_run(const Services& s, const Context& c);

// --- run_history.cpp -------------------------------------------------------------------------

Response timeseries(const Services& s, const Context& c);
Response analysis_history(const Services& s, const Context& c);
Response reference(const Services& s, const Context& c);
Response resolved(const Services& s, const Context& c);
Response run_log(const Services& s, const Context& c);
Response spectrum(const Services& s, const Context& c);
Response statistics(const Services& s, const Context& c);

// --- run_files.cpp ---------------------------------------------------------------------------

Response latest_image(const Services& s, const Context& c);
Response list_frames(const Services& s, const Context& c);
Response get_frame(const Services& s, const Context& c);
Response list_files(const Services& s, const Context& c);
Response get_file(const Services& s, const Context& c);
Response get_archive(const Services& s, const Context& c);
/// POST /api/runs/{id}/movies: the run's saved frames of a field as movies/FIELD.webm
/// (render/movie.hpp), 201 with its path, url, frames, size and duration.
Response make_movie(const Services& s, const Context& c);

// --- references.cpp --------------------------------------------------------------------------

Response list_references(const Services& s, const Context& c);
Response create_reference(const Services& s, const Context& c);
Response get_reference(const Services& s, const Context& c);
Response delete_reference(const Services& s, const Context& c);

/// POST /api/references/{id}/ACTION: the transition, then the job.
template <void (control::ReferenceJobs::*Action)(const std::string&)>
Response reference_transition(const Services& s, const Context& c) {
  control::ReferenceJobs& jobs = s.manager.references();
  (jobs.*Action)(c.params[0]);
  return json_response(c.request, reference_job_json(jobs.get(c.params[0])));
}

}  // namespace handlers
}  // namespace sphles::server
