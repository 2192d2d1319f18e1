// SPDX-License-Identifier: GPL-3.0-or-later
// Run control: state machine, live changes, rendering sink, checkpoint on stop and resume, and
// the run manager's queue and recovery. Real runs (tiny 2D Taylor-Green), real files.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>

#include "control/run.hpp"
#include "control/run_manager.hpp"
#include "io/checkpoint.hpp"
#include "scratch_directory.hpp"
#include "sim/scene.hpp"

namespace sphles::control {
namespace {

using nlohmann::json;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

std::filesystem::path fresh_directory(const std::string& name) {
  return sphles::scratch::scratch_directory("control", name, false);
}

/// 16² Taylor-Green at Re = 100 on a lattice; about 40 steps per 0.1 s of simulated time.
json tiny_scene(double end_time, bool render = false) {
  json scene = {{"name", "tiny"},
                {"case", "tgv2d"},
                {"particles_per_side", 16},
                {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 6}}},
                {"fluid",
                 {{"reference_density", 1.0},
                  {"dynamic_viscosity", 0.01},
                  {"sound_speed", 10.0},
                  {"reference_pressure", 1.0}}},
                {"packing", {{"enabled", false}}},
                {"time", {{"end", end_time}}}};
  if (render) {
    scene["analysis"] = {{"every", 0.05},
                         {"products", {"energy", "vorticity", "slices"}},
                         {"slice", {{"fields", {"omega2", "tau_sfs"}}}}};
    scene["render"] = {{"fields", {"omega2", "tau_sfs"}}, {"width", 480}, {"height", 240}};
  }
  return scene;
}

