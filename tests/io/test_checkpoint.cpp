// SPDX-License-Identifier: GPL-3.0-or-later
// HDF5 checkpoints: exact round trip, bitwise restart, rejection of damaged and implausible
// files, failed writes (file-size limit, unwritable directory, HDF5 errors) that leave nothing
// open and nothing half-written, and crash safety of the atomic write under SIGKILL of a real
// sphles process; `sphles run`, `serve` and `inspect` are run as real processes.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <random>
#include <thread>

#include "io/checkpoint.hpp"
#include "io/checkpoint_collective.hpp"
#include "io/particle_snapshot.hpp"
#include "scene/document.hpp"
#include "server_test_support.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace sphles::io {
namespace {

class CheckpointTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("sphles_ckpt_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

void expect_identical(const sim::ParticleArrays& a, const sim::ParticleArrays& b) {
  ASSERT_EQ(a.dimension, b.dimension);
  for (int d = 0; d < a.dimension; ++d) {
    EXPECT_TRUE(same_bits(a.position[d], b.position[d])) << "position " << d;
    EXPECT_TRUE(same_bits(a.velocity[d], b.velocity[d])) << "velocity " << d;
    EXPECT_TRUE(same_bits(a.acceleration[d], b.acceleration[d])) << "acceleration " << d;
  }
  EXPECT_TRUE(same_bits(a.mass, b.mass));
  EXPECT_TRUE(same_bits(a.volume, b.volume));
  EXPECT_TRUE(same_bits(a.density, b.density));
  EXPECT_TRUE(same_bits(a.pressure, b.pressure));
  EXPECT_TRUE(same_bits(a.eddy_viscosity, b.eddy_viscosity));
  EXPECT_EQ(a.id, b.id);
}

std::unique_ptr<sim::Simulation> random_simulation(
    int dim, sim::SubfilterModel model, sim::SchemeType scheme = sim::SchemeType::Thesis) {
  auto flow = sim::testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, 21);
  flow.config.subfilter.model = model;
  flow.config.scheme.type = scheme;
  return sim::make_simulation(flow.config, flow.particles);
}

TEST_F(CheckpointTest, RoundTripIsBitForBit) {
  for (const int dim : {2, 3})
    for (const int gzip : {0, 6}) {
      auto sim = random_simulation(dim, sim::SubfilterModel::Smagorinsky);
      for (int k = 0; k < 7; ++k) sim->step();
      const sim::SolverState state = sim->state();
      const CheckpointMetadata meta{R"({"case":"test"})", "9.9.9", "lattice"};
      const auto file = dir_ / ("rt_" + std::to_string(dim) + "_" + std::to_string(gzip) + ".h5");
      write_checkpoint(file, state, meta, {.gzip_level = gzip});
      const Checkpoint back = read_checkpoint(file);
      expect_identical(state.particles, back.state.particles);
      for (int d = 0; d < dim; ++d)
        EXPECT_TRUE(
            same_bits(state.list_reference_positions[d], back.state.list_reference_positions[d]));
      EXPECT_EQ(std::memcmp(&state.time, &back.state.time, sizeof(double)), 0);
      EXPECT_EQ(back.state.step, 7u);
      EXPECT_EQ(back.state.neighbour_builds, state.neighbour_builds);
      EXPECT_EQ(back.metadata.scene_json, meta.scene_json);
      EXPECT_EQ(back.metadata.code_version, "9.9.9");
      EXPECT_EQ(back.metadata.packing, "lattice");
      // Nothing but the file itself is left in the directory.
      for (const auto& entry : std::filesystem::directory_iterator(dir_))
        EXPECT_EQ(entry.path().extension(), ".h5") << entry.path();
    }
}

// The room a checkpoint written by the ranks reserves before HDF5 writes to disk
// (checkpoint_size_bound, io/checkpoint_collective.hpp) holds the file: HDF5 1.10 does not survive
// a failed write, so a bound below the real size would let a full disk crash the run. Checked on
// the files one process writes, which the ranks' file equals: 2D and 3D, with and without ν_t,
// gzip 0 and 9 on random (incompressible) values, from a few particles to several chunks, with a
// long scene attribute; and the reader's header (no particles) agrees with the file.
TEST_F(CheckpointTest, TheRoomReservedForACheckpointHoldsIt) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.01, 1.0);
  for (const int dim : {2, 3})
    for (const bool eddy : {false, true})
      for (const std::size_t n : {std::size_t{3}, std::size_t{70000}, std::size_t{140001}})
        for (const int gzip : {0, 9}) {
          sim::SolverState state;
          state.particles.dimension = dim;
          state.particles.resize(n);
          sim::ParticleArrays& p = state.particles;
          for (std::vector<double>* f : p.double_fields())
            for (double& v : *f) v = u(rng);
          if (eddy) p.eddy_viscosity.assign(n, 0.0);
          for (double& v : p.eddy_viscosity) v = u(rng);
          for (int d = 0; d < dim; ++d) state.list_reference_positions[d] = p.position[d];
          state.time = 1.0;
          state.step = 3;
          state.neighbour_builds = 2;
          const CheckpointMetadata meta{"{\"text\": \"" + std::string(20000, 'x') + "\"}", "9.9.9",
                                        "lattice"};
          const auto file = dir_ / "bound.h5";
          write_checkpoint(file, state, meta, {.gzip_level = gzip});
          const std::uint64_t bound = checkpoint_size_bound(
              dim, n, eddy,
              meta.scene_json.size() + meta.code_version.size() + meta.packing.size());
          EXPECT_LE(std::filesystem::file_size(file), bound)
              << dim << "D, " << n << " particles, ν_t " << eddy << ", gzip " << gzip;
          const CheckpointHeader header = read_checkpoint_header(file);
          EXPECT_EQ(header.shape.particles, n);
          EXPECT_EQ(header.shape.dimension, dim);
          EXPECT_EQ(header.shape.eddy_viscosity, eddy);
          EXPECT_EQ(header.step, 3u);
          EXPECT_EQ(header.metadata.scene_json, meta.scene_json);
        }
  // Equal blocks: in rank order, covering [0, N) once, lengths differing by at most one; the
  // rank of an id is the one whose block holds it.
  for (const std::uint64_t total : {0ull, 1ull, 7ull, 1000003ull})
    for (const int ranks : {1, 2, 3, 8}) {
      std::uint64_t next = 0;
      for (int r = 0; r < ranks; ++r) {
        const Block b = equal_block(total, r, ranks);
        EXPECT_EQ(b.first, next);
        EXPECT_LE(b.count, total / static_cast<std::uint64_t>(ranks) + 1);
        EXPECT_GE(b.count, total / static_cast<std::uint64_t>(ranks));
        for (const std::uint64_t id : {b.first, b.first + b.count / 2, b.first + b.count - 1})
          if (b.count > 0) {
            EXPECT_EQ(equal_block_rank(id, total, ranks), r) << id << " of " << total;
          }
        next += b.count;
      }
      EXPECT_EQ(next, total);
    }
}

