// SPDX-License-Identifier: GPL-3.0-or-later
// Reading validated configuration objects from JSON: every read names its dotted field and takes
// the field's type and bounds from the scene's schema (scene/scene.schema.json, scene/schema.hpp);
// keys the schema does not declare are reported as unknown. Used by every module that owns a
// section of a scene.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/schema.hpp"
#include "sim/format.hpp"
#include "sim/name_table.hpp"
#include "sim/scene.hpp"

namespace sphles::scene {

using sim::format_number;
using sim::NameTable;
using sim::parse_name;
using sim::SceneError;
using sim::throw_scene_error;

using nlohmann::json;

inline std::string describe_type(const json& value) {
  return value.type_name();
}

/// Levenshtein distance of two keys (insertions, deletions and substitutions).
inline std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

/// The known key `key` is most likely a typo of: the nearest by edit distance, if at most a
/// third of the key's length (and at least 1) edits away; of equally near keys, the one sharing
/// the longest prefix with `key` (tgv3d-case99: tgv3d-case9 rather than tgv3d-case19).
inline std::optional<std::string> closest_key(const std::string& key,
                                              const std::set<std::string>& known) {
  const auto common_prefix = [&](const std::string& candidate) {
    std::size_t n = 0;
    while (n < key.size() && n < candidate.size() && key[n] == candidate[n]) ++n;
    return n;
  };
  std::optional<std::string> best;
  std::size_t best_distance = std::max<std::size_t>(1, key.size() / 3) + 1, best_prefix = 0;
  for (const std::string& candidate : known) {
    const std::size_t d = edit_distance(key, candidate), prefix = common_prefix(candidate);
    if (d < best_distance || (d == best_distance && best && prefix > best_prefix)) {
      best_distance = d;
      best_prefix = prefix;
      best = candidate;
    }
  }
  return best;
}

/// Reads keys of one JSON object, remembering which were used so that the rest can be reported
/// as unknown. Targets hold their defaults on entry.
class ObjectReader {
 public:
  static constexpr bool kReads = true;

  /// The object at the dotted `path` of the scene ("" for the whole scene), whose schema the
  /// scene's schema must declare.
  ObjectReader(const json& object, std::string path)
      : object_(object), path_(std::move(path)), schema_(scene_schema_node(path_)) {
    if (!schema_) throw std::logic_error("scene schema declares no '" + label() + "'");
    if (!object_.is_object())
      throw_scene_error(label(), "must be an object, got " + describe_type(object_));
  }

  std::string field(const std::string& key) const {
    return path_.empty() ? key : path_ + "." + key;
  }

  /// The value of `key`, nullptr when absent. Throws std::logic_error when the schema does not
  /// declare the key (a reader asking for a key the schema does not declare is a defect).
  const json* find(const std::string& key) {
    schema_of(key);
    seen_.insert(key);
    const auto it = object_.find(key);
    return it == object_.end() ? nullptr : &*it;
  }

  ObjectReader object(const std::string& key) {
    static const json kEmpty = json::object();
    const json* value = find(key);
    return ObjectReader(value ? *value : kEmpty, field(key));
  }