std::vector<std::string> lines_of(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

template <class Predicate>
bool eventually(Predicate predicate, std::chrono::milliseconds limit = 60s) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    if (predicate()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return predicate();
}

ManagerOptions manager_options(const std::filesystem::path& data, int max_running) {
  ManagerOptions options;
  options.data_directory = data;
  options.max_running = max_running;
  return options;
}

class Recorder : public RunObserver {
 public:
  explicit Recorder(bool want_images = false) : want_images_(want_images) {}
  void on_metrics(std::span<const MetricsSample> batch) override {
    std::lock_guard lock(mutex);
    for (const auto& m : batch) metrics.push_back(m);
  }
  void on_image(const ImageEvent& image) override {
    std::lock_guard lock(mutex);
    images.push_back(image);
  }
  void on_state(RunState state, const std::string&,
                std::span<const std::string_view> verbs) override {
    std::lock_guard lock(mutex);
    states.push_back(state);
    actions.emplace_back(verbs.begin(), verbs.end());
  }
  bool wants_images() const override { return want_images_; }
  std::mutex mutex;
  std::vector<MetricsSample> metrics;
  std::vector<ImageEvent> images;
  std::vector<std::vector<std::string_view>> actions;  // with each state
  std::vector<RunState> states;

 private:
  bool want_images_;
};

TEST(RunControl, RunsToTheEndAndRecordsItsState) {
  const auto dir = fresh_directory("finish");
  control::Run run("r1", parse_run_spec(tiny_scene(0.1)), dir);
  EXPECT_EQ(run.status().state, RunState::Created);
  auto recorder = std::make_shared<Recorder>();
  run.add_observer(recorder);
  EXPECT_EQ(run.run_here(), RunState::Finished);
  const RunStatus s = run.status();
  EXPECT_NEAR(s.time, 0.1, 1e-12);
  EXPECT_GT(s.step, 5u);
  ASSERT_TRUE(s.latest.has_value());
  EXPECT_EQ(s.latest->step, s.step);
  EXPECT_EQ(lines_of(dir / "timeseries.csv").size(), s.step + 2);  // header + t = 0 + steps
  const json run_file = json::parse(std::ifstream(dir / "run.json"));
  EXPECT_EQ(run_file.at("state"), "finished");
  {
    std::lock_guard lock(recorder->mutex);
    EXPECT_EQ(recorder->metrics.size(), s.step + 1);
    EXPECT_EQ(recorder->states.back(), RunState::Finished);
    // At its time.end a finished run accepts only its deletion.
    EXPECT_EQ(recorder->actions.back(), std::vector<std::string_view>{"delete"});
  }
  // A finished run cannot start again until time.end is raised. (Not while holding the
  // observer's lock: a transition may notify observers while it holds the run's own.)
  EXPECT_THROW(run.start(), StateError);
  EXPECT_THROW(run.pause(), StateError);
  // The wall time spent stepping is recorded and survives reopening (a server restart), and a
  // continuation adds to it instead of starting from zero.
  EXPECT_GT(s.wall_seconds, 0.0);
  EXPECT_EQ(run_file.at("wall_seconds").get<double>(), s.wall_seconds);
  std::unique_ptr<control::Run> reopened = control::Run::open("r1", dir);
  EXPECT_EQ(reopened->status().wall_seconds, s.wall_seconds);
  reopened->apply_changes({{"time", {{"end", 0.2}}}});
  EXPECT_EQ(reopened->run_here(), RunState::Finished);
  EXPECT_GT(reopened->status().wall_seconds, s.wall_seconds);
  // run.log: one UTC-stamped line per event, appended over both starts.
  const std::vector<std::string> log = lines_of(dir / "run.log");
  const std::regex line(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z (info |warn |error) .+)");
  for (const std::string& l : log) EXPECT_TRUE(std::regex_match(l, line)) << l;
  const auto position = [&](const std::string& text, std::size_t from = 0) {
    for (std::size_t i = from; i < log.size(); ++i)
      if (log[i].find(text) != std::string::npos) return i;
    return log.size();
  };
  const std::size_t started = position("info  state: created -> running");
  const std::size_t finished = position("info  state: running -> finished", started);
  const std::size_t changed =
      position("info  changed time.end by {\"time\":{\"end\":0.2}}", finished);
  const std::size_t again = position("info  state: finished -> running", changed);
  EXPECT_LT(position("info  state: running -> finished", again), log.size())
      << "state changes, live change and restart in order";
  EXPECT_LT(position("sphles run: tiny (tgv2d), 256 particles"), finished);
  EXPECT_LT(position("restart: "), log.size());
}

// Every analysis snapshot carries -de_v/dt of the time series at its time, so that
// stats/snapshots.csv has the dissipation three ways (SPEC §5) side by side.
TEST(RunControl, SnapshotStatisticsCarryTheTimeSeriesDissipation) {
  const auto dir = fresh_directory("dissipation");
  json scene = tiny_scene(0.1);
  scene["analysis"] = {{"every", 0.05}, {"products", {"spectrum", "vorticity"}}};
  control::Run run("r1", parse_run_spec(scene), dir);
  ASSERT_EQ(run.run_here(), RunState::Finished);
  const auto split = [](const std::string& line) {
    std::vector<std::string> parts;
    std::stringstream stream(line);
    for (std::string part; std::getline(stream, part, ',');) parts.push_back(part);
    return parts;
  };
  const std::vector<std::string> series = lines_of(dir / "timeseries.csv");
  const std::vector<std::string> stats = lines_of(dir / "stats" / "snapshots.csv");
  // Header and the snapshots of t = 0, 0.05, 0.1 that were analysed (the pipeline drops a waiting
  // snapshot when a newer one arrives; the last one is always analysed).
  ASSERT_GE(stats.size(), 2u);
  const std::vector<std::string> names = split(stats[0]);
  const auto column = std::find(names.begin(), names.end(), "dissipation_energy") - names.begin();
  ASSERT_LT(static_cast<std::size_t>(column), names.size());
  std::size_t finite = 0;
  for (std::size_t r = 1; r < stats.size(); ++r) {
    const std::vector<std::string> cells = split(stats[r]);
    ASSERT_EQ(cells.size(), names.size());
    // The time series row of the same time (t,step,dt,e_v,dissipation,...).
    std::string expected;
    for (std::size_t k = 1; k < series.size(); ++k) {
      const std::vector<std::string> row = split(series[k]);
      if (row[0] == cells[0]) expected = row[4];
    }
    ASSERT_FALSE(expected.empty()) << "no time series row at t = " << cells[0];
    EXPECT_EQ(cells[static_cast<std::size_t>(column)], expected) << "t = " << cells[0];
    finite += expected != "nan";
  }
  EXPECT_GE(finite, 1u) << "-de_v/dt is known after the first row (at least at t = 0.1)";
  EXPECT_EQ(split(stats.back())[0], split(series.back())[0]) << "the last snapshot is analysed";
}

// What a running run is doing (the dashboard's "packing…"): packing its lattice (into a fresh
// cache, so that it really packs), then stepping; nothing once it has ended.
TEST(RunControl, ReportsItsPhaseFromPackingToStepping) {
  const auto dir = fresh_directory("phase");
  json scene = tiny_scene(1000.0);
  scene["particles_per_side"] = 48;
  scene["packing"] = {{"enabled", true}};
  RunOptions options;
  options.packing_cache_dir = dir / "packing-cache";
  control::Run run("r", parse_run_spec(scene), dir / "run", options);
  EXPECT_EQ(run.status().phase, "") << "not active";
  run.start();
  std::vector<std::string> seen;
  ASSERT_TRUE(eventually([&] {
    const std::string phase = run.status().phase;
    if (seen.empty() || seen.back() != phase) seen.push_back(phase);
    return phase == "stepping";
  }));
  const auto packing = std::find(seen.begin(), seen.end(), "packing");
  ASSERT_NE(packing, seen.end()) << "a 48² lattice packs for a while";
  EXPECT_LT(packing - seen.begin(), static_cast<long>(seen.size()) - 1) << "then it steps";
  run.pause();
  EXPECT_EQ(run.status().phase, "stepping");
  run.stop();
  EXPECT_EQ(run.status().phase, "") << "stopped";
  // A resume reads its checkpoint first.
  run.start();
  seen.clear();
  ASSERT_TRUE(eventually([&] {
    const std::string phase = run.status().phase;
    if (seen.empty() || seen.back() != phase) seen.push_back(phase);
    return phase == "stepping";
  }));
  run.stop();
}

TEST(RunControl, RefusesADirectoryThatHoldsARun) {
  const auto dir = fresh_directory("twice");
  { control::Run run("a", parse_run_spec(tiny_scene(0.1)), dir); }
  EXPECT_THROW(control::Run("b", parse_run_spec(tiny_scene(0.1)), dir), std::runtime_error);
}

TEST(RunControl, PauseHoldsTheStepAndResumeContinues) {
  const auto dir = fresh_directory("pause");
  control::Run run("r", parse_run_spec(tiny_scene(50.0)), dir);
  using Verbs = std::vector<std::string_view>;
  // The actions a client is offered are exactly the transitions that do not throw.
  EXPECT_EQ(run.status().actions, (Verbs{"start", "stop", "delete"}));
  EXPECT_THROW(run.pause(), StateError);  // created
  run.start();
  EXPECT_EQ(run.status().actions, (Verbs{"pause", "stop"}));
  EXPECT_THROW(run.start(), StateError);
  ASSERT_TRUE(eventually([&] { return run.status().step > 5; }));
  run.pause();
  EXPECT_EQ(run.status().state, RunState::Paused);
  EXPECT_EQ(run.status().actions, (Verbs{"resume", "stop"}));
  EXPECT_THROW(run.pause(), StateError);
  ASSERT_TRUE(eventually([&] { return run.status().holding; }));  // the step in flight ended
  const std::uint64_t held = run.status().step;
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(run.status().step, held);
  run.resume();
  EXPECT_THROW(run.resume(), StateError);
  ASSERT_TRUE(eventually([&] { return run.status().step > held + 5; }));
  run.stop();
  EXPECT_EQ(run.status().state, RunState::Stopped);
  EXPECT_EQ(run.status().actions, (Verbs{"start", "delete"}));
  EXPECT_THROW(run.stop(), StateError);
  run.retire();
  EXPECT_TRUE(run.status().actions.empty());
  // The stop wrote a checkpoint of the state it stopped at.
  const auto files = io::list_checkpoints(dir / "checkpoints");
  ASSERT_FALSE(files.empty());
  EXPECT_EQ(io::read_checkpoint(files.front()).state.step, run.status().step);
}

TEST(RunControl, StopAndResumeGivesTheSameResultAsAnUninterruptedRun) {
  const auto dir = fresh_directory("interrupted");
  double stopped_at = 0.0;
  {
    control::Run first("i", parse_run_spec(tiny_scene(50.0)), dir);
    first.start();
    ASSERT_TRUE(eventually([&] { return first.status().step > 10; }));
    first.stop("test");
    ASSERT_EQ(first.status().state, RunState::Stopped);
    stopped_at = first.status().time;
  }
  const double end = std::floor(stopped_at) + 1.0;
  // A new process: open the directory, end the run at `end`, resume from the checkpoint.
  std::unique_ptr<control::Run> reopened = control::Run::open("i", dir);
  EXPECT_EQ(reopened->status().state, RunState::Stopped);
  EXPECT_EQ(reopened->status().time, stopped_at);
  reopened->apply_changes({{"time", {{"end", end}}}});
  reopened->resume();
  reopened->wait();
  ASSERT_EQ(reopened->status().state, RunState::Finished) << reopened->status().reason;

  const auto straight_dir = fresh_directory("straight");
  control::Run straight("s", parse_run_spec(tiny_scene(end)), straight_dir);
  ASSERT_EQ(straight.run_here(), RunState::Finished);
  EXPECT_EQ(reopened->status().step, straight.status().step);
  // Bitwise: the time series rows (17 significant digits) are identical.
  EXPECT_EQ(lines_of(dir / "timeseries.csv"), lines_of(straight_dir / "timeseries.csv"));
}

// A run whose every checkpoint was truncated failed naming a truncated file as the "last valid
// checkpoint".
TEST(RunControl, AFailureNamesOnlyACheckpointThatReadsWhole) {
  json scene = tiny_scene(0.05);
  scene["checkpoint"] = {{"every", 0.02}};
  const auto dir = fresh_directory("truncated");
  control::Run run("r", parse_run_spec(scene), dir);
  ASSERT_EQ(run.run_here(), RunState::Finished);
  const auto files = io::list_checkpoints(dir / "checkpoints");
  ASSERT_FALSE(files.empty());
  for (const auto& f : files) std::filesystem::resize_file(f, std::filesystem::file_size(f) / 2);
  run.apply_changes({{"time", {{"end", 1.0}}}});
  EXPECT_EQ(run.run_here(), RunState::Failed);
  const std::string reason = run.status().reason;
  EXPECT_EQ(reason.find("last valid checkpoint"), std::string::npos) << reason;
  EXPECT_NE(reason.find("no valid checkpoint is left (" + std::to_string(files.size()) +
                        " file(s) in checkpoints/, none reads whole)"),
            std::string::npos)
      << reason;
}

TEST(RunControl, ABlowUpFailsTheRunCleanlyAndKeepsTheLastValidCheckpoint) {
  json scene = tiny_scene(5.0);
  scene["time"]["fixed_step"] = 0.1;  // 2.5 x the acoustic limit: blows up within ~1.2 s
  scene["checkpoint"] = {{"every", 0.2}};
  const auto dir = fresh_directory("blowup");
  control::Run run("r", parse_run_spec(scene), dir);
  EXPECT_EQ(run.run_here(), RunState::Failed);
  const RunStatus s = run.status();
  EXPECT_NE(s.reason.find("blow-up"), std::string::npos) << s.reason;
  EXPECT_NE(s.reason.find("last valid checkpoint: checkpoints/"), std::string::npos) << s.reason;
  const auto files = io::list_checkpoints(dir / "checkpoints");
  ASSERT_FALSE(files.empty());
  const io::Checkpoint newest = io::read_checkpoint(files.front());  // validates, all finite
  EXPECT_LT(newest.state.time, 5.0);
  EXPECT_EQ(json::parse(std::ifstream(dir / "run.json")).at("state"), "failed");
  // The failure and its diagnosis are in run.log, at error level.
  bool logged = false;
  for (const std::string& l : lines_of(dir / "run.log"))
    logged = logged || (l.find(" error state: running -> failed: ") != std::string::npos &&
                        l.find("blow-up") != std::string::npos &&
                        l.find("last valid checkpoint: checkpoints/") != std::string::npos);
  EXPECT_TRUE(logged);
}

TEST(RunControl, LiveChangesApplyAtTheNextStepAndFixedFieldsAreRejected) {
  const auto dir = fresh_directory("changes");
  control::Run run("r", parse_run_spec(tiny_scene(50.0)), dir);
  run.start();
  ASSERT_TRUE(eventually([&] { return run.status().step > 3; }));
  const auto changed = run.apply_changes({{"fluid", {{"reference_pressure", 4.0}}}});
  EXPECT_EQ(changed, std::vector<std::string>{"fluid.reference_pressure"});
  EXPECT_EQ(run.document().at("fluid").at("reference_pressure"), 4.0);
  try {
    run.apply_changes({{"kernel", {{"type", "quintic_spline"}}}});
    ADD_FAILURE() << "kernel change accepted";
  } catch (const ChangeError& e) {
    EXPECT_EQ(e.field(), "kernel.type");
    EXPECT_NE(std::string(e.what()).find("create a new run"), std::string::npos);
  } catch (const std::exception& e) {
    ADD_FAILURE() << "kernel change: " << e.what();
  }
  try {
    // The stored a^n belongs to the scheme that computed it.
    run.apply_changes({{"scheme", {{"type", "transport_velocity"}}}});
    ADD_FAILURE() << "scheme change accepted";
  } catch (const ChangeError& e) {
    EXPECT_EQ(e.field(), "scheme.type");
    EXPECT_NE(std::string(e.what()).find("create a new run"), std::string::npos) << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "scheme change: " << e.what();
  }
  try {
    run.apply_changes({{"fluid", {{"reference_pressure", "high"}}}});
    ADD_FAILURE() << "string p_ref accepted";
  } catch (const ChangeError& e) {
    EXPECT_EQ(e.field(), "fluid.reference_pressure");
  } catch (const std::exception& e) {
    ADD_FAILURE() << "string p_ref: " << e.what();
  }
  try {
    run.apply_changes({{"time", {{"end", 0.0}}}});
    ADD_FAILURE() << "end time 0 accepted";
  } catch (const ChangeError& e) {
    EXPECT_EQ(e.field(), "time.end");
  } catch (const std::exception& e) {
    ADD_FAILURE() << "end time 0: " << e.what();
  }
  EXPECT_THROW(run.apply_changes(json::array()), ChangeError);
  // Shorten the run: it finishes at the new end. The run holds while the end is set, so that
  // the new end is still ahead of it when the change takes effect (a change is parsed, admitted
  // and written while the run goes on).
  run.pause();
  ASSERT_TRUE(eventually([&] { return run.status().holding; }));
  const double end = run.status().time + 0.05;
  run.apply_changes({{"time", {{"end", end}}}});
  run.resume();
  run.wait();
  EXPECT_EQ(run.status().state, RunState::Finished);
  EXPECT_NEAR(run.status().time, end, 1e-9);
  const json scene = json::parse(std::ifstream(dir / "scene.json"));
  EXPECT_EQ(scene.at("fluid").at("reference_pressure"), 4.0);
  // Raising time.end lets a finished run continue.
  run.apply_changes({{"time", {{"end", end + 0.02}}}});
  run.start();
  run.wait();
  EXPECT_EQ(run.status().state, RunState::Finished);
  EXPECT_NEAR(run.status().time, end + 0.02, 1e-9);
}

TEST(RunControl, ALiveChangeBeingCheckedDoesNotHoldTheRunUp) {
  // Parsing, validation, admission and the scene.json write of a change run outside the state
  // lock the solver thread takes every step: the run steps on and answers while a change waits.
  const auto dir = fresh_directory("change_lock");
  std::mutex gate_mutex;
  std::condition_variable gate;
  bool admitting = false, release = false;
  RunOptions options;
  options.admit = [&](const RunSpec&, int) {
    std::unique_lock lock(gate_mutex);
    admitting = true;
    gate.notify_all();
    gate.wait(lock, [&] { return release; });
  };
  control::Run run("r", parse_run_spec(tiny_scene(50.0)), dir, options);
  run.start();
  ASSERT_TRUE(eventually([&] { return run.status().step > 3; }));
  std::thread changer([&] { run.apply_changes({{"fluid", {{"reference_pressure", 4.0}}}}); });
  {
    std::unique_lock lock(gate_mutex);
    gate.wait(lock, [&] { return admitting; });
  }
  const std::uint64_t step = run.status().step;  // answers while the change is admitted
  const bool stepped = eventually([&] { return run.status().step > step + 2; });
  {
    std::lock_guard lock(gate_mutex);
    release = true;
  }
  gate.notify_all();
  changer.join();
  EXPECT_TRUE(stepped) << "the solver waited for a change being admitted";
  EXPECT_EQ(run.document().at("fluid").at("reference_pressure"), 4.0);
  run.stop();
}

bool is_png(const std::vector<unsigned char>& bytes) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  return bytes.size() > 8 && std::equal(kSignature, kSignature + 8, bytes.begin());
}

