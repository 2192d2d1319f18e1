// SPDX-License-Identifier: GPL-3.0-or-later
// The scene's schema as the program publishes it: scene/scene.schema.json with the names of every
// registry filled in (kernels, schemes, sub-filter models, analysis products and fields, presets),
// for the API (GET /api/schema/scene, the OpenAPI document), the dashboard, `sphles schema` and
// docs/scenes.md; the validation of a whole scene document against it; and the live-change rules
// it declares ("x-live", "x-fixed", "x-scope").
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace sphles::control {

/// The published scene schema (draft-07 JSON Schema): "$ref"s inlined, registry names as "enum".
const nlohmann::json& scene_schema();

/// The same for a JSON merge patch of a scene (PATCH /api/runs/{id}/parameters): every value may
/// also be null (a removal).
nlohmann::json scene_patch_schema();
/// The scene schema as the schema of a document to create a run from: every key optional (a
/// left-out key takes its default), so no "default" keywords (a typed client generated with
/// openapi-typescript's defaults makes a key with a default mandatory).
nlohmann::json scene_document_schema();

/// A violation of a schema: the dotted field valijson names ("(top level)" for the document)
/// and what is wrong with it.
struct SchemaViolation {
  std::string field;
  std::string reason;
};

/// The first violation of scene_schema() by `document` (valijson); nullopt when it conforms.
std::optional<SchemaViolation> first_schema_violation(const nlohmann::json& document);

/// The same as "'dotted.field' reason".
std::optional<std::string> schema_violation(const nlohmann::json& document);

/// The first violation of the JSON Schema (draft-07) `schema` by `document`, as "'dotted.field'
/// reason"; nullopt when it conforms. "$ref"s resolve within `schema` ("#/..."), so a schema
/// may be {"$ref": "#/components/messages/metrics/payload", "components": {...}} to check a
/// message against a part of a larger document (the AsyncAPI document's payloads, tests).
std::optional<std::string> json_schema_violation(const nlohmann::json& schema,
                                                 const nlohmann::json& document);

/// Whether a running run may change the dotted field, and why not: the nearest "x-live" /
/// "x-fixed" of the field or its parents in the schema. `reason` is empty for a refusal the
/// schema gives no reason for. `scope` is the part of a run a change of it reconfigures, the
/// nearest "x-scope" ("solver", "analysis", "render"; empty: none of them).
struct LiveRule {
  bool live = false;
  std::string reason;
  std::string scope;
};
LiveRule live_rule(const std::string& dotted);

}  // namespace sphles::control
