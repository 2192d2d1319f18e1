#include "control/live_changes.hpp"

#include <set>

#include "sim/scene.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

// Live changes (docs/rendering.md): fields the run may change between two steps, and why the
// others may not. A path is allowed if an entry equals it or is a prefix of it.
const std::vector<std::string> kChangeable = {
    "name",
    "time.end",
    "time.cfl_acoustic",
    "time.cfl_viscous",
    "time.cfl_force",
    "time.fixed_step",
    "fluid.reference_pressure",
    "fluid.dynamic_viscosity",
    "subfilter.smagorinsky_constant",
    "subfilter.sigma_constant",
    "subfilter.filter_width",
    "forcing.amplitude",
    "forcing.friction",
    "analysis.every",
    "analysis.products",
    "analysis.slice",
    "analysis.particle_fields",
    "analysis.grid_points_per_spacing",
    "analysis.gridding",
    "analysis.histogram_bins",
    "analysis.angle_bins",
    "analysis.angle_threshold",
    "analysis.spectrum_length_scale",
    "render",
    "checkpoint",
    "output.timeseries_every",
    "output.progress_every_seconds",
};

const std::vector<std::pair<std::string, std::string>> kFixedReasons = {
    {"case", "fixes the flow being simulated; create a new run"},
    {"preset", "fixes the flow being simulated; create a new run"},
    {"particles_per_side", "fixes the particle set; create a new run"},
    {"box_length", "fixes the particle set; create a new run"},
    {"kernel", "fixes the interaction stencil and the neighbour list; create a new run"},
    {"fluid.sound_speed",
     "sets the equation of state: changing it mid-run sends pressure waves through the flow; "
     "create a new run"},
    {"fluid.reference_density", "sets the particle masses; create a new run"},
    {"subfilter.model",
     "switching the sub-filter model mid-run is not supported; create a new run"},
    {"scheme.type",
     "fixes the discretisation the stored state belongs to (a^n, and the transport velocity of "
     "the TVF, are the scheme's); create a new run"},
    {"flow", "applies to the initial condition only"},
    {"packing", "applies to the initial condition only"},
    {"initial", "applies to the initial condition only"},
    {"neighbours", "fixes the neighbour list that a bitwise restart relies on"},
    {"analysis.dissipation_window", "is fixed for the run's dissipation estimate"},
};

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
    if (has_prefix(f, "analysis"))
      s.analysis = true;
    else if (has_prefix(f, "render"))
      s.render = true;
    else if (has_prefix(f, "time") || has_prefix(f, "fluid") || has_prefix(f, "subfilter") ||
             has_prefix(f, "scheme") || has_prefix(f, "forcing"))
      s.solver = true;
    else
      s.other = true;
  }
  return s;
}

const std::vector<std::string>& changeable_fields() {
  return kChangeable;
}

CheckedChange check_change(const json& before, const json& after) {
  CheckedChange change;
  try {
    change.spec = parse_run_spec(after);
  } catch (const sim::SceneError& e) {
    // "scene: 'a.b' must ..." → field a.b.
    std::string message = e.what();
    std::string field = "(body)";
    if (const auto open = message.find('\''); open != std::string::npos)
      if (const auto close = message.find('\'', open + 1); close != std::string::npos)
        field = message.substr(open + 1, close - open - 1);
    const std::string prefix = "scene: '" + field + "' ";
    throw ChangeError(field,
                      message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message);
  }
  std::set<std::string> fields;
  for (const json& op : json::diff(before, run_spec_to_json(change.spec)))
    fields.insert(dotted_field(op.at("path").get<std::string>()));
  for (const std::string& field : fields) {
    bool allowed = false;
    for (const std::string& c : kChangeable) allowed = allowed || has_prefix(field, c);
    if (allowed) continue;
    for (const auto& [prefix, why] : kFixedReasons)
      if (has_prefix(field, prefix))
        throw ChangeError(field, "cannot change while a run exists: " + why);
    throw ChangeError(field, "cannot change while a run exists");
  }
  change.fields.assign(fields.begin(), fields.end());
  return change;
}

}  // namespace sphles::control