// Restarting after k steps continues bitwise identically to the uninterrupted run, with an
// explicit model (so ν_t and the gradient pass are part of the state's history) and with list
// rebuilds on both sides of the checkpoint; for both schemes (the TVF's background
// acceleration is not in the file: the restore recomputes it from the positions).
TEST_F(CheckpointTest, RestartEqualsUninterruptedRunBitwise) {
  for (const auto scheme : {sim::SchemeType::Thesis, sim::SchemeType::TransportVelocity})
    for (const int dim : {2, 3}) {
      SCOPED_TRACE(std::string(sim::scheme_name(scheme)) + " " + std::to_string(dim) + "D");
      auto uninterrupted = random_simulation(dim, sim::SubfilterModel::Smagorinsky, scheme);
      auto first_leg = random_simulation(dim, sim::SubfilterModel::Smagorinsky, scheme);
      for (int k = 0; k < 23; ++k) first_leg->step();
      const auto file = dir_ / ("restart_" + std::string(sim::scheme_name(scheme)) + "_" +
                                std::to_string(dim) + ".h5");
      write_checkpoint(file, first_leg->state(), {"{}", "test", "lattice"});
      Checkpoint c = read_checkpoint(file);
      auto second_leg = sim::restore_simulation(first_leg->config(), std::move(c.state));
      for (int k = 0; k < 23 + 40; ++k) uninterrupted->step();
      for (int k = 0; k < 40; ++k) second_leg->step();
      EXPECT_EQ(second_leg->step_count(), uninterrupted->step_count());
      EXPECT_EQ(second_leg->time(), uninterrupted->time());
      EXPECT_GT(uninterrupted->diagnostics().neighbour_builds, 2u);
      EXPECT_EQ(second_leg->diagnostics().neighbour_builds,
                uninterrupted->diagnostics().neighbour_builds);
      expect_identical(second_leg->particles(), uninterrupted->particles());
    }
}

// --- damaged and mismatched files ----------------------------------------------------------

std::string error_reading(const std::filesystem::path& file) {
  try {
    read_checkpoint(file);
  } catch (const CheckpointError& e) {
    return e.what();
  }
  return "";
}

template <class T>
void overwrite_attribute(const std::filesystem::path& file, const char* name, hid_t type, T value) {
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(h5, 0);
  const hid_t attribute = H5Aopen(h5, name, H5P_DEFAULT);
  ASSERT_GE(attribute, 0);
  ASSERT_GE(H5Awrite(attribute, type, &value), 0);
  H5Aclose(attribute);
  H5Fclose(h5);
}

TEST_F(CheckpointTest, DamagedFilesAreRejectedWithTheirReason) {
  auto sim = random_simulation(3, sim::SubfilterModel::Implicit);
  sim->step();
  const auto good = dir_ / "good.h5";
  write_checkpoint(good, sim->state(), {"{}", "test", "lattice"});
  const auto copy = [&](const std::string& name) {
    const auto f = dir_ / name;
    std::filesystem::copy_file(good, f);
    return f;
  };

  EXPECT_NE(error_reading(dir_ / "missing.h5").find("file does not exist"), std::string::npos);

  const auto truncated = copy("truncated.h5");
  std::filesystem::resize_file(truncated, std::filesystem::file_size(good) / 2);
  EXPECT_NE(error_reading(truncated).find("truncated or corrupted"), std::string::npos)
      << error_reading(truncated);

  const auto empty = copy("empty.h5");
  std::filesystem::resize_file(empty, 0);
  EXPECT_NE(error_reading(empty).find("not a readable HDF5 file"), std::string::npos);

  // One flipped byte in the middle of the particle data: the Fletcher-32 checksum catches it.
  const auto flipped = copy("flipped.h5");
  {
    std::fstream f(flipped, std::ios::in | std::ios::out | std::ios::binary);
    const auto middle = static_cast<std::streamoff>(std::filesystem::file_size(flipped) / 2);
    f.seekg(middle);
    const char byte = static_cast<char>(f.get());
    f.seekp(middle);
    f.put(static_cast<char>(byte ^ 0x5a));
  }
  const std::string flipped_error = error_reading(flipped);
  EXPECT_FALSE(flipped_error.empty()) << "a flipped byte went unnoticed";

  const auto version = copy("version.h5");
  overwrite_attribute(version, "schema_version", H5T_NATIVE_INT, 99);
  EXPECT_NE(error_reading(version).find("schema version 99 is not supported"), std::string::npos);

  const auto dimension = copy("dimension.h5");
  overwrite_attribute(dimension, "dimension", H5T_NATIVE_INT, 4);
  EXPECT_NE(error_reading(dimension).find("dimension 4 (expected 2 or 3)"), std::string::npos);

  const auto count = copy("count.h5");
  overwrite_attribute(count, "num_particles", H5T_NATIVE_UINT64, std::uint64_t{1001});
  EXPECT_NE(error_reading(count).find("has 1000 entries, expected 1001 (particle count mismatch)"),
            std::string::npos)
      << error_reading(count);

  sim::SolverState bad = sim->state();
  bad.particles.velocity[1][17] = std::nan("");
  const auto nan_file = dir_ / "nan.h5";
  write_checkpoint(nan_file, bad, {"{}", "test", "lattice"});
  EXPECT_NE(error_reading(nan_file).find("non-finite value in 'particles/velocity_y' at index 17"),
            std::string::npos)
      << error_reading(nan_file);

  std::ofstream(dir_ / "text.h5") << "not hdf5 at all";
  EXPECT_NE(error_reading(dir_ / "text.h5").find("not a readable HDF5 file"), std::string::npos);

  // The good file is still good, and the newest valid one is found past damaged newer ones.
  EXPECT_EQ(error_reading(good), "");
  const auto run = dir_ / "run";
  std::filesystem::create_directories(run);
  std::filesystem::copy_file(good, run / checkpoint_file_name(5));
  std::filesystem::copy_file(truncated, run / checkpoint_file_name(9));
  std::filesystem::copy_file(version, run / checkpoint_file_name(12));
  std::vector<std::string> rejected;
  EXPECT_EQ(newest_valid_checkpoint(run, &rejected).filename(), checkpoint_file_name(5));
  EXPECT_EQ(rejected.size(), 2u);
  std::filesystem::remove(run / checkpoint_file_name(5));
  EXPECT_THROW(newest_valid_checkpoint(run), CheckpointError);
}

