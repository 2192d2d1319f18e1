// SPDX-License-Identifier: GPL-3.0-or-later
// Spectral references computed by the service (POST /api/references, docs/api.md): real servers
// on loopback ports, the real spectral solver, runs of the 3D Taylor-Green vortex at a Reynolds
// number no shipped reference covers.
#include "control/scene_schema.hpp"
#include "server_test_support.hpp"

namespace {

using namespace sphles_server_test;

/// The 3D Taylor-Green vortex at Re = 1000 (ν = 1e-3): 16³ particles without packing, spectra
/// at t = 0, 0.25 and 0.5. No reference run in data/reference/ has its flow.
json re1000_scene(double end_time = 0.5) {
  return {{"name", "re1000"},
          {"case", "tgv3d"},
          {"particles_per_side", 16},
          {"fluid", {{"dynamic_viscosity", 1e-3}}},
          {"packing", {{"enabled", false}}},
          {"time", {{"end", end_time}}},
          {"analysis", {{"every", 0.25}, {"products", {"spectrum"}}}}};
}

/// A reference job's answer conforms to the served OpenAPI document's ReferenceJob schema.
void expect_job_schema(const Api& api, const json& job) {
  json schema = api.get("/api/openapi.json").body_json();
  schema["$ref"] = "#/components/schemas/ReferenceJob";
  EXPECT_EQ(sphles::control::json_schema_violation(schema, job), std::nullopt) << job;
}

/// GET /api/references/{id} until `done` says so (30 s at most); the last answer.
json wait_for_job(const Api& api, const std::string& id,
                  const std::function<bool(const json&)>& done) {
  json job;
  EXPECT_TRUE(wait_until([&] {
    job = api.get("/api/references/" + id).body_json();
    return done(job);
  })) << job;
  return job;
}

// The whole path a dashboard user takes: a run without a reference, its estimate, the job, then
// the resolved scales against it; and every refusal, with the field it names.
TEST(ServerReferences, ComputesTheReferenceOfARunsFlow) {
  const fs::path base = scratch("references");
  constexpr double kMemoryLimit = 2.0 * (1u << 30);
  TestServer server(base / "data", "", 2, {},
                    [&](sphles::control::ManagerOptions& m) { m.max_memory_bytes = kMemoryLimit; });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", re1000_scene()}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  EXPECT_EQ(api.run(id)["available"]["resolved"], false);
  expect_error(api.get("/api/runs/" + id + "/resolved"), 404);

  // The estimate changes nothing.
  const Reply dry =
      api.post("/api/references", {{"run", id}, {"points_per_side", 16}, {"dry_run", true}});
  ASSERT_EQ(dry.status, 200) << dry.body;
  const json estimate = dry.body_json();
  EXPECT_EQ(estimate["points_per_side"], 16);
  EXPECT_EQ(estimate["max_wavenumber"], 5);  // (16 - 1)/3
  EXPECT_GT(estimate["memory_bytes"].get<double>(), 0.0);
  EXPECT_GT(estimate["checkpoint_bytes"].get<double>(), 0.0);
  EXPECT_GT(estimate["steps"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(estimate["memory_limit_bytes"].get<double>(), kMemoryLimit);
  EXPECT_EQ(estimate["admitted"], true);
  EXPECT_EQ(api.get("/api/references").body_json(), json::array());
  EXPECT_TRUE(fs::is_empty(base / "data" / "references"));

  // Refusals name the request's field; nothing is created.
  expect_error(api.post("/api/references", {{"run", "0999-none"}}), 404, "run");
  const Reply odd = api.post("/api/references", {{"run", id}, {"points_per_side", 17}});
  expect_error(odd, 400, "points_per_side");
  EXPECT_NE(odd.body.find("an even integer in [8, 1024]"), std::string::npos) << odd.body;
  expect_error(api.post("/api/references", {{"run", id}, {"points_per_side", 2048}}), 400,
               "points_per_side");
  expect_error(api.post("/api/references", {{"run", id}, {"points_per_side", "many"}}), 400,
               "points_per_side");
  expect_error(api.post("/api/references", {{"run", id}, {"cfl", 2}}), 400, "cfl");
  expect_error(api.post("/api/references", {{"run", id}, {"dry_run", "yes"}}), 400, "dry_run");
  expect_error(api.post("/api/references", {{"run", id}, {"colour", "red"}}), 400, "colour");
  expect_error(api.post("/api/references", {{"points_per_side", 16}}), 400, "run");
  // Beyond --max-memory: the estimate says so, a job is refused.
  const json big =
      api.post("/api/references", {{"run", id}, {"points_per_side", 1024}, {"dry_run", true}})
          .body_json();
  EXPECT_EQ(big["admitted"], false) << big;
  EXPECT_EQ(big["refusal"]["field"], "points_per_side");
  expect_error(api.post("/api/references", {{"run", id}, {"points_per_side", 1024}}), 422,
               "points_per_side");
  EXPECT_EQ(api.get("/api/references").body_json(), json::array());

  // The job: a 16³ reference to t = 0.5, well under a second.
  const Reply created = api.post("/api/references", {{"run", id}, {"points_per_side", 16}});
  ASSERT_EQ(created.status, 201) << created.body;
  const json queued = created.body_json();
  const std::string job = queued["id"];
  EXPECT_EQ(created.header("location"), "/api/references/" + job);
  EXPECT_EQ(queued["run"], id);
  EXPECT_EQ(queued["directory"], job);
  expect_job_schema(api, queued);
  const json done = wait_for_job(
      api, job, [](const json& j) { return j["state"] != "queued" && j["state"] != "running"; });
  ASSERT_EQ(done["state"], "done") << done;
  EXPECT_DOUBLE_EQ(done["time"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(done["progress"].get<double>(), 1.0);
  EXPECT_GT(done["step"].get<int>(), 0);
  expect_job_schema(api, done);
  EXPECT_TRUE(fs::exists(base / "data" / "references" / job / "spectra" / "index.csv"));
  EXPECT_TRUE(fs::exists(base / "data" / "references" / job / "job.json"));
  expect_error(api.post("/api/references/" + job + "/stop"), 409);
  expect_error(api.post("/api/references/" + job + "/resume"), 409);
  expect_error(api.get("/api/references/0999-none"), 404, "id");

  // The run is judged against it.
  EXPECT_EQ(api.run(id)["available"]["resolved"], true);
  const Reply resolved = api.get("/api/runs/" + id + "/resolved");
  ASSERT_EQ(resolved.status, 200) << resolved.body;
  EXPECT_EQ(resolved.body_json()["reference"], job);
  EXPECT_EQ(resolved.body_json()["samples"].size(), 3u);  // t = 0, 0.25, 0.5

  // A server started again on the data directory lists the job, and judges the run by it.
  server.shutdown();
  TestServer again(base / "data");
  const Api next{again.port()};
  const json listed = next.get("/api/references").body_json();
  ASSERT_EQ(listed.size(), 1u) << listed;
  EXPECT_EQ(listed[0]["state"], "done");
  EXPECT_EQ(next.get("/api/runs/" + id + "/resolved").body_json()["reference"], job);

  // Deleted, it is gone with its directory, and the run has no reference again.
  const Reply deleted = next.remove("/api/references/" + job);
  ASSERT_EQ(deleted.status, 200) << deleted.body;
  EXPECT_EQ(deleted.body_json()["deleted"], job);
  EXPECT_FALSE(fs::exists(base / "data" / "references" / job));
  expect_error(next.get("/api/references/" + job), 404);
  EXPECT_EQ(next.run(id)["available"]["resolved"], false);
}

// A long job stops with a checkpoint, refuses deletion while it runs, is listed after a server
// restart (also when the server died while it ran) and continues from its checkpoint.
TEST(ServerReferences, StopsResumesAndOutlivesTheServer) {
  const fs::path data = scratch("references_restart") / "data";
  constexpr const char* kToken = "reference-token";
  std::string job;
  double stopped_at = 0.0;
  {
    TestServer server(data, kToken);
    const Api api{server.port(), kToken};
    // Not started: the reference needs only the run's scene. 32³ to t = 1000 runs for minutes.
    json scene = re1000_scene(1000.0);
    scene.erase("analysis");
    const std::string id = api.create({{"scene", scene}, {"start", false}});
    expect_error(Api{server.port()}.post("/api/references", {{"run", id}}), 401, "Authorization");
    const Reply created = api.post("/api/references", {{"run", id}, {"points_per_side", 32}});
    ASSERT_EQ(created.status, 201) << created.body;
    job = created.body_json()["id"];
    wait_for_job(api, job, [](const json& j) { return j["step"].get<int>() > 0; });
    expect_error(api.remove("/api/references/" + job), 409);
    const Reply stop = api.post("/api/references/" + job + "/stop");
    ASSERT_EQ(stop.status, 200) << stop.body;
    EXPECT_EQ(stop.body_json()["state"], "stopped");
    stopped_at = stop.body_json()["time"].get<double>();
    EXPECT_GT(stopped_at, 0.0);
    EXPECT_FALSE(fs::is_empty(data / "references" / job / "checkpoints"));
    expect_error(api.post("/api/references/" + job + "/stop"), 409);

    // Resumed, it continues from the checkpoint; the server's shutdown stops it again.
    ASSERT_EQ(api.post("/api/references/" + job + "/resume").status, 200);
    const json resumed =
        wait_for_job(api, job, [&](const json& j) { return j["time"].get<double>() > stopped_at; });
    EXPECT_EQ(resumed["state"], "running");
    const auto start = std::chrono::steady_clock::now();
    server.shutdown();
    EXPECT_LT(std::chrono::steady_clock::now() - start, 20s) << "shutdown waits one step";
  }
  const json record = json::parse(std::ifstream(data / "references" / job / "job.json"));
  EXPECT_EQ(record["state"], "stopped");
  // As if the server had died while the job ran.
  std::ofstream(data / "references" / job / "job.json")
      << json{{"run", record["run"]}, {"state", "running"}, {"error", ""}}.dump();

  TestServer again(data, kToken);
  const Api api{again.port(), kToken};
  const json list = api.get("/api/references").body_json();
  ASSERT_EQ(list.size(), 1u) << list;
  EXPECT_EQ(list[0]["id"], job);
  EXPECT_EQ(list[0]["state"], "stopped");
  EXPECT_GT(list[0]["time"].get<double>(), stopped_at);
  ASSERT_EQ(api.post("/api/references/" + job + "/resume").status, 200);
  const json resumed = wait_for_job(api, job, [&](const json& j) {
    return j["state"] == "running" && j["step"].get<int>() > list[0]["step"].get<int>();
  });
  EXPECT_GE(resumed["time"].get<double>(), list[0]["time"].get<double>());
}

}  // namespace
