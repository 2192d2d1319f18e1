// SPDX-License-Identifier: GPL-3.0-or-later
// Reference jobs (docs/api.md "Reference jobs", control/reference_jobs.hpp): the spectral DNS of
// a run's flow, estimated or queued, listed, read, stopped, resumed and deleted. The stop and
// resume transitions are handlers::reference_transition (handlers.hpp).
#include <memory>

#include "server/handlers/handlers.hpp"

namespace sphles::server::handlers {

namespace http = boost::beast::http;

/// A spectral reference of a run's flow: its estimate with "dry_run", else a queued job.
Response create_reference(const Services& s, const Context& c) {
  const control::ReferenceRequest request = control::parse_reference_request(json_body(c.request));
  std::shared_ptr<control::Run> run;
  try {
    run = s.manager.get(request.run);
  } catch (const control::UnknownRunError& e) {
    throw ApiError(404, e.what(), "run");
  }
  control::ReferenceJobs& jobs = s.manager.references();
  const control::ReferencePlan plan = control::ReferenceJobs::plan(run->document(), request);
  if (request.dry_run) return json_response(c.request, jobs.estimate(plan));
  const control::ReferenceJobStatus job = jobs.submit(run->id(), plan);
  Response res = json_response(c.request, reference_job_json(job), http::status::created);
  res.set(http::field::location, "/api/references/" + job.id);
  return res;
}

Response list_references(const Services& s, const Context& c) {
  nlohmann::json jobs = nlohmann::json::array();
  for (const auto& job : s.manager.references().list()) jobs.push_back(reference_job_json(job));
  return json_response(c.request, jobs);
}

Response get_reference(const Services& s, const Context& c) {
  return json_response(c.request, reference_job_json(s.manager.references().get(c.params[0])));
}

Response delete_reference(const Services& s, const Context& c) {
  s.manager.references().remove(c.params[0]);  // 404 unknown, 409 queued or running
  return json_response(c.request, {{"deleted", c.params[0]}});
}

}  // namespace sphles::server::handlers
