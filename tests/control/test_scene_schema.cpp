// SPDX-License-Identifier: GPL-3.0-or-later
// The scene schema (sim/scene.schema.json) as the one declaration of the scene: the readers,
// valijson, the defaults, the live-change rules and the registries agree with it.
#include <gtest/gtest.h>

#include <optional>
#include <set>
#include <string>

#include "control/live_changes.hpp"
#include "control/run.hpp"
#include "control/scene_schema.hpp"
#include "scene/presets.hpp"
#include "scene/schema.hpp"
#include "sim/kernels.hpp"
#include "sim/scene.hpp"

namespace {

using nlohmann::json;
namespace control = sphles::control;
namespace scene = sphles::scene;
namespace sim = sphles::sim;

/// Every section present, so that the normalised document holds every key its writers write.
json with_every_section(json scene) {
  scene["analysis"] = {{"every", 0.5},
                       {"products", {"energy", "slices", "particles", "fields"}},
                       {"slice", {{"fields", {"omega2", "tau_sfs"}}}}};
  scene["render"] = {{"fields", {"omega2"}},
                     {"colour", {{"omega2", {{"scale", "linear"}}}}},
                     {"view3d", {{"enabled", true}}}};
  scene["checkpoint"] = {{"every", 1.0}};
  return scene;
}

/// The fields with_every_section sets away from their defaults.
const std::set<std::string> kSetBySection = {"analysis.every",        "analysis.products",
                                             "analysis.slice.fields", "render.fields",
                                             "render.view3d.enabled", "checkpoint.every"};

json normalised(const json& scene) {
  return control::run_spec_to_json(control::parse_run_spec(scene));
}

/// The value at a dotted field of a document, nullptr if absent.
const json* value_at(const json& document, const std::string& dotted) {
  const json* node = &document;
  std::size_t start = 0;
  while (start <= dotted.size()) {
    std::size_t end = dotted.find('.', start);
    if (end == std::string::npos) end = dotted.size();
    if (!node->is_object()) return nullptr;
    const auto it = node->find(dotted.substr(start, end - start));
    if (it == node->end()) return nullptr;
    node = &*it;
    start = end + 1;
  }
  return node;
}

const std::vector<std::string> kCases = {"tgv3d", "tgv2d", "kolmogorov2d"};

std::string parse_error(const json& document) {
  try {
    control::parse_run_spec(document);
  } catch (const sim::SceneError& e) {
    return e.what();
  }
  return "";
}

TEST(SceneSchema, EveryPresetAndItsNormalisedDocumentConform) {
  for (const std::string& preset : scene::preset_names()) {
    const json scene = {{"preset", preset}, {"particles_per_side", 16}};
    EXPECT_EQ(control::schema_violation(scene), std::nullopt) << preset;
    EXPECT_EQ(control::schema_violation(scene::preset_document(preset)), std::nullopt) << preset;
  }
  for (const std::string& c : kCases) {
    const json full = normalised(with_every_section({{"case", c}}));
    const std::optional<std::string> violation = control::schema_violation(full);
    EXPECT_EQ(violation, std::nullopt) << c << ": " << violation.value_or("") << "\n"
                                       << full.dump(1);
  }
}

TEST(SceneSchema, EveryDeclaredKeyIsWrittenAndReadBack) {
  // The normalised documents of the three cases together hold every declared value key (but
  // the preset and the ignored packing.cache_dir), and parsing them back succeeds: the readers
  // throw std::logic_error on a declared key nobody reads, and on a read of an undeclared one.
  std::vector<json> documents;
  for (const std::string& c : kCases) {
    documents.push_back(normalised(with_every_section({{"case", c}})));
    EXPECT_NO_THROW(control::parse_run_spec(documents.back())) << c;
  }
  for (const std::string& field : scene::scene_schema_fields()) {
    const json* node = scene::scene_schema_node(field);
    ASSERT_NE(node, nullptr) << field;
    if (node->contains("properties") || field == "preset" || field == "packing.cache_dir" ||
        field == "render.colour")
      continue;
    bool written = false;
    for (const json& d : documents) written = written || value_at(d, field) != nullptr;
    EXPECT_TRUE(written) << "no case writes the declared key '" << field << "'";
  }
}

TEST(SceneSchema, DeclaredDefaultsAreTheReadersDefaults) {
  std::size_t checked = 0;
  for (const std::string& c : kCases) {
    const json full = normalised(with_every_section({{"case", c}}));
    for (const std::string& field : scene::scene_schema_fields()) {
      const json* node = scene::scene_schema_node(field);
      if (!node->contains("default")) continue;
      const json* value = value_at(full, field);
      if (!value || kSetBySection.contains(field)) continue;
      EXPECT_EQ(*value, node->at("default")) << c << ": " << field;
      ++checked;
    }
    // The colour mapping of render.view3d (the same declaration as render.colour.FIELD).
    const json* mapping = value_at(full, "render.view3d.colour");
    ASSERT_NE(mapping, nullptr);
    EXPECT_EQ(mapping->at("lower_percentile"),
              scene::scene_schema_node("render.view3d.colour.lower_percentile")->at("default"));
  }
  EXPECT_GT(checked, 100u);
}

TEST(SceneSchema, ReadersAndValidatorRefuseTheSameDocumentsNamingTheField) {
  const std::vector<std::pair<json, std::string>> bad = {
      {{{"fluid", {{"sound_speed", -1}}}}, "fluid.sound_speed"},
      {{{"fluid", {{"sound_speed", "fast"}}}}, "fluid.sound_speed"},
      {{{"kernel", {{"diameter_over_spacing", 17}}}}, "kernel.diameter_over_spacing"},
      {{{"kernel", {{"type", "gauss"}}}}, "kernel.type"},
      {{{"kernel", {{"typ", "wendland_c4"}}}}, "kernel.typ"},
      {{{"time", {{"cfl_acoustic", 0}}}}, "time.cfl_acoustic"},
      {{{"particles_per_side", 1}}, "particles_per_side"},
      {{{"particles_per_side", 8.5}}, "particles_per_side"},
      {{{"packing", {{"perturbation", 0.5}}}}, "packing.perturbation"},
      {{{"packing", {{"enabled", 1}}}}, "packing.enabled"},
      {{{"scheme", {{"type", "sph"}}}}, "scheme.type"},
      {{{"analysis", {{"every", 0.5}, {"products", {"energy", "helicity"}}}}},
       "analysis.products[1]"},
      {{{"analysis", {{"histogram_bins", 257}}}}, "analysis.histogram_bins"},
      {{{"render", {{"width", 63}}}}, "render.width"},
      {{{"render", {{"colour", {{"omega2", {{"scale", "cubic"}}}}}}}},
       "render.colour.omega2.scale"},
      {{{"wibble", 1}}, "wibble"},
  };
  for (const auto& [document, field] : bad) {
    const std::string error = parse_error(document);
    EXPECT_NE(error.find("'" + field + "'"), std::string::npos)
        << document.dump() << ": " << (error.empty() ? "accepted" : error);
    const std::optional<std::string> violation = control::schema_violation(document);
    ASSERT_TRUE(violation.has_value()) << document.dump() << " conforms to the schema";
    // valijson's path names the field or the object holding it (unknown keys, array items).
    const std::string object = field.substr(0, field.find_last_of(".["));
    EXPECT_TRUE(violation->find("'" + field + "'") != std::string::npos ||
                violation->find("'" + object) == 0 || field.find('.') == std::string::npos)
        << document.dump() << ": " << *violation;
  }
  // The readers' own words, from the schema's bounds.
  EXPECT_EQ(parse_error({{"fluid", {{"sound_speed", -1}}}}),
            "scene: 'fluid.sound_speed' must be > 0, got -1");
  EXPECT_EQ(parse_error({{"time", {{"cfl_acoustic", 3}}}}),
            "scene: 'time.cfl_acoustic' must be in (0, 2], got 3");
  EXPECT_EQ(parse_error({{"packing", {{"perturbation", 0.5}}}}),
            "scene: 'packing.perturbation' must be in [0, 0.5), got 0.5");
  EXPECT_EQ(parse_error({{"particles_per_side", 5000}}),
            "scene: 'particles_per_side' must be in [2, 4096], got 5000");
  EXPECT_EQ(parse_error({{"kernel", {{"typ", "x"}}}}),
            "scene: unknown key 'kernel.typ'; did you mean 'kernel.type'?");
}

/// `document` with `value` at the dotted `field` (objects made on the way).
json with_value(json document, const std::string& field, const json& value) {
  json* node = &document;
  std::size_t start = 0;
  for (std::size_t end = field.find('.'); end != std::string::npos;
       start = end + 1, end = field.find('.', start))
    node = &(*node)[field.substr(start, end - start)];
  (*node)[field.substr(start)] = value;
  return document;
}

/// Calls f(dotted field, schema node) for every object and every key the schema declares.
template <class F>
void for_each_schema_node(const json& node, const std::string& field, F&& f) {
  f(field, node);
  if (const auto properties = node.find("properties"); properties != node.end())
    for (const auto& [key, child] : properties->items())
      for_each_schema_node(child, field.empty() ? key : field + "." + key, f);
}

TEST(SceneSchema, TheReadersEnforceEveryKeywordOfTheSchema) {
  // parse_run_spec's readers are the scene's one validation: every object of the schema refuses
  // an unknown key, every key a value of another type, every bound, enum and array rule, each
  // naming the field (or, for an unknown key or an array item, the field inside it).
  std::size_t checked = 0;
  for_each_schema_node(
      control::scene_schema(), "", [&](const std::string& field, const json& node) {
        // The forcing applies to the Kolmogorov case only; the reference needs nothing else.
        const json base =
            field.rfind("forcing", 0) == 0 ? json{{"case", "kolmogorov2d"}} : json::object();
        std::vector<json> bad;
        const json kind = node.value("type", json(""));
        const std::string type =
            kind.is_array() ? kind.at(0).get<std::string>() : kind.get<std::string>();
        if (type == "object" && node.contains("additionalProperties") &&
            node["additionalProperties"] == false)
          bad.push_back(field.empty() ? json{{"zz_unknown", 1}}
                                      : with_value(base, field + ".zz_unknown", 1));
        if (field.empty() || type == "object") {
          checked += bad.size();
          for (const json& document : bad)
            EXPECT_NE(parse_error(document).find("zz_unknown"), std::string::npos)
                << document.dump() << ": " << parse_error(document);
          return;
        }
        if (type == "number" || type == "integer") {
          bad.push_back(with_value(base, field, "text"));
          if (node.contains("minimum"))
            bad.push_back(with_value(base, field, node["minimum"].get<double>() - 1.0));
          if (node.contains("exclusiveMinimum"))
            bad.push_back(with_value(base, field, node["exclusiveMinimum"]));
          if (node.contains("maximum"))
            bad.push_back(with_value(base, field, node["maximum"].get<double>() + 1.0));
          if (node.contains("exclusiveMaximum"))
            bad.push_back(with_value(base, field, node["exclusiveMaximum"]));
          if (node.contains("multipleOf"))
            bad.push_back(with_value(base, field, node["multipleOf"].get<int>() * 8 + 1));
          if (type == "integer") bad.push_back(with_value(base, field, 2.5));
        } else if (type == "boolean") {
          bad.push_back(with_value(base, field, "yes"));
        } else if (type == "string") {
          bad.push_back(with_value(base, field, 1));
          if (node.contains("enum")) bad.push_back(with_value(base, field, "zz_not_a_name"));
        } else if (type == "array") {
          bad.push_back(with_value(base, field, "text"));
          if (node.contains("minItems") && node["minItems"].get<int>() > 0)
            bad.push_back(with_value(base, field, json::array()));
          if (const auto items = node.find("items"); items != node.end())
            bad.push_back(with_value(
                base, field, {items->value("type", "") == "string" ? json(1) : json("text")}));
          if (const auto items = node.find("items"); items != node.end() && items->contains("enum"))
            bad.push_back(with_value(base, field, {"zz_not_a_name"}));
          if (node.value("uniqueItems", false))
            bad.push_back(with_value(
                base, field, {(*node.find("items"))["enum"][0], (*node.find("items"))["enum"][0]}));
        }
        for (const json& document : bad) {
          ++checked;
          std::string error, named;
          try {
            control::parse_run_spec(document);
          } catch (const sim::SceneError& e) {
            error = e.what();
            named = e.field();
          }
          EXPECT_TRUE(named.rfind(field, 0) == 0 || error.find("'" + field) != std::string::npos)
              << document.dump() << ": " << (error.empty() ? "accepted" : error);
        }
      });
  EXPECT_GT(checked, 150u);
}

TEST(SceneSchema, RegistryNamesArePublishedAsEnumsAndEachIsAccepted) {
  const json& schema = control::scene_schema();
  const json& kernels = schema["properties"]["kernel"]["properties"]["type"]["enum"];
  const std::vector<std::string> kernel_names = sim::kKernelNames.names();
  ASSERT_EQ(kernels.size(), kernel_names.size());
  for (const std::string& name : kernel_names) {
    EXPECT_NE(std::find(kernels.begin(), kernels.end(), name), kernels.end()) << name;
    EXPECT_EQ(parse_error({{"kernel", {{"type", name}}}}), "") << name;
  }
  for (const char* field : {"scheme.type", "subfilter.model", "case", "initial.mass",
                            "analysis.gridding.vorticity", "preset"}) {
    const json* node = &schema;
    std::string rest = field;
    while (!rest.empty()) {
      const std::size_t dot = rest.find('.');
      node = &(*node)["properties"][rest.substr(0, dot)];
      rest = dot == std::string::npos ? "" : rest.substr(dot + 1);
    }
    ASSERT_TRUE(node->contains("enum")) << field;
    EXPECT_GE(node->at("enum").size(), 2u) << field;
  }
  // References are inlined: the published schema stands alone (an OpenAPI component).
  EXPECT_EQ(schema.dump().find("$ref"), std::string::npos);
  EXPECT_FALSE(schema.contains("$defs"));
  // The patch schema takes null for any value (a removal) and is itself a valid scene patch.
  const json patch = control::scene_patch_schema();
  EXPECT_NE(
      patch["properties"]["fluid"]["properties"]["dynamic_viscosity"]["type"].dump().find("null"),
      std::string::npos);
}

TEST(SceneSchema, LiveChangeRulesComeFromTheSchema) {
  EXPECT_TRUE(control::live_rule("time.end").live);
  EXPECT_TRUE(control::live_rule("render.colour.omega2.scale").live);
  EXPECT_TRUE(control::live_rule("fluid.dynamic_viscosity").live);
  EXPECT_TRUE(control::live_rule("analysis.grid_fields").live);
  EXPECT_FALSE(control::live_rule("fluid.sound_speed").live);
  EXPECT_NE(control::live_rule("fluid.sound_speed").reason.find("equation of state"),
            std::string::npos);
  EXPECT_FALSE(control::live_rule("subfilter.model").live);
  EXPECT_FALSE(control::live_rule("analysis.dissipation_window").live);
  EXPECT_FALSE(control::live_rule("blow_up.energy_factor").live);
  EXPECT_EQ(control::live_rule("blow_up.energy_factor").reason, "");
  const std::vector<std::string>& changeable = control::changeable_fields();
  const std::set<std::string> set(changeable.begin(), changeable.end());
  for (const char* f : {"name", "time", "checkpoint", "output", "render", "fluid.dynamic_viscosity",
                        "subfilter.smagorinsky_constant", "analysis.every"})
    EXPECT_TRUE(set.contains(f)) << f;
  for (const char* f : {"fluid", "subfilter", "analysis", "kernel", "scheme", "blow_up"})
    EXPECT_FALSE(set.contains(f)) << f;
  // A live change is refused with the schema's reason.
  const json before = normalised({{"case", "tgv2d"}, {"particles_per_side", 16}});
  json after = before;
  after["fluid"]["sound_speed"] = 20.0;
  try {
    control::check_change(before, after);
    FAIL() << "a change of fluid.sound_speed was accepted";
  } catch (const control::ChangeError& e) {
    EXPECT_NE(std::string(e.what()).find("equation of state"), std::string::npos) << e.what();
  }
  after = before;
  after["time"]["end"] = 9.0;
  EXPECT_EQ(control::check_change(before, after).fields, std::vector<std::string>{"time.end"});
}

TEST(SceneSchema, TheScopeOfAChangeComesFromTheSchema) {
  // The part of a run a change reconfigures is the schema's "x-scope" of the field or a parent.
  EXPECT_EQ(control::live_rule("fluid.dynamic_viscosity").scope, "solver");
  EXPECT_EQ(control::live_rule("time.end").scope, "solver");
  EXPECT_EQ(control::live_rule("forcing.amplitude").scope, "solver");
  EXPECT_EQ(control::live_rule("subfilter.smagorinsky_constant").scope, "solver");
  EXPECT_EQ(control::live_rule("analysis.every").scope, "analysis");
  EXPECT_EQ(control::live_rule("render.colour.omega2.scale").scope, "render");
  EXPECT_EQ(control::live_rule("checkpoint.every").scope, "");
  EXPECT_EQ(control::live_rule("name").scope, "");
  // Every scope the schema declares is one the run knows how to apply.
  for (const std::string& field : scene::scene_schema_fields()) {
    const std::string scope = control::live_rule(field).scope;
    EXPECT_TRUE(scope.empty() || scope == "solver" || scope == "analysis" || scope == "render")
        << field << ": " << scope;
  }
  const control::ChangeScope s =
      control::scope_of({"analysis.every", "checkpoint.every", "fluid.dynamic_viscosity"});
  EXPECT_TRUE(s.solver);
  EXPECT_TRUE(s.analysis);
  EXPECT_FALSE(s.render);
  EXPECT_TRUE(s.other);
  const control::ChangeScope render_only = control::scope_of({"render.colour.omega2.scale"});
  EXPECT_TRUE(render_only.render);
  EXPECT_FALSE(render_only.solver || render_only.analysis || render_only.other);
}

}  // namespace
