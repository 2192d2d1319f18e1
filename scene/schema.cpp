// SPDX-License-Identifier: GPL-3.0-or-later
#include "scene/schema.hpp"

#include <sstream>
#include <stdexcept>

namespace sphles::scene {

using nlohmann::json;

namespace {

/// "#/$defs/name" (the only references the schema uses) resolved against the whole document.
const json& resolve(const json& node) {
  const auto ref = node.find("$ref");
  if (ref == node.end()) return node;
  const std::string target = ref->get<std::string>();
  if (target.rfind("#/", 0) != 0)
    throw std::logic_error("scene schema: unsupported $ref '" + target + "'");
  return scene_schema_document().at(json::json_pointer(target.substr(1)));
}

std::string format_bound(const json& value) {
  if (value.is_number_integer()) return std::to_string(value.get<long long>());
  if (value.is_number_unsigned()) return std::to_string(value.get<unsigned long long>());
  std::ostringstream s;
  s << value.get<double>();
  return s.str();
}

void collect_fields(const json& node, const std::string& path, std::vector<std::string>& out) {
  const json& object = resolve(node);
  const auto properties = object.find("properties");
  if (properties == object.end()) return;
  for (const auto& [key, child] : properties->items()) {
    const std::string field = path.empty() ? key : path + "." + key;
    out.push_back(field);
    collect_fields(child, field, out);
  }
}

}  // namespace

const json& scene_schema_document() {
  static const json document = json::parse(scene_schema_text());
  return document;
}

const json* scene_schema_property(const json& object, const std::string& key) {
  const json& resolved = resolve(object);
  if (const auto properties = resolved.find("properties"); properties != resolved.end())
    if (const auto it = properties->find(key); it != properties->end()) return &resolve(*it);
  if (const auto extra = resolved.find("additionalProperties");
      extra != resolved.end() && extra->is_object())
    return &resolve(*extra);
  return nullptr;
}

std::vector<std::string> dotted_keys(std::string_view dotted) {
  std::vector<std::string> keys;
  if (dotted.empty()) return keys;
  std::size_t start = 0;
  while (true) {
    const std::size_t end = dotted.find('.', start);
    keys.emplace_back(dotted.substr(start, end == std::string_view::npos ? end : end - start));
    if (end == std::string_view::npos) return keys;
    start = end + 1;
  }
}

const json* scene_schema_node(std::string_view dotted) {
  const json* node = &scene_schema_document();
  for (const std::string& key : dotted_keys(dotted)) {
    if (!node) break;
    node = scene_schema_property(*node, key);
  }
  return node;
}

std::optional<std::string> violated_bounds(const json& node, double x) {
  const auto lower_inclusive = node.find("minimum"),
             lower_exclusive = node.find("exclusiveMinimum");
  const auto upper_inclusive = node.find("maximum"),
             upper_exclusive = node.find("exclusiveMaximum");
  const bool has_lower = lower_inclusive != node.end() || lower_exclusive != node.end();
  const bool has_upper = upper_inclusive != node.end() || upper_exclusive != node.end();
  bool ok = true;
  if (lower_inclusive != node.end()) ok = ok && x >= lower_inclusive->get<double>();
  if (lower_exclusive != node.end()) ok = ok && x > lower_exclusive->get<double>();
  if (upper_inclusive != node.end()) ok = ok && x <= upper_inclusive->get<double>();
  if (upper_exclusive != node.end()) ok = ok && x < upper_exclusive->get<double>();
  if (ok) return std::nullopt;
  const json& lower = lower_exclusive != node.end() ? *lower_exclusive : *lower_inclusive;
  const json& upper = upper_exclusive != node.end() ? *upper_exclusive : *upper_inclusive;
  if (has_lower && has_upper)
    return "must be in " + std::string(lower_exclusive != node.end() ? "(" : "[") +
           format_bound(lower) + ", " + format_bound(upper) +
           (upper_exclusive != node.end() ? ")" : "]");
  if (has_lower)
    return std::string(lower_exclusive != node.end() ? "must be > " : "must be >= ") +
           format_bound(lower);
  return std::string(upper_exclusive != node.end() ? "must be < " : "must be <= ") +
         format_bound(upper);
}

std::vector<std::string> scene_schema_fields() {
  std::vector<std::string> fields;
  collect_fields(scene_schema_document(), "", fields);
  return fields;
}

}  // namespace sphles::scene