// --- real sphles processes -----------------------------------------------------------------

using namespace std::chrono_literals;
using nlohmann::json;

/// Writes beyond this file size fail in the fault tests: above scene.json, run.json, the first
/// rows of timeseries.csv and the captured output, below a 16² checkpoint (about 61 KiB).
constexpr rlim_t kFileSizeLimit = 16 * 1024;

/// How long a sphles process of these tests may take: a hang detector, not a timing assertion
/// (they take well under a second).
constexpr auto kProcessTimeout = 120s;

struct ProcessOptions {
  std::filesystem::path out = "/dev/null";  // stdout
  std::filesystem::path err = "/dev/null";  // stderr
  std::optional<rlim_t> file_size_limit;    // RLIMIT_FSIZE
};

/// Starts the sphles binary. Under a file-size limit SIGXFSZ is ignored, so a write beyond the
/// limit fails with EFBIG (as one on a full disk fails with ENOSPC) instead of killing sphles.
pid_t spawn_sphles(const std::vector<std::string>& arguments, const ProcessOptions& options = {}) {
  std::string binary = SPHLES_BINARY;
  std::vector<std::string> copies = arguments;
  std::vector<char*> argv{binary.data()};
  for (std::string& a : copies) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(::open(options.out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), 1);
    dup2(::open(options.err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), 2);
    if (options.file_size_limit) {
      signal(SIGXFSZ, SIG_IGN);
      const rlimit limit{*options.file_size_limit, *options.file_size_limit};
      setrlimit(RLIMIT_FSIZE, &limit);
    }
    execv(binary.c_str(), argv.data());
    _exit(127);
  }
  return pid;
}

struct ProcessEnd {
  bool exited = false;  // normally, with `code`
  int code = -1;
  int signal = 0;  // or by this signal
  std::string describe() const {
    return exited ? "exit code " + std::to_string(code)
                  : "signal " + std::to_string(signal) + " (" + strsignal(signal) + ")";
  }
};

/// Waits for `pid`, killing it after `timeout` (a hang: the test fails).
ProcessEnd wait_for(pid_t pid, std::chrono::milliseconds timeout = kProcessTimeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      ADD_FAILURE() << "process " << pid << " still running after " << timeout.count() << " ms";
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(10ms);
  }
  ProcessEnd end;
  end.exited = WIFEXITED(status);
  end.code = end.exited ? WEXITSTATUS(status) : -1;
  end.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return end;
}

/// Kills a process a failed assertion left running.
struct Reaper {
  pid_t pid = 0;
  ~Reaper() {
    if (pid > 0 && waitpid(pid, nullptr, WNOHANG) == 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
  }
};

std::string file_text(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

struct Finished {
  ProcessEnd end;
  std::string out, err;
};

/// Runs sphles to its end with stdout and stderr captured in files in `scratch`.
Finished run_sphles(const std::vector<std::string>& arguments, const std::filesystem::path& scratch,
                    std::optional<rlim_t> file_size_limit = {}) {
  static int counter = 0;
  const std::string stem = "process" + std::to_string(counter++);
  const ProcessOptions options{scratch / (stem + ".out"), scratch / (stem + ".err"),
                               file_size_limit};
  Finished f;
  f.end = wait_for(spawn_sphles(arguments, options));
  f.out = file_text(options.out);
  f.err = file_text(options.err);
  return f;
}

/// Names of temporary files (NAME.tmp.PID) in `directory`.
std::vector<std::string> temporaries(const std::filesystem::path& directory) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec))
    if (entry.path().filename().string().find(".tmp") != std::string::npos)
      names.push_back(entry.path().filename().string());
  return names;
}

/// A 2D Taylor-Green run of 16² particles, packing off (sphles_server_test::tiny_scene), with
/// checkpoints every 0.02 s when asked.
json tiny_run_scene(bool checkpoints = false) {
  json scene = sphles_server_test::tiny_scene(1.0);
  if (checkpoints) scene["checkpoint"] = {{"every", 0.02}};
  return scene;
}