TEST(RunControl, RendersAndSavesTheImageSeriesWithAnIndex) {
  const auto dir = fresh_directory("render");
  control::Run run("r", parse_run_spec(tiny_scene(0.1, true)), dir);
  auto recorder = std::make_shared<Recorder>();
  run.add_observer(recorder);
  ASSERT_EQ(run.run_here(), RunState::Finished) << run.status().reason;
  const auto index = lines_of(dir / "frames" / "index.csv");
  ASSERT_GE(index.size(), 2u);
  EXPECT_EQ(index.front(), "time,step,field,file");
  std::set<std::string> fields;
  for (std::size_t k = 1; k < index.size(); ++k) {
    const std::string file = index[k].substr(index[k].rfind(',') + 1);
    fields.insert(index[k]
                      .substr(0, index[k].rfind(','))
                      .substr(index[k].substr(0, index[k].rfind(',')).rfind(',') + 1));
    std::ifstream in(dir / "frames" / file, std::ios::binary);
    ASSERT_TRUE(in) << file;
    EXPECT_TRUE(is_png(std::vector<unsigned char>(std::istreambuf_iterator<char>(in), {})));
  }
  EXPECT_EQ(fields, (std::set<std::string>{"combined", "omega2", "tau_sfs"}));
  // Saved frames are never dropped: every analysis time t = 0, 0.05, 0.1, each field.
  EXPECT_EQ(index.size(), 1u + 3u * 3u);
  for (const char* time : {"0.0000", "0.0500", "0.1000"})
    for (const char* field : {"combined", "omega2", "tau_sfs"})
      EXPECT_TRUE(
          std::filesystem::exists(dir / "frames" / (std::string(field) + "_t" + time + ".png")))
          << field << " at " << time;
  std::lock_guard lock(recorder->mutex);
  ASSERT_FALSE(recorder->images.empty());
  EXPECT_TRUE(is_png(*recorder->images.back().png));
  const auto latest = run.latest_image("combined");
  ASSERT_TRUE(latest.has_value());
  EXPECT_NEAR(latest->time, 0.1, 1e-12);
}

