// SPDX-License-Identifier: GPL-3.0-or-later
// The service itself (docs/api.md "Routes"): health, the API's own documents, the scene schema,
// the presets and scene files, and the dashboard's files from web/ for every path outside /api.
#include <optional>
#include <utility>

#include "control/scene_schema.hpp"
#include "server/handlers/handlers.hpp"
#include "server/openapi.hpp"

namespace sphles::server::handlers {

namespace http = boost::beast::http;

Response health(const Services& s, const Context& c) {
  return json_response(
      c.request,
      {{"status", "ok"}, {"version", SPHLES_VERSION}, {"runs", s.manager.list().size()}});
}

Response openapi(const Services&, const Context& c) {
  return make_response(c.request, http::status::ok, served_openapi_document(), "application/json");
}

Response asyncapi(const Services&, const Context& c) {
  return make_response(c.request, http::status::ok, served_asyncapi_document(), "application/json");
}

Response scene_schema(const Services&, const Context& c) {
  return json_response(c.request, control::scene_schema());
}

Response presets(const Services& s, const Context& c) {
  if (!s.presets.empty())
    return make_response(c.request, http::status::ok, s.presets, "application/json");
  return json_response(c.request, control::RunManager::presets());
}

Response scene_files(const Services& s, const Context& c) {
  return json_response(c.request, control::RunManager::scene_files(s.scenes_dir));
}

Response serve_static(const Services& s, const Request& request, std::string_view path) {
  if (request.method() != http::verb::get && request.method() != http::verb::head) {
    Response res = error_response(ApiError(405, "static files allow GET and HEAD only", "method"),
                                  request.version(), request.keep_alive());
    res.set(http::field::allow, "GET, HEAD");
    return res;
  }
  const StaticLookup found = s.web.lookup(path);
  if (found.status != 200) throw ApiError(found.status, found.message, "path");
  std::optional<std::string> content = read_file(found.file, s.limits.max_bytes);
  if (!content) throw ApiError(404, "path: cannot read the file", "path");
  return make_response(request, http::status::ok, std::move(*content), mime_type(found.file));
}

}  // namespace sphles::server::handlers