struct TinyRun {
  sim::Scene scene;
  std::unique_ptr<sim::Simulation> simulation;
  /// The complete run configuration as a run stores it (scene with defaults, plus analysis).
  CheckpointMetadata metadata() const {
    json j = scene::scene_to_json(scene);
    j["analysis"] = json::object();
    return {j.dump(), "test", "lattice"};
  }
};

TinyRun tiny_run(int steps) {
  TinyRun run;
  run.scene = scene::parse_scene(tiny_run_scene());
  sim::RunSetup setup = sim::setup_run(run.scene);
  run.simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  for (int k = 0; k < steps; ++k) run.simulation->step();
  return run;
}

// --- crash safety with a real process --------------------------------------------------------

pid_t start_sphles(const std::vector<std::string>& arguments) {
  return spawn_sphles(arguments);
}

// A run that writes a checkpoint after every step is killed with SIGKILL at random moments,
// ten times, each time continuing from its checkpoints. After every kill each ckpt_*.h5 file
// validates (temporary files may remain, but never a file that looks valid and is not), and the
// restart picks the newest valid one.
TEST_F(CheckpointTest, SigkillDuringWritesNeverLeavesAnInvalidCheckpoint) {
  const auto scene = dir_ / "scene.json";
  std::ofstream(scene) << R"({"case": "tgv3d", "particles_per_side": 20,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 100.0},
      "packing": {"enabled": false},
      "checkpoint": {"every_seconds": 1e-6, "keep": 4, "compression": 9}})";
  const auto run = dir_ / "run";
  std::mt19937 rng(12345);
  std::uniform_int_distribution<int> delay_ms(150, 900);
  int kills = 0, rounds_with_leftover_temporaries = 0;
  std::uint64_t last_step = 0;
  for (int round = 0; round < 10; ++round) {
    const pid_t pid =
        round == 0 || io::list_checkpoints(run / "checkpoints").empty()
            ? start_sphles({"run", scene.string(), "--out", run.string(), "--threads", "1"})
            : start_sphles({"run", "--restart", run.string(), "--threads", "1"});
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms(rng)));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) ++kills;
    const auto files = io::list_checkpoints(run / "checkpoints");
    if (std::filesystem::exists(run / "checkpoints"))
      for (const auto& entry : std::filesystem::directory_iterator(run / "checkpoints"))
        if (entry.path().string().find(".tmp.") != std::string::npos) {
          ++rounds_with_leftover_temporaries;
          std::filesystem::remove(entry.path());
          break;
        }
    for (const auto& f : files) EXPECT_EQ(error_reading(f), "") << "round " << round;
    if (!files.empty()) {
      const auto newest = newest_valid_checkpoint(run / "checkpoints");
      EXPECT_EQ(newest, files.front());
      const std::uint64_t step = read_checkpoint(newest).state.step;
      EXPECT_GE(step, last_step) << "a restart went backwards";
      last_step = step;
    }
  }
  std::printf(
      "SIGKILL: %d kills, %d of them inside a checkpoint write (temporary left), newest "
      "valid step %llu\n",
      kills, rounds_with_leftover_temporaries, static_cast<unsigned long long>(last_step));
  EXPECT_GE(kills, 8);
  EXPECT_GT(last_step, 0u) << "no checkpoint was ever written";
}

// --- failed writes -----------------------------------------------------------------------------

/// HDF5 identifiers of every kind a writer creates (files, groups, datasets, attributes,
/// dataspaces, datatypes, property lists) and the objects H5Fget_obj_count sees open.
std::map<std::string, long long> hdf5_identifiers() {
  std::map<std::string, long long> counts;
  for (const auto& [name, type] :
       {std::pair{"files", H5I_FILE}, std::pair{"groups", H5I_GROUP},
        std::pair{"datasets", H5I_DATASET}, std::pair{"attributes", H5I_ATTR},
        std::pair{"dataspaces", H5I_DATASPACE}, std::pair{"datatypes", H5I_DATATYPE},
        std::pair{"property lists", H5I_GENPROP_LST}}) {
    hsize_t n = 0;
    H5Inmembers(type, &n);
    counts[name] = static_cast<long long>(n);
  }
  counts["open objects"] = static_cast<long long>(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL));
  return counts;
}

std::string describe(const std::map<std::string, long long>& counts) {
  std::string text;
  for (const auto& [name, n] : counts) text += name + " " + std::to_string(n) + "; ";
  return text;
}

/// The error a write throws ("" when it does not throw).
std::string error_writing(const std::function<void()>& write) {
  try {
    write();
  } catch (const CheckpointError& e) {
    return e.what();
  }
  return "";
}

/// Runs `body` in a forked child that then exits normally, so HDF5's clean-up at exit runs: an
/// identifier that a failed close left behind crashes the process there. `body` appends one
/// "FAIL: ..." line per failed check to the report, which the child leaves in `report_file`.
ProcessEnd in_child(const std::filesystem::path& report_file,
                    const std::function<void(std::string& report)>& body) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::string report;
    try {
      body(report);
    } catch (const std::exception& e) {
      report += std::string("FAIL: unexpected exception: ") + e.what() + "\n";
    }
    report += "DONE\n";
    std::ofstream(report_file) << report;
    std::exit(0);
  }
  return wait_for(pid);
}

