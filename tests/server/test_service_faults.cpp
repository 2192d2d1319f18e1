// SPDX-License-Identifier: GPL-3.0-or-later
// Faults of the run-control layer that ordinary use of the service provoked: duplicate and
// concurrent transitions, stops during a long set-up, finished runs restarted, changes that cannot
// be saved, unwritable or vanishing run directories, crashes, restarts with inconsistent overrides
// and paths chosen by clients. Each test drives a real server (or the real binary) over real
// sockets and reproduces the fault first.
#include <atomic>
#include <future>
#include <latch>
#include <map>
#include <set>
#include <string>

#include "io/checkpoint.hpp"
#include "server_test_support.hpp"

namespace {

using namespace sphles_server_test;

/// A tiny run that goes on until stopped (16², lattice, thousands of steps per second).
json long_scene(const std::string& name = "long") {
  return tiny_scene(1e6, name);
}

/// A run whose packing never converges (the residual never reaches 1e-300): only a stop or a
/// signal ends its set-up.
json endless_packing_scene(const std::string& name = "packing") {
  json scene = tiny_scene(1e6, name);
  scene["particles_per_side"] = 32;
  scene["packing"] = {
      {"enabled", true}, {"cache", false}, {"tolerance", 1e-300}, {"max_iterations", 1000000}};
  return scene;
}

/// Sends the same request from `count` threads at once; returns the statuses (0: no answer
/// within the client's timeout).
std::vector<int> concurrently(int count, const std::function<Reply()>& request) {
  std::vector<std::future<int>> answers;
  for (int k = 0; k < count; ++k)
    answers.push_back(std::async(std::launch::async, [&] {
      try {
        return request().status;
      } catch (const std::exception&) {
        return 0;  // timed out or reset
      }
    }));
  std::vector<int> statuses;
  for (auto& a : answers) statuses.push_back(a.get());
  std::sort(statuses.begin(), statuses.end());
  return statuses;
}

/// One of concurrent stops stops the run (200); each other one answers at once, 202 while the
/// first is under way or 409 once it is done.
void expect_one_stop(const std::vector<int>& statuses) {
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.front(), 200) << "0 means no answer within 30 s";
  EXPECT_EQ(std::count(statuses.begin(), statuses.end(), 200), 1);
  for (std::size_t k = 1; k < statuses.size(); ++k)
    EXPECT_TRUE(statuses[k] == 202 || statuses[k] == 409) << statuses[k];
}

bool running_with_steps(const Api& api, const std::string& id, std::uint64_t steps) {
  const json run = api.run(id);
  return run["state"] == "running" && run["step"].get<std::uint64_t>() > steps;
}