  /// A number within the schema's bounds of the key, and `check` (for bounds that depend on
  /// other keys) when given.
  void number(const std::string& key, double& target,
              const std::function<std::optional<std::string>(double)>& check = {}) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_number())
      throw_scene_error(field(key), "must be a number, got " + describe_type(*value));
    const double x = value->get<double>();
    if (!std::isfinite(x)) throw_scene_error(field(key), "must be finite");
    if (auto reason = violated_bounds(schema_of(key), x))
      throw_scene_error(field(key), *reason + ", got " + format_number(x));
    if (check)
      if (auto reason = check(x))
        throw_scene_error(field(key), *reason + ", got " + format_number(x));
    target = x;
  }

  /// An integer within the schema's bounds of the key.
  template <class Int>
  void integer(const std::string& key, Int& target) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_number_integer())
      throw_scene_error(field(key),
                        "must be an integer, got " +
                            (value->is_number() ? "a fractional number" : describe_type(*value)));
    if (value->is_number_unsigned() && value->get<unsigned long long>() > kMaxLongLong)
      throw_scene_error(field(key), "must be at most " + std::to_string(kMaxLongLong));
    const long long x = value->get<long long>();
    if (auto reason = violated_bounds(schema_of(key), static_cast<double>(x)))
      throw_scene_error(field(key), *reason + ", got " + std::to_string(x));
    target = static_cast<Int>(x);
  }

  void boolean(const std::string& key, bool& target) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_boolean())
      throw_scene_error(field(key), "must be true or false, got " + describe_type(*value));
    target = value->get<bool>();
  }

  void string(const std::string& key, std::string& target) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_string())
      throw_scene_error(field(key), "must be a string, got " + describe_type(*value));
    target = value->get<std::string>();
  }

  /// A name of `table` (target keeps its value when the key is absent).
  template <class Enum, std::size_t N>
  void choice(const std::string& key, const NameTable<Enum, N>& table, Enum& target) {
    std::string name(table.name(target));
    string(key, name);
    target = parse_name(table, name, field(key));
  }

  void vector(const std::string& key, std::array<double, 3>& target, std::size_t size) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_array() || value->size() != size)
      throw_scene_error(field(key), "must be an array of " + std::to_string(size) + " numbers");
    for (std::size_t k = 0; k < size; ++k) {
      if (!(*value)[k].is_number() || !std::isfinite((*value)[k].get<double>()))
        throw_scene_error(field(key) + "[" + std::to_string(k) + "]", "must be a finite number");
      target[k] = (*value)[k].get<double>();
    }
  }

  /// An array of strings; each element's field is named "key[i]" in errors.
  void strings(const std::string& key, std::vector<std::string>& target) {
    const json* value = find(key);
    if (!value) return;
    if (!value->is_array())
      throw_scene_error(field(key), "must be an array of strings, got " + describe_type(*value));
    std::vector<std::string> result;
    for (std::size_t k = 0; k < value->size(); ++k) {
      if (!(*value)[k].is_string())
        throw_scene_error(field(key) + "[" + std::to_string(k) + "]",
                          "must be a string, got " + describe_type((*value)[k]));
      result.push_back((*value)[k].get<std::string>());
    }
    target = std::move(result);
  }

  /// An array of names of `table`, as a set (a repeated name counts once); present, it replaces
  /// the target's default. Each element's field is named "key[i]" in errors.
  template <class Enum, std::size_t N>
  void names(const std::string& key, const NameTable<Enum, N>& table, std::set<Enum>& target) {
    std::vector<std::string> list;
    strings(key, list);
    if (!object_.contains(key)) return;
    target.clear();
    for (std::size_t k = 0; k < list.size(); ++k)
      target.insert(parse_name(table, list[k], field(key) + "[" + std::to_string(k) + "]"));
  }

  /// A number, or null for none (null clears a value, as a JSON merge patch would).
  void optional_number(const std::string& key, std::optional<double>& target) {
    const json* value = find(key);
    if (!value) return;
    if (value->is_null()) {
      target.reset();
      return;
    }
    double x = 0.0;
    number(key, x);
    target = x;
  }

  /// reject_unknown(), the end of a section read by a function shared with ObjectWriter.
  void finish() const { reject_unknown(); }

  /// Throws on the first key the schema does not declare, suggesting the declared key it is a
  /// typo of; std::logic_error for a declared key that no read asked for (a defect: the key
  /// would be accepted and ignored).
  void reject_unknown() const {
    std::set<std::string> declared;
    if (const auto properties = schema_->find("properties"); properties != schema_->end())
      for (const auto& [key, value] : properties->items()) declared.insert(key);
    for (const auto& [key, value] : object_.items()) {
      if (seen_.contains(key)) continue;
      if (declared.contains(key))
        throw std::logic_error("scene schema declares '" + field(key) + "', which no reader reads");
      const std::optional<std::string> near = closest_key(key, declared);
      throw SceneError(field(key),
                       "scene: unknown key '" + field(key) + "'" +
                           (near ? "; did you mean '" + field(*near) + "'?" : std::string()));
    }
  }

 private:
  static constexpr auto kMaxLongLong =
      static_cast<unsigned long long>(std::numeric_limits<long long>::max());
  std::string label() const { return path_.empty() ? "(top level)" : path_; }
  const json& schema_of(const std::string& key) const {
    const json* node = scene_schema_property(*schema_, key);
    if (!node) throw std::logic_error("scene schema declares no '" + field(key) + "'");
    return *node;
  }
  const json& object_;
  std::string path_;
  const json* schema_;
  std::set<std::string> seen_;
};

}  // namespace sphles::scene