/// Under a file-size limit a checkpoint or snapshot write fails. The error names the file and the
/// reason, no HDF5 identifier outlives the write, the temporary is gone, the previous file still
/// reads, and the process exits normally afterwards (HDF5 1.10 used to keep the id of a file whose
/// close had failed and crash on it at exit).
TEST_F(CheckpointTest, WritesOverAFileSizeLimitFailCleanlyAndKeepThePreviousFiles) {
  TinyRun run = tiny_run(3);
  const sim::SolverState previous = run.simulation->state();
  run.simulation->step();
  const sim::SolverState next = run.simulation->state();
  const CheckpointMetadata meta = run.metadata();
  const auto file = dir_ / checkpoint_file_name(previous.step);
  const auto snapshot = dir_ / "particles.h5";
  const std::size_t n = previous.particles.size();
  const std::vector<ParticleField> fields{{"a", "1", std::vector<double>(n, 1.0)},
                                          {"b", "1", std::vector<double>(n, 2.0)}};
  write_checkpoint(file, previous, meta);
  write_particle_snapshot(snapshot, previous.particles, previous.time, previous.step, fields,
                          {meta.scene_json, meta.code_version});
  const std::string previous_snapshot = file_text(snapshot);
  ASSERT_GT(std::filesystem::file_size(file), kFileSizeLimit);
  ASSERT_GT(previous_snapshot.size(), kFileSizeLimit);
  const auto baseline = hdf5_identifiers();
  const auto report_file = dir_ / "report.txt";
  const ProcessEnd end = in_child(report_file, [&](std::string& report) {
    const auto check = [&](bool ok, const std::string& what) {
      if (!ok) report += "FAIL: " + what + "\n";
    };
    signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{kFileSizeLimit, kFileSizeLimit};
    check(setrlimit(RLIMIT_FSIZE, &limit) == 0, "setrlimit");
    const std::string reason = std::strerror(EFBIG);

    const std::string checkpoint_error = error_writing([&] { write_checkpoint(file, next, meta); });
    report += "checkpoint error: " + checkpoint_error + "\n";
    check(checkpoint_error.find("checkpoint '" + file.string() + "'") != std::string::npos,
          "the checkpoint error names the file");
    check(checkpoint_error.find(reason) != std::string::npos,
          "the checkpoint error gives the reason '" + reason + "'");
    check(hdf5_identifiers() == baseline,
          "HDF5 identifiers after the failed checkpoint write: " + describe(hdf5_identifiers()) +
              "before: " + describe(baseline));
    check(temporaries(dir_).empty(), "a temporary file is left behind");
    check(error_reading(file).empty(), "the previous checkpoint no longer reads");

    const std::string snapshot_error = error_writing([&] {
      write_particle_snapshot(snapshot, next.particles, next.time, next.step, fields,
                              {meta.scene_json, meta.code_version});
    });
    report += "snapshot error: " + snapshot_error + "\n";
    check(snapshot_error.find(snapshot.string()) != std::string::npos &&
              snapshot_error.find(reason) != std::string::npos,
          "the snapshot error names the file and the reason");
    check(hdf5_identifiers() == baseline,
          "HDF5 identifiers after the failed snapshot write: " + describe(hdf5_identifiers()) +
              "before: " + describe(baseline));
    check(temporaries(dir_).empty(), "a temporary file is left behind");
    check(file_text(snapshot) == previous_snapshot, "the previous snapshot changed");
  });
  const std::string report = file_text(report_file);
  std::printf("%s", report.c_str());
  EXPECT_TRUE(end.exited && end.code == 0)
      << "the process ended with " << end.describe() << " after the failed writes";
  EXPECT_NE(report.find("DONE"), std::string::npos) << report;
  EXPECT_EQ(report.find("FAIL"), std::string::npos) << report;
}

/// Beyond HDF5's 64 KiB limit for a message in an object header: an attribute this long cannot
/// be created, a real failure inside HDF5 in the middle of a write.
constexpr std::size_t kOversizedAttribute = std::size_t{128} << 10;

/// Failures at other steps: the temporary cannot be created (its directory is a regular file),
/// HDF5 refuses an attribute, a dataset cannot be created. Each error names the file and the
/// reason, and leaves no identifier open, no temporary and the previous file intact.
TEST_F(CheckpointTest, FailuresAtEveryStepOfAWriteLeaveNoHdf5IdentifierOpen) {
  TinyRun run = tiny_run(2);
  const sim::SolverState state = run.simulation->state();
  const CheckpointMetadata meta = run.metadata();
  const auto file = dir_ / "ckpt.h5";
  write_checkpoint(file, state, meta);
  const auto baseline = hdf5_identifiers();

  std::ofstream(dir_ / "plain") << "a regular file, not a directory";
  const auto nowhere = dir_ / "plain" / "ckpt.h5";
  const std::string create_error = error_writing([&] { write_checkpoint(nowhere, state, meta); });
  EXPECT_NE(create_error.find(nowhere.string()), std::string::npos) << create_error;
  EXPECT_NE(create_error.find(std::strerror(ENOTDIR)), std::string::npos) << create_error;
  EXPECT_EQ(hdf5_identifiers(), baseline) << describe(hdf5_identifiers());

  CheckpointMetadata oversized = meta;
  oversized.scene_json = json{{"name", std::string(kOversizedAttribute, 'x')}}.dump();
  const std::string attribute_error =
      error_writing([&] { write_checkpoint(file, state, oversized); });
  EXPECT_NE(
      attribute_error.find("checkpoint '" + file.string() + "': cannot write attribute 'scene'"),
      std::string::npos)
      << attribute_error;
  EXPECT_EQ(hdf5_identifiers(), baseline) << describe(hdf5_identifiers());
  EXPECT_EQ(error_reading(file), "");
  EXPECT_EQ(read_checkpoint(file).state.step, state.step);

  // The snapshot writer: a field named like a standard dataset (the dataset cannot be created),
  // and a field whose units attribute HDF5 refuses after its dataset was written.
  const auto snapshot = dir_ / "particles.h5";
  const std::size_t n = state.particles.size();
  const std::string dataset_error = error_writing([&] {
    write_particle_snapshot(snapshot, state.particles, state.time, state.step,
                            {{"mass", "kg", std::vector<double>(n, 1.0)}},
                            {meta.scene_json, meta.code_version});
  });
  EXPECT_NE(dataset_error.find("snapshot '" + snapshot.string() + "': cannot write dataset 'mass'"),
            std::string::npos)
      << dataset_error;
  EXPECT_EQ(hdf5_identifiers(), baseline) << describe(hdf5_identifiers());
  const std::string units_error = error_writing([&] {
    write_particle_snapshot(
        snapshot, state.particles, state.time, state.step,
        {{"omega2", std::string(kOversizedAttribute, 'x'), std::vector<double>(n, 1.0)}},
        {meta.scene_json, meta.code_version});
  });
  EXPECT_NE(units_error.find("cannot write attribute 'units'"), std::string::npos) << units_error;
  EXPECT_EQ(hdf5_identifiers(), baseline) << describe(hdf5_identifiers());
  EXPECT_FALSE(std::filesystem::exists(snapshot));
  EXPECT_TRUE(temporaries(dir_).empty());
}