TEST(RunControl, RendersThe3dViewAtItsOwnCadence) {
  json scene = tiny_scene(0.1, true);
  scene["analysis"]["products"] = {"vorticity", "slices", "particles"};
  scene["analysis"]["particle_fields"] = {"omega2"};
  scene["render"]["view3d"] = {{"enabled", true}, {"every", 0.1}, {"width", 320}, {"height", 320}};
  const auto dir = fresh_directory("view3d");
  control::Run run("r", parse_run_spec(scene), dir);
  ASSERT_EQ(run.run_here(), RunState::Finished) << run.status().reason;
  const auto latest = run.latest_image("view3d");
  ASSERT_TRUE(latest.has_value());
  EXPECT_TRUE(is_png(*latest->png));
  EXPECT_TRUE(std::filesystem::exists(dir / "frames" / latest->file));
  int views = 0;
  for (const std::string& row : lines_of(dir / "frames" / "index.csv"))
    views += row.find(",view3d,") != std::string::npos;
  EXPECT_GE(views, 1);
  EXPECT_LE(views, 2);  // t = 0 and t = 0.1 at most, never the frame at 0.05
}

TEST(RunControl, UnsavedImagesAreRenderedOnlyForViewersThatWantThem) {
  json scene = tiny_scene(0.1, true);
  scene["render"]["save"] = false;
  {
    const auto dir = fresh_directory("nobody");
    control::Run run("r", parse_run_spec(scene), dir);
    ASSERT_EQ(run.run_here(), RunState::Finished);
    EXPECT_EQ(run.status().frames_rendered, 0u);
    EXPECT_GT(run.status().frames_skipped, 0u);
    EXPECT_FALSE(std::filesystem::exists(dir / "frames" / "index.csv"));
  }
  {
    const auto dir = fresh_directory("viewer");
    control::Run run("r", parse_run_spec(scene), dir);
    auto viewer = std::make_shared<Recorder>(/*want_images=*/true);
    run.add_observer(viewer);
    ASSERT_EQ(run.run_here(), RunState::Finished);
    EXPECT_GT(run.status().frames_rendered, 0u);
    EXPECT_FALSE(std::filesystem::exists(dir / "frames" / "index.csv"));
    std::lock_guard lock(viewer->mutex);
    ASSERT_FALSE(viewer->images.empty());
    EXPECT_TRUE(viewer->images.front().file.empty());
  }
}

