// SPDX-License-Identifier: GPL-3.0-or-later
// Integration tests of the sphles service (server/) against real servers on ephemeral loopback
// ports, driving real runs (tiny 2D Taylor-Green scenes) through the REST API and WebSocket
// streams of docs/api.md. Clients are Boost.Beast / raw sockets; nothing is mocked.
#include "control/scene_schema.hpp"
#include "server_test_support.hpp"
#include "sim/kernels.hpp"

#include <numbers>
#include <set>

namespace {

using namespace sphles_server_test;

/// The run stream's messages as the served AsyncAPI document declares them.
json stream_messages(const Api& api) {
  const Reply r = api.get("/api/asyncapi.json");
  EXPECT_EQ(r.status, 200);
  return r.body_json();
}

/// A stream message (either direction) conforms to its payload schema in the AsyncAPI document,
/// checked by valijson.
void expect_declared(const json& asyncapi, const json& message) {
  const std::string type = message.value("type", "");
  ASSERT_TRUE(asyncapi["components"]["messages"].contains(type)) << "undeclared message " << type;
  json schema = asyncapi;
  schema["$ref"] = "#/components/messages/" + type + "/payload";
  const std::optional<std::string> violation =
      sphles::control::json_schema_violation(schema, message);
  EXPECT_EQ(violation, std::nullopt)
      << violation.value_or("") << " in " << message.dump().substr(0, 600);
}

// =============================================================================================

TEST(Server, HealthAndVersion) {
  TestServer server(scratch("health") / "data");
  const Reply r = Api{server.port()}.get("/api/health");
  ASSERT_EQ(r.status, 200);
  EXPECT_EQ(r.header("content-type"), "application/json");
  const json body = r.body_json();
  EXPECT_EQ(body["status"], "ok");
  EXPECT_EQ(body["version"], "0.1.0");
  EXPECT_EQ(body["runs"], 0);
}

TEST(Server, OpenApiDocumentListsEveryRoute) {
  TestServer server(scratch("openapi") / "data");
  const Reply r = Api{server.port()}.get("/api/openapi.json");
  ASSERT_EQ(r.status, 200);
  const json doc = r.body_json();
  ASSERT_TRUE(doc.contains("openapi"));
  EXPECT_EQ(doc["openapi"].get<std::string>().substr(0, 2), "3.");
  // The licence the API is published under (LICENSE), by its SPDX identifier (OpenAPI 3.1).
  EXPECT_EQ(doc["info"]["license"],
            json({{"name", "GPL-3.0-or-later"}, {"identifier", "GPL-3.0-or-later"}}));
  const json& paths = doc.at("paths");
  std::size_t operations = 0;
  for (const auto& route : sphles::server::Router::routes()) {
    std::string method(http::to_string(route.method));
    for (char& c : method) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    const std::string path(route.path);
    ASSERT_TRUE(paths.contains(path)) << path << " is missing from server/openapi.json";
    EXPECT_TRUE(paths[path].contains(method)) << method << " " << path << " is not documented";
    ++operations;
  }
  // And nothing documented that the router does not know.
  std::size_t documented = 0;
  for (const auto& [path, item] : paths.items())
    for (const auto& [key, value] : item.items())
      if (key != "parameters" && key != "summary" && key != "description") ++documented;
  EXPECT_EQ(documented, operations);
  // Scene bodies are described by the scene schema, served as a component and on its own.
  const json& scene = doc["components"]["schemas"]["Scene"];
  EXPECT_EQ(scene["properties"]["kernel"]["properties"]["type"]["enum"][0], "wendland_c2");
  EXPECT_FALSE(scene.contains("$schema"));
  // A scene to create a run from leaves out what it does not set: the schema without defaults.
  EXPECT_EQ(doc["components"]["schemas"]["CreateRequest"]["properties"]["scene"]["$ref"],
            "#/components/schemas/SceneDocument");
  const json& document = doc["components"]["schemas"]["SceneDocument"];
  EXPECT_EQ(document["properties"]["kernel"]["properties"]["type"]["enum"],
            scene["properties"]["kernel"]["properties"]["type"]["enum"]);
  EXPECT_FALSE(document["properties"]["kernel"]["properties"]["type"].contains("default"));
  EXPECT_EQ(scene["properties"]["kernel"]["properties"]["type"]["default"], "wendland_c4");
  const Reply schema = Api{server.port()}.get("/api/schema/scene");
  ASSERT_EQ(schema.status, 200);
  EXPECT_EQ(
      schema.body_json()["properties"]["fluid"]["properties"]["sound_speed"]["exclusiveMinimum"],
      0);
  EXPECT_EQ(schema.body_json()["properties"]["kernel"], scene["properties"]["kernel"]);

  // The stream's AsyncAPI document: its payloads use the same component schemas, and the
  // validation the stream tests rely on refuses what the declarations refuse.
  const json asyncapi = stream_messages(Api{server.port()});
  EXPECT_EQ(asyncapi["asyncapi"], "3.0.0");
  EXPECT_EQ(asyncapi["info"]["license"]["name"], "GPL-3.0-or-later");
  EXPECT_EQ(asyncapi["components"]["schemas"]["Metrics"], doc["components"]["schemas"]["Metrics"]);
  const auto violation = [&](const json& message) {
    json schema = asyncapi;
    schema["$ref"] = "#/components/messages/" + message["type"].get<std::string>() + "/payload";
    return sphles::control::json_schema_violation(schema, message);
  };
  EXPECT_EQ(violation({{"type", "state"},
                       {"state", "paused"},
                       {"reason", ""},
                       {"actions", {"resume", "stop"}}}),
            std::nullopt);
  EXPECT_NE(violation({{"type", "state"}, {"state", "paused"}, {"reason", ""}}), std::nullopt);
  EXPECT_NE(
      violation(
          {{"type", "state"}, {"state", "dancing"}, {"reason", ""}, {"actions", json::array()}}),
      std::nullopt);
  EXPECT_NE(violation({{"type", "metrics"}, {"samples", json::array()}}), std::nullopt);
  EXPECT_NE(violation({{"type", "images"}, {"enabled", "no"}}), std::nullopt);
  EXPECT_NE(violation({{"type", "parameters"}, {"patch", {{"kernel", {{"type", "gauss"}}}}}}),
            std::nullopt);
}

TEST(Server, ListsPresets) {
  TestServer server(scratch("presets") / "data");
  const Reply r = Api{server.port()}.get("/api/presets");
  ASSERT_EQ(r.status, 200);
  const json presets = r.body_json();
  ASSERT_TRUE(presets.is_array());
  ASSERT_GE(presets.size(), 22u);
  bool kolmogorov = false;
  for (const json& p : presets) {
    EXPECT_TRUE(p.contains("name") && p.contains("scene") && p.contains("dimension")) << p;
    kolmogorov |= p["name"] == "kolmogorov2d";
  }
  EXPECT_TRUE(kolmogorov);
}

// The scene files the form offers beside the presets (GET /api/scenes): every file of the
// shipped scenes/ is a valid scene; a directory's files by name, each ready to create a run,
// one that is no scene named with its error.
TEST(Server, ListsSceneFiles) {
  {
    TestServer shipped(scratch("scenes_shipped") / "data");
    const json listed = Api{shipped.port()}.get("/api/scenes").body_json();
    EXPECT_TRUE(listed["skipped"].empty()) << listed["skipped"];
    std::set<std::string> files;
    for (const json& e : listed["scenes"]) files.insert(e["file"].get<std::string>());
    EXPECT_TRUE(files.contains("tgv3d-accurate.json") && files.contains("tgv2d-peers.json") &&
                files.contains("kolmogorov2d-reduced.json"))
        << listed;
  }
  const fs::path dir = scratch("scenes_own");
  fs::create_directories(dir / "scenes");
  std::ofstream(dir / "scenes" / "b-small.json") << tiny_scene(0.1, "small").dump();
  std::ofstream(dir / "scenes" / "a-broken.json")
      << R"({"case": "tgv2d", "particles_per_side": 1})";
  std::ofstream(dir / "scenes" / "notes.txt") << "not a scene";
  TestServer server(dir / "data", "", 2, [&](ServerOptions& o) { o.scenes_dir = dir / "scenes"; });
  const Api api{server.port()};
  const Reply r = api.get("/api/scenes");
  ASSERT_EQ(r.status, 200) << r.body;
  const json listed = r.body_json();
  ASSERT_EQ(listed["scenes"].size(), 1u) << listed;
  const json& small = listed["scenes"][0];
  EXPECT_EQ(small["file"], "b-small.json");
  EXPECT_EQ(small["name"], "small");
  EXPECT_EQ(small["particles_per_side"], 16);
  EXPECT_EQ(small["scene"]["time"]["end"], 0.1);
  ASSERT_EQ(listed["skipped"].size(), 1u);
  EXPECT_EQ(listed["skipped"][0]["file"], "a-broken.json");
  EXPECT_NE(listed["skipped"][0]["error"].get<std::string>().find("particles_per_side"),
            std::string::npos)
      << listed;
  const std::string id = api.create({{"scene", small["scene"]}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
}

TEST(Server, CreateListGetRun) {
  TestServer server(scratch("create") / "data");
  const Api api{server.port()};
  const Reply created =
      api.post("/api/runs", {{"scene", tiny_scene()}, {"name", "first"}, {"start", false}});
  ASSERT_EQ(created.status, 201) << created.body;
  const json summary = created.body_json();
  const std::string id = summary["id"];
  EXPECT_EQ(created.header("location"), "/api/runs/" + id);
  EXPECT_EQ(summary["state"], "created");
  EXPECT_EQ(summary["actions"], json({"start", "stop", "delete"}));
  EXPECT_EQ(summary["name"], "first");
  EXPECT_EQ(summary["case"], "tgv2d");
  EXPECT_EQ(summary["dimension"], 2);
  EXPECT_EQ(summary["particles_per_side"], 16);
  EXPECT_DOUBLE_EQ(summary["end_time"], 1000.0);
  for (const char* key : {"reason", "time", "step", "progress", "steps_per_second", "wall_seconds"})
    EXPECT_TRUE(summary.contains(key)) << key;

  // From a preset with a merge patch and overrides.
  const Reply from_preset = api.post(
      "/api/runs", {{"preset", "kolmogorov2d"},
                    {"patch", {{"packing", {{"enabled", false}}}}},
                    {"overrides", {"particles_per_side=16", "kernel.diameter_over_spacing=8"}},
                    {"start", false}});
  ASSERT_EQ(from_preset.status, 201) << from_preset.body;
  EXPECT_EQ(from_preset.body_json()["case"], "kolmogorov2d");

  const json runs = api.get("/api/runs").body_json();
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[0]["id"], id);  // oldest first

  const json detail = api.run(id);
  EXPECT_EQ(detail["scene"]["particles_per_side"], 16);
  EXPECT_TRUE(detail["latest"].is_null());
  EXPECT_TRUE(detail["changeable"].is_array());
  EXPECT_EQ(detail["stream"]["clients"], 0);
  EXPECT_EQ(detail["stream"]["dropped"], 0);
  EXPECT_TRUE(detail["counters"].contains("frames_rendered"));
  EXPECT_EQ(api.get("/api/health").body_json()["runs"], 2);

  expect_error(api.get("/api/runs/no-such-run"), 404, "id");
  expect_error(api.get("/api/runs/no-such-run/timeseries"), 404, "id");
}

TEST(Server, CreateRejectsBadRequestsNamingTheField) {
  TestServer server(scratch("badcreate") / "data");
  const Api api{server.port()};
  expect_error(api.post("/api/runs", {{"scene", tiny_scene()}, {"colour", "red"}}), 400, "colour");
  expect_error(api.post("/api/runs", {{"preset", 5}}), 400, "preset");
  expect_error(api.post("/api/runs", {{"preset", "no-such-preset"}}), 400, "preset");
  expect_error(api.post("/api/runs", {{"scene", "tgv2d"}}), 400, "scene");
  expect_error(api.post("/api/runs", {{"scene", tiny_scene()}, {"start", "yes"}}), 400, "start");
  // A name the run's directory would have to rewrite ("my run!" became id 0003-my-run-).
  expect_error(api.post("/api/runs", {{"scene", tiny_scene()}, {"name", "my run!"}}), 400, "name");
  expect_error(api.post("/api/runs", {{"scene", tiny_scene(1.0, ".hidden")}}), 400, "name");
  expect_error(api.post("/api/runs", {{"scene", tiny_scene(1.0, std::string(41, 'a'))}}), 400,
               "name");
  expect_error(api.post("/api/runs", {{"scene", tiny_scene()}, {"overrides", {1}}}), 400,
               "overrides[0]");
  json bad_scene = tiny_scene();
  bad_scene["particles_per_side"] = "many";
  expect_error(api.post("/api/runs", {{"scene", bad_scene}}), 400, "particles_per_side");
  bad_scene = tiny_scene();
  bad_scene["kernel"]["shape"] = "round";
  expect_error(api.post("/api/runs", {{"scene", bad_scene}}), 400, "kernel.shape");
  expect_error(send(server.port(), {http::verb::post, "/api/runs", "[1,2]"}), 400);
  expect_error(send(server.port(), {http::verb::post, "/api/runs", "{\"scene\": "}), 400);
  expect_error(send(server.port(), {http::verb::post, "/api/runs", ""}), 400);
  expect_error(send(server.port(), {http::verb::post, "/api/runs", std::string(200, '[')}), 400);
  expect_error(send(server.port(), {http::verb::post, "/api/runs", "preset=tgv2d", "text/plain"}),
               415, "Content-Type");
  // Nothing was created.
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 0u);
  EXPECT_TRUE(fs::is_empty(server.data_directory / "runs"));
}

// POST /api/estimate (the dashboard's Estimate button): what a create request would need and take,
// measured on the server, and whether create would accept it; nothing is created.
TEST(Server, EstimateMeasuresARunWithoutCreatingIt) {
  TestServer server(scratch("estimate") / "data");
  const Api api{server.port()};
  Reply r = api.post("/api/estimate", {{"scene", tiny_scene(2.0)}});
  ASSERT_EQ(r.status, 200) << r.body;
  json e = r.body_json();
  EXPECT_EQ(e["particles"], 256.0);
  EXPECT_EQ(e["admitted"], true);
  EXPECT_GT(e["memory_bytes"].get<double>(), 0.0);
  EXPECT_GT(e["memory_limit_bytes"].get<double>(), e["memory_bytes"].get<double>());
  ASSERT_TRUE(e["time"].is_object()) << e;
  EXPECT_EQ(e["time"]["calibration"]["particles_per_side"], 16);
  EXPECT_GT(e["time"]["seconds_per_step"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(e["time"]["solver_seconds"].get<double>(),
                   e["time"]["seconds_per_step"].get<double>() * e["steps"].get<double>());
  // The server's runs analyse for live viewing by default: their frames are timed too.
  EXPECT_GT(e["time"]["frames"].get<double>(), 0.0) << e;
  EXPECT_GT(e["time"]["analysis_seconds_per_frame"].get<double>(), 0.0) << e;
  EXPECT_GE(e["time"]["seconds_to_end"].get<double>(), e["time"]["solver_seconds"].get<double>());
  // 16² at D_K = 8Δl resolves up to k_SPH = 1, below the vortices' √2: said, with the remedy.
  ASSERT_EQ(e["warnings"].size(), 1u) << e;
  EXPECT_EQ(e["warnings"][0]["field"], "particles_per_side");
  EXPECT_NE(e["warnings"][0]["message"].get<std::string>().find(">= 23 resolves it"),
            std::string::npos)
      << e;
  // A run create would refuse is described with create's reason and not timed.
  r = api.post("/api/estimate", {{"preset", "tgv3d"}, {"patch", {{"particles_per_side", 2048}}}});
  ASSERT_EQ(r.status, 200) << r.body;
  e = r.body_json();
  EXPECT_EQ(e["admitted"], false);
  EXPECT_EQ(e["refusal"]["field"], "particles_per_side") << e;
  EXPECT_NE(e["refusal"]["message"].get<std::string>().find("the server allows (--max-memory)"),
            std::string::npos)
      << e;
  EXPECT_FALSE(e.contains("time"));
  // With ranks: what each would hold, and not admitted by a server that launches no MPI jobs.
  r = api.post("/api/estimate", {{"scene", tiny_scene(2.0)}, {"ranks", 2}});
  ASSERT_EQ(r.status, 200) << r.body;
  e = r.body_json();
  ASSERT_TRUE(e["per_rank"].is_object()) << e;
  EXPECT_EQ(e["per_rank"]["ranks"], 2);
  // Each rank's share of the particles is less than the whole run's; each rank is also a
  // process of its own (the program and the MPI runtime).
  double particle_share = 0.0, process = 0.0;
  for (const json& part : e["per_rank"]["memory"])
    (part["name"] == "rank_process" ? process : particle_share) += part["bytes"].get<double>();
  EXPECT_LT(particle_share, e["memory_bytes"].get<double>()) << e;
  EXPECT_GT(process, 90.0 * 1024 * 1024) << e;
  EXPECT_EQ(e["admitted"], false);
  EXPECT_EQ(e["refusal"]["field"], "ranks") << e;
  EXPECT_FALSE(e.contains("time"));
  expect_error(api.post("/api/estimate", {{"scene", tiny_scene()}, {"colour", "red"}}), 400,
               "colour");
  expect_error(api.post("/api/estimate", {{"preset", "no-such-preset"}}), 400, "preset");
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 0u);
  EXPECT_TRUE(fs::is_empty(server.data_directory / "runs"));
}

TEST(Server, EveryStateTransitionAndItsIllegalVariants) {
  TestServer server(scratch("states") / "data");
  const Api api{server.port()};
  const auto action = [&](const std::string& id, const std::string& name) {
    return api.post("/api/runs/" + id + "/" + name);
  };
  const auto state = [&](const std::string& id) { return api.run(id)["state"].get<std::string>(); };

  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  // created
  expect_error(action(id, "pause"), 409);
  expect_error(action(id, "resume"), 409);
  // created → running
  Reply r = action(id, "start");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "running");
  expect_error(action(id, "start"), 409);
  expect_error(action(id, "resume"), 409);
  ASSERT_TRUE(wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > 20; }));
  // running → paused
  r = action(id, "pause");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "paused");
  EXPECT_EQ(r.body_json()["actions"], json({"resume", "stop"}));
  expect_error(action(id, "pause"), 409);
  expect_error(action(id, "start"), 409);
  std::this_thread::sleep_for(100ms);
  const std::uint64_t paused_step = api.run(id)["step"];
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(api.run(id)["step"].get<std::uint64_t>(), paused_step) << "a paused run stepped";
  // paused → running
  r = action(id, "resume");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "running");
  ASSERT_TRUE(wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > paused_step; }));
  // running → stopped
  r = action(id, "stop");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "stopped");
  expect_error(action(id, "stop"), 409);
  expect_error(action(id, "pause"), 409);
  const double stopped_time = api.run(id)["time"];
  // stopped → running (from the checkpoint written at stop)
  r = action(id, "resume");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "running");
  ASSERT_TRUE(wait_until([&] { return api.run(id)["time"].get<double>() > stopped_time; }));
  // paused → stopped; stopped → running with start
  ASSERT_EQ(action(id, "pause").status, 200);
  ASSERT_EQ(action(id, "stop").status, 200);
  r = action(id, "start");
  ASSERT_EQ(r.status, 200) << r.body;
  ASSERT_EQ(action(id, "stop").status, 200);

  // created → stopped
  const std::string idle = api.create({{"scene", tiny_scene()}, {"start", false}});
  ASSERT_EQ(action(idle, "stop").status, 200);
  EXPECT_EQ(state(idle), "stopped");

  // running → finished; nothing but a raised time.end revives it
  const std::string short_run = api.create({{"scene", tiny_scene(0.2, "short")}});
  ASSERT_TRUE(wait_until([&] { return state(short_run) == "finished"; }));
  EXPECT_DOUBLE_EQ(api.run(short_run)["progress"], 1.0);
  for (const char* name : {"start", "pause", "resume", "stop"})
    expect_error(action(short_run, name), 409);

  // unknown run
  for (const char* name : {"start", "pause", "resume", "stop"})
    expect_error(action("0999-nothing", name), 404, "id");

  // delete: refused while active, then the run and its directory are gone
  const std::string doomed = api.create({{"scene", tiny_scene()}});
  ASSERT_EQ(state(doomed), "running");
  expect_error(api.remove("/api/runs/" + doomed), 409);
  EXPECT_EQ(state(doomed), "running");  // the refused delete harmed nothing
  ASSERT_EQ(action(doomed, "stop").status, 200);
  const fs::path doomed_directory = server.data_directory / "runs" / doomed;
  ASSERT_TRUE(fs::exists(doomed_directory / "run.json"));
  const Reply deleted = api.remove("/api/runs/" + doomed);
  ASSERT_EQ(deleted.status, 200) << deleted.body;
  EXPECT_EQ(deleted.body_json()["deleted"], doomed);
  EXPECT_FALSE(fs::exists(doomed_directory));
  expect_error(api.get("/api/runs/" + doomed), 404, "id");
  expect_error(api.remove("/api/runs/" + doomed), 404, "id");
  ASSERT_EQ(api.remove("/api/runs/" + short_run).status, 200);  // finished runs go too
  for (const auto& run : api.get("/api/runs").body_json()) {
    EXPECT_NE(run["id"], doomed);
    EXPECT_NE(run["id"], short_run);
  }
}