std::vector<std::string> csv_lines(const fs::path& file) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Two or more POST /stop on one run hung the API for good (each duplicate joined the same solver
// thread, blocking one I/O worker forever; SIGTERM then never exited).
TEST(ServiceFaults, DuplicateStopsOfOneRunAllAnswer) {
  TestServer server(scratch("double-stop") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", long_scene()}});
  ASSERT_TRUE(wait_until([&] { return running_with_steps(api, id, 20); }));
  const std::vector<int> statuses =
      concurrently(3, [&] { return api.post("/api/runs/" + id + "/stop"); });
  expect_one_stop(statuses);
  EXPECT_EQ(api.run(id)["state"], "stopped");
  EXPECT_EQ(api.get("/api/health").status, 200);
  // And the run can be resumed and stopped again (the thread was joined exactly once).
  ASSERT_EQ(api.post("/api/runs/" + id + "/resume").status, 200);
  ASSERT_TRUE(wait_until([&] { return running_with_steps(api, id, 40); }));
  expect_one_stop(concurrently(4, [&] { return api.post("/api/runs/" + id + "/stop"); }));
}

// Two concurrent starts of a finished run (time.end raised) answered 500 "No such process" or
// killed the server with std::system_error from a noexcept path.
TEST(ServiceFaults, ConcurrentStartsOfAFinishedRunStartItOnce) {
  TestServer server(scratch("double-start") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene(0.05, "short")}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  ASSERT_EQ(api.patch("/api/runs/" + id + "/parameters", {{"time", {{"end", 1e6}}}}).status, 200);
  EXPECT_EQ(concurrently(4, [&] { return api.post("/api/runs/" + id + "/start"); }),
            (std::vector<int>{200, 409, 409, 409}));
  EXPECT_EQ(api.run(id)["state"], "running");
  ASSERT_TRUE(wait_until([&] { return api.run(id)["time"].get<double>() > 0.05; }));
  // The race window (reaping the previous solver thread) is short: try it many times, with
  // start and resume mixed.
  constexpr int kRounds = 15;
  for (int round = 0; round < kRounds; ++round) {
    ASSERT_EQ(api.post("/api/runs/" + id + "/stop").status, 200);
    const std::vector<int> mixed = concurrently(4, [&, k = std::make_shared<std::atomic<int>>(0)] {
      return api.post("/api/runs/" + id + ((*k)++ % 2 ? "/start" : "/resume"));
    });
    ASSERT_EQ(mixed, (std::vector<int>{200, 409, 409, 409})) << "round " << round;
    ASSERT_EQ(api.run(id)["state"], "running");
  }
  EXPECT_EQ(api.get("/api/health").status, 200);
}

// The same, without sockets in between: eight threads released at once on a run that has just
// finished (its solver thread ended by itself, not reaped by a stop), many times. Exactly one start
// wins; the others are refused with StateError, never another error.
TEST(ServiceFaults, StartsReleasedAtOnceStartTheRunExactlyOnce) {
  TestServer server(scratch("start-latch") / "data");
  constexpr double kSegment = 0.01;  // simulated time per round: a few steps
  sphles::control::CreateRequest request;
  request.scene = tiny_scene(kSegment, "latch");
  const std::shared_ptr<sphles::control::Run> run = server.manager->create(request);
  constexpr int kThreads = 8, kRounds = 30;
  for (int round = 0; round < kRounds; ++round) {
    ASSERT_TRUE(wait_until([&] {
      return run->status().state == sphles::control::RunState::Finished;
    })) << "round "
        << round;
    run->apply_changes({{"time", {{"end", kSegment * (round + 2)}}}});
    std::latch go(kThreads);
    std::atomic<int> started{0}, refused{0};
    std::vector<std::string> other;
    std::mutex other_mutex;
    std::vector<std::thread> threads;
    for (int k = 0; k < kThreads; ++k)
      threads.emplace_back([&, k] {
        go.arrive_and_wait();
        try {
          if (k % 2)
            server.manager->start(run->id());
          else
            server.manager->resume(run->id());
          ++started;
        } catch (const sphles::control::StateError&) {
          ++refused;
        } catch (const std::exception& e) {
          std::lock_guard lock(other_mutex);
          other.push_back(e.what());
        }
      });
    for (std::thread& t : threads) t.join();
    ASSERT_TRUE(other.empty()) << "round " << round << ": " << other.front();
    ASSERT_EQ(started, 1) << "round " << round;
    ASSERT_EQ(refused, kThreads - 1) << "round " << round;
  }
}

// Stop and pause did not check that DELETE had retired the run, and wrote run.json into a directory
// being deleted. A deleted run accepts nothing.
TEST(ServiceFaults, NothingReachesARunOnceItIsDeleted) {
  TestServer server(scratch("retired") / "data");
  sphles::control::CreateRequest request;
  request.scene = tiny_scene();
  request.start = false;
  const std::shared_ptr<sphles::control::Run> run = server.manager->create(request);
  run->retire();  // the first half of DELETE: no transition or change from here on
  for (const auto& action : std::vector<std::function<void()>>{
           [&] { run->start(); }, [&] { run->stop(); }, [&] { run->pause(); },
           [&] { run->resume(); }, [&] { run->mark_queued(); },
           [&] {
             run->apply_changes({{"time", {{"end", 5.0}}}});
           }})
    EXPECT_THROW(action(), sphles::control::StateError);
  EXPECT_FALSE(run->start_if_queued());
  run->reinstate();  // the deletion failed: the run is usable again
  EXPECT_NO_THROW(run->stop());
}

// Stop and SIGTERM could not interrupt a run's set-up; three stops during packing blocked every
// worker (even /api/health timed out) and SIGTERM did not exit within 20 s.
TEST(ServiceFaults, StopsDuringPackingAnswerAndTheRunCanStartAgain) {
  TestServer server(scratch("packing-stop") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", endless_packing_scene()}});
  std::this_thread::sleep_for(500ms);  // well inside the packing
  ASSERT_EQ(api.run(id)["step"], 0u);
  const std::vector<int> statuses =
      concurrently(3, [&] { return api.post("/api/runs/" + id + "/stop"); });
  expect_one_stop(statuses);
  const json run = api.run(id);
  EXPECT_EQ(run["state"], "stopped");
  EXPECT_NE(run["reason"].get<std::string>().find("packing cancelled"), std::string::npos) << run;
  EXPECT_EQ(api.get("/api/health").status, 200);
  // Nothing was stepped, so it starts afresh (packing again), and stops again.
  ASSERT_EQ(api.post("/api/runs/" + id + "/start").status, 200);
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(api.post("/api/runs/" + id + "/stop").status, 200);
}

TEST(ServiceFaults, SigtermDuringPackingExitsPromptly) {
  const fs::path base = scratch("packing-sigterm");
  ServeProcess serve({"--data", (base / "data").string(), "--threads", "1"}, base / "stderr.log");
  const Api api{serve.port()};
  const std::string id = api.create({{"scene", endless_packing_scene()}});
  std::this_thread::sleep_for(500ms);
  ASSERT_EQ(api.run(id)["state"], "running");
  serve.signal(SIGTERM);
  const std::optional<int> code = serve.wait_exit(20s);
  ASSERT_TRUE(code.has_value()) << "sphles serve did not exit within 20 s of SIGTERM";
  EXPECT_EQ(*code, 0);
  std::ifstream record(base / "data" / "runs" / id / "run.json");
  EXPECT_EQ(json::parse(record)["state"], "stopped");
}

// Start on a finished run while the slot was busy answered "queued"; when the slot freed, a run
// without checkpoints restarted from t = 0 and overwrote its time series.
TEST(ServiceFaults, AFinishedRunQueuedBehindABusySlotContinuesWhereItEnded) {
  TestServer server(scratch("queued-finished") / "data", "", /*max_running=*/1);
  const Api api{server.port()};
  const std::string done = api.create({{"scene", tiny_scene(0.1, "done")}});
  ASSERT_TRUE(wait_until([&] { return api.run(done)["state"] == "finished"; }));
  const fs::path series = server.data_directory / "runs" / done / "timeseries.csv";
  const std::vector<std::string> before = csv_lines(series);
  const std::uint64_t last_step = api.run(done)["step"];
  ASSERT_GT(before.size(), 3u);

  const std::string busy = api.create({{"scene", long_scene("busy")}});
  ASSERT_EQ(api.run(busy)["state"], "running");
  // A changed viscosity shows whether the first segment is computed again: it must not be.
  ASSERT_EQ(api.patch("/api/runs/" + done + "/parameters",
                      {{"time", {{"end", 0.2}}}, {"fluid", {{"dynamic_viscosity", 0.05}}}})
                .status,
            200);
  const Reply queued = api.post("/api/runs/" + done + "/start");
  ASSERT_EQ(queued.status, 200) << queued.body;
  EXPECT_EQ(queued.body_json()["state"], "queued");
  ASSERT_EQ(api.post("/api/runs/" + busy + "/stop").status, 200);
  ASSERT_TRUE(wait_until([&] { return api.run(done)["state"] == "finished"; }));
  EXPECT_DOUBLE_EQ(api.run(done)["time"], 0.2);
  const std::vector<std::string> after = csv_lines(series);
  ASSERT_GT(after.size(), before.size());
  for (std::size_t k = 0; k < before.size(); ++k)
    ASSERT_EQ(after[k], before[k]) << "row " << k << " of the first segment was rewritten";
  const std::string& next = after[before.size()];
  EXPECT_GT(std::stoull(next.substr(next.find(',') + 1)), last_step) << next;
}

// A run that stepped but has no checkpoint (every run ends with one; here it was deleted) cannot
// continue; it says so at once instead of starting again at t = 0 when a slot frees.
TEST(ServiceFaults, ARunWithoutACheckpointRefusesToContinue) {
  const fs::path dir = scratch("no-checkpoint") / "run";
  sphles::control::Run run("r", sphles::control::parse_run_spec(tiny_scene(0.05)), dir);
  ASSERT_EQ(run.run_here(), sphles::control::RunState::Finished);
  ASSERT_EQ(sphles::io::list_checkpoints(dir / "checkpoints").size(), 1u);
  using Verbs = std::vector<std::string_view>;
  EXPECT_EQ(run.status().actions, Verbs{"delete"});  // time.end reached
  run.apply_changes({{"time", {{"end", 1.0}}}});
  EXPECT_EQ(run.status().actions, (Verbs{"start", "delete"}));
  fs::remove_all(dir / "checkpoints");
  EXPECT_EQ(run.status().actions, Verbs{"delete"});  // no checkpoint to continue from
  try {
    run.start();
    FAIL() << "a run without checkpoints started again";
  } catch (const sphles::control::StateError& e) {
    EXPECT_NE(std::string(e.what()).find("no checkpoint to continue from"), std::string::npos)
        << e.what();
    // It said "its scene writes none" although every run writes one when it ends.
    EXPECT_EQ(std::string(e.what()).find("writes none"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("checkpoints/ holds none"), std::string::npos) << e.what();
  }
  EXPECT_THROW(run.mark_queued(), sphles::control::StateError);
  EXPECT_EQ(run.status().state, sphles::control::RunState::Finished);
}

// A PATCH whose scene.json write failed answered 500 but kept the change in memory, to be lost at
// the next restart. Writes fail here because a directory sits where the temporary file goes (as
// root, permissions do not stop writes).
TEST(ServiceFaults, AChangeThatCannotBeSavedIsNotMade) {
  const fs::path data = scratch("unsaved-change") / "data";
  std::string idle, live;
  {
    TestServer server(data);
    const Api api{server.port()};
    idle = api.create({{"scene", tiny_scene(1e6, "idle")}, {"start", false}});
    live = api.create({{"scene", tiny_scene(1e6, "live")}});
    for (const std::string& id : {idle, live}) {
      const fs::path blocker = data / "runs" / id / "scene.json.tmp";
      fs::create_directories(blocker / "x");
      const Reply r = api.patch("/api/runs/" + id + "/parameters", {{"time", {{"end", 77.0}}}});
      EXPECT_EQ(r.status, 500) << r.body;
      EXPECT_NE(r.body.find("scene.json"), std::string::npos) << r.body;
      EXPECT_DOUBLE_EQ(api.run(id)["end_time"], 1e6) << "a change that was not saved was made";
      EXPECT_DOUBLE_EQ(api.run(id)["scene"]["time"]["end"], 1e6);
      fs::remove_all(blocker);
    }
    std::this_thread::sleep_for(100ms);
    EXPECT_DOUBLE_EQ(api.run(live)["end_time"], 1e6);
    // Once the disk takes it again, the change is made and saved.
    ASSERT_EQ(api.patch("/api/runs/" + idle + "/parameters", {{"time", {{"end", 55.0}}}}).status,
              200);
  }
  TestServer again(data);
  const Api api{again.port()};
  EXPECT_DOUBLE_EQ(api.run(idle)["end_time"], 55.0);
  EXPECT_DOUBLE_EQ(api.run(live)["end_time"], 1e6);
}

// Opening a run rewrote its files, so a data directory that could not be written listed no runs.
TEST(ServiceFaults, RunsThatCannotBeWrittenAreStillListed) {
  const fs::path data = scratch("unwritable") / "data";
  std::string stopped, crashed;
  {
    TestServer server(data);
    const Api api{server.port()};
    stopped = api.create({{"scene", tiny_scene(1e6, "stopped")}, {"start", false}});
    crashed = api.create({{"scene", tiny_scene(1e6, "crashed")}, {"start", false}});
  }
  // The second one looks like a run the process was running when it died: opening it must
  // record it as stopped, and cannot.
  {
    const fs::path record = data / "runs" / crashed / "run.json";
    std::ifstream in(record);
    json j = json::parse(in);
    in.close();
    j["state"] = "running";
    std::ofstream(record) << j.dump(2);
  }
  for (const std::string& id : {stopped, crashed})
    for (const char* file : {"run.json.tmp", "scene.json.tmp"})
      fs::create_directories(data / "runs" / id / file / "x");
  TestServer server(data);
  const Api api{server.port()};
  const json runs = api.get("/api/runs").body_json();
  ASSERT_EQ(runs.size(), 2u) << runs;
  EXPECT_EQ(api.run(stopped)["state"], "created");
  EXPECT_EQ(api.run(crashed)["state"], "stopped");
  // They still run (their other files can be written); run.json catches up when it can.
  ASSERT_EQ(api.post("/api/runs/" + crashed + "/start").status, 200);
  ASSERT_TRUE(wait_until([&] { return running_with_steps(api, crashed, 20); }));
  ASSERT_EQ(api.post("/api/runs/" + crashed + "/stop").status, 200);
  EXPECT_EQ(api.run(crashed)["state"], "stopped");
  EXPECT_EQ(api.get("/api/health").status, 200);
}

// Deleting the run directory during a run went unnoticed (the time series went on into an unlinked
// file).
TEST(ServiceFaults, DeletingTheRunDirectoryFailsTheRunSayingWhy) {
  TestServer server(scratch("vanished") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", long_scene()}});
  ASSERT_TRUE(wait_until([&] { return running_with_steps(api, id, 20); }));
  // Like `rm -rf` while the run writes: a file the run renames away between remove_all's
  // listing and its unlink makes one pass fail (seen in CI with a .pvd.tmp), so repeat it.
  const fs::path run_dir = server.data_directory / "runs" / id;
  ASSERT_TRUE(wait_until([&] {
    std::error_code ignored;
    fs::remove_all(run_dir, ignored);
    return !fs::exists(run_dir);
  }));
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "failed"; }, 20s));
  const std::string reason = api.run(id)["reason"];
  EXPECT_NE(reason.find("was deleted or replaced"), std::string::npos) << reason;
  EXPECT_EQ(api.get("/api/health").status, 200);
  // Deleting such a run answered 500 (nothing to move to the trash); it leaves the list.
  ASSERT_TRUE(wait_until([&] {
    std::error_code ignored;
    fs::remove_all(run_dir, ignored);
    return !fs::exists(run_dir);
  }));
  EXPECT_EQ(api.remove("/api/runs/" + id).status, 200);
  EXPECT_EQ(json::parse(api.get("/api/runs").body).size(), 0u);
  expect_error(api.remove("/api/runs/" + id), 404, "id");
}

// After a crash runs were listed at time 0 although checkpoints existed at later times. run.json
// now follows the checkpoints.
TEST(ServiceFaults, AfterACrashARunIsListedAtItsNewestCheckpoint) {
  const fs::path base = scratch("crash");
  const fs::path data = base / "data";
  std::string id;
  {
    ServeProcess serve({"--data", data.string(), "--threads", "1"}, base / "stderr.log");
    const Api api{serve.port()};
    json scene = long_scene("crashing");
    scene["checkpoint"] = {{"every", 0.05}};
    id = api.create({{"scene", scene}});
    ASSERT_TRUE(wait_until([&] {
      return sphles::io::list_checkpoints(data / "runs" / id / "checkpoints").size() >= 3;
    }));
    serve.signal(SIGKILL);
    ASSERT_TRUE(serve.wait_exit(10s).has_value());
  }
  // What a kill between a write and its rename leaves (whether this kill fell there is chance):
  // removed when the run continues.
  const fs::path run_dir = data / "runs" / id;
  const std::vector<fs::path> interrupted{run_dir / "run.json.tmp",
                                          run_dir / "checkpoints" / "ckpt_0000000009.h5.tmp.4242",
                                          run_dir / "frames" / "omega2_t0.1000.png.tmp.4242.0",
                                          run_dir / "spectra" / "spectra.xdmf2.tmp"};
  for (const fs::path& file : interrupted) {
    fs::create_directories(file.parent_path());
    std::ofstream(file) << "half a file";
  }
  {
    // As if the kill fell between a checkpoint's rename and run.json's write (whether this kill
    // did is chance): run.json one record behind.
    std::ifstream in(run_dir / "run.json");
    json record = json::parse(in);
    record["time"] = 0.01;
    record["step"] = 1;
    in.close();
    std::ofstream(run_dir / "run.json") << record.dump();
  }
  const fs::path newest = sphles::io::newest_valid_checkpoint(data / "runs" / id / "checkpoints");
  const sphles::io::Checkpoint c = sphles::io::read_checkpoint(newest);
  TestServer server(data);
  const Api api{server.port()};
  const json run = api.run(id);
  EXPECT_EQ(run["state"], "stopped");
  EXPECT_GT(c.state.time, 0.0);
  // The newest checkpoint, also when the kill fell between the file's rename and run.json's
  // write (it was then listed one checkpoint behind, in 6 of 18 restarts).
  EXPECT_EQ(run["time"].get<double>(), c.state.time) << run;
  EXPECT_EQ(run["step"].get<std::uint64_t>(), c.state.step) << run;
  ASSERT_EQ(api.post("/api/runs/" + id + "/resume").status, 200);
  ASSERT_TRUE(wait_until([&] { return api.run(id)["time"].get<double>() > c.state.time; }));
  for (const fs::path& file : interrupted) EXPECT_FALSE(fs::exists(file)) << file;
}

// After a server restart, a finished run's spectrum, statistics and image answered 404 "has no
// spectrum yet" although spectra/, stats/ and frames/ were on disk.
TEST(ServiceFaults, AfterARestartEverythingOnDiskIsServed) {
  const fs::path data = scratch("products-restart") / "data";
  std::string id;
  std::map<std::string, std::string> before;
  const std::vector<std::string> products{"spectrum", "statistics", "images/omega2"};
  {
    TestServer server(data);
    const Api api{server.port()};
    id = api.create({{"scene", rendered_scene(0.1)}});
    ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
    before["latest"] = api.run(id)["latest"].dump();
    before["images"] = api.run(id)["available"]["images"].dump();
    for (const std::string& p : products) {
      const Reply r = api.get("/api/runs/" + id + "/" + p);
      ASSERT_EQ(r.status, 200) << p << ": " << r.body;
      before[p] = r.body;
    }
  }
  TestServer server(data);
  const Api api{server.port()};
  const json run = api.run(id);
  EXPECT_EQ(run["state"], "finished");
  EXPECT_EQ(run["available"]["images"].dump(), before["images"]);
  // The tiny scene's kernel is wider than its vortices: the detail and run.log say so.
  ASSERT_EQ(run["warnings"].size(), 1u) << run;
  EXPECT_EQ(run["warnings"][0]["field"], "particles_per_side");
  EXPECT_NE(api.get("/api/runs/" + id + "/log").body.find("scene: the kernel"), std::string::npos);
  EXPECT_TRUE(run["available"]["spectrum"].get<bool>() && run["available"]["statistics"]) << run;
  // The last row of its time series, as it was reported while the run ran.
  EXPECT_EQ(run["latest"].dump(), before["latest"]);
  // The same bytes: the spectrum and statistics read back exactly, the image is the saved PNG.
  for (const std::string& p : products) {
    const Reply r = api.get("/api/runs/" + id + "/" + p);
    ASSERT_EQ(r.status, 200) << p << ": " << r.body;
    EXPECT_EQ(r.body, before[p]) << p;
  }
}

// `sphles run --restart CKPT --set particles_per_side=48` exited 0 and continued the stored
// particles under an inconsistent scene. A restart accepts what a live change accepts and refuses
// the rest with the same message.
TEST(ServiceFaults, RestartRefusesWhatLiveChangesRefuseWithTheSameMessage) {
  const fs::path base = scratch("restart-set");
  json scene = tiny_scene(0.05, "restartable");
  scene["checkpoint"] = {{"every", 0.05}};
  std::ofstream(base / "scene.json") << scene.dump();
  const fs::path out = base / "out";
  ProcessResult first = run_sphles({"run", "scene.json", "--out", out.string()}, base);
  ASSERT_EQ(first.code, 0) << first.err;

  TestServer server(scratch("restart-set-live") / "data");
  const Api api{server.port()};
  const std::string live = api.create({{"scene", scene}, {"start", false}});
  const std::vector<std::pair<std::string, json>> refused = {
      {"particles_per_side=48", {{"particles_per_side", 48}}},
      {"case=kolmogorov2d", {{"case", "kolmogorov2d"}}},
      {"kernel.type=quintic_spline", {{"kernel", {{"type", "quintic_spline"}}}}},
      {"fluid.sound_speed=20", {{"fluid", {{"sound_speed", 20}}}}},
      {"subfilter.model=smagorinsky", {{"subfilter", {{"model", "smagorinsky"}}}}},
      {"scheme.type=transport_velocity", {{"scheme", {{"type", "transport_velocity"}}}}}};
  for (const auto& [assignment, patch] : refused) {
    const Reply change = api.patch("/api/runs/" + live + "/parameters", patch);
    ASSERT_EQ(change.status, 400) << change.body;
    const std::string message = change.body_json()["error"]["message"];
    const ProcessResult r = run_sphles(
        {"run", "--restart", out.string(), "--set", assignment, "--set", "time.end=0.1"}, base);
    EXPECT_EQ(r.code, 2) << assignment << ": " << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos)
        << assignment << ": expected the live-change message '" << message << "' in: " << r.err;
  }
  // What a live change may change, a restart may too.
  const ProcessResult ok = run_sphles({"run", "--restart", out.string(), "--set", "time.end=0.1",
                                       "--set", "fluid.dynamic_viscosity=0.02"},
                                      base);
  EXPECT_EQ(ok.code, 0) << ok.err;
  std::ifstream record(out / "run.json");
  EXPECT_DOUBLE_EQ(json::parse(record)["time"].get<double>(), 0.1);
}

// `sphles run --restart DIR` took a 24² checkpoint dropped among a 16² run's checkpoints and
// rewrote the run's scene.json with its scene. A file of another run is passed over (and, named
// explicitly, refused); the run's scene stays.
TEST(ServiceFaults, RestartPassesOverACheckpointOfAnotherRun) {
  const fs::path base = scratch("restart-foreign");
  json own = tiny_scene(0.05, "own");
  own["checkpoint"] = {{"every", 0.02}};
  json other = own;
  other["name"] = "other";
  other["particles_per_side"] = 24;
  other["time"]["end"] = 0.1;
  std::ofstream(base / "own.json") << own.dump();
  std::ofstream(base / "other.json") << other.dump();
  const fs::path out = base / "own", elsewhere = base / "other";
  ASSERT_EQ(run_sphles({"run", "own.json", "--out", out.string()}, base).code, 0);
  ASSERT_EQ(run_sphles({"run", "other.json", "--out", elsewhere.string()}, base).code, 0);
  const fs::path foreign = sphles::io::list_checkpoints(elsewhere / "checkpoints").front();
  const fs::path mine = sphles::io::list_checkpoints(out / "checkpoints").front();
  ASSERT_GT(foreign.filename().string(), mine.filename().string());  // the newer name
  fs::copy_file(foreign, out / "checkpoints" / foreign.filename());

  const ProcessResult r =
      run_sphles({"run", "--restart", out.string(), "--set", "time.end=0.08"}, base);
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(
      r.err.find("skipped: checkpoint '" + (out / "checkpoints" / foreign.filename()).string() +
                 "' is not a checkpoint of the run in"),
      std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("particles_per_side"), std::string::npos) << r.err;
  std::ifstream record(out / "run.json");
  EXPECT_DOUBLE_EQ(json::parse(record)["time"].get<double>(), 0.08);
  EXPECT_EQ(json::parse(std::ifstream(out / "scene.json"))["particles_per_side"], 16);

  const ProcessResult named =
      run_sphles({"run", "--restart", (out / "checkpoints" / foreign.filename()).string()}, base);
  EXPECT_NE(named.code, 0) << named.err;
  EXPECT_NE(named.err.find("is not a checkpoint of the run in"), std::string::npos) << named.err;
  EXPECT_EQ(json::parse(std::ifstream(out / "scene.json"))["particles_per_side"], 16);
}

// The server's resume took the newest file among a run's checkpoints whatever run wrote it (and
// the listing showed its time). A file of another run is passed over there too, saying why.
TEST(ServiceFaults, AResumeOnTheServerPassesOverACheckpointOfAnotherRun) {
  const fs::path base = scratch("resume-foreign");
  const fs::path data = base / "data";
  json other = tiny_scene(0.1, "other");
  other["particles_per_side"] = 24;
  std::ofstream(base / "other.json") << other.dump();
  ASSERT_EQ(run_sphles({"run", "other.json", "--out", (base / "other").string()}, base).code, 0);
  const fs::path foreign = sphles::io::list_checkpoints(base / "other" / "checkpoints").front();
  std::string id;
  {
    TestServer server(data);
    const Api api{server.port()};
    id = api.create({{"scene", tiny_scene(0.05, "own")}});
    ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  }
  const fs::path run_dir = data / "runs" / id;
  const fs::path mine = sphles::io::list_checkpoints(run_dir / "checkpoints").front();
  ASSERT_GT(foreign.filename().string(), mine.filename().string());  // the newer name
  fs::copy_file(foreign, run_dir / "checkpoints" / foreign.filename());

  TestServer server(data);
  const Api api{server.port()};
  EXPECT_DOUBLE_EQ(api.run(id)["time"].get<double>(), 0.05);  // not the other run's 0.1
  ASSERT_EQ(api.patch("/api/runs/" + id + "/parameters", {{"time", {{"end", 0.08}}}}).status, 200);
  const Reply started = api.post("/api/runs/" + id + "/start");
  ASSERT_EQ(started.status, 200) << started.body;
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  EXPECT_DOUBLE_EQ(api.run(id)["time"].get<double>(), 0.08);
  EXPECT_EQ(api.run(id)["particles_per_side"], 16);
  const std::string log = api.get("/api/runs/" + id + "/log").body;
  EXPECT_NE(
      log.find("skipped: checkpoint '" + (run_dir / "checkpoints" / foreign.filename()).string() +
               "' is not a checkpoint of the run in"),
      std::string::npos)
      << log;
  EXPECT_NE(log.find("restart: " + mine.string()), std::string::npos) << log;
}

// The server's terminal log was 94 % dashboard polls (592 of 630 lines). Successful reads are
// logged at debug; changes, refusals and failures at info or above.
TEST(ServiceFaults, PollsStayOutOfTheLogChangesAndRefusalsStayIn) {
  const fs::path base = scratch("access-log");
  const fs::path log = base / "stderr.log";
  {
    ServeProcess serve({"--data", (base / "data").string()}, log);
    const Api api{serve.port()};
    for (int k = 0; k < 5; ++k) ASSERT_EQ(api.get("/api/health").status, 200);
    const std::string id = api.create({{"scene", tiny_scene(0.01, "logged")}});
    ASSERT_EQ(api.get("/api/runs/" + id).status, 200);
    ASSERT_EQ(api.get("/api/runs/0999-none").status, 404);
    ASSERT_EQ(api.post("/api/runs", {{"preset", 5}}).status, 400);
    serve.signal(SIGTERM);
    ASSERT_TRUE(serve.wait_exit(30s).has_value());
  }
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.find("\"GET /api/health\" 200"), std::string::npos) << text;
  EXPECT_EQ(text.find("\"GET /api/runs/0001-logged\" 200"), std::string::npos) << text;
  EXPECT_NE(text.find("\"POST /api/runs\" 201"), std::string::npos) << text;
  EXPECT_NE(text.find("\"POST /api/runs\" 400"), std::string::npos) << text;
  EXPECT_NE(text.find("\"GET /api/runs/0999-none\" 404"), std::string::npos) << text;
}