TEST(RenderConfig, RejectsFieldsTheAnalysisDoesNotCompute) {
  json scene = tiny_scene(0.1, true);
  scene["analysis"]["slice"]["fields"] = {"omega2"};
  try {
    parse_run_spec(scene);
    ADD_FAILURE() << "accepted";
  } catch (const sim::SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("'render.fields[1]'"), std::string::npos) << e.what();
  }
  scene = tiny_scene(0.1, true);
  scene["render"]["colour"] = {{"omega2", {{"scale", "log"}, {"min", -1.0}}}};
  EXPECT_THROW(parse_run_spec(scene), sim::SceneError);
  scene["render"]["colour"] = {{"omega2", {{"scale", "linear"}, {"min", 2.0}, {"max", 1.0}}}};
  EXPECT_THROW(parse_run_spec(scene), sim::SceneError);
  scene["render"]["colour"] = {{"vorticity", json::object()}};
  EXPECT_THROW(parse_run_spec(scene), sim::SceneError);
  scene["render"] = {{"view3d", {{"enabled", true}}}};
  EXPECT_THROW(parse_run_spec(scene), sim::SceneError);  // needs the particles product
  // Round trip.
  scene = tiny_scene(0.1, true);
  scene["render"]["colour"] = {{"tau_sfs", {{"scale", "linear"}, {"min", 0.0}, {"max", 2.0}}}};
  const RunSpec spec = parse_run_spec(scene);
  EXPECT_EQ(run_spec_to_json(parse_run_spec(run_spec_to_json(spec))), run_spec_to_json(spec));
}