TEST(Server, RunsQueueBeyondMaxRunning) {
  TestServer server(scratch("queue") / "data", "", /*max_running=*/1);
  const Api api{server.port()};
  const std::string first = api.create({{"scene", tiny_scene()}});
  const std::string second = api.create({{"scene", tiny_scene()}});
  EXPECT_EQ(api.run(first)["state"], "running");
  EXPECT_EQ(api.run(second)["state"], "queued");
  expect_error(api.post("/api/runs/" + second + "/pause"), 409);
  expect_error(api.post("/api/runs/" + second + "/resume"), 409);
  ASSERT_EQ(api.post("/api/runs/" + first + "/stop").status, 200);
  ASSERT_TRUE(wait_until([&] { return api.run(second)["state"] == "running"; }));
  // queued → stopped
  const std::string third = api.create({{"scene", tiny_scene()}});
  EXPECT_EQ(api.run(third)["state"], "queued");
  ASSERT_EQ(api.post("/api/runs/" + third + "/stop").status, 200);
  EXPECT_EQ(api.run(third)["state"], "stopped");
}

TEST(Server, ParameterChangesTakeEffect) {
  TestServer server(scratch("params") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}});
  ASSERT_TRUE(wait_until([&] { return !api.run(id)["latest"].is_null(); }));
  WsClient ws(server.port(), "/api/runs/" + id + "/stream");
  ws.read_type("hello");

  Reply r = api.patch("/api/runs/" + id + "/parameters",
                      {{"fluid", {{"reference_pressure", 2.5}}}, {"time", {{"fixed_step", 1e-3}}}});
  ASSERT_EQ(r.status, 200) << r.body;
  const json changed = r.body_json();
  EXPECT_EQ(changed["effective"], "next step");
  EXPECT_NE(
      std::find(changed["changed"].begin(), changed["changed"].end(), "fluid.reference_pressure"),
      changed["changed"].end())
      << changed;
  // Visible in the scene and in the metrics from the next step on: dt = fixed_step.
  EXPECT_TRUE(
      wait_until([&] { return api.run(id)["scene"]["fluid"]["reference_pressure"] == 2.5; }));
  ws.read_until([](const WsMessage& m) {
    if (m.binary) return false;
    const json j = m.text();
    if (j["type"] != "metrics") return false;
    for (const json& s : j["samples"])
      if (std::abs(s["dt"].get<double>() - 1e-3) < 1e-12) return true;
    return false;
  });
  EXPECT_NEAR(api.run(id)["latest"]["dt"].get<double>(), 1e-3, 1e-12);

  // time.end: visible in the summary.
  ASSERT_EQ(api.patch("/api/runs/" + id + "/parameters", {{"time", {{"end", 2000.0}}}}).status,
            200);
  EXPECT_TRUE(wait_until([&] { return api.run(id)["end_time"] == 2000.0; }));

  // Rejected, naming the field: not changeable, wrong type, unknown, not an object, not JSON.
  expect_error(api.patch("/api/runs/" + id + "/parameters", {{"particles_per_side", 32}}), 400,
               "particles_per_side");
  expect_error(
      api.patch("/api/runs/" + id + "/parameters", {{"fluid", {{"reference_pressure", "high"}}}}),
      400, "fluid.reference_pressure");
  // Out of what can run: the run blew up at once when it was taken.
  expect_error(
      api.patch("/api/runs/" + id + "/parameters", {{"fluid", {{"reference_pressure", 1e308}}}}),
      400, "fluid.reference_pressure");
  expect_error(api.patch("/api/runs/" + id + "/parameters", {{"nonsense", 1}}), 400, "nonsense");
  expect_error(api.patch("/api/runs/" + id + "/parameters", {{"name", "new name?"}}), 400, "name");
  expect_error(send(server.port(), {http::verb::patch, "/api/runs/" + id + "/parameters", "[]"}),
               400);
  expect_error(send(server.port(),
                    {http::verb::patch, "/api/runs/" + id + "/parameters", "x", "text/plain"}),
               415);
  expect_error(api.patch("/api/runs/0999-none/parameters", {{"time", {{"end", 5.0}}}}), 404);
  EXPECT_DOUBLE_EQ(api.run(id)["scene"]["fluid"]["reference_pressure"], 2.5);

  // The same over the WebSocket; the messages either way are those the AsyncAPI document declares.
  const json asyncapi = stream_messages(api);
  const json change = {{"type", "parameters"},
                       {"patch", {{"fluid", {{"reference_pressure", 3.0}}}}}};
  expect_declared(asyncapi, change);
  expect_declared(asyncapi, {{"type", "images"}, {"enabled", false}});
  ws.send(change);
  const json ok = ws.read_until([](const WsMessage& m) {
                      if (m.binary) return false;
                      const std::string type = m.text().value("type", "");
                      return type == "changed" || type == "error";
                    }).text();
  ASSERT_EQ(ok["type"], "changed") << ok;
  EXPECT_EQ(ok["changed"], json({"fluid.reference_pressure"}));
  expect_declared(asyncapi, ok);
  EXPECT_TRUE(
      wait_until([&] { return api.run(id)["scene"]["fluid"]["reference_pressure"] == 3.0; }));
  ws.send({{"type", "parameters"}, {"patch", {{"particles_per_side", 8}}}});
  json error = ws.read_type("error").text();
  EXPECT_EQ(error["error"]["field"], "particles_per_side");
  expect_declared(asyncapi, error);
  ws.send({{"type", "parameters"}, {"patch", 3}});
  EXPECT_EQ(ws.read_type("error").text()["error"]["field"], "patch");
  ws.send({{"type", "launch"}});
  EXPECT_EQ(ws.read_type("error").text()["error"]["field"], "type");
  ws.send({{"type", "images"}, {"enabled", "no"}});
  EXPECT_EQ(ws.read_type("error").text()["error"]["field"], "enabled");
  ws.send({{"type", "images"}, {"enabled", false}, {"extra", 1}});
  EXPECT_EQ(ws.read_type("error").text()["error"]["field"], "extra");
  ws.send_raw("{not json");
  EXPECT_EQ(ws.read_type("error").text()["error"]["status"], 400);
  ws.send_raw("binary", true);
  EXPECT_EQ(ws.read_type("error").text()["error"]["status"], 400);

  // The run's log (run.log) records the start and each accepted change with its patch.
  const Reply log = api.get("/api/runs/" + id + "/log");
  ASSERT_EQ(log.status, 200) << log.body;
  EXPECT_EQ(log.header("content-type"), "text/plain; charset=utf-8");
  EXPECT_NE(log.body.find(" info  state: created -> running\n"), std::string::npos) << log.body;
  EXPECT_NE(log.body.find(" info  changed time.end by {\"time\":{\"end\":2000.0}} (applied at the "
                          "next step)\n"),
            std::string::npos)
      << log.body;
  EXPECT_NE(log.body.find("by {\"fluid\":{\"reference_pressure\":3.0}}"), std::string::npos)
      << log.body;
  EXPECT_EQ(log.body.find("{\"particles_per_side\""), std::string::npos)
      << "a refused change is not";
  const std::string last = api.get("/api/runs/" + id + "/log?lines=1").body;
  EXPECT_EQ(std::count(last.begin(), last.end(), '\n'), 1) << last;
  expect_error(api.get("/api/runs/" + id + "/log?lines=0"), 400, "lines");
  expect_error(api.get("/api/runs/" + id + "/log?lines=many"), 400, "lines");
  expect_error(api.get("/api/runs/0999-none/log"), 404);
}

