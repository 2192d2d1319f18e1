// SPDX-License-Identifier: GPL-3.0-or-later
// Scene keys whose extremes only cost memory or time are bounded (docs/scenes.md, "Limits"):
// extreme requests (tiny kernels, huge histograms, cadences far below a time step, ...) are
// refused naming the field and the range, the bounds themselves are accepted, and every preset
// and shipped scene still parses.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>

#include "analysis/config.hpp"
#include "control/run.hpp"
#include "control/run_manager.hpp"
#include "render/config.hpp"
#include "scene/document.hpp"
#include "scene/presets.hpp"
#include "sim/scene.hpp"

namespace sphles::control {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

std::string error_of(const json& document) {
  try {
    parse_run_spec(document);
  } catch (const sim::SceneError& e) {
    return e.what();
  }
  return "";
}

json analysed(json document, const json& analysis) {
  document["analysis"] = analysis;
  return document;
}

const json kProducts = {"spectrum", "slices", "sfs_stats"};

struct Refused {
  std::string label;
  json document;
  std::string expected;
};

// Extreme requests, each of which used to be accepted (and failed later, stalled, or filled the
// disk).
TEST(SceneLimits, ExtremeRequestsAreRefusedNamingTheField) {
  const json tgv3d = {{"preset", "tgv3d"}};
  const std::vector<Refused> cases{
      {"tiny kernel",
       {{"preset", "tgv3d"}, {"kernel", {{"diameter_over_spacing", 0.02}}}},
       "'kernel.diameter_over_spacing' must be in [3, 16], got 0.02"},
      {"10^4 histogram bins",
       analysed(tgv3d, {{"every", 0.5}, {"products", kProducts}, {"histogram_bins", 10000}}),
       "'analysis.histogram_bins' must be in [1, 256], got 10000"},
      {"10^4 angle bins",
       analysed(tgv3d, {{"every", 0.5}, {"products", kProducts}, {"angle_bins", 10000}}),
       "'analysis.angle_bins' must be in [1, 360], got 10000"},
      {"analysis every 1e-9", analysed(tgv3d, {{"every", 1e-9}, {"products", kProducts}}),
       "'analysis.every' = 1e-09 s is below the smallest accepted cadence"},
      {"1000 checkpoints kept",
       {{"preset", "tgv3d"}, {"checkpoint", {{"every", 1}, {"keep", 1000}}}},
       "'checkpoint.keep' must be in [1, 100], got 1000"},
      {"checkpoint every 1e-9",
       {{"preset", "tgv3d"}, {"checkpoint", {{"every", 1e-9}}}},
       "'checkpoint.every' = 1e-09 s is below the smallest accepted cadence"},
      {"time series every 1e-9",
       {{"preset", "tgv3d"}, {"output", {{"timeseries_every", 1e-9}}}},
       "'output.timeseries_every' = 1e-09 s is below the smallest accepted cadence"},
      {"nanometre Kolmogorov box",
       {{"preset", "kolmogorov2d"}, {"box_length", 1e-9}, {"particles_per_side", 32}},
       "'box_length', 'particles_per_side', 'fluid.dynamic_viscosity', "
       "'fluid.reference_density' and 'time.cfl_viscous' give an estimated initial time step of "
       "7.62939e-17 s (viscous limit"},
      {"8192 px frames",
       {{"preset", "tgv3d"}, {"render", {{"width", 8192}}}},
       "'render.width' must be in [64, 4096], got 8192"},
      {"8192 px 3D view",
       {{"preset", "tgv3d"}, {"render", {{"view3d", {{"height", 8192}}}}}},
       "'render.view3d.height' must be in [64, 4096], got 8192"},
      {"iso-surface of a field the analysis does not grid",
       {{"preset", "tgv3d"}, {"render", {{"view3d", {{"enabled", true}, {"kind", "isosurface"}}}}}},
       "'render.view3d' draws the iso-surface of omega2 on the analysis grid, which the analysis "
       "does not compute: add \"fields\" to 'analysis.products' and omega2 to "
       "'analysis.grid_fields'"},
      {"iso-surface of a 2D case",
       {{"preset", "tgv2d"},
        {"analysis", {{"every", 0.5}, {"products", {"fields"}}, {"grid_fields", {"omega2"}}}},
        {"render", {{"view3d", {{"enabled", true}, {"kind", "isosurface"}}}}}},
       "'render.view3d.kind' is isosurface, which needs a 3D case"},
      {"iso-surface quantile 1",
       {{"preset", "tgv3d"}, {"render", {{"view3d", {{"quantile", 1.0}}}}}},
       "'render.view3d.quantile' must be in [0.01, 0.9999], got 1"},
  };
  for (const Refused& c : cases) {
    const std::string error = error_of(c.document);
    EXPECT_NE(error.find(c.expected), std::string::npos)
        << c.label << ": " << (error.empty() ? "accepted" : error);
  }
}

// A live change goes through the same validation: a running run cannot be switched to a cadence
// that stalls it.
TEST(SceneLimits, LiveChangeToAStallingCadenceIsRefused) {
  const fs::path dir =
      fs::temp_directory_path() / ("sphles_scene_limits_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  control::Run run("limits",
                   parse_run_spec(analysed({{"preset", "tgv2d"}, {"particles_per_side", 16}},
                                           {{"every", 0.1}, {"products", kProducts}})),
                   dir);
  try {
    run.apply_changes({{"analysis", {{"every", 1e-9}}}});
    ADD_FAILURE() << "a cadence of 1e-9 s was accepted";
  } catch (const ChangeError& e) {
    EXPECT_EQ(e.field(), "analysis.every");
    EXPECT_NE(std::string(e.what()).find("estimated initial time step"), std::string::npos)
        << e.what();
  }
  EXPECT_DOUBLE_EQ(run.document()["analysis"]["every"].get<double>(), 0.1);  // unchanged
  fs::remove_all(dir);
}

// The real program exits 2 with the reason and writes nothing (it used to start the run and
// report an ETA of 2.5e11 hours; the wait below is the hang detector).
TEST(SceneLimits, ProgramRefusesAStalledRunAndWritesNothing) {
  const fs::path dir =
      fs::temp_directory_path() / ("sphles_scene_limits_out_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path out = dir / "run", log = dir / "log.txt";
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execl(SPHLES_BINARY, SPHLES_BINARY, "run", "kolmogorov2d", "--set", "box_length=1e-9",
            "--set", "particles_per_side=32", "--out", out.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      ADD_FAILURE() << "sphles run still running after 60 s";
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::ifstream in(log);
  const std::string output((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << output;
  EXPECT_NE(output.find("'box_length'"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(dir);
}

/// The value at the bound is accepted, the next representable one beyond it is refused with a
/// message naming the field.
void expect_bound(const json& base, const std::string& key, const json& at, const json& beyond,
                  const std::string& field) {
  json accepted = base, refused = base;
  scene::apply_override(accepted, key + "=" + at.dump());
  scene::apply_override(refused, key + "=" + beyond.dump());
  EXPECT_EQ(error_of(accepted), "") << key << " = " << at.dump();
  const std::string error = error_of(refused);
  EXPECT_NE(error.find("'" + field + "'"), std::string::npos)
      << key << " = " << beyond.dump() << ": " << (error.empty() ? "accepted" : error);
}

TEST(SceneLimits, BoundsAreAcceptedAndTheNextValueBeyondIsRefused) {
  const json tgv3d = {{"preset", "tgv3d"}};
  // The limits of docs/scenes.md ("Limits"), declared by sim/scene.schema.json.
  const double min_d = 3.0, max_d = 16.0;
  const int max_keep = 100, max_bins = 256, max_angle_bins = 360, max_side = 4096;
  expect_bound(tgv3d, "kernel.diameter_over_spacing", min_d, std::nextafter(min_d, 0.0),
               "kernel.diameter_over_spacing");
  expect_bound(tgv3d, "kernel.diameter_over_spacing", max_d, std::nextafter(max_d, 100.0),
               "kernel.diameter_over_spacing");
  expect_bound(tgv3d, "checkpoint.keep", max_keep, max_keep + 1, "checkpoint.keep");
  const json analysis = analysed(tgv3d, {{"every", 0.5}, {"products", kProducts}});
  expect_bound(analysis, "analysis.histogram_bins", max_bins, max_bins + 1,
               "analysis.histogram_bins");
  expect_bound(analysis, "analysis.angle_bins", max_angle_bins, max_angle_bins + 1,
               "analysis.angle_bins");
  for (const std::string key :
       {"render.width", "render.height", "render.view3d.width", "render.view3d.height"})
    expect_bound(tgv3d, key, max_side, max_side + 1, key);
  expect_bound(tgv3d, "render.view3d.max_points", 1000, 999, "render.view3d.max_points");
}

TEST(SceneLimits, CadenceBoundFollowsTheTimeStepAndThePointsToTheEnd) {
  // 16² Taylor-Green on a lattice: estimated initial step 0.01428 s (acoustic), as the solver.
  const json base = {{"preset", "tgv2d"},
                     {"particles_per_side", 16},
                     {"kernel", {{"diameter_over_spacing", 6}}},
                     {"packing", {{"enabled", false}}},
                     {"time", {{"end", 100.0}}}};
  const sim::Scene scene = scene::parse_scene(base);
  const double dt = sim::estimate_initial_time_step(scene).step();
  EXPECT_NEAR(dt, 0.01428, 1e-5);
  // Long run: the time-step side binds (half a step).
  const double minimum = sim::min_cadence(scene);
  EXPECT_DOUBLE_EQ(minimum, sim::kMinCadenceOverTimeStep * dt);
  for (const std::string key : {"output.timeseries_every", "checkpoint.every"}) {
    expect_bound(base, key, minimum, std::nextafter(minimum, 0.0), key);
    json off = base;
    scene::apply_override(off, key + "=0");
    EXPECT_EQ(error_of(off), "") << key << " = 0 (every step, or off)";
  }
  const json with_products = analysed(base, {{"every", 1.0}, {"products", kProducts}});
  expect_bound(with_products, "analysis.every", minimum, std::nextafter(minimum, 0.0),
               "analysis.every");
  // Without products there are no snapshots, and no step is cut short (the preset's products
  // are the base of the scene's analysis section: emptied here).
  EXPECT_EQ(error_of(analysed(base, {{"every", 1e-9}, {"products", json::array()}})), "");

  // Short run: at most kMaxShortCadencePoints cut steps are accepted (the run manager's live
  // analysis default is 60 frames per run, whatever its length).
  json short_run = base;
  short_run["time"]["end"] = 0.1;
  const double short_minimum = sim::min_cadence(scene::parse_scene(short_run));
  EXPECT_DOUBLE_EQ(short_minimum, 0.1 / sim::kMaxShortCadencePoints);
  expect_bound(short_run, "output.timeseries_every", short_minimum,
               std::nextafter(short_minimum, 0.0), "output.timeseries_every");
  EXPECT_EQ(error_of(with_live_defaults(short_run)), "");
}

TEST(SceneLimits, TimeStepBelowTheResolutionOfTheEndTimeIsRefused) {
  // The fixed step is the estimate: 2^-40 of time.end is the smallest accepted.
  const json base = {{"preset", "tgv2d"}, {"time", {{"end", 1.0}}}};
  const double smallest = sim::kMinTimeStepOverEndTime * 1.0;
  expect_bound(base, "time.fixed_step", smallest, std::nextafter(smallest, 0.0), "time.fixed_step");
  // A long end time with the preset's step: refused, naming the spacing and sound speed keys.
  const std::string error = error_of({{"preset", "tgv2d"}, {"time", {{"end", 1e12}}}});
  EXPECT_NE(error.find("'particles_per_side', 'fluid.sound_speed'"), std::string::npos) << error;
  EXPECT_NE(error.find("'time.end'"), std::string::npos) << error;
}

TEST(SceneLimits, EveryPresetAndShippedSceneParses) {
  for (const std::string& name : scene::preset_names()) {
    EXPECT_EQ(error_of({{"preset", name}}), "") << name;
    EXPECT_EQ(error_of(with_live_defaults({{"preset", name}})), "") << name << " (live defaults)";
  }
  for (const auto& entry : fs::directory_iterator(fs::path(SPHLES_SOURCE_DIR) / "scenes")) {
    const json document = scene::read_scene_file(entry.path());
    EXPECT_EQ(error_of(document), "") << entry.path().filename();
  }
}

// scenes/tgv2d-peers.json and scenes/tgv3d-tvf.json run the TVF at a larger step than the
// default with p_b lowered so that p_b Δt, which sets the background pressure's regularisation
// per unit time, stays that of the configuration each was calibrated from: p_b = ρ c_s² at the
// default acoustic step (docs/accuracy.md, docs/models.md). Editing one without the other breaks
// that calibration.
TEST(SceneLimits, TvfScenesKeepTheCalibratedBackgroundPressureTimesStep) {
  for (const char* name : {"tgv2d-peers.json", "tgv3d-tvf.json"}) {
    SCOPED_TRACE(name);
    const json document = scene::read_scene_file(fs::path(SPHLES_SOURCE_DIR) / "scenes" / name);
    const sim::Scene scene = parse_run_spec(document).scene;
    ASSERT_EQ(scene.scheme.type, sim::SchemeType::TransportVelocity);
    const sim::FluidParameters& fluid = scene.fluid;
    const double calibrated = fluid.reference_density * fluid.sound_speed * fluid.sound_speed *
                              sim::TimeStepConfig{}.cfl_acoustic;
    EXPECT_NEAR(fluid.reference_pressure * scene.time_step.cfl_acoustic, calibrated,
                1e-12 * calibrated);
    // The acoustic step binds before the viscous one, or p_b Δt falls below the calibration.
    const double spacing = scene.particle_spacing();
    EXPECT_LT(scene.time_step.cfl_acoustic * spacing / fluid.sound_speed,
              scene.time_step.cfl_viscous * spacing * spacing / fluid.kinematic_viscosity());
  }
}

}  // namespace
}  // namespace sphles::control