TEST(RunManager, QueuesBeyondTheSlotLimitAndRecoversRunsAfterARestart) {
  const auto data = fresh_directory("manager");
  std::string first_id, second_id, long_id;
  {
    RunManager manager(manager_options(data, 1));
    CreateRequest request;
    request.scene = tiny_scene(0.1);
    first_id = manager.create(request)->id();
    second_id = manager.create(request)->id();
    EXPECT_NE(first_id, second_id);
    const auto second = manager.get(second_id);
    EXPECT_TRUE(second->status().state == RunState::Queued || is_terminal(second->status().state));
    ASSERT_TRUE(eventually([&] { return second->status().state == RunState::Finished; }));
    EXPECT_EQ(manager.get(first_id)->status().state, RunState::Finished);
    EXPECT_THROW(manager.get("nope"), UnknownRunError);

    CreateRequest long_request;
    long_request.scene = tiny_scene(50.0);
    long_request.name = "long one";  // a name the run's directory would rewrite: refused
    EXPECT_THROW(manager.create(long_request), sim::SceneError);
    long_request.name = "long-one";
    const auto long_run = manager.create(long_request);
    long_id = long_run->id();
    EXPECT_EQ(long_id.substr(4), "-long-one");
    ASSERT_TRUE(eventually([&] { return long_run->status().step > 5; }));
    manager.shutdown();  // checkpoints and stops it
    EXPECT_EQ(long_run->status().state, RunState::Stopped);
  }
  {
    RunManager again(manager_options(data, 1));
    ASSERT_EQ(again.list().size(), 3u);
    const auto long_run = again.get(long_id);
    EXPECT_EQ(long_run->status().state, RunState::Stopped);
    const double stopped_at = long_run->status().time;
    EXPECT_GT(stopped_at, 0.0);
    again.resume(long_id);
    ASSERT_TRUE(eventually([&] { return long_run->status().time > stopped_at; }));
    again.stop(long_id);
    // A new run gets a number after the recovered ones.
    CreateRequest request;
    request.preset = "kolmogorov2d";
    request.start = false;
    EXPECT_EQ(again.create(request)->id().substr(0, 4), "0004");

    // Deleting: the run object refuses every transition afterwards, the directory is gone, and a
    // restart neither lists it nor keeps a half-deleted leftover in trash/.
    const fs::path long_directory = long_run->directory();
    again.remove(long_id);
    EXPECT_FALSE(fs::exists(long_directory));
    EXPECT_THROW(again.get(long_id), UnknownRunError);
    EXPECT_THROW(long_run->start(), StateError);
    EXPECT_THROW(long_run->apply_changes({{"time", {{"end", 9.0}}}}), StateError);
  }  // the second server ends before the third starts: one server per data directory
  fs::create_directories(data / "trash" / "0009-interrupted");
  RunManager third(manager_options(data, 1));
  EXPECT_EQ(third.list().size(), 3u);  // 2 recovered + the kolmogorov run, not the deleted one
  EXPECT_FALSE(fs::exists(data / "trash" / "0009-interrupted"));
  EXPECT_THROW(third.get(long_id), UnknownRunError);
}