TEST(Server, TimeSeries) {
  TestServer server(scratch("timeseries") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > 50; }));
  ASSERT_EQ(api.post("/api/runs/" + id + "/pause").status, 200);
  const json series = api.get("/api/runs/" + id + "/timeseries").body_json();
  const json& columns = series["columns"];
  ASSERT_GE(columns.size(), 7u);
  EXPECT_EQ(columns[0], "time");
  EXPECT_EQ(columns[1], "step");
  EXPECT_EQ(columns[3], "kinetic_energy");
  const json& data = series["data"];
  ASSERT_EQ(data.size(), columns.size());
  const std::size_t rows = data[0].size();
  ASSERT_GT(rows, 20u);
  for (const json& column : data) EXPECT_EQ(column.size(), rows);
  for (std::size_t k = 1; k < rows; ++k) EXPECT_GT(data[1][k], data[1][k - 1]);
  EXPECT_NEAR(data[3][0].get<double>(), 0.25, 0.01);  // e_v(0) = v0²/4 for the 2D TGV

  const std::uint64_t since = data[1][rows / 2];
  const json tail =
      api.get("/api/runs/" + id + "/timeseries?since_step=" + std::to_string(since)).body_json();
  ASSERT_FALSE(tail["data"][1].empty());
  EXPECT_GT(tail["data"][1][0].get<std::uint64_t>(), since);
  expect_error(api.get("/api/runs/" + id + "/timeseries?since_step=soon"), 400, "since_step");
}

