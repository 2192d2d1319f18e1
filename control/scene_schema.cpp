// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/scene_schema.hpp"

#include <stdexcept>
#include <string_view>
#include <vector>

#include <valijson/adapters/nlohmann_json_adapter.hpp>
#include <valijson/schema.hpp>
#include <valijson/schema_parser.hpp>
#include <valijson/validation_results.hpp>
#include <valijson/validator.hpp>

#include "analysis/config.hpp"
#include "scene/presets.hpp"
#include "scene/schema.hpp"
#include "sim/kernels.hpp"
#include "sim/scene.hpp"
#include "sim/scheme.hpp"
#include "sim/subfilter.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

/// A copy of `node` with every {"$ref": "#/..."} replaced by its target (the published schema
/// stands alone, e.g. as a component of the OpenAPI document).
json inline_refs(const json& node, const json& root) {
  if (node.is_object()) {
    if (const auto ref = node.find("$ref"); ref != node.end())
      return inline_refs(root.at(json::json_pointer(ref->get<std::string>().substr(1))), root);
    json out = json::object();
    for (const auto& [key, value] : node.items())
      if (key != "$defs") out[key] = inline_refs(value, root);
    return out;
  }
  if (node.is_array()) {
    json out = json::array();
    for (const json& value : node) out.push_back(inline_refs(value, root));
    return out;
  }
  return node;
}

json& node_at(json& schema, std::string_view dotted) {
  json* node = &schema;
  for (const std::string& key : scene::dotted_keys(dotted)) node = &node->at("properties").at(key);
  return *node;
}

json build_schema() {
  const json& document = scene::scene_schema_document();
  json schema = inline_refs(document, document);
  const std::vector<std::string> slice_fields = analysis::kSliceFieldNames.names();
  std::vector<std::string> grid_fields = {"velocity"};
  grid_fields.insert(grid_fields.end(), slice_fields.begin(), slice_fields.end());
  const auto set_enum = [&](std::string_view field, const std::vector<std::string>& values) {
    node_at(schema, field)["enum"] = values;
  };
  const auto set_item_enum = [&](std::string_view field, const std::vector<std::string>& values) {
    node_at(schema, field)["items"]["enum"] = values;
  };
  set_enum("preset", scene::preset_names());
  set_enum("case", sim::kCaseNames.names());
  set_enum("kernel.type", sim::kKernelNames.names());
  set_enum("scheme.type", sim::kSchemeNames.names());
  const auto scheme_choice = [&](const auto& p) {
    if constexpr (requires { p.names; }) set_enum("scheme." + std::string(p.key), p.names->names());
  };
  std::apply([&](const auto&... p) { (scheme_choice(p), ...); }, sim::kSchemeParameters);
  set_enum("subfilter.model", sim::kSubfilterModelNames.names());
  set_enum("initial.mass", sim::kInitialMassNames.names());
  set_item_enum("analysis.products", analysis::kProductNames.names());
  set_item_enum("analysis.slice.fields", slice_fields);
  set_item_enum("analysis.particle_fields", slice_fields);
  set_item_enum("analysis.grid_fields", grid_fields);
  set_enum("analysis.gridding.velocity", analysis::kVelocityGriddingNames.names());
  set_enum("analysis.gridding.vorticity", analysis::kVorticityEstimateNames.names());
  set_item_enum("render.fields", slice_fields);
  set_enum("render.view3d.field", slice_fields);
  node_at(schema, "render.colour")["propertyNames"] = {{"enum", slice_fields}};
  return schema;
}

/// The schema with null allowed beside every value, and no key required.
json patch_of(const json& node) {
  json out = node;
  // A patch changes what it names and leaves the rest: no key has a default (a typed client
  // generated from a schema with defaults makes every key mandatory).
  out.erase("default");
  if (out.contains("properties"))
    for (auto& [key, child] : out["properties"].items()) child = patch_of(child);
  if (out.contains("additionalProperties") && out["additionalProperties"].is_object())
    out["additionalProperties"] = patch_of(out["additionalProperties"]);
  json type = out.value("type", json());
  if (type.is_string()) type = json::array({type});
  if (type.is_array() && std::find(type.begin(), type.end(), "null") == type.end())
    type.push_back("null");
  if (!type.is_null()) out["type"] = type;
  if (out.contains("enum") &&
      std::find(out["enum"].begin(), out["enum"].end(), nullptr) == out["enum"].end())
    out["enum"].push_back(nullptr);
  return out;
}