TEST(RunManager, CreateRequestsAreValidatedBeforeAnythingIsCreated) {
  const auto data = fresh_directory("requests");
  RunManager manager(manager_options(data, 1));
  const auto message = [&](const json& body) -> std::string {
    try {
      manager.create(parse_create_request(body));
    } catch (const sim::SceneError& e) {
      return e.what();
    }
    return "accepted";
  };
  EXPECT_NE(message({{"preset", "nope"}}).find("'preset'"), std::string::npos);
  EXPECT_NE(message({{"preset", 3}}).find("'preset'"), std::string::npos);
  EXPECT_NE(message({{"scene", tiny_scene(1.0)}, {"colour", 1}}).find("'colour'"),
            std::string::npos);
  EXPECT_NE(message(json::object()).find("exactly one"), std::string::npos);
  json bad = tiny_scene(1.0);
  bad["fluid"]["sound_speed"] = -1.0;
  EXPECT_NE(message({{"scene", bad}}).find("'fluid.sound_speed'"), std::string::npos);
  EXPECT_NE(message({{"scene", tiny_scene(1.0)}, {"patch", {{"kernel", {{"type", "box"}}}}}})
                .find("'kernel.type'"),
            std::string::npos);
  EXPECT_TRUE(manager.list().empty());
  EXPECT_FALSE(RunManager::presets().empty());
}

