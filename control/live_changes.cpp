// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/live_changes.hpp"

#include <algorithm>
#include <set>

#include "control/scene_schema.hpp"
#include "scene/schema.hpp"
#include "sim/scene.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

bool has_prefix(const std::string& path, const std::string& prefix) {
  return path == prefix ||
         (path.size() > prefix.size() && path.compare(0, prefix.size(), prefix) == 0 &&
          path[prefix.size()] == '.');
}

/// Dotted field of a JSON-pointer path from json::diff, cut at array indices ("/a/b/2" → "a.b",
/// "/a/b/-" → "a.b").
std::string dotted_field(const std::string& pointer) {
  std::string field;
  std::size_t start = 1;
  while (start <= pointer.size()) {
    std::size_t end = pointer.find('/', start);
    if (end == std::string::npos) end = pointer.size();
    const std::string token = pointer.substr(start, end - start);
    // An array index, or "-" (json::diff's "append to the array").
    if (token == "-" ||
        (!token.empty() && token.find_first_not_of("0123456789") == std::string::npos))
      break;
    field += (field.empty() ? "" : ".") + token;
    start = end + 1;
  }
  return field;
}

}  // namespace

ChangeScope scope_of(const std::vector<std::string>& fields) {
  ChangeScope s;
  for (const std::string& f : fields) {
    const std::string scope = live_rule(f).scope;  // the schema's "x-scope"
    if (scope == "solver")
      s.solver = true;
    else if (scope == "analysis")
      s.analysis = true;
    else if (scope == "render")
      s.render = true;
    else
      s.other = true;
  }
  return s;
}

const std::vector<std::string>& changeable_fields() {
  // The smallest set of prefixes covering every field the schema lets a run change: a field
  // whose own fields are all changeable stands for them.
  static const std::vector<std::string> fields = [] {
    const std::vector<std::string> all = scene::scene_schema_fields();
    std::vector<std::string> out;
    for (const std::string& field : all) {
      bool whole = live_rule(field).live;
      for (const std::string& other : all)
        if (whole && other != field && has_prefix(other, field)) whole = live_rule(other).live;
      const bool covered = std::any_of(out.begin(), out.end(),
                                       [&](const std::string& p) { return has_prefix(field, p); });
      if (whole && !covered) out.push_back(field);
    }
    return out;
  }();
  return fields;
}

CheckedChange check_change(const json& before, const json& after) {
  CheckedChange change;
  try {
    change.spec = parse_run_spec(after);
  } catch (const sim::SceneError& e) {
    // "scene: 'a.b' must ..." → field a.b, reason "must ...".
    const std::string message = e.what();
    const std::string field = e.field().empty() ? "(body)" : e.field();
    const std::string prefix = "scene: '" + field + "' ";
    throw ChangeError(field,
                      message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message);
  }
  std::set<std::string> fields;
  for (const json& op : json::diff(before, run_spec_to_json(change.spec)))
    fields.insert(dotted_field(op.at("path").get<std::string>()));
  for (const std::string& field : fields) {
    const LiveRule rule = live_rule(field);  // declared by the scene schema ("x-live", "x-fixed")
    if (rule.live) continue;
    throw ChangeError(field, "cannot change while a run exists" +
                                 (rule.reason.empty() ? std::string() : ": " + rule.reason));
  }
  change.fields.assign(fields.begin(), fields.end());
  return change;
}

}  // namespace sphles::control
