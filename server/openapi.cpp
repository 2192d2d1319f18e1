// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/openapi.hpp"

#include <nlohmann/json.hpp>

#include "control/scene_schema.hpp"

namespace sphles::server {

namespace {

/// A JSON Schema document as an OpenAPI component: the component is named by the document, so
/// the schema's own "$schema" and "$id" stay out.
nlohmann::json as_component(nlohmann::json schema) {
  schema.erase("$schema");
  schema.erase("$id");
  return schema;
}

}  // namespace

const std::string& served_openapi_document() {
  static const std::string document = [] {
    nlohmann::json d = nlohmann::json::parse(openapi_document());
    nlohmann::json& schemas = d["components"]["schemas"];
    schemas["Scene"] = as_component(control::scene_schema());
    schemas["ScenePatch"] = as_component(control::scene_patch_schema());
    schemas["SceneDocument"] = as_component(control::scene_document_schema());
    return d.dump(2);
  }();
  return document;
}

const std::string& served_asyncapi_document() {
  static const std::string document = [] {
    nlohmann::json d = nlohmann::json::parse(asyncapi_document());
    d["components"]["schemas"] =
        nlohmann::json::parse(served_openapi_document())["components"]["schemas"];
    return d.dump(2);
  }();
  return document;
}

}  // namespace sphles::server