/// valijson's context ("<root>", "[kernel]", "[type]", "[0]") as the dotted field "kernel.type[0]".
std::string dotted_context(const std::vector<std::string>& context) {
  std::string field;
  for (const std::string& part : context) {
    if (part == "<root>" || part.size() < 2) continue;
    const std::string inner = part.substr(1, part.size() - 2);
    const bool index = !inner.empty() && inner.find_first_not_of("0123456789") == std::string::npos;
    if (index)
      field += part;
    else
      field += (field.empty() ? "" : ".") + inner;
  }
  return field.empty() ? "(top level)" : field;
}

/// "'dotted.field' reason".
std::optional<std::string> text_of(const std::optional<SchemaViolation>& violation) {
  if (!violation) return std::nullopt;
  return "'" + violation->field + "' " + violation->reason;
}

/// A parsed draft-07 schema and the first violation of it by a document.
class Validator {
 public:
  explicit Validator(const json& schema) {
    valijson::SchemaParser parser(valijson::SchemaParser::kDraft7);
    valijson::adapters::NlohmannJsonAdapter adapter(schema);
    parser.populateSchema(adapter, schema_);
  }
  std::optional<SchemaViolation> violation(const json& document) const {
    valijson::Validator check;
    valijson::ValidationResults results;
    valijson::adapters::NlohmannJsonAdapter adapter(document);
    if (check.validate(schema_, adapter, &results)) return std::nullopt;
    // The deepest error names the field most precisely (the first is its enclosing object).
    valijson::ValidationResults::Error error, deepest;
    while (results.popError(error))
      if (error.context.size() > deepest.context.size()) deepest = error;
    return SchemaViolation{dotted_context(deepest.context), deepest.description};
  }

 private:
  valijson::Schema schema_;
};

}  // namespace

const json& scene_schema() {
  static const json schema = build_schema();
  return schema;
}

json scene_document_schema() {
  const std::function<void(json&)> strip = [&strip](json& node) {
    if (node.is_object()) {
      node.erase("default");
      for (auto& [key, child] : node.items()) strip(child);
    } else if (node.is_array()) {
      for (json& child : node) strip(child);
    }
  };
  json document = scene_schema();
  strip(document);
  document["title"] = "sphles scene document";
  return document;
}

json scene_patch_schema() {
  json patch = patch_of(scene_schema());
  patch["title"] = "sphles scene patch";
  patch["description"] =
      "A JSON merge patch (RFC 7396) of a scene: the keys of the scene, each also null (removes "
      "the key, back to its default).";
  patch["type"] = "object";
  return patch;
}

std::optional<SchemaViolation> first_schema_violation(const json& document) {
  static const Validator validator(scene_schema());
  return validator.violation(document);
}

std::optional<std::string> schema_violation(const json& document) {
  return text_of(first_schema_violation(document));
}

std::optional<std::string> json_schema_violation(const json& schema, const json& document) {
  return text_of(Validator(schema).violation(document));
}

LiveRule live_rule(const std::string& dotted) {
  // The innermost x-live, x-fixed or x-scope on the way from the scene to the field decides.
  LiveRule rule;
  const json* node = &scene::scene_schema_document();
  for (const std::string& key : scene::dotted_keys(dotted)) {
    node = scene::scene_schema_property(*node, key);
    if (!node) break;
    if (const auto live = node->find("x-live"); live != node->end()) {
      rule.live = live->get<bool>();
      rule.reason.clear();
    }
    if (const auto fixed = node->find("x-fixed"); fixed != node->end()) {
      rule.live = false;
      rule.reason = fixed->get<std::string>();
    }
    if (const auto scope = node->find("x-scope"); scope != node->end())
      rule.scope = scope->get<std::string>();
  }
  return rule;
}

}  // namespace sphles::control
