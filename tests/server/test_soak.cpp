// SPDX-License-Identifier: GPL-3.0-or-later
// Concurrency soak of the service: six clients send random transitions, changes, deletions and
// reads to three run slots of one real server over real sockets, at least kMinimumTransitions in
// all, within a wall-time bound. Every answer must be a documented one (never a 5xx, never no
// answer), and at the end the runs must be in consistent states, on disk as in the API, with the
// server answering and shutting down. Built with ThreadSanitizer in CI (scripts/test.sh), where it
// checks run control, the run manager and the server together.
#include <atomic>
#include <future>
#include <mutex>
#include <random>
#include <set>

#include "server_test_support.hpp"

namespace {

using namespace sphles_server_test;

constexpr int kClients = 6;
constexpr int kSlots = 3;
constexpr int kMinimumTransitions = 2000;
constexpr auto kWallLimit = 110s;  // the soak gives up here and fails if it has not done enough

/// A run of a slot, tiny 2D: slot 0 has a short end time so that it finishes now and then, and
/// little analysis (a finishing run drains its analysis queue before it ends); slot 1 has the
/// service's live defaults (every product, rendered ω² and |τ_SFS| frames); slot 2 computes a
/// spectrum and statistics.
json slot_scene(int slot, int generation) {
  json scene = tiny_scene(slot == 0 ? 0.05 : 1e6,
                          "soak" + std::to_string(slot) + "-" + std::to_string(generation));
  scene["checkpoint"] = {{"keep", 2}};
  if (slot == 0) scene["analysis"] = {{"every", 0.01}, {"products", {"energy"}}};
  if (slot == 2)
    scene["analysis"] = {{"every", 0.02}, {"products", {"energy", "spectrum", "sfs_stats"}}};
  return scene;
}

struct Slots {
  std::mutex mutex;
  std::array<std::string, kSlots> ids;
  std::array<int, kSlots> generation{};
};

/// Statuses each request may answer (beyond them the soak fails): 404 when another client
/// deleted the run, 409 for a transition the state does not allow, 429 when the queue is full.
// 202: a stop while another stop of the run is under way (it answers at once).
const std::set<int> kTransitionAnswers = {200, 202, 404, 409, 429};

TEST(ServiceSoak, RandomTransitionsFromSixClientsLeaveConsistentStates) {
  TestServer server(scratch("soak") / "data", "", /*max_running=*/2);
  const Api api{server.port()};
  Slots slots;
  for (int s = 0; s < kSlots; ++s)
    slots.ids[s] = api.create({{"scene", slot_scene(s, 0)}, {"start", s != 1}});

  std::atomic<int> transitions{0};
  std::mutex failures_mutex;
  std::vector<std::string> failures;
  std::map<std::string, int> counts;  // "action status" → number, for the report
  const auto deadline = std::chrono::steady_clock::now() + kWallLimit;
  const auto client = [&](int number) {
    std::mt19937 rng(1000 + static_cast<unsigned>(number));
    const auto note = [&](const std::string& what, int status) {
      std::lock_guard lock(failures_mutex);
      ++counts[what + " " + std::to_string(status)];
    };
    const auto fail = [&](const std::string& what) {
      std::lock_guard lock(failures_mutex);
      failures.push_back(what);
    };
    while (transitions.load() < kMinimumTransitions &&
           std::chrono::steady_clock::now() < deadline) {
      const int slot = static_cast<int>(rng() % kSlots);
      std::string id;
      {
        std::lock_guard lock(slots.mutex);
        id = slots.ids[slot];
      }
      const std::string base = "/api/runs/" + id;
      const int action = static_cast<int>(rng() % 10);
      try {
        Reply r;
        std::string what;
        switch (action) {
          case 0:
          case 1:
            what = "start";
            r = api.post(base + "/start");
            break;
          case 2:
            what = "pause";
            r = api.post(base + "/pause");
            break;
          case 3:
            what = "resume";
            r = api.post(base + "/resume");
            break;
          case 4:
          case 5:
            what = "stop";
            r = api.post(base + "/stop");
            break;
          case 6: {
            what = "patch";
            const double end = slot == 0 ? 0.05 * (1 + rng() % 40) : 1e6;
            r = api.patch(base + "/parameters",
                          {{"time", {{"end", end}}},
                           {"fluid", {{"dynamic_viscosity", 0.01 + 0.001 * (rng() % 5)}}}});
            // 400 only when the new time.end is not after the current time (the run moved on).
            if (r.status == 400 &&
                r.body.find("'time.end' must be after the current time") != std::string::npos)
              r.status = 409;
            break;
          }
          case 7: {
            what = "delete";
            r = api.remove(base);
            if (r.status == 200) {
              std::lock_guard lock(slots.mutex);
              if (slots.ids[slot] == id) {
                const int g = ++slots.generation[slot];
                slots.ids[slot] = api.create({{"scene", slot_scene(slot, g)}, {"start", false}});
              }
            }
            break;
          }
          case 8:
            what = "get";
            r = api.get(base);
            if (r.status == 200 && !r.body_json().contains("state"))
              fail("run detail without state");
            break;
          default:
            what = "timeseries";
            r = api.get(base + "/timeseries?max_points=64");
            break;
        }
        ++transitions;
        note(what, r.status);
        if (!kTransitionAnswers.contains(r.status))
          fail(what + " " + id + " answered " + std::to_string(r.status) + ": " + r.body);
      } catch (const std::exception& e) {
        fail("no answer to action " + std::to_string(action) + " on " + id + ": " + e.what());
      }
    }
  };
  const auto started = std::chrono::steady_clock::now();
  std::vector<std::thread> clients;
  for (int k = 0; k < kClients; ++k) clients.emplace_back(client, k);
  for (std::thread& t : clients) t.join();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::string summary;
  for (const auto& [what, n] : counts) summary += " " + what + ":" + std::to_string(n);
  std::printf("soak: %d requests from %d clients in %.1f s;%s\n", transitions.load(), kClients,
              seconds, summary.c_str());
  for (const std::string& f : failures) ADD_FAILURE() << f;
  EXPECT_GE(transitions.load(), kMinimumTransitions) << "the soak did not finish in time";

  // Consistent end states: every run answers; stopped, it is stopped on disk too; none failed.
  ASSERT_EQ(api.get("/api/health").status, 200);
  const json runs = api.get("/api/runs").body_json();
  ASSERT_EQ(runs.size(), static_cast<std::size_t>(kSlots)) << runs;
  for (const json& run : runs) {
    const std::string id = run["id"];
    const int stop = api.post("/api/runs/" + id + "/stop").status;
    EXPECT_TRUE(stop == 200 || stop == 202 || stop == 409) << id << " " << stop;
    EXPECT_TRUE(wait_until([&] {
      const std::string s = api.run(id)["state"];
      return s != "running" && s != "paused";
    })) << id;
    const json detail = api.run(id);
    const std::string state = detail["state"];
    EXPECT_TRUE(state == "created" || state == "stopped" || state == "finished")
        << id << " ended " << state << ": " << detail["reason"];
    std::ifstream in(server.data_directory / "runs" / id / "run.json");
    const json record = json::parse(in);
    EXPECT_EQ(record["state"], state) << id;
    EXPECT_DOUBLE_EQ(record["time"].get<double>(), detail["time"].get<double>()) << id;
  }
  // Deleted runs left nothing behind but the runs listed.
  std::size_t directories = 0;
  for (const auto& entry : fs::directory_iterator(server.data_directory / "runs")) {
    EXPECT_TRUE(entry.is_directory());
    ++directories;
  }
  EXPECT_EQ(directories, static_cast<std::size_t>(kSlots));
  // And the server shuts down (as on SIGTERM) without hanging.
  auto shutdown = std::async(std::launch::async, [&] { server.shutdown(); });
  EXPECT_EQ(shutdown.wait_for(30s), std::future_status::ready) << "shutdown hung";
}

}  // namespace