// The spectral references a service computes (ReferenceJobs): one worker, jobs in order, stop
// with a checkpoint and resume from it, admission by memory, requests refused naming the key.
TEST(ReferenceJobs, OfferTheActionsTheirStateAccepts) {
  using Verbs = std::vector<std::string_view>;
  EXPECT_EQ(control::job_actions(control::JobState::Queued), (Verbs{"stop"}));
  EXPECT_EQ(control::job_actions(control::JobState::Running), (Verbs{"stop"}));
  EXPECT_EQ(control::job_actions(control::JobState::Stopped), (Verbs{"resume", "delete"}));
  EXPECT_EQ(control::job_actions(control::JobState::Failed), (Verbs{"resume", "delete"}));
  EXPECT_EQ(control::job_actions(control::JobState::Done), (Verbs{"delete"}));
}

TEST(ReferenceJobs, ComputesStopsResumesAndAdmitsJobs) {
  const auto data = fresh_directory("reference_jobs");
  ReferenceRequest grid;
  grid.points_per_side = 16;
  const ReferencePlan quick =
      ReferenceJobs::plan({{"preset", "tgv2d"},
                           {"time", {{"end", 0.5}}},
                           {"reference", {{"every", 0.25}}}},  // 3 frames to render
                          grid);
  // The Kolmogorov forcing's wavenumber 7 needs 22 points; forced, the flow keeps its speed:
  // millions of steps to t = 1e4.
  const json kolmogorov = {{"preset", "kolmogorov2d"}, {"time", {{"end", 1e4}}}};
  try {
    ReferenceJobs::plan(kolmogorov, grid);
    ADD_FAILURE() << "a grid without the forcing's wavenumber is accepted";
  } catch (const sim::SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("at least 22"), std::string::npos) << e.what();
  }
  grid.points_per_side = 22;
  const ReferencePlan slow = ReferenceJobs::plan(kolmogorov, grid);
  grid.points_per_side = 16;
  {
    ReferenceJobs jobs(data, 1e12);
    const std::string first = jobs.submit("0001-a", slow).id;
    const std::string second = jobs.submit("0002-b", quick).id;
    EXPECT_EQ(first.substr(0, 5), "0001-");
    ASSERT_TRUE(eventually([&] { return jobs.get(first).step > 0; }));
    EXPECT_EQ(jobs.get(second).state, JobState::Queued);  // one job at a time
    EXPECT_THROW(jobs.remove(first), StateError);
    jobs.stop(first);  // returns once the checkpoint is written
    EXPECT_EQ(jobs.get(first).state, JobState::Stopped);
    EXPECT_FALSE(fs::is_empty(data / "references" / first / "checkpoints"));
    ASSERT_TRUE(eventually([&] { return jobs.get(second).state == JobState::Done; }));
    EXPECT_EQ(jobs.done_directories(), std::vector<fs::path>{data / "references" / second});
    const double stopped_at = jobs.get(first).time;
    jobs.resume(first);
    ASSERT_TRUE(eventually([&] { return jobs.get(first).time > stopped_at; }));
    EXPECT_THROW(jobs.resume(first), StateError);
    EXPECT_THROW(jobs.get("nope"), UnknownRunError);
  }  // shutdown: the running job stops with a checkpoint
  ReferenceJobs again(data, 1e6);
  ASSERT_EQ(again.list().size(), 2u);
  EXPECT_EQ(again.list()[0].state, JobState::Stopped);
  EXPECT_EQ(again.list()[1].state, JobState::Done);
  try {
    again.submit("0001-a", quick);
    ADD_FAILURE() << "a reference beyond the memory limit is admitted";
  } catch (const AdmissionError& e) {
    EXPECT_EQ(e.field(), "points_per_side");
  }
  again.remove(again.list()[1].id);
  EXPECT_EQ(again.list().size(), 1u);

  const auto refusal = [](const json& body) -> std::string {
    try {
      parse_reference_request(body);
    } catch (const sim::SceneError& e) {
      return e.what();
    }
    return "accepted";
  };
  EXPECT_EQ(refusal({{"run", "0001-a"}, {"points_per_side", 64}, {"dry_run", true}}), "accepted");
  EXPECT_NE(refusal({{"run", "0001-a"}, {"points_per_side", 33}}).find("'points_per_side'"),
            std::string::npos);
  EXPECT_NE(refusal({{"run", "0001-a"}, {"cfl", 0}}).find("in (0, 1.5]"), std::string::npos);
  EXPECT_NE(refusal({{"points_per_side", 64}}).find("'run'"), std::string::npos);
  EXPECT_NE(refusal({{"run", "0001-a"}, {"every", 1}}).find("'every'"), std::string::npos);
}

}  // namespace
}  // namespace sphles::control