/// `sphles run` whose checkpoint writes fail (file-size limit) ends with exit code 1 and a message
/// naming the file and the reason, not by a signal at exit.
TEST_F(CheckpointTest, RunWhoseCheckpointWritesFailExitsWithCodeOne) {
  const auto scene = dir_ / "scene.json";
  std::ofstream(scene) << tiny_run_scene(/*checkpoints=*/true).dump();
  const auto run = dir_ / "run";
  const Finished f = run_sphles({"run", scene.string(), "--out", run.string(), "--threads", "1"},
                                dir_, kFileSizeLimit);
  EXPECT_TRUE(f.end.exited) << f.end.describe() << "\n" << f.err;
  EXPECT_EQ(f.end.code, 1) << f.err;
  EXPECT_NE(f.err.find((run / "checkpoints" / "ckpt_").string()), std::string::npos) << f.err;
  EXPECT_NE(f.err.find(std::strerror(EFBIG)), std::string::npos) << f.err;
  EXPECT_EQ(f.err.find("infinite loop closing library"), std::string::npos) << f.err;
  EXPECT_TRUE(list_checkpoints(run / "checkpoints").empty());
  EXPECT_TRUE(temporaries(run / "checkpoints").empty());
}

/// A run of `sphles serve` fails on a checkpoint write (file-size limit); SIGTERM then stops the
/// server, which exits normally (it used to print "stopped" and crash in HDF5's clean-up at exit).
TEST_F(CheckpointTest, ServeExitsCleanlyOnSigtermAfterAFailedCheckpointWrite) {
  const ProcessOptions options{dir_ / "serve.out", dir_ / "serve.err", kFileSizeLimit};
  Reaper server{spawn_sphles({"serve", "--port", "0", "--bind", "127.0.0.1", "--data",
                              (dir_ / "data").string(), "--threads", "1"},
                             options)};
  const std::string prefix = "listening on http://127.0.0.1:";
  unsigned short port = 0;
  ASSERT_TRUE(sphles_server_test::wait_until([&] {
    const std::string out = file_text(options.out);
    const auto at = out.find(prefix);
    if (at != std::string::npos)
      port = static_cast<unsigned short>(std::stoi(out.substr(at + prefix.size())));
    return port != 0;
  })) << file_text(options.err);
  const sphles_server_test::Api api{port};
  const std::string id = api.create({{"scene", tiny_run_scene(/*checkpoints=*/true)}});
  ASSERT_FALSE(id.empty());
  json status;
  ASSERT_TRUE(sphles_server_test::wait_until([&] {
    status = api.run(id);
    return status.value("state", "") == "failed";
  })) << status.dump();
  EXPECT_NE(status.value("reason", "").find(std::strerror(EFBIG)), std::string::npos)
      << status.dump();
  kill(server.pid, SIGTERM);
  const ProcessEnd end = wait_for(server.pid);
  server.pid = 0;
  const std::string err = file_text(options.err);
  EXPECT_TRUE(end.exited) << end.describe() << "\n" << err;
  EXPECT_NE(err.find(" info  serve: stopped\n"), std::string::npos) << err;
  // The service's log has the request and the run's failure with its diagnosis; so has run.log.
  EXPECT_NE(err.find(" info  http: 127.0.0.1 \"POST /api/runs\" 201 "), std::string::npos) << err;
  const std::string failure = "run " + id + ": state: running -> failed: ";
  EXPECT_NE(err.find(" error " + failure), std::string::npos) << err;
  const std::string run_log = file_text(dir_ / "data" / "runs" / id / "run.log");
  EXPECT_NE(run_log.find(" error state: running -> failed: "), std::string::npos) << run_log;
  EXPECT_NE(run_log.find(std::strerror(EFBIG)), std::string::npos) << run_log;
  EXPECT_EQ(err.find("infinite loop closing library"), std::string::npos) << err;
}

// --- implausible content ----------------------------------------------------------------------

/// Replaces a fixed-length string attribute (the writer's layout) with `value`.
void replace_string_attribute(const std::filesystem::path& file, const char* name,
                              const std::string& value) {
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(h5, 0);
  ASSERT_GE(H5Adelete(h5, name), 0);
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, value.size());
  H5Tset_strpad(type, H5T_STR_NULLPAD);
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attribute = H5Acreate2(h5, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(attribute, 0);
  ASSERT_GE(H5Awrite(attribute, type, value.data()), 0);
  H5Aclose(attribute);
  H5Sclose(space);
  H5Tclose(type);
  H5Fclose(h5);
}

