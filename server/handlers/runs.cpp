// SPDX-License-Identifier: GPL-3.0-or-later
// Runs (docs/api.md "Routes", "Creating a run", "Run summary and detail", "Live parameter
// changes"): list, create, estimate, get, delete, change parameters. The state transitions are
// handlers::transition (handlers.hpp), one instance per action.
#include <memory>
#include <string>
#include <vector>

#include "server/handlers/handlers.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server::handlers {

namespace http = boost::beast::http;

Response list_runs(const Services& s, const Context& c) {
  nlohmann::json runs = nlohmann::json::array();
  for (const auto& run : s.manager.list()) runs.push_back(run_summary_json(*run));
  return json_response(c.request, runs);
}

Response create_run(const Services& s, const Context& c) {
  const nlohmann::json body = json_body(c.request);
  const control::CreateRequest request = control::parse_create_request(body);
  const std::shared_ptr<control::Run> run = s.manager.create(request);
  Response res = json_response(c.request, run_summary_json(*run), http::status::created);
  res.set(http::field::location, "/api/runs/" + run->id());
  return res;
}

/// What a create request would need and take (memory, disk, steps, time per step on this
/// machine), creating nothing: RunManager::estimate.
Response estimate_run(const Services& s, const Context& c) {
  const nlohmann::json body = json_body(c.request);
  return json_response(c.request, s.manager.estimate(control::parse_create_request(body)));
}

Response get_run(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  nlohmann::json detail = run_detail_json(*run, s.streams.counters(run->id()));
  // Whether GET resolved answers: a spectrum and a reference run of the run's flow.
  detail["available"]["resolved"] = detail["available"]["spectrum"].get<bool>() &&
                                    reference_run_of(s, run->spec().scene).has_value();
  return json_response(c.request, detail);
}

Response stop_run(const Services& s, const Context& c) {
  const std::string& id = c.params[0];
  const bool ended = s.manager.stop(id);
  return json_response(c.request, run_summary_json(*find_run(s, id)),
                       ended ? http::status::ok : http::status::accepted);
}

Response delete_run(const Services& s, const Context& c) {
  const std::string& id = c.params[0];
  s.manager.remove(id);  // 404 unknown, 409 active; the directory goes with it
  return json_response(c.request, {{"deleted", id}});
}

Response change_parameters(const Services& s, const Context& c) {
  // The body before the run (docs/api.md "Conventions": 415 and 400 before the run's 404).
  const nlohmann::json patch = json_body(c.request);
  const auto run = find_run(s, c.params[0]);
  const std::vector<std::string> changed = run->apply_changes(patch);
  return json_response(c.request, {{"changed", changed}, {"effective", "next step"}});
}

Response stream_without_upgrade(const Services& s, const Context& c) {
  find_run(s, c.params[0]);
  Response res = error_response(
      ApiError(426, "this is a WebSocket endpoint: send an Upgrade: websocket request"),
      c.request.version(), c.request.keep_alive());
  res.set(http::field::upgrade, "websocket");
  return res;
}

}  // namespace sphles::server::handlers