// `sphles serve --start-run SCENE` run again continues the run it started before and that was
// stopped, from its newest checkpoint, instead of starting the scene again at t = 0 (so that
// ./scripts/run.sh, run again, picks up where Ctrl-C stopped it); a different scene starts a new
// run.
TEST(ServiceFaults, StartRunAgainContinuesTheStoppedRun) {
  const fs::path base = scratch("start_run_again");
  const fs::path data = base / "data";
  const std::vector<std::string> args{"--data",      data.string(),
                                      "--threads",   "1",
                                      "--start-run", "tgv2d",
                                      "--set",       "particles_per_side=16",
                                      "--set",       "packing.enabled=false",
                                      "--set",       "time.end=1000"};
  double stopped_at = 0.0;
  {
    ServeProcess serve(args, base / "first.log");
    Api api{serve.port()};
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    for (;;) {
      const Reply r = api.get("/api/runs");
      const json runs = json::parse(r.body);
      if (runs.size() == 1 && runs[0]["time"].get<double>() > 0.2) break;
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << r.body;
      std::this_thread::sleep_for(100ms);
    }
    serve.signal(SIGTERM);  // stops the run with a checkpoint
    ASSERT_EQ(serve.wait_exit(60s), 0);
  }
  {
    std::ifstream in(data / "runs" / "0001-tgv2d" / "run.json");
    const json record = json::parse(in);
    ASSERT_EQ(record["state"], "stopped");
    stopped_at = record["time"].get<double>();
    ASSERT_GT(stopped_at, 0.0);
  }
  {
    ServeProcess serve(args, base / "second.log");
    Api api{serve.port()};
    const json runs = json::parse(api.get("/api/runs").body);
    ASSERT_EQ(runs.size(), 1u) << runs.dump();
    EXPECT_EQ(runs[0]["id"], "0001-tgv2d");
    EXPECT_NE(runs[0]["state"], "stopped");
    EXPECT_GE(runs[0]["time"].get<double>(), stopped_at);
    serve.signal(SIGTERM);
    ASSERT_EQ(serve.wait_exit(60s), 0);
  }
  std::ifstream log(base / "second.log");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("continuing run 0001-tgv2d"), std::string::npos) << text;
  // Another scene is a new run.
  std::vector<std::string> other = args;
  other.back() = "time.end=999";
  ServeProcess serve(other, base / "third.log");
  const json runs = json::parse(Api{serve.port()}.get("/api/runs").body);
  EXPECT_EQ(runs.size(), 2u) << runs.dump();
  serve.signal(SIGTERM);
  EXPECT_EQ(serve.wait_exit(60s), 0);
}