/// Overwrites one element of a particle dataset in place (its checksum is recomputed).
template <class T>
void overwrite_element(const std::filesystem::path& file, const std::string& dataset, hsize_t index,
                       hid_t type, T value) {
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(h5, 0);
  const hid_t set = H5Dopen2(h5, ("particles/" + dataset).c_str(), H5P_DEFAULT);
  ASSERT_GE(set, 0);
  const hid_t space = H5Dget_space(set);
  const hsize_t count = 1;
  ASSERT_GE(H5Sselect_hyperslab(space, H5S_SELECT_SET, &index, nullptr, &count, nullptr), 0);
  const hid_t memory = H5Screate_simple(1, &count, nullptr);
  ASSERT_GE(H5Dwrite(set, type, memory, space, H5P_DEFAULT, &value), 0);
  H5Sclose(memory);
  H5Sclose(space);
  H5Dclose(set);
  H5Fclose(h5);
}

/// Files whose structure is sound but whose content is not are rejected, by read_checkpoint
/// (restart) and by `sphles inspect` (exit code 2), naming the file, the attribute or dataset and
/// the reason.
TEST_F(CheckpointTest, ImplausibleContentIsRejectedNamingTheField) {
  TinyRun run = tiny_run(5);
  const sim::SolverState state = run.simulation->state();
  const CheckpointMetadata meta = run.metadata();
  const auto good = dir_ / "good.h5";
  write_checkpoint(good, state, meta);
  ASSERT_EQ(error_reading(good), "");
  const Finished inspected = run_sphles({"inspect", good.string()}, dir_);
  EXPECT_EQ(inspected.end.code, 0) << inspected.err;
  EXPECT_NE(inspected.out.find("periodic box:     L = 6.283185307179586 m (case tgv2d, 16^2"),
            std::string::npos)
      << inspected.out;

  const std::uint64_t n = state.particles.size();
  const double box = run.scene.box_length();
  const std::uint64_t id3 = state.particles.id[3];
  const std::string step = std::to_string(state.step);
  json boxed = json::parse(meta.scene_json);
  boxed["box_length"] = 1.0;
  struct Case {
    std::string name;
    std::function<void(const std::filesystem::path&)> corrupt;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"scene_not_json",
       [](const auto& f) { replace_string_attribute(f, "scene", R"({"case": tgv2d})"); },
       "attribute 'scene' is not JSON (byte 11 of 15)"},
      {"scene_not_object", [](const auto& f) { replace_string_attribute(f, "scene", "[1, 2]"); },
       "attribute 'scene' is JSON but not an object (array)"},
      {"scene_without_box",
       [&](const auto& f) { replace_string_attribute(f, "scene", boxed.dump()); },
       "attribute 'scene' does not determine the periodic box: scene: 'box_length' is fixed"},
      {"negative_time",
       [](const auto& f) { overwrite_attribute(f, "time", H5T_NATIVE_DOUBLE, -1.0); },
       "attribute 'time' is -1 (must be >= 0)"},
      {"steps_without_time",
       [](const auto& f) { overwrite_attribute(f, "time", H5T_NATIVE_DOUBLE, 0.0); },
       "attribute 'step' is " + step + " but 'time' is 0"},
      {"step_beyond_2_53",
       [](const auto& f) {
         overwrite_attribute(f, "step", H5T_NATIVE_UINT64, std::uint64_t{1} << 63);
       },
       "attribute 'step' is 9223372036854775808, above 2^53 = 9007199254740992"},
      {"neighbour_builds",
       [&](const auto& f) {
         overwrite_attribute(f, "neighbour_builds", H5T_NATIVE_UINT64, state.step + 2);
       },
       "attribute 'neighbour_builds' is " + std::to_string(state.step + 2) +
           ", expected 1 to step + 1 = " + std::to_string(state.step + 1)},
      {"dimension_against_scene",
       [](const auto& f) { overwrite_attribute(f, "dimension", H5T_NATIVE_INT, 3); },
       "attribute 'dimension' is 3 but the scene's case 'tgv2d' is 2D"},
      {"count_against_scene",
       [&](const auto& f) { overwrite_attribute(f, "num_particles", H5T_NATIVE_UINT64, n + 1); },
       "attribute 'num_particles' is 257 but the scene has 256 (particles_per_side 16 in 2D)"},
      {"position_far_away",
       [](const auto& f) { overwrite_element(f, "position_x", 17, H5T_NATIVE_DOUBLE, 1e300); },
       "dataset 'particles/position_x' has 1e+300 at index 17, outside the periodic box [0, "
       "6.283185307179586) m"},
      {"position_negative",
       [](const auto& f) { overwrite_element(f, "position_y", 4, H5T_NATIVE_DOUBLE, -0.5); },
       "dataset 'particles/position_y' has -0.5 at index 4, outside the periodic box"},
      {"reference_on_the_boundary",
       [&](const auto& f) { overwrite_element(f, "list_reference_x", 9, H5T_NATIVE_DOUBLE, box); },
       "dataset 'particles/list_reference_x' has 6.283185307179586 at index 9, outside"},
      {"negative_mass",
       [](const auto& f) { overwrite_element(f, "mass", 17, H5T_NATIVE_DOUBLE, -1.0); },
       "dataset 'particles/mass' has a non-positive value -1 at index 17"},
      {"zero_volume",
       [](const auto& f) { overwrite_element(f, "volume", 0, H5T_NATIVE_DOUBLE, 0.0); },
       "dataset 'particles/volume' has a non-positive value 0 at index 0"},
      {"negative_density",
       [](const auto& f) { overwrite_element(f, "density", 255, H5T_NATIVE_DOUBLE, -1000.0); },
       "dataset 'particles/density' has a non-positive value -1000 at index 255"},
      {"duplicate_id",
       [&](const auto& f) { overwrite_element(f, "id", 40, H5T_NATIVE_UINT64, id3); },
       "dataset 'particles/id' repeats " + std::to_string(id3) + " at index 40 (first at index 3"},
      {"id_out_of_range",
       [&](const auto& f) { overwrite_element(f, "id", 7, H5T_NATIVE_UINT64, n); },
       "dataset 'particles/id' has 256 at index 7, outside 0..255"},
  };
  for (const Case& c : cases) {
    const auto file = dir_ / (c.name + ".h5");
    std::filesystem::copy_file(good, file);
    c.corrupt(file);
    const std::string error = error_reading(file);
    EXPECT_NE(error.find("checkpoint '" + file.string() + "': " + c.expected), std::string::npos)
        << c.name << ": " << error;
    const Finished inspect = run_sphles({"inspect", file.string()}, dir_);
    EXPECT_TRUE(inspect.end.exited && inspect.end.code == 2)
        << c.name << ": " << inspect.end.describe() << "\n"
        << inspect.out;
    EXPECT_NE(inspect.err.find("checkpoint '" + file.string() + "': " + c.expected),
              std::string::npos)
        << c.name << ": " << inspect.err;
  }

  // A restart from a file whose scene is not JSON names the file and the attribute (it used to
  // fail with a bare "[json.exception.parse_error.101]").
  const Finished restart = run_sphles({"run", "--restart", (dir_ / "scene_not_json.h5").string(),
                                       "--out", (dir_ / "restarted").string()},
                                      dir_);
  EXPECT_EQ(restart.end.code, 2) << restart.end.describe();
  EXPECT_NE(restart.err.find("checkpoint '" + (dir_ / "scene_not_json.h5").string() +
                             "': attribute 'scene' is not JSON"),
            std::string::npos)
      << restart.err;
}

