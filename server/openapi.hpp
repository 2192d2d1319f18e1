// server/openapi.json, embedded at build time (server/CMakeLists.txt generates the definition).
#pragma once

#include <string_view>

namespace sphles::server {

/// The OpenAPI 3 document served at /api/openapi.json.
std::string_view openapi_document();

}  // namespace sphles::server