// Two servers on one data directory started without a word and then ran the same runs, wrote
// the same checkpoints and run.json, and deleted each other's runs. The second is refused,
// naming the first; a killed server leaves no stale lock.
TEST(ServiceFaults, ASecondServerOnTheSameDataDirectoryIsRefusedNamingTheFirst) {
  const fs::path base = scratch("two_servers");
  const fs::path data = base / "data";
  const std::vector<std::string> args{"--data", data.string(), "--threads", "1"};
  ServeProcess first(args, base / "first.log");
  std::vector<std::string> second_args{"serve", "--port", "0"};
  second_args.insert(second_args.end(), args.begin(), args.end());
  const ProcessResult second = run_sphles(second_args, base, 60s);
  EXPECT_EQ(second.code, 1) << second.err;
  const std::string holder =
      "in use by another sphles server (process " + std::to_string(first.pid()) + ")";
  EXPECT_NE(second.err.find(holder), std::string::npos) << second.err;
  EXPECT_NE(second.err.find(data.string()), std::string::npos) << second.err;
  EXPECT_EQ(Api{first.port()}.get("/api/health").status, 200);

  // In one process too: a second run manager on the directory is refused while the first
  // lives, and accepted once it is gone.
  const fs::path other = base / "other";
  sphles::control::ManagerOptions options;
  options.data_directory = other;
  {
    sphles::control::RunManager manager(options);
    try {
      sphles::control::RunManager again(options);
      ADD_FAILURE() << "a second run manager took the data directory";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("(process " + std::to_string(::getpid()) + ")"),
                std::string::npos)
          << e.what();
    }
  }
  EXPECT_NO_THROW(sphles::control::RunManager{options});

  first.signal(SIGKILL);
  ASSERT_TRUE(first.wait_exit(30s).has_value());
  ServeProcess third(args, base / "third.log");
  EXPECT_EQ(Api{third.port()}.get("/api/health").status, 200);
  third.signal(SIGTERM);
  EXPECT_EQ(third.wait_exit(60s), 0);
}

