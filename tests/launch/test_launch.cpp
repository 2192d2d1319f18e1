// SPDX-License-Identifier: GPL-3.0-or-later
// The channel to a run's MPI job and the job's solver (launch/, docs/scaling.md "From the
// service"): values cross a real TCP connection bit for bit, malformed messages and a vanished peer
// are refused with clear errors, a launcher that fails is diagnosed from its exit status and log,
// and a solver in a real 2-rank job (mpirun, `sphles worker`) steps bitwise like one process.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <limits>
#include <random>
#include <thread>

#include <unistd.h>
#include "analysis/products.hpp"
#include "io/checkpoint.hpp"
#include "launch/channel.hpp"
#include "launch/job.hpp"
#include "remote/messages.hpp"
#include "scene/document.hpp"
#include "scratch_directory.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"

namespace sphles::launch {
namespace {

std::filesystem::path fresh_directory(const std::string& name) {
  return sphles::scratch::scratch_directory("launch", name);
}

/// Particles with random bits in every array (NaN and infinities included), ν_t when asked.
sim::ParticleArrays random_particles(int dimension, std::size_t n, bool eddy, std::uint64_t seed) {
  std::mt19937_64 bits(seed);
  sim::ParticleArrays p;
  p.dimension = dimension;
  p.resize(n);
  if (eddy) p.eddy_viscosity.resize(n);
  for (std::vector<double>* field : p.double_fields())
    for (double& v : *field) {
      const std::uint64_t b = bits();
      std::memcpy(&v, &b, sizeof v);
    }
  for (auto& id : p.id) id = bits();
  return p;
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

void expect_same_particles(const sim::ParticleArrays& a, const sim::ParticleArrays& b) {
  ASSERT_EQ(a.dimension, b.dimension);
  const auto fa = a.double_fields();
  const auto fb = b.double_fields();
  ASSERT_EQ(fa.size(), fb.size());
  for (std::size_t f = 0; f < fa.size(); ++f) EXPECT_TRUE(same_bits(*fa[f], *fb[f])) << f;
  EXPECT_EQ(a.id, b.id);
}

/// A connected pair of channels over 127.0.0.1.
struct ConnectedPair {
  Channel service;
  std::unique_ptr<Channel> job_end = std::make_unique<Channel>();
  Channel& job = *job_end;
  ConnectedPair() {
    const unsigned short port = service.listen("127.0.0.1");
    std::thread connector([&] { job.connect("127.0.0.1", port); });
    service.accept({}, 0.05);
    connector.join();
  }
};

TEST(JobChannel, StatesAndDiagnosticsCrossTheConnectionBitForBit) {
  ConnectedPair pair;
  for (const int dimension : {2, 3})
    for (const bool eddy : {false, true}) {
      sim::SolverState state;
      state.particles = random_particles(dimension, 1000, eddy, 17 + dimension);
      for (int a = 0; a < dimension; ++a)
        state.list_reference_positions[static_cast<std::size_t>(a)] =
            random_particles(dimension, 1000, false, 99 + a).mass;
      state.time = 0.1 + 0.2;
      state.step = 123456789012345ull;
      state.neighbour_builds = 42;
      sim::StepDiagnostics g;
      g.time = state.time;
      g.step = state.step;
      g.dt = std::numeric_limits<double>::quiet_NaN();
      g.kinetic_energy = std::numeric_limits<double>::denorm_min();
      g.momentum = {1e-300, -0.0, std::numeric_limits<double>::infinity()};
      g.neighbour_builds = 7;
      g.mean_neighbours = 123.25;

      Encoder e;
      encode(e, state);
      encode(e, remote::SolverStatus{state.time, state.step, 0.003, g});
      pair.service.send(MessageKind::Reply, e);
      const Message m = pair.job.receive();
      ASSERT_EQ(m.kind, MessageKind::Reply);
      Decoder d(m.body);
      sim::SolverState back;
      decode(d, back);
      remote::SolverStatus status;
      decode(d, status);
      d.finish();
      expect_same_particles(state.particles, back.particles);
      for (int a = 0; a < dimension; ++a)
        EXPECT_TRUE(same_bits(state.list_reference_positions[static_cast<std::size_t>(a)],
                              back.list_reference_positions[static_cast<std::size_t>(a)]));
      EXPECT_EQ(back.time, state.time);
      EXPECT_EQ(back.step, state.step);
      EXPECT_EQ(back.neighbour_builds, state.neighbour_builds);
      EXPECT_EQ(status.stable_time_step, 0.003);
      EXPECT_TRUE(std::isnan(status.diagnostics.dt));
      EXPECT_EQ(status.diagnostics.kinetic_energy, g.kinetic_energy);
      EXPECT_TRUE(std::signbit(status.diagnostics.momentum[1]));
      EXPECT_EQ(status.diagnostics.momentum[2], g.momentum[2]);
      EXPECT_EQ(status.diagnostics.neighbour_builds, 7u);
      EXPECT_EQ(status.diagnostics.mean_neighbours, 123.25);
    }
}

TEST(JobChannel, AFreshParticleSetKeepsItsEmptyArrays) {
  sim::ParticleArrays p;
  p.dimension = 2;
  p.position[0] = {0.5, 1.5};
  p.position[1] = {2.5, 3.5};
  p.velocity[0] = {1.0, 2.0};
  p.velocity[1] = {3.0, 4.0};
  p.mass = {0.25, 0.25};
  p.id = {4, 9};
  Encoder e;
  encode(e, p);
  Decoder d(e.bytes());
  sim::ParticleArrays back;
  decode(d, back);
  d.finish();
  EXPECT_EQ(back.position[0], p.position[0]);
  EXPECT_EQ(back.velocity[1], p.velocity[1]);
  EXPECT_EQ(back.mass, p.mass);
  EXPECT_TRUE(back.volume.empty());
  EXPECT_TRUE(back.acceleration[0].empty());
  EXPECT_TRUE(back.eddy_viscosity.empty());
  EXPECT_EQ(back.id, p.id);
}

TEST(JobChannel, ErrorsKeepTheirTypeAndFacts) {
  const auto round_trip = [](const std::exception& error) {
    Encoder e;
    encode_error(e, error);
    Decoder d(e.bytes());
    throw_error(d);
  };
  try {
    round_trip(sim::BlowUpError("blew up at t = 1", 1.0, 77, "velocity[0]", 1e300, 4242));
    FAIL() << "no throw";
  } catch (const sim::BlowUpError& e) {
    EXPECT_STREQ(e.what(), "blew up at t = 1");
    EXPECT_EQ(e.time(), 1.0);
    EXPECT_EQ(e.step(), 77u);
    EXPECT_EQ(e.quantity(), "velocity[0]");
    EXPECT_EQ(e.value(), 1e300);
    EXPECT_EQ(e.particle_id(), 4242u);
  }
  EXPECT_THROW(round_trip(std::invalid_argument("state does not fit")), std::invalid_argument);
  try {
    round_trip(std::runtime_error("decomposition too fine"));
    FAIL() << "no throw";
  } catch (const sim::SimulationError& e) {
    EXPECT_STREQ(e.what(), "decomposition too fine");
  }
}

TEST(JobChannel, TruncatedAndOversizedMessagesAreRefused) {
  Encoder e;
  encode(e, random_particles(3, 10, false, 5));
  std::vector<std::byte> bytes = e.bytes();
  bytes.resize(bytes.size() - 1);
  Decoder truncated(bytes);
  sim::ParticleArrays back;
  EXPECT_THROW(decode(truncated, back), ProtocolError);

  Encoder huge;
  huge.u64(3);
  huge.u64(std::uint64_t{1} << 60);  // a length far beyond the message
  Decoder lying(huge.bytes());
  EXPECT_THROW(decode(lying, back), ProtocolError);

  Encoder wrong_dimension;
  wrong_dimension.u64(4);
  Decoder four(wrong_dimension.bytes());
  EXPECT_THROW(decode(four, back), ProtocolError);

  Encoder extra;
  extra.f64(1.0);
  extra.u64(2);
  Decoder left_over(extra.bytes());
  left_over.f64();
  EXPECT_THROW(left_over.finish(), ProtocolError);
}

TEST(JobChannel, APeerThatGoesAwayEndsTheWait) {
  ConnectedPair pair;
  std::thread closer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    pair.job_end.reset();  // the job's end closes its socket
  });
  EXPECT_THROW(pair.service.receive({}, 0.05), ChannelClosed);
  closer.join();
}

TEST(JobChannel, AWaitGivesUpWhenTheCheckThrows) {
  ConnectedPair pair;
  int checks = 0;
  EXPECT_THROW(pair.service.receive(
                   [&] {
                     if (++checks == 3) throw std::runtime_error("the job ended");
                   },
                   0.01),
               std::runtime_error);
  EXPECT_EQ(checks, 3);
}

sim::Scene small_tgv2d() {
  return scene::parse_scene({{"preset", "tgv2d"},
                             {"particles_per_side", 32},
                             {"packing", {{"enabled", false}}},
                             {"time", {{"end", 1.0}}}});
}

LaunchOptions options_for(const std::string& launcher, const std::filesystem::path& log) {
  // The job inherits this process' environment: OpenMPI refuses root (CI's containers) unless
  // told, and its ranks should yield when they wait on CI's 2 oversubscribed cores.
  for (const char* name :
       {"OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "OMPI_MCA_mpi_yield_when_idle"})
    ::setenv(name, "1", 0);
  LaunchOptions o;
  o.launcher = launcher;
  o.executable = SPHLES_BINARY;
  o.ranks = 2;
  o.threads = 1;
  o.log_file = log;
  o.connect_timeout_seconds = 60.0;
  return o;
}

TEST(JobSolverFactories, ALauncherWithoutTheRankCountIsRefused) {
  LaunchOptions o = options_for("mpirun -n 2", "job.log");
  try {
    validate(o);
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("{ranks}"), std::string::npos) << e.what();
  }
}

TEST(JobSolverFactories, ALauncherThatFailsIsDiagnosedFromItsStatusAndLog) {
  const auto dir = fresh_directory("launch_failing");
  const std::filesystem::path log = dir / "job.log";
  const sim::Scene scene = small_tgv2d();
  sim::SolverFactories solvers =
      job_solvers(options_for("/bin/sh -c 'echo cannot place {ranks} ranks >&2; exit 3'", log))
          .solvers;
  try {
    solvers.make(scene, sim::setup_run(scene).particles);
    FAIL() << "no throw";
  } catch (const sim::SimulationError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("exited with status 3"), std::string::npos) << what;
    EXPECT_NE(what.find("before its rank 0 connected"), std::string::npos) << what;
    EXPECT_NE(what.find("cannot place 2 ranks"), std::string::npos) << what;
  }
}

TEST(JobSolverFactories, AJobWithAnotherRankCountIsRefused) {
  const auto dir = fresh_directory("launch_ranks");
  const sim::Scene scene = small_tgv2d();
  // A launcher that ignores the rank count: one rank where the run asked for two.
  sim::SolverFactories solvers =
      job_solvers(
          options_for("mpiexec --oversubscribe --bind-to none -n 1 env SPHLES_IGNORED={ranks}",
                      dir / "job.log"))
          .solvers;
  try {
    solvers.make(scene, sim::setup_run(scene).particles);
    FAIL() << "no throw";
  } catch (const sim::SimulationError& e) {
    EXPECT_NE(std::string(e.what()).find("the job has 1 ranks where the run asked for 2"),
              std::string::npos)
        << e.what();
  }
}

TEST(JobSolverFactories, AJobReachesAServiceListeningOnEveryInterface) {
  const auto dir = fresh_directory("launch_any");
  const sim::Scene scene = small_tgv2d();
  LaunchOptions o =
      options_for("mpiexec --oversubscribe --bind-to none -n {ranks}", dir / "job.log");
  o.listen_address = "0.0.0.0";  // rank 0 connects to this host's name
  sim::SolverFactories solvers = job_solvers(o).solvers;
  const auto remote = solvers.make(scene, sim::setup_run(scene).particles);
  remote->step();
  EXPECT_EQ(remote->step_count(), 1u);
}

TEST(JobSolverFactories, KolmogorovDiagnosticsAreSummedInTheJobBitwiseLikeOneProcess) {
  const auto dir = fresh_directory("launch_kolmogorov");
  const sim::Scene scene = scene::parse_scene(
      {{"preset", "kolmogorov2d"}, {"particles_per_side", 48}, {"packing", {{"enabled", false}}}});
  const sim::RunSetup setup = sim::setup_run(scene);
  auto local = sim::make_simulation(setup.solver, setup.particles);
  sim::SolverFactories solvers =
      job_solvers(options_for("mpiexec --oversubscribe --bind-to none -n {ranks}", dir / "job.log"))
          .solvers;
  const auto remote = solvers.make(scene, setup.particles);
  for (int s = 0; s < 10; ++s) {
    local->step();
    remote->step();
  }
  const std::vector<double> expected = local->case_diagnostics(scene);
  ASSERT_EQ(expected.size(), 3u);
  EXPECT_EQ(remote->case_diagnostics(scene), expected);
}

/// Bitwise equality of two states by particle id.
void expect_same_by_id(const sim::ParticleArrays& a, const sim::ParticleArrays& b) {
  ASSERT_EQ(a.size(), b.size());
  std::vector<std::size_t> where(a.size());
  for (std::size_t k = 0; k < b.size(); ++k) where[b.id[k]] = k;
  const auto fa = a.double_fields();
  const auto fb = b.double_fields();
  ASSERT_EQ(fa.size(), fb.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    for (std::size_t f = 0; f < fa.size(); ++f)
      if (std::memcmp(&(*fa[f])[i], &(*fb[f])[where[a.id[i]]], sizeof(double)) != 0) {
        ++differing;
        break;
      }
  EXPECT_EQ(differing, 0u);
}

// A new run whose particles the job's ranks make and pack (each those of its sub-box; none
// cross the channel) is the run set up here, bit for bit, with the same packing report. A
// cancellation while the job packs ends the job and throws SetupCancelled.
TEST(JobSolverFactories, ARunSetUpByTheJobsRanksIsTheRunSetUpHere) {
  const auto dir = fresh_directory("launch_setup");
  sim::Scene scene = small_tgv2d();
  scene.packing.enabled = true;
  const sim::RunSetup setup = sim::setup_run(scene, {.packing_cache_dir = dir / "here"});
  auto local = sim::make_simulation(setup.solver, setup.particles);
  sim::SolverFactories solvers =
      job_solvers(options_for("mpiexec --oversubscribe --bind-to none -n {ranks}", dir / "job.log"))
          .solvers;
  ASSERT_TRUE(solvers.set_up);
  sim::PackingReport report;
  std::unique_ptr<sim::Simulation> remote =
      solvers.set_up(scene, {.packing_cache_dir = dir / "job"}, report);
  EXPECT_FALSE(report.from_cache);
  EXPECT_EQ(report.iterations, setup.packing.iterations);
  EXPECT_EQ(report.final_residual, setup.packing.final_residual);
  EXPECT_EQ(report.cache_file,
            (dir / "job" / std::filesystem::path(setup.packing.cache_file).filename()).string());
  for (int s = 0; s < 10; ++s) {
    local->step();
    remote->step();
  }
  EXPECT_EQ(remote->diagnostics().kinetic_energy, local->diagnostics().kinetic_energy);
  expect_same_by_id(local->particles(), remote->particles());
  remote.reset();  // the job ends with its last solver

  scene.packing.tolerance = 1e-300;  // never converges: only the cancellation ends it
  scene.packing.max_iterations = 1000000;
  int polls = 0;
  sim::SetupOptions cancelled{.packing_cache_dir = dir / "job",
                              .cancelled = [&] { return ++polls > 3; }};
  EXPECT_THROW(solvers.set_up(scene, cancelled, report), sim::SetupCancelled);
  EXPECT_GT(polls, 3);
}

TEST(JobSolverFactories, ASolverInATwoRankJobStepsBitwiseLikeOneProcess) {
  const auto dir = fresh_directory("launch_job");
  const sim::Scene scene = small_tgv2d();
  sim::RunSetup setup = sim::setup_run(scene);
  auto local = sim::make_simulation(setup.solver, setup.particles);
  sim::SolverFactories solvers =
      job_solvers(options_for("mpiexec --oversubscribe --bind-to none -n {ranks}", dir / "job.log"))
          .solvers;
  std::unique_ptr<sim::Simulation> remote = solvers.make(scene, setup.particles);
  EXPECT_EQ(remote->diagnostics().kinetic_energy, local->diagnostics().kinetic_energy);
  for (int s = 0; s < 20; ++s) {
    local->step();
    remote->step();
  }
  EXPECT_EQ(remote->time(), local->time());
  EXPECT_EQ(remote->step_count(), 20u);
  EXPECT_EQ(remote->stable_time_step(), local->stable_time_step());
  EXPECT_EQ(remote->diagnostics().kinetic_energy, local->diagnostics().kinetic_energy);
  expect_same_by_id(local->particles(), remote->particles());
  EXPECT_EQ(remote->neighbour_list()->num_particles(), local->particles().size());

  // The particle products computed on the job's ranks against the analysis of all particles
  // here: the same bits (par/particle_products.hpp); request and reply cross the channel.
  const auto* ranks = dynamic_cast<const analysis::DistributedProducts*>(remote.get());
  ASSERT_NE(ranks, nullptr);
  const analysis::SnapshotPtr here = analysis::make_snapshot(*local);
  analysis::AnalysisConfig config;
  config.every = 1.0;
  config.products = {analysis::Product::Vorticity, analysis::Product::Slices,
                     analysis::Product::SubfilterStatistics};
  // A ν_t slice asked of an implicit run: no slice here, an empty one from the ranks.
  config.slice.fields.insert(analysis::SliceField::EddyViscosity);
  const analysis::AnalysisFrame frame = analysis::analyse(here, config);
  ASSERT_TRUE(frame.vorticity && frame.subfilter && frame.subfilter->alignment);
  ASSERT_EQ(frame.slices.size(), 2u);
  analysis::RanksRequest request = analysis::ranks_request(*here, config);
  const analysis::RanksProducts got = ranks->particle_products(request);
  EXPECT_EQ(got.request, request);
  EXPECT_EQ(got.mean_vorticity_squared, frame.vorticity->mean_vorticity_squared);
  EXPECT_EQ(got.slice_omega2, frame.slices[0].values);
  EXPECT_EQ(got.slice_tau, frame.slices[1].values);
  EXPECT_TRUE(request.slice_eddy && got.slice_eddy.empty());
  ASSERT_TRUE(got.statistics && got.statistics->alignment);
  EXPECT_EQ(got.statistics->mean_norm, frame.subfilter->mean_norm);
  EXPECT_EQ(got.statistics->joint.counts, frame.subfilter->joint.counts);
  EXPECT_EQ(got.statistics->alignment->counts, frame.subfilter->alignment->counts);
  request.fit_radius *= 3.0;  // further than the halo: refused, typed
  EXPECT_THROW(ranks->particle_products(request), std::invalid_argument);

  // A checkpoint written by the job's ranks into the one file: read back, it is the state the
  // service would have fetched (in id order), every array bit for bit; a failure on the job
  // comes back with the job's message.
  const auto* writer = dynamic_cast<const io::DistributedCheckpoints*>(remote.get());
  ASSERT_NE(writer, nullptr);
  const io::CheckpointMetadata metadata{scene::scene_to_json(scene).dump(), "test", "none"};
  writer->write_checkpoint(dir / "ckpt.h5", metadata, {.gzip_level = 1});
  const io::Checkpoint read = io::read_checkpoint(dir / "ckpt.h5");
  const sim::SolverState fetched = remote->state();
  EXPECT_EQ(read.state.time, fetched.time);
  EXPECT_EQ(read.state.step, fetched.step);
  EXPECT_EQ(read.state.particles.id, fetched.particles.id);
  EXPECT_EQ(read.state.particles.velocity, fetched.particles.velocity);
  EXPECT_EQ(read.state.particles.pressure, fetched.particles.pressure);
  EXPECT_EQ(read.state.list_reference_positions, fetched.list_reference_positions);
  EXPECT_EQ(read.metadata.scene_json, metadata.scene_json);
  EXPECT_TRUE(std::filesystem::exists(io::checkpoint_xdmf_path(dir / "ckpt.h5")));
  try {
    writer->write_checkpoint(dir / "missing" / "ckpt.h5", metadata, {});
    ADD_FAILURE() << "a checkpoint into a missing directory was written";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("cannot query the free space"), std::string::npos)
        << e.what();
  }
  local->step();
  remote->step();  // the job goes on after a failed checkpoint
  expect_same_by_id(local->particles(), remote->particles());

  // A live change: the job's solver continued on its ranks (no state crosses the channel), the
  // old one stale, the job the same; bitwise what a restore from the state gives.
  ASSERT_TRUE(solvers.change);
  EXPECT_THROW(solvers.change(*local, scene), std::invalid_argument);
  sim::Scene thicker = scene;  // the change: twice the viscosity
  thicker.fluid.dynamic_viscosity *= 2.0;
  std::unique_ptr<sim::Simulation> changed = solvers.change(*remote, thicker);
  EXPECT_THROW(remote->step(), std::logic_error);
  remote.reset();
  auto local_again = sim::restore_simulation(sim::make_solver_config(thicker), local->state());
  for (int s = 0; s < 10; ++s) {
    local_again->step();
    changed->step();
  }
  expect_same_by_id(local_again->particles(), changed->particles());
  changed.reset();  // the job finishes

  std::ifstream in(dir / "job.log");
  const std::string log((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(log.find("rank 0 of 2 done"), std::string::npos) << log;
}

/// Whether a process is gone (or a zombie nobody reaped yet).
bool gone(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(stat, text)) return true;
  const std::size_t paren = text.rfind(')');
  return paren != std::string::npos && paren + 2 < text.size() && text[paren + 2] == 'Z';
}

bool all_gone_within(const std::vector<pid_t>& pids, std::chrono::seconds limit) {
  const auto until = std::chrono::steady_clock::now() + limit;
  for (;;) {
    if (std::all_of(pids.begin(), pids.end(), gone)) return true;
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// A batch queue that never starts the job: the launch waited the whole connect timeout (and a
// stop of the run with it). Given up, it fails at once and the launcher is ended.
TEST(JobSolverFactories, AJobThatNeverConnectsIsGivenUpAtOnce) {
  const auto dir = fresh_directory("launch_never");
  const sim::Scene scene = small_tgv2d();
  const std::filesystem::path pid_file = dir / "launcher.pid";
  JobSolvers job = job_solvers(options_for(
      "sh -c 'echo $$ > \"" + pid_file.string() + "\"; sleep 300' {ranks}", dir / "job.log"));
  auto made = std::async(std::launch::async,
                         [&] { return job.solvers.make(scene, sim::setup_run(scene).particles); });
  ASSERT_EQ(made.wait_for(std::chrono::seconds(1)), std::future_status::timeout);
  pid_t launcher = 0;
  std::ifstream(pid_file) >> launcher;
  ASSERT_GT(launcher, 0);
  const auto asked = std::chrono::steady_clock::now();
  job.end_job("a test gave up on it");
  try {
    made.get();
    FAIL() << "no throw";
  } catch (const sim::SimulationError& e) {
    EXPECT_NE(std::string(e.what()).find("the service ended it: a test gave up on it"),
              std::string::npos)
        << e.what();
  }
  EXPECT_LT(seconds_since(asked), 10.0);
  EXPECT_TRUE(all_gone_within({launcher}, std::chrono::seconds(5)));
}

// A frozen rank (SIGSTOP, as a hung node): the step waited for it for good. Given up, the step
// fails within the job's end (a poll, SIGTERM, SIGKILL 5 s later) and no rank is left.
TEST(JobSolverFactories, AJobWithAFrozenRankIsGivenUpAndEnded) {
  const auto dir = fresh_directory("launch_frozen");
  const sim::Scene scene = small_tgv2d();
  const std::filesystem::path pids = dir / "ranks.pid";
  // Each rank notes its process id, then becomes the worker.
  JobSolvers job = job_solvers(
      options_for("mpiexec --oversubscribe --bind-to none -n {ranks} sh -c 'echo $$ >> \"" +
                      pids.string() + "\"; exec \"$0\" \"$@\"'",
                  dir / "job.log"));
  std::unique_ptr<sim::Simulation> remote =
      job.solvers.make(scene, sim::setup_run(scene).particles);
  remote->step();
  std::vector<pid_t> ranks;
  std::ifstream in(pids);
  for (pid_t pid = 0; in >> pid;) ranks.push_back(pid);
  ASSERT_EQ(ranks.size(), 2u);
  ASSERT_EQ(::kill(ranks.back(), SIGSTOP), 0);
  auto stepped = std::async(std::launch::async, [&] { remote->step(); });
  EXPECT_EQ(stepped.wait_for(std::chrono::seconds(2)), std::future_status::timeout);
  const auto asked = std::chrono::steady_clock::now();
  job.end_job("it did not answer");
  try {
    stepped.get();
    FAIL() << "no throw";
  } catch (const sim::SimulationError& e) {
    EXPECT_NE(std::string(e.what()).find("the service ended it: it did not answer"),
              std::string::npos)
        << e.what();
  }
  EXPECT_LT(seconds_since(asked), 15.0);
  EXPECT_TRUE(all_gone_within(ranks, std::chrono::seconds(10)));
  for (const pid_t pid : ranks)
    if (!gone(pid)) ::kill(pid, SIGKILL);  // not left behind by a failed test
}

}  // namespace
}  // namespace sphles::launch