// The resolved scales (SPEC §9) of a run against the reference run of its flow in the server's
// reference data, here a `sphles reference` run of the tiny 2D Taylor-Green vortex.
TEST(Server, ResolvedScalesAgainstTheReferenceRunOfTheFlow) {
  const fs::path base = scratch("resolved");
  const fs::path references = base / "references";
  fs::create_directories(references);
  const std::string command = std::string(SPHLES_BINARY) +
                              " reference tgv2d --set reference.points_per_side=32 "
                              "--set time.end=1 --set reference.every=0.1 --out " +
                              (references / "tgv2d_re100_sphles_32").string() + " > " +
                              (base / "reference.log").string() + " 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  TestServer server(base / "data", "", 2, [&](ServerOptions& o) { o.reference_dir = references; });
  const Api api{server.port()};
  json scene = rendered_scene(0.3);
  scene["fluid"] = {{"dynamic_viscosity", 0.01}};  // the preset's Re = 100, as the reference
  scene["render"] = {{"fields", json::array()}};
  const std::string id = api.create({{"scene", scene}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  const Reply r = api.get("/api/runs/" + id + "/resolved");
  ASSERT_EQ(r.status, 200) << r.body;
  const json body = r.body_json();
  EXPECT_EQ(body["reference"], "tgv2d_re100_sphles_32");
  const json& samples = body["samples"];
  ASSERT_EQ(samples.size(), 7u) << body;  // t = 0, 0.05, ..., 0.3 (between the reference's 0.1)
  // 16², D_K = 8Δl: k_kern = 2, k_SPH = 1; at t = 0 the only shell, k = 1, holds the energy.
  EXPECT_DOUBLE_EQ(samples[0]["k_kernel"].get<double>(), 2.0);
  EXPECT_EQ(samples[0]["shell"], json({1.0, 2.0}));
  EXPECT_NEAR(samples[0]["reference_resolved_energy"].get<double>(), 0.25, 1e-12);
  EXPECT_TRUE(samples[0]["shell_ratio"][1].is_null());  // the reference's shell 2 is empty
  const double ratio = samples[6]["resolved_energy"].get<double>() /
                       samples[6]["reference_resolved_energy"].get<double>();
  EXPECT_GT(ratio, 0.5);
  EXPECT_LT(ratio, 1.1);
  EXPECT_NEAR(body["reference_spectrum"]["t"].get<double>(), samples[6]["t"].get<double>(), 1e-9);
  EXPECT_FALSE(body["reference_spectrum"]["energy"].empty());
  EXPECT_EQ(body["filter"], "none");
  // Against the reference filtered by the run's kernel, every ratio is the plain one over Ŵ(k)².
  const Reply f = api.get("/api/runs/" + id + "/resolved?filter=kernel");
  ASSERT_EQ(f.status, 200) << f.body;
  const json filtered = f.body_json();
  EXPECT_EQ(filtered["filter"], "kernel");
  const double w = sphles::sim::kernel_transfer(sphles::sim::KernelType::WendlandC4, 2,
                                                0.5 * 8.0 * 2.0 * std::numbers::pi / 16.0, 1.0);
  EXPECT_NEAR(filtered["samples"][6]["shell_ratio"][0].get<double>(),
              samples[6]["shell_ratio"][0].get<double>() / (w * w), 1e-12);
  EXPECT_EQ(filtered["mean_shell_ratio"]["shell"], json({1.0, 2.0}));
  expect_error(api.get("/api/runs/" + id + "/resolved?filter=gaussian"), 400, "filter");
  // Another Reynolds number: none, and why.
  scene["fluid"] = {{"dynamic_viscosity", 0.02}};
  const std::string other = api.create({{"scene", scene}, {"start", false}});
  const Reply none = api.get("/api/runs/" + other + "/resolved");
  expect_error(none, 404);
  EXPECT_NE(none.body.find("sphles reference"), std::string::npos) << none.body;
}

// A run's saved frames as a video a browser plays (POST movies): movies/FIELD.webm of the run,
// listed and downloaded as video/webm; bad options are 400s naming the key, a field without
// saved frames a 404.
TEST(Server, MakesAMovieOfTheSavedFrames) {
  TestServer server(scratch("movie") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", rendered_scene(0.3)}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  const std::string movies = "/api/runs/" + id + "/movies";
  const Reply made = api.post(movies, {{"field", "omega2"}, {"fps", 5}});
  ASSERT_EQ(made.status, 201) << made.body;
  const json m = made.body_json();
  EXPECT_EQ(m["path"], "movies/omega2.webm");
  EXPECT_EQ(m["frames"], 7);  // t = 0, 0.05, ..., 0.3
  EXPECT_EQ(m["width"], 64);  // a single field's frame is height x height
  EXPECT_EQ(m["height"], 64);
  EXPECT_DOUBLE_EQ(m["duration_seconds"].get<double>(), 1.4);
  EXPECT_EQ(made.header("location"), m["url"]);
  const Reply video = api.get(m["url"].get<std::string>());
  ASSERT_EQ(video.status, 200);
  EXPECT_EQ(video.header("content-type"), "video/webm");
  EXPECT_EQ(video.body.size(), m["bytes"].get<std::size_t>());
  EXPECT_EQ(video.body.substr(0, 4), std::string("\x1A\x45\xDF\xA3"));  // EBML (WebM) header
  EXPECT_NE(video.body.find("webm"), std::string::npos);                // its DocType
  EXPECT_NE(api.get("/api/runs/" + id + "/files").body.find("movies/omega2.webm"),
            std::string::npos);
  expect_error(api.post(movies, {{"fps", 0}}), 400, "fps");
  expect_error(api.post(movies, {{"quality", 2.5}}), 400, "quality");
  expect_error(api.post(movies, {{"speed", 2}}), 400, "speed");
  expect_error(api.post(movies, {{"field", "pressure"}}), 400, "field");
  expect_error(api.post(movies, {{"field", "tau_sfs"}}), 404, "field");  // rendered: omega2 only
  expect_error(api.post("/api/runs/nope/movies", json::object()), 404);
}

// The analysis history: one row per analysis frame from stats/snapshots.csv, so that a page loaded
// late (or after a restart) plots the dissipation estimates and |τ_SFS| of every frame, not only
// those streamed since it connected.
TEST(Server, AnalysisHistoryHasEveryFrame) {
  TestServer server(scratch("analysis_history") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", rendered_scene(0.3)}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  const json h = api.get("/api/runs/" + id + "/analysis").body_json();
  const json& columns = h["columns"];
  ASSERT_GE(columns.size(), 9u) << h;
  EXPECT_EQ(columns[0], "time");
  EXPECT_EQ(columns[1], "step");
  const auto column = [&](const std::string& name) -> const json& {
    for (std::size_t k = 0; k < columns.size(); ++k)
      if (columns[k] == name) return h["data"][k];
    throw std::runtime_error("no column " + name);
  };
  // analysis.every = 0.05 to t = 0.3: frames at 0, 0.05, ..., 0.3.
  const json& time = column("time");
  ASSERT_EQ(time.size(), 7u) << h;
  for (std::size_t k = 0; k < time.size(); ++k)
    EXPECT_NEAR(time[k].get<double>(), 0.05 * static_cast<double>(k), 1e-9);
  for (const json& v : column("tau_sfs_max")) EXPECT_GT(v.get<double>(), 0.0);
  for (const json& v : column("dissipation_spectral")) EXPECT_GT(v.get<double>(), 0.0);
  EXPECT_EQ(h["more"], false);
  // Paged and decimated as the time series.
  const json page = api.get("/api/runs/" + id + "/analysis?limit=2").body_json();
  EXPECT_EQ(page["data"][0].size(), 2u);
  EXPECT_EQ(page["more"], true);
  const json few = api.get("/api/runs/" + id + "/analysis?max_points=3").body_json();
  EXPECT_LE(few["data"][0].size(), 3u);
  EXPECT_EQ(few["data"][0].back(), time.back()) << "the last frame is kept";
  expect_error(api.get("/api/runs/" + id + "/analysis?limit=0"), 400, "limit");
  expect_error(api.get("/api/runs/0999-none/analysis"), 404);
  // A run without analysis frames has no columns yet.
  const std::string bare = api.create({{"scene", tiny_scene()}, {"start", false}});
  EXPECT_TRUE(api.get("/api/runs/" + bare + "/analysis").body_json()["columns"].empty());

  // The reference curve the dashboard draws dashed: the analytic decay of this 2D TGV; none
  // (404 with the reason) for a 3D TGV at another Reynolds number than the DNS'.
  const json ref = api.get("/api/runs/" + bare + "/reference").body_json();
  EXPECT_EQ(ref["label"], "analytic decay");
  EXPECT_EQ(ref["columns"], json({"time", "kinetic_energy", "dissipation"}));
  ASSERT_EQ(ref["data"][0].size(), 201u);
  EXPECT_DOUBLE_EQ(ref["data"][1][0].get<double>(), 0.25);
  EXPECT_DOUBLE_EQ(ref["data"][0].back().get<double>(), 1000.0);  // tiny_scene's end time
  // ?until= ends it early, sampled as finely over the shorter span; past the end it is the same.
  const json early = api.get("/api/runs/" + bare + "/reference?until=2.5").body_json();
  ASSERT_EQ(early["data"][0].size(), 201u);
  EXPECT_DOUBLE_EQ(early["data"][0].back().get<double>(), 2.5);
  EXPECT_DOUBLE_EQ(early["data"][0][1].get<double>(), 2.5 / 200);
  EXPECT_EQ(api.get("/api/runs/" + bare + "/reference?until=5000").body_json(), ref);
  for (const char* bad : {"0", "-1", "abc", "nan", "inf", ""})
    expect_error(api.get("/api/runs/" + bare + "/reference?until=" + bad), 400, "until");
  EXPECT_EQ(api.run(bare)["available"]["reference"], true);
  const std::string thesis =
      api.create({{"preset", "tgv3d"}, {"patch", {{"particles_per_side", 16}}}, {"start", false}});
  EXPECT_EQ(api.run(thesis)["available"]["reference"], false);
  const Reply none = api.get("/api/runs/" + thesis + "/reference");
  expect_error(none, 404);
  EXPECT_NE(none.body.find("Re = 5000"), std::string::npos) << none.body;
}

// Downloads: every file of a run is listed with its size and served whole, byte for byte, streamed
// from disk: also a file larger than one response may be in memory.
TEST(Server, RunFilesAreListedAndDownloadedWhole) {
  constexpr std::size_t kAnswerLimit = 2048;  // bytes of one in-memory answer (507 beyond)
  TestServer server(scratch("files") / "data", "", 2,
                    [&](ServerOptions& o) { o.responses.max_bytes = kAnswerLimit; });
  const Api api{server.port()};
  json scene = rendered_scene(0.2);
  scene["checkpoint"] = {{"every", 0.1}};
  const std::string id = api.create({{"scene", scene}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  const fs::path dir = server.data_directory / "runs" / id;
  const json list = api.get("/api/runs/" + id + "/files").body_json();
  std::map<std::string, json> by_path;
  for (const json& f : list) by_path[f["path"]] = f;
  for (const char* expected : {"scene.json", "run.json", "run.log", "timeseries.csv",
                               "spectra/index.csv", "stats/snapshots.csv"})
    EXPECT_TRUE(by_path.count(expected)) << expected << " not listed: " << list;
  std::string checkpoint;
  for (const auto& [path, f] : by_path) {
    EXPECT_EQ(f["bytes"].get<std::uintmax_t>(), fs::file_size(dir / path)) << path;
    EXPECT_EQ(f["url"], "/api/runs/" + id + "/files/" + path);
    EXPECT_EQ(path.find(".tmp"), std::string::npos) << path;
    if (path.rfind("checkpoints/ckpt_", 0) == 0 && fs::path(path).extension() == ".h5")
      checkpoint = path;
  }
  ASSERT_FALSE(checkpoint.empty()) << list;
  ASSERT_GT(fs::file_size(dir / checkpoint), kAnswerLimit) << "larger than one in-memory answer";
  const auto bytes_of = [](const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  for (const std::string& path : {std::string("timeseries.csv"), checkpoint}) {
    const Reply r = api.get("/api/runs/" + id + "/files/" + path);
    ASSERT_EQ(r.status, 200) << path << ": " << r.body.substr(0, 300);
    EXPECT_TRUE(r.body == bytes_of(dir / path)) << path << ": " << r.body.size() << " bytes";
    EXPECT_EQ(r.header("content-disposition"),
              "attachment; filename=\"" + fs::path(path).filename().string() + "\"");
  }
  EXPECT_EQ(api.get("/api/runs/" + id + "/files/timeseries.csv").header("content-type"),
            "text/csv; charset=utf-8");
  EXPECT_EQ(api.get("/api/runs/" + id + "/files/" + checkpoint).header("content-type"),
            "application/x-hdf5");
  // The whole run as one tar archive: RUN_ID.tar, every listed file under RUN_ID/, byte for byte
  // (read back by Python's tarfile).
  const Reply archive = api.get("/api/runs/" + id + "/archive");
  ASSERT_EQ(archive.status, 200) << archive.body.substr(0, 300);
  EXPECT_EQ(archive.header("content-type"), "application/x-tar");
  EXPECT_EQ(archive.header("content-disposition"), "attachment; filename=\"" + id + ".tar\"");
  EXPECT_EQ(archive.header("content-length"), std::to_string(archive.body.size()));
  const fs::path work = scratch("archive");
  const fs::path tar = work / (id + ".tar");
  std::ofstream(tar, std::ios::binary) << archive.body;
  const fs::path listing = work / "members.txt";
  const std::string check =
      "python3 -c \"import sys, tarfile; t = tarfile.open(sys.argv[1], 'r:'); "
      "[print(m.name, m.size) for m in t.getmembers() if m.isfile()]\" " +
      tar.string() + " > " + listing.string();
  ASSERT_EQ(std::system(check.c_str()), 0) << "not a tar archive Python reads";
  std::string members, expected;
  {
    std::ifstream in(listing);
    members.assign(std::istreambuf_iterator<char>(in), {});
  }
  for (const auto& [path, f] : by_path)
    expected += id + "/" + path + " " + std::to_string(f["bytes"].get<std::uintmax_t>()) + "\n";
  EXPECT_EQ(members, expected);
  const std::string check_bytes =
      "python3 -c \"import sys, tarfile; t = tarfile.open(sys.argv[1]); "
      "sys.exit(t.extractfile(sys.argv[2]).read() != open(sys.argv[3], 'rb').read())\" " +
      tar.string() + " " + id + "/" + checkpoint + " " + (dir / checkpoint).string();
  EXPECT_EQ(std::system(check_bytes.c_str()), 0) << checkpoint << " differs in the archive";
  expect_error(api.get("/api/runs/0999-none/archive"), 404);
  // HEAD: the size, no body.
  const Reply head =
      send(server.port(), {http::verb::head, "/api/runs/" + id + "/files/" + checkpoint});
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.header("content-length"), std::to_string(fs::file_size(dir / checkpoint)));
  EXPECT_TRUE(head.body.empty());
  // Nothing outside the run's files.
  expect_error(api.get("/api/runs/" + id + "/files/no-such-file"), 404, "path");
  expect_error(api.get("/api/runs/" + id + "/files/checkpoints"), 404, "path");
  expect_error(api.get("/api/runs/" + id + "/files/..%2Frun.json"), 400);
  expect_error(api.get("/api/runs/" + id + "/files/../" + id + "/run.json"), 404);  // no route
  expect_error(api.get("/api/runs/" + id + "/files/.hidden"), 400, "path");
  expect_error(api.get("/api/runs/0999-none/files"), 404);
}

TEST(Server, WebSocketStreamsMetricsSpectraAndFrames) {
  TestServer server(scratch("stream") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", rendered_scene()}});
  WsClient ws(server.port(), "/api/runs/" + id + "/stream");
  const json hello = ws.read().text();
  ASSERT_EQ(hello["type"], "hello");
  EXPECT_EQ(hello["run"]["id"], id);
  EXPECT_TRUE(hello["run"].contains("scene"));
  const json asyncapi = stream_messages(api);
  expect_declared(asyncapi, hello);

  bool metrics = false, spectrum = false, statistics = false, image = false;
  std::optional<std::uint64_t> last_step;
  ws.read_until(
      [&](const WsMessage& m) {
        if (m.binary) {
          // 4-byte big-endian header length, JSON header, PNG.
          const auto* p = reinterpret_cast<const unsigned char*>(m.data.data());
          const std::size_t length = (std::size_t{p[0]} << 24) | (std::size_t{p[1]} << 16) |
                                     (std::size_t{p[2]} << 8) | std::size_t{p[3]};
          EXPECT_LT(4 + length, m.data.size());
          const json header = json::parse(m.data.substr(4, length));
          EXPECT_EQ(header["type"], "image");
          if (!image) expect_declared(asyncapi, header);
          EXPECT_TRUE(header["field"] == "omega2" || header["field"] == "combined") << header;
          EXPECT_TRUE(header["created_ns"].is_number_integer());
          EXPECT_TRUE(header["url"].get<std::string>().starts_with("/api/runs/" + id + "/"));
          EXPECT_EQ(m.data.substr(4 + length, 8), kPngSignature);
          image = true;
        } else {
          const json j = m.text();
          if ((j["type"] == "metrics" && !metrics) || (j["type"] == "spectrum" && !spectrum) ||
              (j["type"] == "statistics" && !statistics))
            expect_declared(asyncapi, j);
          if (j["type"] == "metrics") {
            EXPECT_FALSE(j["samples"].empty());
            for (const json& s : j["samples"]) {
              if (last_step) {
                EXPECT_GT(s["step"].get<std::uint64_t>(), *last_step);
              }
              last_step = s["step"].get<std::uint64_t>();
              EXPECT_TRUE(s.contains("kinetic_energy") && s.contains("max_speed"));
            }
            metrics = true;
          } else if (j["type"] == "spectrum") {
            EXPECT_EQ(j["k"].size(), j["energy"].size());
            EXPECT_GT(j["kernel_wavenumber"].get<double>(), 0.0);
            // The dissipation estimates of SPEC §5 (4.6) travel with the spectrum; -de_v/dt is
            // null until the time series has two rows.
            EXPECT_GT(j["dissipation"].get<double>(), 0.0);
            EXPECT_GT(j["dissipation_vorticity"].get<double>(), 0.0);
            EXPECT_TRUE(j["dissipation_energy"].is_null() || j["dissipation_energy"].is_number())
                << j["dissipation_energy"];
            EXPECT_EQ(j["vorticity_estimate"], "mls");
            spectrum = true;
          } else if (j["type"] == "statistics") {
            EXPECT_TRUE(j.contains("joint") && j.contains("max_norm"));
            statistics = true;
          }
        }
        return metrics && spectrum && statistics && image;
      },
      60s);
  EXPECT_EQ(api.run(id)["stream"]["clients"], 1);

  // The same products over REST.
  Reply r = api.get("/api/runs/" + id + "/images/omega2");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.header("content-type"), "image/png");
  EXPECT_EQ(r.body.substr(0, 8), kPngSignature);
  expect_error(api.get("/api/runs/" + id + "/images/view3d"), 404, "field");
  expect_error(api.get("/api/runs/" + id + "/images/..%2fscene.json"), 400);
  expect_error(api.get("/api/runs/" + id + "/images/omega2.png"), 400, "field");
  EXPECT_EQ(api.get("/api/runs/" + id + "/spectrum").status, 200);
  EXPECT_EQ(api.get("/api/runs/" + id + "/statistics").status, 200);
  // The run detail says which products exist, so clients need not probe for 404s.
  const json available = api.run(id)["available"];
  EXPECT_TRUE(available["spectrum"].get<bool>());
  EXPECT_TRUE(available["statistics"].get<bool>());
  const auto& images = available["images"];
  EXPECT_NE(std::find(images.begin(), images.end(), "omega2"), images.end()) << images;
  EXPECT_EQ(std::find(images.begin(), images.end(), "view3d"), images.end()) << images;
  json frames;
  ASSERT_TRUE(wait_until([&] {
    frames = api.get("/api/runs/" + id + "/frames").body_json();
    return !frames.empty();
  }));
  const json& frame = frames[0];
  EXPECT_TRUE(frame.contains("time") && frame.contains("step") && frame.contains("field"));
  r = api.get(frame["url"].get<std::string>());
  ASSERT_EQ(r.status, 200) << frame;
  EXPECT_EQ(r.body.substr(0, 8), kPngSignature);
  expect_error(api.get("/api/runs/" + id + "/frames/nothing.png"), 404, "file");
  for (const char* bad : {"..%2f..%2fscene.json", "%2e%2e", "..", ".hidden.png", "a%00.png"}) {
    const Reply t = api.get("/api/runs/" + id + "/frames/" + bad);
    EXPECT_TRUE(t.status == 400 || t.status == 404) << bad << ": " << t.status;
  }

  // Images off: the stream goes on with metrics only. Images the server sent before it handled
  // the switch may still be unread in the socket, as many as the test left unread meanwhile
  // (a fixed bound on them failed once on a loaded CI machine), so the check is that they end:
  // 20 text messages in a row (about a second of metrics, spectra and statistics, among which
  // images come every analysis frame while they are on) within 300 messages.
  ws.send({{"type", "images"}, {"enabled", false}});
  int in_a_row = 0, read = 0;
  ws.read_until([&](const WsMessage& m) {
    ++read;
    in_a_row = m.binary ? 0 : in_a_row + 1;
    return in_a_row >= 20 || read >= 300;
  });
  EXPECT_GE(in_a_row, 20) << "images still arrive after " << read << " messages";
  int later_images = 0, later = 0;
  ws.read_until([&](const WsMessage& m) {
    later_images += m.binary ? 1 : 0;
    return ++later >= 100;
  });
  EXPECT_EQ(later_images, 0) << "images among the next 100 messages";

  // A state change reaches the client.
  ASSERT_EQ(api.post("/api/runs/" + id + "/pause").status, 200);
  const json state = ws.read_type("state").text();
  EXPECT_EQ(state["state"], "paused");
  EXPECT_EQ(state["actions"], json({"resume", "stop"}));  // those of the new state
  expect_declared(asyncapi, state);

  // Unknown run or path: the upgrade is declined with 404.
  EXPECT_EQ(upgrade_status(server.port(), "/api/runs/0999-none/stream"), 404);
  EXPECT_EQ(upgrade_status(server.port(), "/api/runs"), 404);
  EXPECT_EQ(upgrade_status(server.port(), "/api/runs/" + id + "/stream"), 101);
  // Plain GET on the stream endpoint.
  expect_error(api.get("/api/runs/" + id + "/stream"), 426);
}

TEST(Server, ManyClientsAndDisconnectsLeaveTheRunAlone) {
  TestServer server(scratch("clients") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", rendered_scene()}});
  {
    std::vector<std::unique_ptr<WsClient>> clients;
    for (int k = 0; k < 8; ++k)
      clients.push_back(std::make_unique<WsClient>(server.port(), "/api/runs/" + id + "/stream"));
    for (auto& c : clients) c->read_type("metrics");
    EXPECT_EQ(api.run(id)["stream"]["clients"], 8);
    // Some vanish without a close frame.
    for (int k = 0; k < 4; ++k) clients.pop_back();
  }
  ASSERT_TRUE(wait_until([&] { return api.run(id)["stream"]["clients"] == 0; }));
  const std::uint64_t step = api.run(id)["step"];
  ASSERT_TRUE(wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > step; }));
  EXPECT_EQ(api.run(id)["state"], "running");
}

TEST(Server, TokenGuardsMutatingCalls) {
  const std::string token = "s3cret-token";
  TestServer server(scratch("token") / "data", token);
  const Api anonymous{server.port()};
  const Api wrong{server.port(), "not-the-token"};
  const Api owner{server.port(), token};

  for (const Api* api : {&anonymous, &wrong}) {
    const Reply r = api->post("/api/runs", {{"scene", tiny_scene()}});
    expect_error(r, 401, "Authorization");
    EXPECT_EQ(r.header("www-authenticate"), "Bearer");
  }
  EXPECT_EQ(send(server.port(), {http::verb::post,
                                 "/api/runs",
                                 json{{"scene", tiny_scene()}}.dump(),
                                 "application/json",
                                 {{"Authorization", "Basic " + token}}})
                .status,
            401);
  const std::string id = owner.create({{"scene", tiny_scene()}, {"start", false}});
  ASSERT_FALSE(id.empty());
  EXPECT_EQ(owner.run(id)["available"], json({{"spectrum", false},
                                              {"statistics", false},
                                              {"images", json::array()},
                                              {"reference", true},
                                              {"resolved", false}}));
  // Reading needs no token.
  EXPECT_EQ(anonymous.get("/api/runs").status, 200);
  EXPECT_EQ(anonymous.get("/api/runs/" + id).status, 200);
  for (const char* action : {"start", "pause", "resume", "stop"})
    expect_error(anonymous.post("/api/runs/" + id + "/" + action), 401);
  expect_error(anonymous.patch("/api/runs/" + id + "/parameters", {{"time", {{"end", 5.0}}}}), 401);
  expect_error(anonymous.remove("/api/runs/" + id), 401);
  // An estimate spends the server's CPU on a calibration: the token's holders only.
  expect_error(anonymous.post("/api/estimate", {{"scene", tiny_scene()}}), 401, "Authorization");
  EXPECT_EQ(owner.post("/api/estimate", {{"scene", tiny_scene()}}).status, 200);
  EXPECT_EQ(anonymous.run(id)["state"], "created");
  ASSERT_EQ(owner.post("/api/runs/" + id + "/start").status, 200);

  // WebSocket: reading is open, parameter messages need ?token=.
  {
    WsClient ws(server.port(), "/api/runs/" + id + "/stream");
    ws.read_type("hello");
    ws.send({{"type", "parameters"}, {"patch", {{"time", {{"end", 5000.0}}}}}});
    EXPECT_EQ(ws.read_type("error").text()["error"]["status"], 401);
  }
  {
    WsClient ws(server.port(), "/api/runs/" + id + "/stream?token=" + token);
    ws.read_type("hello");
    ws.send({{"type", "parameters"}, {"patch", {{"time", {{"end", 5000.0}}}}}});
    EXPECT_EQ(ws.read_type("changed").text()["changed"], json({"time.end"}));
  }
  EXPECT_TRUE(wait_until([&] { return owner.run(id)["end_time"] == 5000.0; }));
}

TEST(Server, RestartResumesFromTheCheckpoint) {
  const fs::path data = scratch("restart") / "data";
  std::string id;
  double stopped_time = 0.0;
  std::uint64_t stopped_step = 0;
  {
    TestServer a(data);
    const Api api{a.port()};
    id = api.create({{"scene", tiny_scene()}});
    ASSERT_TRUE(wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > 100; }));
    a.shutdown();  // as on SIGTERM: stop accepting, RunManager::shutdown, stop
  }
  {
    // run.json says stopped, and a checkpoint is there.
    std::ifstream in(data / "runs" / id / "run.json");
    const json record = json::parse(in);
    EXPECT_EQ(record["state"], "stopped") << record;
    stopped_time = record["time"];
    stopped_step = record["step"];
    EXPECT_GT(stopped_step, 100u);
    ASSERT_TRUE(fs::exists(data / "runs" / id / "checkpoints"));
    EXPECT_FALSE(fs::is_empty(data / "runs" / id / "checkpoints"));
  }
  TestServer b(data);
  const Api api{b.port()};
  const json runs = api.get("/api/runs").body_json();
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0]["id"], id);
  EXPECT_EQ(runs[0]["state"], "stopped");
  EXPECT_DOUBLE_EQ(runs[0]["time"], stopped_time);

  WsClient ws(b.port(), "/api/runs/" + id + "/stream");
  ws.read_type("hello");
  const Reply r = api.post("/api/runs/" + id + "/resume");
  ASSERT_EQ(r.status, 200) << r.body;
  EXPECT_EQ(r.body_json()["state"], "running");
  // The first metrics after the restart continue from the checkpoint, not from t = 0.
  const json first = ws.read_type("metrics").text()["samples"][0];
  EXPECT_GT(first["step"].get<std::uint64_t>(), stopped_step);
  EXPECT_GE(first["time"].get<double>(), stopped_time);
  ASSERT_TRUE(
      wait_until([&] { return api.run(id)["step"].get<std::uint64_t>() > stopped_step + 50; }));
  EXPECT_GT(api.run(id)["time"].get<double>(), stopped_time);
  // The time series on disk goes on without repeating steps.
  std::ifstream csv(data / "runs" / id / "timeseries.csv");
  std::string line;
  std::getline(csv, line);
  long long previous = -1;
  while (std::getline(csv, line)) {
    const std::size_t comma = line.find(',');
    if (comma == std::string::npos || line.find(',', comma + 1) == std::string::npos) continue;
    const long long step = std::atoll(line.c_str() + comma + 1);
    EXPECT_GT(step, previous) << line;
    previous = step;
  }
}

TEST(Server, StaticFilesAndTraversal) {
  TestServer server(scratch("static") / "data");
  const Api api{server.port()};
  Reply r = api.get("/");
  ASSERT_EQ(r.status, 200);
  EXPECT_EQ(r.header("content-type"), "text/html; charset=utf-8");
  EXPECT_NE(r.body.find("sphles"), std::string::npos);
  r = api.get("/app.js");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.header("content-type"), "text/javascript; charset=utf-8");
  r = api.get("/sub/style.css?v=3");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.header("content-type"), "text/css; charset=utf-8");
  r = send(server.port(), {http::verb::head, "/app.js"});
  EXPECT_EQ(r.status, 200);
  EXPECT_TRUE(r.body.empty());
  EXPECT_EQ(r.header("content-length"), "22");
  expect_error(api.get("/missing.html"), 404);
  expect_error(api.post("/index.html"), 405);
  expect_error(api.get("/api/nothing-here"), 404, "path");
  r = send(server.port(), {http::verb::delete_, "/api/runs"});
  expect_error(r, 405, "method");
  EXPECT_EQ(r.header("allow"), "GET, HEAD, POST");

  const std::vector<std::string> attacks = {"/../secret.txt",
                                            "/%2e%2e/secret.txt",
                                            "/%2E%2E/secret.txt",
                                            "/%2e%2e%2fsecret.txt",
                                            "/..%2fsecret.txt",
                                            "/sub/../../secret.txt",
                                            "/sub/%2e%2e/%2e%2e/secret.txt",
                                            "/%252e%252e/secret.txt",
                                            "/..\\secret.txt",
                                            "/%5c..%5csecret.txt",
                                            "//etc/passwd",
                                            "/escape/secret.txt",
                                            "/escape/data/../secret.txt",
                                            "/.hidden",
                                            "/%00",
                                            "/sub/%00/../../secret.txt",
                                            "/%",
                                            "/%zz",
                                            "/./secret.txt",
                                            "/sub/./../../secret.txt"};
  for (const std::string& target : attacks) {
    const std::string raw = raw_exchange(
        server.port(), "GET " + target + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
    const int status = status_of(raw);
    EXPECT_TRUE(status == 400 || status == 404) << target << " → " << status;
    EXPECT_EQ(raw.find(kSecret), std::string::npos) << target;
  }
  for (const std::string& target :
       {std::string("http://127.0.0.1/etc/passwd"), std::string("*"), std::string("/etc/passwd")}) {
    const std::string raw = raw_exchange(
        server.port(), "GET " + target + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
    EXPECT_TRUE(status_of(raw) == 400 || status_of(raw) == 404) << target << ": " << raw;
  }
  EXPECT_EQ(api.get("/api/health").status, 200);
}

TEST(Server, LimitsOnBodiesHeadersAndKeepAlive) {
  TestServer server(scratch("limits") / "data");
  const Api api{server.port()};
  // Declared body over 1 MiB: 413 before any of it is read.
  std::string raw = raw_exchange(server.port(),
                                 "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: "
                                 "application/json\r\nContent-Length: 99999999999\r\n\r\n");
  EXPECT_EQ(status_of(raw), 413) << raw;
  EXPECT_EQ(json::parse(body_of(raw))["error"]["status"], 413);
  // An actual 2 MiB body: the server answers after the header and reads the rest away, so the
  // client gets the 413 rather than a reset.
  const std::string big = "{\"name\":\"" + std::string(2u << 20, 'a') + "\"}";
  raw = raw_exchange(server.port(),
                     "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                     "Content-Length: " +
                         std::to_string(big.size()) + "\r\n\r\n" + big);
  EXPECT_EQ(status_of(raw), 413) << raw.substr(0, 200);
  // Chunked over the limit.
  std::string chunked =
      "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
      "Transfer-Encoding: chunked\r\n\r\n";
  for (int k = 0; k < 20; ++k) chunked += "10000\r\n" + std::string(0x10000, ' ') + "\r\n";
  raw = raw_exchange(server.port(), chunked);
  EXPECT_EQ(status_of(raw), 413) << raw.substr(0, 200);
  // Header over the limit.
  raw = raw_exchange(server.port(), "GET /api/health HTTP/1.1\r\nHost: x\r\nX-Big: " +
                                        std::string(40000, 'b') + "\r\n\r\n");
  EXPECT_EQ(status_of(raw), 431) << raw.substr(0, 200);
  // Keep-alive: three requests on one connection.
  raw = raw_exchange(server.port(),
                     "GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n"
                     "GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n"
                     "GET /api/health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  std::size_t count = 0;
  for (std::size_t at = raw.find("HTTP/1.1 200"); at != std::string::npos;
       at = raw.find("HTTP/1.1 200", at + 1))
    ++count;
  EXPECT_EQ(count, 3u);
  EXPECT_EQ(api.get("/api/health").status, 200);
}

/// Thousands of malformed requests; afterwards the server answers correctly and a run that
/// existed before is unharmed.
TEST(Server, HostileInputFuzz) {
  TestServer server(scratch("fuzz") / "data");
  const Api api{server.port()};
  // `precious` is never addressed by the fuzz; `id` is, and may legitimately change state.
  const std::string precious = api.create({{"scene", tiny_scene(1000.0, "precious")}});
  ASSERT_TRUE(wait_until([&] { return api.run(precious)["step"].get<std::uint64_t>() > 10; }));
  ASSERT_EQ(api.post("/api/runs/" + precious + "/pause").status, 200);
  std::this_thread::sleep_for(200ms);  // pausing takes effect between two steps
  const json before = api.run(precious);
  const std::string id = api.create({{"scene", tiny_scene(1000.0, "target")}, {"start", false}});

  std::mt19937 random(20241122);  // deterministic
  const auto pick = [&](const auto& items) -> const auto& {
    return items[std::uniform_int_distribution<std::size_t>(0, items.size() - 1)(random)];
  };
  const auto bytes = [&](std::size_t n) {
    std::string s(n, '\0');
    for (char& c : s) c = static_cast<char>(random() & 0xff);
    return s;
  };
  const std::vector<std::string> methods = {"GET",     "POST",  "PATCH",   "PUT",  "DELETE", "HEAD",
                                            "OPTIONS", "TRACE", "CONNECT", "BREW", "G\x01T", ""};
  const std::vector<std::string> targets = {"/api/runs",
                                            "/api/runs/" + id,
                                            "/api/runs/" + id + "/parameters",
                                            "/api/runs/" + id + "/start",
                                            "/api/runs/" + id + "/stop",
                                            "/api/runs/" + id + "/pause",
                                            "/api/runs/%2e%2e/frames/x",
                                            "/api/runs/" + id + "/frames/..%2f..%2frun.json",
                                            "/api/runs/" + id + "/images/%00",
                                            "/api/runs/" + id + "/timeseries?since_step=-1",
                                            "/api/health?%zz",
                                            "/../../etc/passwd",
                                            "/%2e%2e/%2e%2e/etc/passwd",
                                            "/api/presets",
                                            "/api/openapi.json",
                                            "/index.html",
                                            "/api/runs/" + id + "/stream",
                                            "*",
                                            "",
                                            "http://x/api/health",
                                            "/api/runs/\xff\xfe",
                                            "/api/runs/" + std::string(3000, 'r')};
  const std::vector<std::string> bodies = {
      "{}",
      "[]",
      "null",
      "1",
      "\"x\"",
      "{\"preset\":5}",
      "{\"scene\":\"x\"}",
      "{\"scene\":{\"case\":\"tgv9d\"},\"start\":false}",
      "{\"start\":\"yes\"}",
      "{\"overrides\":[1]}",
      "{\"overrides\":\"a=b\"}",
      "{\"patch\":[]}",
      "{\"preset\":\"tgv2d\"",
      "{\"fluid\":{\"reference_pressure\":\"high\"}}",
      "{\"time\":{\"end\":-1}}",
      "{\"particles_per_side\":1e308}",
      "{\"a\":{\"b\":{\"c\":{\"d\":[[[[[[]]]]]]}}}}",
      std::string(5000, '['),
      std::string(5000, '{'),
      "{\"\xff\":1}",
      "{\"name\":\"\\ud800\"}",
      "{\"scene\":{},\"preset\":\"tgv3d-case1\",\"start\":false}",
      "\xef\xbb\xbf{}",
      "{\"time\":{\"end\":1e999}}",
      "{\"render\":{\"colour\":{\"omega2\":{\"min\":-1}}}}"};
  const json valid_create = {{"scene", tiny_scene()}, {"start", false}, {"name", "fuzz"}};
  const std::vector<std::string> content_types = {
      "application/json",         "text/plain",         "", "application/json; charset=utf-8",
      "application/problem+json", "multipart/form-data"};

  int answered = 0, server_errors = 0, created = 0;
  std::map<int, int> statuses;
  constexpr int kCases = 5000;
  for (int k = 0; k < kCases; ++k) {
    std::string request;
    bool expect_answer = true;
    switch (k % 10) {
      case 0:  // garbage bytes
        request = bytes(1 + random() % 600);
        expect_answer = false;
        break;
      case 1: {  // bad request lines
        const std::vector<std::string> lines = {
            "GET\r\n\r\n",
            "GET / HTTP/9.9\r\n\r\n",
            "GET  / HTTP/1.1\r\n\r\n",
            "GET / HTTP/1.1 extra\r\n\r\n",
            "/ GET HTTP/1.1\r\n\r\n",
            "GET / FTP/1.1\r\n\r\n",
            "\r\n\r\n",
            "GET /\x7f HTTP/1.1\r\nHost: x\r\n\r\n",
            "GET " + std::string(20000, 'a') + " HTTP/1.1\r\n\r\n"};
        request = pick(lines);
        break;
      }
      case 2: {  // bad headers
        const std::vector<std::string> headers = {
            "Host: x\r\nBad Header\r\n",
            "Host: x\r\n: empty\r\n",
            "Host x\r\n",
            "Host: x\r\nContent-Length: -5\r\n",
            "Host: x\r\nContent-Length: 1, 2\r\n",
            "Host: x\r\nContent-Length: abc\r\n",
            "Host: x\r\nTransfer-Encoding: gzip\r\n",
            "Host: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
            "Host: x\r\nX: " + std::string(20000, 'x') + "\r\n",
            "Host: x\r\n\tfolded\r\n",
            "Host: x\r\nContent-Length: 3\r\nContent-Length: 4\r\n"};
        request = pick(methods) + " " + pick(targets) + " HTTP/1.1\r\n" + pick(headers) + "\r\n";
        break;
      }
      case 3:  // huge declared length
        request =
            "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            "Content-Length: " +
            std::to_string(
                std::uniform_int_distribution<long long>((1 << 20) + 1, 1LL << 50)(random)) +
            "\r\n\r\n{";
        break;
      case 4: {  // truncated body
        const std::string body = valid_create.dump();
        request =
            "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            "Content-Length: " +
            std::to_string(body.size() + 10) + "\r\n\r\n" + body.substr(0, random() % body.size());
        break;
      }
      case 5:
      case 6: {  // malformed or wrongly typed JSON, or a mutated valid request
        std::string body = pick(bodies);
        if (k % 20 == 5) {
          body = valid_create.dump();
          for (int m = 0; m < 3; ++m) body[random() % body.size()] = static_cast<char>(random());
        }
        const std::string target = pick(std::vector<std::string>{
            "/api/runs", "/api/runs/" + id + "/parameters", "/api/runs/" + id + "/start"});
        const std::string method = target.ends_with("parameters") ? "PATCH" : "POST";
        request = method + " " + target + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n" +
                  "Content-Type: " + pick(content_types) +
                  "\r\nContent-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
        break;
      }
      case 7: {  // random method/target combinations
        request = pick(methods) + " " + pick(targets) +
                  " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
        expect_answer = !request.starts_with(" ") && !request.starts_with("G\x01T");
        break;
      }
      case 8: {  // traversal
        const std::vector<std::string> paths = {
            "/..",
            "/../",
            "/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
            "/.%2e/.%2e/etc/passwd",
            "/static/..%5c..%5cwindows",
            "/%c0%ae%c0%ae/etc/passwd",
            "/%252e%252e%252f",
            "/api/runs/" + id + "/frames/%2e%2e%2f%2e%2e%2fscene.json",
            "/api/runs/" + id + "/frames/..",
            "/escape/secret.txt",
            "/escape/../secret.txt"};
        request = "GET " + pick(paths) + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
        break;
      }
      case 9: {  // a valid request with random bytes flipped
        request =
            "POST /api/runs HTTP/1.1\r\nHost: x\r\nConnection: close\r\n"
            "Content-Type: application/json\r\nContent-Length: " +
            std::to_string(valid_create.dump().size()) + "\r\n\r\n" + valid_create.dump();
        for (int m = 0; m < 2; ++m)
          request[random() % request.size()] = static_cast<char>(random() & 0xff);
        expect_answer = false;
        break;
      }
    }
    const std::string raw = raw_exchange(server.port(), request, true, 10s);
    const int status = status_of(raw);
    ++statuses[status];
    if (status != 0) {
      ++answered;
      if (status >= 500) {
        ++server_errors;
        ADD_FAILURE() << "case " << k << ": " << status << "\n" << raw.substr(0, 300);
      }
      if (status == 201) ++created;
      if (status >= 400 && status != 405 && !body_of(raw).empty() &&
          raw.find("chunked") == std::string::npos) {
        // Every error body is the JSON error object.
        const json error = json::parse(body_of(raw), nullptr, false);
        EXPECT_FALSE(error.is_discarded()) << "case " << k << ": " << raw.substr(0, 300);
        if (!error.is_discarded()) {
          EXPECT_EQ(error["error"]["status"], status) << raw;
        }
      }
      if (raw.find("top-secret") != std::string::npos) ADD_FAILURE() << "leak in case " << k;
    } else if (expect_answer && k % 10 != 4) {
      ADD_FAILURE() << "case " << k << " got no answer: " << request.substr(0, 200);
    }
    if (server_errors > 5) break;
  }
  std::printf("fuzz: %d cases, %d answered, %d created runs; status (count):", kCases, answered,
              created);
  for (const auto& [status, count] : statuses) std::printf(" %d (%d)", status, count);
  std::printf("\n");
  EXPECT_GT(answered, kCases * 7 / 10);

  // Still healthy, and the run from before is exactly as it was, then continues.
  const Reply health = api.get("/api/health");
  ASSERT_EQ(health.status, 200);
  EXPECT_EQ(health.body_json()["status"], "ok");
  const json after = api.run(precious);
  EXPECT_EQ(after["state"], "paused");
  EXPECT_EQ(after["step"], before["step"]);
  EXPECT_EQ(after["scene"], before["scene"]);
  ASSERT_EQ(api.post("/api/runs/" + precious + "/resume").status, 200);
  ASSERT_TRUE(wait_until([&] {
    return api.run(precious)["step"].get<std::uint64_t>() > before["step"].get<std::uint64_t>();
  }));
  EXPECT_NE(api.run(id)["state"], "failed");
  EXPECT_TRUE(wait_until([&] { return server.http->connections() == 0; }, 5s));
}

// --- pieces without sockets ------------------------------------------------------------------

TEST(ServerParts, ClientQueueDropsOldestImagesAndCoalescesMetrics) {
  int wakes = 0;
  sphles::server::StreamLimits limits;
  limits.max_images = 3;
  limits.max_samples = 5;
  sphles::server::ClientQueue queue(limits, [&] { ++wakes; });
  for (int k = 0; k < 10; ++k) {
    sphles::control::ImageEvent image;
    image.field = "omega2";
    image.step = static_cast<std::uint64_t>(k);
    image.png = std::make_shared<const std::vector<unsigned char>>(8, 0);
    queue.push_image(image);
  }
  std::vector<sphles::control::MetricsSample> samples(4);
  for (std::size_t k = 0; k < samples.size(); ++k) samples[k].step = k;
  queue.push_metrics(samples);
  queue.push_metrics(samples);  // 8 > 5: the oldest 3 go
  EXPECT_EQ(wakes, 1);          // one wake until the consumer finds the queue empty
  EXPECT_EQ(queue.counters().images_dropped, 7u);
  EXPECT_EQ(queue.counters().samples_dropped, 3u);

  auto item = queue.pop();  // metrics first, coalesced into one message
  ASSERT_TRUE(item && std::holds_alternative<sphles::server::QueuedMetrics>(*item));
  EXPECT_EQ(std::get<sphles::server::QueuedMetrics>(*item).samples.size(), 5u);
  for (std::uint64_t expected : {7u, 8u, 9u}) {  // the newest three images, oldest first
    item = queue.pop();
    ASSERT_TRUE(item && std::holds_alternative<sphles::control::ImageEvent>(*item));
    EXPECT_EQ(std::get<sphles::control::ImageEvent>(*item).step, expected);
  }
  EXPECT_FALSE(queue.pop());
  queue.push_text("{}");
  EXPECT_EQ(wakes, 2);
  queue.set_images_enabled(false);
  sphles::control::ImageEvent image;
  image.png = std::make_shared<const std::vector<unsigned char>>(8, 0);
  queue.push_image(image);
  EXPECT_EQ(queue.counters().images_queued, 10u);
  queue.close();
  queue.push_text("{}");
  EXPECT_FALSE(queue.pop());
}

TEST(ServerParts, UrlDecodingIsStrict) {
  using sphles::server::path_segments;
  using sphles::server::percent_decode;
  EXPECT_EQ(percent_decode("a%41+b"), "aA+b");
  EXPECT_EQ(percent_decode("a+b", true), "a b");
  EXPECT_FALSE(percent_decode("%4"));
  EXPECT_FALSE(percent_decode("%zz"));
  EXPECT_EQ(*path_segments("/api//runs/%61"), (std::vector<std::string>{"api", "runs", "a"}));
  EXPECT_FALSE(path_segments("/a%2fb"));
  EXPECT_FALSE(path_segments("/a%5cb"));
  EXPECT_FALSE(path_segments("/a%00b"));
  EXPECT_FALSE(sphles::server::split_target("http://x/y"));
  const auto query = sphles::server::parse_query("a=1&b=x%20y&c");
  ASSERT_TRUE(query);
  EXPECT_EQ(query->at("b"), "x y");
  EXPECT_EQ(query->at("c"), "");
  // A request log never shows the server's token.
  using sphles::server::loggable_target;
  EXPECT_EQ(loggable_target("/api/runs/a/stream?token=s3cret"), "/api/runs/a/stream?token=***");
  EXPECT_EQ(loggable_target("/x?a=1&token=s&b=token"), "/x?a=1&token=***&b=token");
  EXPECT_EQ(loggable_target("/x?tokens=1&token"), "/x?tokens=1&token");
  EXPECT_EQ(loggable_target("/api/runs"), "/api/runs");
}

}  // namespace