// A scene's packing.cache_dir made the server create directories and write files wherever it
// could; in the command line a scene name of ../../x wrote outside runs/.
TEST(ServiceFaults, ClientsChooseNoPaths) {
  TestServer server(scratch("paths") / "data");
  const Api api{server.port()};
  json scene = tiny_scene(0.05);
  scene["packing"] = {{"cache_dir", (server.data_directory / "elsewhere").string()}};
  expect_error(api.post("/api/runs", {{"scene", scene}}), 400, "packing.cache_dir");
  EXPECT_FALSE(fs::exists(server.data_directory / "elsewhere"));
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 0u);

  const fs::path base = scratch("cli-name");
  fs::create_directories(base / "deep" / "work");
  json named = tiny_scene(0.02, "../../escaped");
  std::ofstream(base / "deep" / "work" / "scene.json") << named.dump();
  const ProcessResult r = run_sphles({"run", "scene.json"}, base / "deep" / "work");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(fs::exists(base / "escaped"));
  EXPECT_FALSE(fs::exists(base / "deep" / "escaped"));
  std::size_t inside = 0;
  for (const auto& entry : fs::directory_iterator(base / "deep" / "work" / "runs")) {
    EXPECT_TRUE(fs::exists(entry.path() / "timeseries.csv")) << entry.path();
    ++inside;
  }
  EXPECT_EQ(inside, 1u);
}

