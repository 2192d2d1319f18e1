// SPDX-License-Identifier: GPL-3.0-or-later
// Live changes (docs/rendering.md "Live changes", docs/api.md): which fields of a run's scene
// document may change while the run exists, and why the others may not (declared by the scene
// schema, scene/scene.schema.json: "x-live", "x-fixed"). One rule serves live
// parameter changes (PATCH, WebSocket) and the overrides of a restart (`sphles run --restart
// --set`), so both refuse the same fields with the same message.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "control/run_types.hpp"

namespace sphles::control {

/// Dotted names of the fields (or sections) that may change while a run exists.
const std::vector<std::string>& changeable_fields();

/// A validated change of a run's document.
struct CheckedChange {
  RunSpec spec;                     // the document after the change, parsed
  std::vector<std::string> fields;  // dotted fields that differ, sorted; empty: no change
};

/// Parses `after` in full and compares it with `before` (a complete, normalised run document):
/// every field that differs must be changeable. Throws ChangeError naming the first field that
/// is malformed ("'a.b' must be ...") or fixed ("'a.b' cannot change while a run exists: why").
CheckedChange check_change(const nlohmann::json& before, const nlohmann::json& after);

/// Which parts of a run a set of changed fields touches: the schema's "x-scope" of each.
struct ChangeScope {
  bool solver = false, analysis = false, render = false, other = false;
};
ChangeScope scope_of(const std::vector<std::string>& fields);

}  // namespace sphles::control
