// HDF5 checkpoints: exact round trip, bitwise restart, rejection of damaged files, and crash
// safety of the atomic write under SIGKILL of a real sphles process.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "io/checkpoint.hpp"
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

std::unique_ptr<sim::Simulation> random_simulation(int dim, sim::SubfilterModel model) {
  auto flow = sim::testing::random_flow(dim, dim == 3 ? 10 : 24, 4.0, 1.0, 21);
  flow.config.subfilter.model = model;
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

// Restarting after k steps continues bitwise identically to the uninterrupted run, with an
// explicit model (so ν_t and the gradient pass are part of the state's history) and with list
// rebuilds on both sides of the checkpoint.
TEST_F(CheckpointTest, RestartEqualsUninterruptedRunBitwise) {
  for (const int dim : {2, 3}) {
    auto uninterrupted = random_simulation(dim, sim::SubfilterModel::Smagorinsky);
    auto first_leg = random_simulation(dim, sim::SubfilterModel::Smagorinsky);
    for (int k = 0; k < 23; ++k) first_leg->step();
    const auto file = dir_ / ("restart_" + std::to_string(dim) + ".h5");
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

// --- crash safety with a real process --------------------------------------------------------

pid_t start_sphles(const std::vector<std::string>& arguments) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> argv;
    std::string binary = SPHLES_BINARY;
    argv.push_back(binary.data());
    std::vector<std::string> copies = arguments;
    for (std::string& a : copies) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int null = ::open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    execv(binary.c_str(), argv.data());
    _exit(127);
  }
  return pid;
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

}  // namespace
}  // namespace sphles::io