// The packing cache is the program's setting, not a scene's.
TEST(ServiceFaults, ThePackingCacheIsTheServersSetting) {
  const fs::path base = scratch("packing-cache");
  const fs::path cache = base / "cache";
  ServeProcess serve(
      {"--data", (base / "data").string(), "--threads", "1", "--packing-cache", cache.string()},
      base / "stderr.log");
  const Api api{serve.port()};
  json scene = tiny_scene(0.02, "packed");
  scene["packing"] = {{"enabled", true}};
  const std::string id = api.create({{"scene", scene}});
  ASSERT_TRUE(wait_until([&] { return api.run(id)["state"] == "finished"; }));
  ASSERT_TRUE(fs::is_directory(cache));
  EXPECT_FALSE(fs::is_empty(cache));
  serve.signal(SIGTERM);
  EXPECT_EQ(serve.wait_exit(20s), std::optional<int>(0));
}

// A run could ask for anything (3D 512³ failed later with a bare std::bad_alloc; tiny kernels, huge
// histograms, cadences far below a time step, a thousand checkpoints, a nanometre Kolmogorov box)
// and unlimited runs and queue length got 201. Each is refused before anything is created, naming
// the field; what does not fit in memory says the estimate.
TEST(ServiceFaults, WhatARunMayAskForIsBounded) {
  TestServer server(scratch("limits") / "data");
  const Api api{server.port()};
  const auto refused = [&](const json& scene, int status, const std::string& field) {
    const Reply r = api.post("/api/runs", {{"scene", scene}});
    expect_error(r, status, field);
    return r.body_json()["error"]["message"].get<std::string>();
  };
  for (const int side : {512, 4096}) {
    const std::string message =
        refused({{"case", "tgv3d"}, {"particles_per_side", side}}, 422, "particles_per_side");
    EXPECT_NE(message.find("estimated"), std::string::npos) << message;
    EXPECT_NE(message.find("--max-memory"), std::string::npos) << message;
  }
  json scene = tiny_scene(1.0);
  scene["kernel"]["diameter_over_spacing"] = 0.02;
  refused(scene, 400, "kernel.diameter_over_spacing");
  scene = tiny_scene(1.0);
  scene["analysis"] = {
      {"every", 0.1}, {"products", {"energy", "sfs_stats"}}, {"histogram_bins", 10000}};
  refused(scene, 400, "analysis.histogram_bins");
  scene["analysis"] = {{"every", 1e-9}, {"products", {"energy"}}};
  refused(scene, 400, "analysis.every");
  scene = tiny_scene(1.0);
  scene["checkpoint"] = {{"every", 1e-6}, {"keep", 1000}};
  refused(scene, 400, "checkpoint.keep");
  refused({{"case", "kolmogorov2d"}, {"box_length", 1e-9}}, 400, "box_length");
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 0u) << "a refused run was created";
}