std::vector<double> read_doubles(const std::filesystem::path& file, const char* dataset) {
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  const hid_t set = H5Dopen2(h5, dataset, H5P_DEFAULT);
  const hid_t space = H5Dget_space(set);
  std::vector<double> values(static_cast<std::size_t>(H5Sget_simple_extent_npoints(space)));
  H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
  H5Sclose(space);
  H5Dclose(set);
  H5Fclose(h5);
  return values;
}

/// Snapshots are written in id order whatever order the solver holds the particles in, carry
/// schema, version and units, and `sphles inspect` describes them; particle ids that are not a
/// permutation of 0..N-1, HDF5 files of other kinds and non-HDF5 files are clear errors.
TEST_F(CheckpointTest, SnapshotsAreInIdOrderAndInspectDescribesThem) {
  TinyRun run = tiny_run(3);
  sim::SolverState state = run.simulation->state();
  sim::ParticleArrays& p = state.particles;
  const std::size_t n = p.size();
  // A deliberately scrambled order (a reversal) on top of the solver's cell order.
  std::vector<std::uint32_t> reversed(n);
  for (std::size_t i = 0; i < n; ++i) reversed[i] = static_cast<std::uint32_t>(n - 1 - i);
  p.reorder(reversed);
  ASSERT_NE(p.id[0], 0u);
  std::vector<double> field(n);
  for (std::size_t i = 0; i < n; ++i) field[i] = 10.0 * static_cast<double>(p.id[i]);
  const auto snapshot = dir_ / "particles_t1.h5";
  write_particle_snapshot(snapshot, p, state.time, state.step, {{"tag", "1", field}},
                          {run.metadata().scene_json, "test-version"});
  const std::vector<double> ids = read_doubles(snapshot, "id");
  const std::vector<double> xyz = read_doubles(snapshot, "position");
  const std::vector<double> tag = read_doubles(snapshot, "tag");
  const std::vector<double> mass = read_doubles(snapshot, "mass");
  ASSERT_EQ(ids.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = p.id[i];
    EXPECT_EQ(ids[k], static_cast<double>(k));
    EXPECT_EQ(xyz[3 * k], p.position[0][i]);
    EXPECT_EQ(xyz[3 * k + 1], p.position[1][i]);
    EXPECT_EQ(xyz[3 * k + 2], 0.0);
    EXPECT_EQ(tag[k], 10.0 * static_cast<double>(k));
    EXPECT_EQ(mass[k], p.mass[i]);
  }

  const Finished inspected = run_sphles({"inspect", snapshot.string()}, dir_);
  EXPECT_EQ(inspected.end.code, 0) << inspected.err;
  for (const std::string expected :
       {"schema:           sphles-particles", "schema_version:   2",
        "code_version:     test-version", "num_particles:    256", "position          256 x 3  [m]",
        "tag               256  [1]", "id order:         row k holds id k"})
    EXPECT_NE(inspected.out.find(expected), std::string::npos) << expected << "\n" << inspected.out;

  sim::ParticleArrays duplicated = p;
  duplicated.id[5] = duplicated.id[6];
  const std::string error = error_writing([&] {
    write_particle_snapshot(dir_ / "bad.h5", duplicated, state.time, state.step, {}, {});
  });
  EXPECT_NE(error.find("particle ids are not a permutation of 0..255"), std::string::npos) << error;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "bad.h5"));

  const auto plain = dir_ / "plain.h5";
  H5Fclose(H5Fcreate(plain.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT));
  const Finished other = run_sphles({"inspect", plain.string()}, dir_);
  EXPECT_EQ(other.end.code, 2);
  EXPECT_NE(other.err.find("has no root attribute 'schema', so it is neither a sphles checkpoint"),
            std::string::npos)
      << other.err;
  std::ofstream(dir_ / "text.h5") << "not HDF5";
  const Finished text = run_sphles({"inspect", (dir_ / "text.h5").string()}, dir_);
  EXPECT_EQ(text.end.code, 2);
  EXPECT_NE(text.err.find("not an HDF5 file"), std::string::npos) << text.err;
}

}  // namespace
}  // namespace sphles::io
