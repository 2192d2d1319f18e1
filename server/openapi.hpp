// SPDX-License-Identifier: GPL-3.0-or-later
// The OpenAPI document of the service (and the AsyncAPI document of its WebSocket stream):
// server/openapi.json (embedded at build time,
// cmake/EmbedFile.cmake) with the scene's schema as its Scene and ScenePatch components
// (control/scene_schema.hpp), so that the API describes scene bodies by the one declaration.
#pragma once

#include <string>
#include <string_view>

namespace sphles::server {

/// The bytes of server/openapi.json.
std::string_view openapi_document();

/// The bytes of server/asyncapi.json.
std::string_view asyncapi_document();

/// The AsyncAPI 3.0 document of the run stream served at /api/asyncapi.json: asyncapi_document()
/// with components.schemas taken from served_openapi_document(), so that a message's payload and
/// the REST body it mirrors are one declaration.
const std::string& served_asyncapi_document();

/// The OpenAPI 3.1 document served at /api/openapi.json: openapi_document() with
/// components.schemas.Scene and ScenePatch filled in from the scene schema.
const std::string& served_openapi_document();

}  // namespace sphles::server