TEST(ServiceFaults, TheQueueAndTheNumberOfRunsAreBounded) {
  TestServer server(scratch("capacity") / "data", "", /*max_running=*/1, {},
                    [](sphles::control::ManagerOptions& m) {
                      m.max_queued = 2;
                      m.max_runs = 4;
                    });
  const Api api{server.port()};
  std::vector<std::string> ids;
  for (int k = 0; k < 3; ++k) ids.push_back(api.create({{"scene", long_scene()}}));
  EXPECT_EQ(api.run(ids[0])["state"], "running");
  EXPECT_EQ(api.run(ids[1])["state"], "queued");
  EXPECT_EQ(api.run(ids[2])["state"], "queued");
  // The queue is full: a run to start is refused whole (nothing is created), one to keep is not.
  expect_error(api.post("/api/runs", {{"scene", long_scene()}}), 429);
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 3u);
  ids.push_back(api.create({{"scene", long_scene()}, {"start", false}}));
  expect_error(api.post("/api/runs/" + ids[3] + "/start"), 429);
  EXPECT_EQ(api.run(ids[3])["state"], "created");
  // Four runs is the limit.
  expect_error(api.post("/api/runs", {{"scene", long_scene()}, {"start", false}}), 429);
  EXPECT_EQ(api.get("/api/runs").body_json().size(), 4u);
  // Room again: one leaves the queue, one is deleted.
  ASSERT_EQ(api.post("/api/runs/" + ids[2] + "/stop").status, 200);
  EXPECT_EQ(api.post("/api/runs/" + ids[3] + "/start").status, 200);
  ASSERT_EQ(api.remove("/api/runs/" + ids[2]).status, 200);
  EXPECT_EQ(api.post("/api/runs", {{"scene", long_scene()}, {"start", false}}).status, 201);
}

TEST(ServiceFaults, MemoryIsSharedByTheActiveRuns) {
  // A 3D 16³ run with energy analysis is estimated at about 17 MiB: one fits in 25 MiB, two do
  // not.
  constexpr double kLimit = 25.0 * 1024 * 1024;
  TestServer server(scratch("memory") / "data", "", /*max_running=*/2, {},
                    [&](sphles::control::ManagerOptions& m) { m.max_memory_bytes = kLimit; });
  const Api api{server.port()};
  json cube = {{"case", "tgv3d"},
               {"particles_per_side", 16},
               {"packing", {{"enabled", false}}},
               {"time", {{"end", 1e6}}},
               {"analysis", {{"every", 0.5}, {"products", {"energy"}}}}};
  const std::string first = api.create({{"scene", cube}});
  const std::string second = api.create({{"scene", cube}});
  EXPECT_EQ(api.run(first)["state"], "running");
  EXPECT_EQ(api.run(second)["state"], "queued") << "two runs were started beyond the memory";
  // A run that does not fit even alone is refused; so is a live change that outgrows it.
  cube["particles_per_side"] = 32;
  expect_error(api.post("/api/runs", {{"scene", cube}}), 422, "particles_per_side");
  const Reply grown = api.patch(
      "/api/runs/" + first + "/parameters",
      {{"analysis",
        {{"products", json::array({"energy", "slices"})}, {"slice", {{"fields", {"omega2"}}}}}},
       {"render", {{"fields", {"omega2"}}, {"width", 4096}, {"height", 4096}}}});
  expect_error(grown, 422, "render");
  // What fits is changed, and named by its field (an appended array element is the array).
  const Reply added =
      api.patch("/api/runs/" + first + "/parameters",
                {{"analysis", {{"products", json::array({"energy", "vorticity"})}}}});
  ASSERT_EQ(added.status, 200) << added.body;
  EXPECT_EQ(added.body_json()["changed"], json::array({"analysis.products"}));
  ASSERT_EQ(api.post("/api/runs/" + first + "/stop").status, 200);
  EXPECT_TRUE(wait_until([&] { return api.run(second)["state"] == "running"; }));
}

// A run with ranks takes this machine's memory for all its ranks when they run here (the
// default launcher), and only the server's share (analysis) with --rank-memory (a cluster's
// launcher), where one rank's estimate must fit that instead. Estimates and refused creates
// only: no MPI job is launched, so the launcher hook is a no-op.
TEST(ServiceFaults, RunsWithRanksAreAdmittedByTheMemoryWhereTheRanksRun) {
  const json cube = {{"case", "tgv3d"},
                     {"particles_per_side", 32},
                     {"packing", {{"enabled", false}}},
                     {"time", {{"end", 1.0}}},
                     {"analysis", {{"every", 0.5}, {"products", {"energy", "spectrum"}}}}};
  const json request = {{"scene", cube}, {"ranks", 2}};
  const auto serve = [&](const std::string& name, double max_memory, double rank_memory) {
    return std::make_unique<TestServer>(
        scratch(name) / "data", "", 1, std::function<void(ServerOptions&)>{},
        [&](sphles::control::ManagerOptions& m) {
          if (max_memory > 0.0) m.max_memory_bytes = max_memory;
          m.rank_memory_bytes = rank_memory;
          m.distribute = [](sphles::control::RunOptions&, int, const fs::path&) {};
        });
  };
  const auto part_names = [](const json& parts) {
    std::set<std::string> names;
    for (const json& p : parts) names.insert(p["name"].get<std::string>());
    return names;
  };
  // The parts of the estimate, from a server with room for everything.
  json whole, gathering;
  {
    const auto server = serve("ranks-room", 0.0, 0.0);
    const Api api{server->port()};
    Reply r = api.post("/api/estimate", request);
    ASSERT_EQ(r.status, 200) << r.body;
    whole = r.body_json();
    json particle_estimate = request;
    particle_estimate["scene"]["analysis"]["products"] = {"energy", "vorticity"};
    particle_estimate["scene"]["analysis"]["gridding"] = {{"vorticity", "particle"}};
    r = api.post("/api/estimate", particle_estimate);
    ASSERT_EQ(r.status, 200) << r.body;
    gathering = r.body_json();
    // Particle snapshots are written by the ranks, and the 3D particle view is sent only its
    // points: the server renders it without holding the particles.
    json particles = request;
    particles["scene"]["analysis"]["products"] = {"energy", "particles"};
    r = api.post("/api/estimate", particles);
    ASSERT_EQ(r.status, 200) << r.body;
    EXPECT_EQ(part_names(r.body_json()["per_rank"]["service"]), std::set<std::string>{"analysis"})
        << r.body;
    particles["scene"]["render"] = {{"view3d", {{"enabled", true}}}};
    r = api.post("/api/estimate", particles);
    ASSERT_EQ(r.status, 200) << r.body;
    EXPECT_EQ(part_names(r.body_json()["per_rank"]["service"]),
              (std::set<std::string>{"analysis", "rendering"}))
        << r.body;
  }
  ASSERT_EQ(whole["admitted"], true) << whole;
  EXPECT_TRUE(whole["rank_memory_limit_bytes"].is_null());
  const double per_rank = whole["per_rank"]["memory_bytes"].get<double>();
  const double server_share = whole["per_rank"]["service_bytes"].get<double>();
  const double here = whole["memory_here_bytes"].get<double>();
  // Both ranks here, and the server's share beside them: its analysis, no particles (the ranks
  // serve the energy and the spectrum), so less than one rank's.
  EXPECT_NEAR(here, 2.0 * per_rank + server_share, 1e-9 * here) << whole;
  EXPECT_EQ(part_names(whole["per_rank"]["service"]), std::set<std::string>{"analysis"}) << whole;
  EXPECT_LT(server_share, per_rank) << whole;
  // The "particle" vorticity estimate is computed from gathered particles: the server then
  // holds snapshots of every particle too.
  EXPECT_EQ(part_names(gathering["per_rank"]["service"]),
            (std::set<std::string>{"analysis", "snapshots"}))
      << gathering;

  // Ranks here, a limit between one rank and both: refused, the whole named.
  {
    const auto server = serve("ranks-here", 1.5 * per_rank, 0.0);
    const Api api{server->port()};
    const json e = api.post("/api/estimate", request).body_json();
    EXPECT_EQ(e["admitted"], false) << e;
    EXPECT_EQ(e["refusal"]["field"], "particles_per_side") << e;
    EXPECT_NE(e["refusal"]["message"].get<std::string>().find("mpi_ranks"), std::string::npos) << e;
    expect_error(api.post("/api/runs", request), 422, "particles_per_side");
  }
  // The same limit with ranks elsewhere that hold one rank's estimate: admitted, and this
  // machine gives only the server's share.
  {
    const auto server = serve("ranks-elsewhere", 1.5 * per_rank, 1.01 * per_rank);
    const json e = Api{server->port()}.post("/api/estimate", request).body_json();
    EXPECT_EQ(e["admitted"], true) << e;
    EXPECT_DOUBLE_EQ(e["rank_memory_limit_bytes"].get<double>(), 1.01 * per_rank);
    EXPECT_NEAR(e["memory_here_bytes"].get<double>(), server_share, 1e-6 * here) << e;
  }
  // Ranks elsewhere that cannot hold one rank: refused by field "ranks"; nothing is created.
  {
    const auto server = serve("ranks-small", 1.5 * per_rank, 0.5 * per_rank);
    const Api api{server->port()};
    const json e = api.post("/api/estimate", request).body_json();
    EXPECT_EQ(e["admitted"], false) << e;
    EXPECT_EQ(e["refusal"]["field"], "ranks") << e;
    expect_error(api.post("/api/runs", request), 422, "ranks");
    EXPECT_NE(e["refusal"]["message"].get<std::string>().find("--rank-memory"), std::string::npos)
        << e;
    EXPECT_EQ(api.get("/api/runs").body_json().size(), 0u);
  }
  // Every rank is a process holding the program and the MPI runtime (about 97 MiB): 1024 ranks
  // of a 128³ run were admitted at 1.8 MB each.
  {
    const auto server = serve("ranks-many", 0.0, 0.0);
    json many = request;
    many["scene"]["particles_per_side"] = 128;
    many["ranks"] = 1024;
    const json e = Api{server->port()}.post("/api/estimate", many).body_json();
    ASSERT_TRUE(e["per_rank"].is_object()) << e;
    EXPECT_GT(e["per_rank"]["memory_bytes"].get<double>(), 90.0 * 1024 * 1024) << e;
    EXPECT_EQ(e["admitted"], false) << e;
    EXPECT_NE(e["refusal"]["message"].get<std::string>().find("mpi_ranks"), std::string::npos) << e;
  }
}

}  // namespace
