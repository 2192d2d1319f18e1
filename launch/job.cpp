// SPDX-License-Identifier: GPL-3.0-or-later
#include "launch/job.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "analysis/snapshot.hpp"
#include "io/checkpoint.hpp"
#include "launch/channel.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/state_view.hpp"

extern char** environ;

namespace sphles::launch {

namespace {

using Clock = std::chrono::steady_clock;

/// How often a waiting request looks whether the job has ended [s].
constexpr double kPollSeconds = 0.2;
/// After the connection broke: how long to wait for the launcher's exit status [s].
constexpr double kExitStatusWaitSeconds = 5.0;
/// After SIGTERM to the job's process group: how long before SIGKILL [s].
constexpr double kTerminateGraceSeconds = 5.0;
/// Lines of the job's log quoted in a failure.
constexpr std::size_t kLogLinesQuoted = 6;
constexpr std::size_t kLogCharactersQuoted = 800;

std::string shell_quote(const std::string& text) {
  std::string quoted = "'";
  for (const char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

std::string random_token() {
  std::random_device device;
  std::string token;
  char hex[9];
  for (int k = 0; k < 4; ++k) {
    std::snprintf(hex, sizeof hex, "%08x", device());
    token += hex;
  }
  return token;
}

std::string describe_wait_status(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return "was killed by signal " + std::to_string(WTERMSIG(status));
  return "ended (wait status " + std::to_string(status) + ")";
}

/// The last non-empty lines of a log, joined by " | ".
std::string log_tail(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return "";
  std::vector<std::string> lines;
  // Lines of text only: not blank, not one of the launcher's rules of dashes.
  for (std::string line; std::getline(in, line);)
    if (line.find_first_not_of(" \t\r-=*") != std::string::npos) lines.push_back(line);
  std::string tail;
  const std::size_t first = lines.size() > kLogLinesQuoted ? lines.size() - kLogLinesQuoted : 0;
  for (std::size_t k = first; k < lines.size(); ++k) tail += (tail.empty() ? "" : " | ") + lines[k];
  if (tail.size() > kLogCharactersQuoted)
    tail = "..." + tail.substr(tail.size() - kLogCharactersQuoted);
  return tail;
}

/// Where rank 0 connects to reach a service listening on `address`: the address itself, or this
/// host's name when the service listens on every interface.
std::string connect_host(const std::string& address) {
  if (address != "0.0.0.0" && address != "::") return address;
  char name[256] = {};
  if (::gethostname(name, sizeof name - 1) != 0 || name[0] == '\0')
    throw std::runtime_error("the job address " + address +
                             " needs this host's name, which gethostname does not give");
  return name;
}

/// The job ended (or broke its connection) while the service waited for it.
class JobEnded : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One launched job: its process (the launcher, in a process group of its own) and the channel
/// to its rank 0. Used by one thread at a time (the run's solver thread).
class Job {
 public:
  explicit Job(LaunchOptions options) : o_(std::move(options)) {
    command_ = launch_command(o_);
    try {
      const unsigned short port = channel_.listen(o_.listen_address);
      const std::string token = random_token();
      std::string shell = "exec " + command_ + " " + shell_quote(o_.executable.string()) +
                          " worker --connect " + shell_quote(connect_host(o_.listen_address)) +
                          ":" + std::to_string(port) + " --token " + token;
      if (o_.threads > 0) shell += " --threads " + std::to_string(o_.threads);
      spawn(shell);
      const auto started = Clock::now();
      channel_.accept(
          [&] {
            check_alive("before its rank 0 connected");
            if (std::chrono::duration<double>(Clock::now() - started).count() >
                o_.connect_timeout_seconds)
              throw JobEnded("its rank 0 did not connect within " +
                             std::to_string(o_.connect_timeout_seconds) + " s");
          },
          kPollSeconds);
      const Message hello =
          channel_.receive([&] { check_alive("before it said hello"); }, kPollSeconds);
      if (hello.kind != MessageKind::Hello) throw ProtocolError("the job's first message");
      Decoder d(hello.body);
      if (d.string() != token) throw ProtocolError("a connection without the job's token");
      const std::uint64_t ranks = d.u64();
      d.finish();
      if (ranks != static_cast<std::uint64_t>(o_.ranks))
        throw JobEnded("the job has " + std::to_string(ranks) + " ranks where the run asked for " +
                       std::to_string(o_.ranks) + " (does the launcher place {ranks}?)");
    } catch (const std::exception& e) {
      broken_ = true;
      end_process();
      throw sim::SimulationError(diagnosis("could not start the MPI job", e.what()));
    }
  }

  ~Job() {
    if (!broken_) {
      try {
        channel_.send(MessageKind::Finish);
      } catch (const std::exception&) {
      }
    }
    end_process();
  }

  Job(const Job&) = delete;
  Job& operator=(const Job&) = delete;

  /// A new solver replaces the job's current one: solvers made before are stale.
  std::uint64_t next_generation() { return ++generation_; }
  void require_current(std::uint64_t generation) const {
    if (generation != generation_)
      throw std::logic_error("a solver of the MPI job was used after a newer one was made");
  }

  /// Sends a request and returns its reply; the job's errors are rethrown as their own type,
  /// a job that ended as a SimulationError saying how. `cancelled` (may be empty) is polled
  /// while the reply is awaited: when it says so, the job is ended (a set-up cannot be told
  /// to stop half-way) and sim::SetupCancelled thrown.
  Message request(MessageKind kind, const Encoder& body, const char* what,
                  const std::function<bool()>& cancelled = {}) {
    if (broken_) throw sim::SimulationError(diagnosis(what, "the job ended earlier"));
    Message reply;
    try {
      channel_.send(kind, body);
      reply = channel_.receive(
          [&] {
            check_alive("while the service waited for it");
            if (cancelled && cancelled())
              throw sim::SetupCancelled(std::string(what) + ": cancelled, the MPI job ended");
          },
          kPollSeconds);
    } catch (const sim::SetupCancelled&) {
      broken_ = true;
      end_process();
      throw;
    } catch (const std::exception& e) {
      broken_ = true;
      wait_for_exit(kExitStatusWaitSeconds);
      end_process();
      throw sim::SimulationError(diagnosis(what, e.what()));
    }
    if (reply.kind == MessageKind::Error) {
      Decoder d(reply.body);
      throw_error(d);
    }
    return reply;
  }

  SolverStatus status(MessageKind kind, const Encoder& body, const char* what) {
    Message reply = request(kind, body, what);
    if (reply.kind != MessageKind::Status) throw ProtocolError("expected a status reply");
    Decoder d(reply.body);
    SolverStatus s = decode_status(d);
    d.finish();
    return s;
  }

 private:
  void spawn(const std::string& shell) {
    posix_spawn_file_actions_t actions;
    posix_spawnattr_t attributes;
    posix_spawn_file_actions_init(&actions);
    posix_spawnattr_init(&attributes);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, o_.log_file.c_str(),
                                     O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    // A process group of its own: the terminal's Ctrl-C goes to the service alone (which stops
    // its runs with checkpoints), and the whole job can be signalled at once.
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    for (const int s : {SIGINT, SIGTERM, SIGPIPE, SIGHUP}) sigaddset(&defaults, s);
    posix_spawnattr_setsigmask(&attributes, &none);
    posix_spawnattr_setsigdefault(&attributes, &defaults);
    posix_spawnattr_setpgroup(&attributes, 0);
    posix_spawnattr_setflags(
        &attributes, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    std::string sh = "/bin/sh", dash_c = "-c", command = shell;
    char* argv[] = {sh.data(), dash_c.data(), command.data(), nullptr};
    const int error = posix_spawn(&pid_, "/bin/sh", &actions, &attributes, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attributes);
    if (error != 0) {
      pid_ = -1;
      throw JobEnded(std::string("the launcher could not be started: ") + std::strerror(error));
    }
  }

  /// Throws JobEnded if the launcher has exited.
  void check_alive(const std::string& when) {
    if (exited()) throw JobEnded("the job " + exit_text_ + " " + when);
  }

  bool exited() {
    if (pid_ <= 0) return true;
    int status = 0;
    const pid_t r = ::waitpid(pid_, &status, WNOHANG);
    if (r == pid_ || (r < 0 && errno == ECHILD)) {
      exit_text_ = r == pid_ ? describe_wait_status(status) : "ended";
      pid_ = -1;
      return true;
    }
    return false;
  }

  bool wait_for_exit(double seconds) {
    const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(seconds));
    while (!exited()) {
      if (Clock::now() > until) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return true;
  }

  /// Waits for the job to end after Finish, then terminates (and kills) its process group.
  void end_process() {
    if (pid_ <= 0) return;
    const pid_t group = pid_;
    if (wait_for_exit(broken_ ? 0.0 : o_.finish_timeout_seconds)) return;
    ::kill(-group, SIGTERM);
    if (wait_for_exit(kTerminateGraceSeconds)) return;
    ::kill(-group, SIGKILL);
    int status = 0;
    ::waitpid(group, &status, 0);
    exit_text_ = describe_wait_status(status);
    pid_ = -1;
  }

  std::string diagnosis(const std::string& what, const std::string& cause) const {
    std::string text = "MPI job (" + std::to_string(o_.ranks) + " ranks, `" + command_ +
                       "`): " + what + ": " + cause;
    if (!exit_text_.empty() && cause.find(exit_text_) == std::string::npos)
      text += "; the launcher " + exit_text_;
    const std::string tail = log_tail(o_.log_file);
    text += tail.empty() ? "; its log " + o_.log_file.filename().string() + " is empty"
                         : "; last lines of " + o_.log_file.filename().string() + ": " + tail;
    return text;
  }

  LaunchOptions o_;
  std::string command_;
  Channel channel_;
  pid_t pid_ = -1;
  std::string exit_text_;
  bool broken_ = false;
  std::uint64_t generation_ = 0;
};

/// The job's solver as the run sees it.
class RemoteSimulation final : public sim::Simulation,
                               public analysis::DistributedProducts,
                               public io::DistributedCheckpoints {
 public:
  RemoteSimulation(std::shared_ptr<Job> job, std::uint64_t generation, sim::SolverConfig config,
                   SolverStatus status)
      : job_(std::move(job)),
        generation_(generation),
        config_(std::move(config)),
        status_(std::move(status)) {}

  void step(double max_dt) override {
    job_->require_current(generation_);
    Encoder e;
    e.f64(max_dt);
    status_ = job_->status(MessageKind::Step, e, "a step failed");
  }
  double time() const override { return status_.time; }
  std::uint64_t step_count() const override { return status_.step; }
  const sim::StepDiagnostics& diagnostics() const override { return status_.diagnostics; }
  const sim::SolverConfig& config() const override { return config_; }
  double stable_time_step() const override { return status_.stable_time_step; }
  std::vector<double> case_diagnostics(const sim::Scene& scene) const override {
    job_->require_current(generation_);
    Encoder e;
    e.string(scene::scene_to_json(scene).dump());
    Message reply = job_->request(MessageKind::CaseDiagnostics, e, "case diagnostics failed");
    if (reply.kind != MessageKind::Values) throw ProtocolError("expected a values reply");
    Decoder d(reply.body);
    std::vector<double> values = d.doubles();
    d.finish();
    return values;
  }

  /// Computed by the job's ranks where the particles live (the job's solver is par's); only the
  /// spectrum crosses the channel.
  analysis::EnergySpectrum velocity_spectrum(int points_per_side) const override {
    job_->require_current(generation_);
    Encoder e;
    e.u64(static_cast<std::uint64_t>(points_per_side));
    Message reply = job_->request(MessageKind::Spectrum, e, "the spectrum failed");
    if (reply.kind != MessageKind::Values) throw ProtocolError("expected a values reply");
    Decoder d(reply.body);
    analysis::EnergySpectrum spectrum;
    spectrum.delta_k = d.f64();
    spectrum.wavenumber = d.doubles();
    spectrum.energy = d.doubles();
    spectrum.k2_energy = d.doubles();
    d.finish();
    return spectrum;
  }

  /// The particle products of `request`, computed by the job's ranks
  /// (par/particle_products.hpp).
  analysis::RanksProducts particle_products(const analysis::RanksRequest& request) const override {
    job_->require_current(generation_);
    Encoder e;
    encode(e, request);
    Message reply = job_->request(MessageKind::ParticleProducts, e, "the particle products failed");
    if (reply.kind != MessageKind::Values) throw ProtocolError("expected a values reply");
    Decoder d(reply.body);
    analysis::RanksProducts result = decode_ranks_products(d);
    d.finish();
    if (!(result.request == request)) throw ProtocolError("the job answered another request");
    return result;
  }

  /// Written by the job's ranks (par's solver), each its own particles, into `path` on the file
  /// system the job shares with the service; no state crosses the channel.
  void write_checkpoint(const std::filesystem::path& path, const io::CheckpointMetadata& metadata,
                        const io::CheckpointWriteOptions& options) const override {
    job_->require_current(generation_);
    Encoder e;
    e.string(path.string());
    e.string(metadata.scene_json);
    e.string(metadata.code_version);
    e.string(metadata.packing);
    e.u64(static_cast<std::uint64_t>(options.gzip_level));
    // A failure on the job comes back with the job's message (io::CheckpointError's there).
    job_->status(MessageKind::WriteCheckpoint, e, "writing a checkpoint failed");
  }

  const sim::ParticleArrays& particles() const override { return whole().particles; }
  std::size_t owned_count() const override { return particles().size(); }
  sim::SolverState state() const override { return whole(); }
  std::shared_ptr<const sim::NeighbourList> neighbour_list() const override {
    return view_.neighbour_list(step_count(), particles());
  }

 private:
  const sim::SolverState& whole() const {
    return view_.state(step_count(), [this] {
      job_->require_current(generation_);
      Message reply = job_->request(MessageKind::State, Encoder{}, "fetching the state failed");
      if (reply.kind != MessageKind::SolverState) throw ProtocolError("expected a state reply");
      Decoder d(reply.body);
      sim::SolverState s = decode_state(d);
      d.finish();
      return s;
    });
  }

  std::shared_ptr<Job> job_;
  std::uint64_t generation_;
  sim::SolverConfig config_;
  SolverStatus status_;
  sim::StateView view_{config_};
};

/// A checkpoint file in a request: its path.
void encode(Encoder& e, const std::filesystem::path& file) {
  e.string(file.string());
}

void encode(Encoder& e, const sim::PackingReport& r) {
  e.u64(static_cast<std::uint64_t>(r.iterations));
  e.f64(r.initial_residual);
  e.f64(r.final_residual);
  e.u64(r.converged ? 1 : 0);
  e.u64(r.from_cache ? 1 : 0);
  e.string(r.cache_file);
}

sim::PackingReport decode_packing_report(Decoder& d) {
  sim::PackingReport r;
  const std::uint64_t iterations = d.u64();
  if (iterations > static_cast<std::uint64_t>(std::numeric_limits<int>::max()))
    throw ProtocolError("a packing report of " + std::to_string(iterations) + " iterations");
  r.iterations = static_cast<int>(iterations);
  r.initial_residual = d.f64();
  r.final_residual = d.f64();
  r.converged = d.u64() != 0;
  r.from_cache = d.u64() != 0;
  r.cache_file = d.string();
  return r;
}

/// A request whose body is the scene alone (a live change).
struct SceneOnly {};
void encode(Encoder&, SceneOnly) {}

/// The job of a run while some solver of it exists; launched by the first solver made.
class JobHolder {
 public:
  explicit JobHolder(LaunchOptions options) : options_(std::move(options)) {}

  template <class Body>
  std::unique_ptr<sim::Simulation> make(MessageKind kind, const sim::Scene& scene, Body&& body,
                                        const char* what) {
    std::shared_ptr<Job> job = current_job();
    Encoder e;
    e.string(scene::scene_to_json(scene).dump());
    encode(e, body);
    const std::uint64_t generation = job->next_generation();
    SolverStatus status = job->status(kind, e, what);
    return std::make_unique<RemoteSimulation>(std::move(job), generation,
                                              sim::make_solver_config(scene), std::move(status));
  }

  /// A new run whose particles the job's ranks make and pack (par::Driver::set_up).
  std::unique_ptr<sim::Simulation> set_up(const sim::Scene& scene, const sim::SetupOptions& options,
                                          sim::PackingReport& report) {
    std::shared_ptr<Job> job = current_job();
    Encoder e;
    e.string(scene::scene_to_json(scene).dump());
    e.string(options.packing_cache_dir.string());
    const std::uint64_t generation = job->next_generation();
    const Message reply = job->request(MessageKind::SetUp, e,
                                       "setting up the run on the ranks failed", options.cancelled);
    if (reply.kind != MessageKind::Status) throw ProtocolError("expected a status reply");
    Decoder d(reply.body);
    SolverStatus status = decode_status(d);
    report = decode_packing_report(d);
    d.finish();
    return std::make_unique<RemoteSimulation>(std::move(job), generation,
                                              sim::make_solver_config(scene), std::move(status));
  }

 private:
  /// The run's job, launched if it has none.
  std::shared_ptr<Job> current_job() {
    std::lock_guard lock(mutex_);
    std::shared_ptr<Job> job = job_.lock();
    if (!job) {
      job = std::make_shared<Job>(options_);
      job_ = job;
    }
    return job;
  }

  LaunchOptions options_;
  std::mutex mutex_;
  std::weak_ptr<Job> job_;
};

}  // namespace

void validate(const LaunchOptions& o) {
  if (o.launcher.find("{ranks}") == std::string::npos)
    throw std::invalid_argument("launcher: '" + o.launcher +
                                "' must contain {ranks} (it becomes the rank count)");
  if (o.ranks < 1) throw std::invalid_argument("ranks: must be at least 1");
  if (o.executable.empty()) throw std::invalid_argument("executable: empty");
  if (o.log_file.empty()) throw std::invalid_argument("log_file: empty");
  if (!(o.connect_timeout_seconds > 0.0) || !(o.finish_timeout_seconds > 0.0))
    throw std::invalid_argument("timeouts: must be positive");
}

std::string launch_command(const LaunchOptions& o) {
  std::string command = o.launcher;
  const std::string placeholder = "{ranks}";
  for (std::size_t at = command.find(placeholder); at != std::string::npos;
       at = command.find(placeholder, at))
    command.replace(at, placeholder.size(), std::to_string(o.ranks));
  return command;
}

sim::SolverFactories job_solvers(LaunchOptions options) {
  validate(options);
  auto holder = std::make_shared<JobHolder>(std::move(options));
  sim::SolverFactories solvers;
  solvers.make = [holder](const sim::Scene& scene, sim::ParticleArrays particles) {
    return holder->make(MessageKind::Make, scene, particles, "setting up the solver failed");
  };
  solvers.restore = [holder](const sim::Scene& scene, sim::SolverState state) {
    return holder->make(MessageKind::Restore, scene, state, "restoring the solver failed");
  };
  // The job's ranks read the checkpoint, each its part (par::Driver::restore_file): the file
  // must be at the same path for the job (the service's node or a shared file system).
  solvers.restore_file = [holder](const sim::Scene& scene, const std::filesystem::path& file) {
    return holder->make(MessageKind::RestoreFile, scene, file,
                        "restoring the solver from its checkpoint failed");
  };
  // A live change: the job's ranks continue their own particles (par::Driver::change), so no
  // state crosses the channel.
  solvers.change = [holder](const sim::Simulation& current, const sim::Scene& scene) {
    if (!dynamic_cast<const RemoteSimulation*>(&current))
      throw std::invalid_argument("a live change of a solver that is not the job's");
    return holder->make(MessageKind::Change, scene, SceneOnly{}, "changing the solver failed");
  };
  // A new run: the job's ranks make, pack and set up its particles, each its part; the
  // packing cache directory must be the same path for the job (as restore_file's file).
  solvers.set_up = [holder](const sim::Scene& scene, const sim::SetupOptions& options,
                            sim::PackingReport& report) {
    return holder->set_up(scene, options, report);
  };
  return solvers;
}

void serve_job(const std::string& host, unsigned short port, const std::string& token,
               const sim::SolverFactories& solvers, int ranks) {
  Channel channel;
  channel.connect(host, port);
  Encoder hello;
  hello.string(token);
  hello.u64(static_cast<std::uint64_t>(ranks));
  channel.send(MessageKind::Hello, hello);
  std::unique_ptr<sim::Simulation> simulation;
  const auto status = [&] {
    Encoder e;
    encode(e, SolverStatus{simulation->time(), simulation->step_count(),
                           simulation->stable_time_step(), simulation->diagnostics()});
    return e;
  };
  for (;;) {
    Message request;
    try {
      request = channel.receive();
    } catch (const ChannelClosed&) {
      return;  // the service went away: the job ends
    }
    if (request.kind == MessageKind::Finish) return;
    MessageKind kind = MessageKind::Status;
    Encoder reply;
    try {
      Decoder d(request.body);
      switch (request.kind) {
        case MessageKind::Make:
        case MessageKind::Restore:
        case MessageKind::RestoreFile:
        case MessageKind::Change: {
          const sim::Scene scene = scene::parse_scene(nlohmann::json::parse(d.string()));
          std::unique_ptr<sim::Simulation> fresh;
          if (request.kind == MessageKind::Make) {
            sim::ParticleArrays particles = decode_particles(d);
            d.finish();
            fresh = solvers.make(scene, std::move(particles));
          } else if (request.kind == MessageKind::Change) {
            d.finish();
            if (!simulation) throw std::logic_error("a change before the solver was made");
            if (!solvers.change)
              throw std::invalid_argument("the job's solvers do not change in place");
            fresh = solvers.change(*simulation, scene);
          } else if (request.kind == MessageKind::RestoreFile) {
            const std::filesystem::path file = d.string();
            d.finish();
            if (!solvers.restore_file)
              throw std::invalid_argument("the job's solvers do not read checkpoint files");
            fresh = solvers.restore_file(scene, file);
          } else {
            sim::SolverState state = decode_state(d);
            d.finish();
            fresh = solvers.restore(scene, std::move(state));
          }
          simulation = std::move(fresh);  // the new solver first, then the old one goes
          reply = status();
          break;
        }
        case MessageKind::SetUp: {
          const sim::Scene scene = scene::parse_scene(nlohmann::json::parse(d.string()));
          sim::SetupOptions options;
          options.packing_cache_dir = d.string();
          d.finish();
          if (!solvers.set_up) throw std::invalid_argument("the job's solvers do not set up runs");
          sim::PackingReport report;
          std::unique_ptr<sim::Simulation> fresh = solvers.set_up(scene, options, report);
          simulation = std::move(fresh);
          reply = status();
          encode(reply, report);
          break;
        }
        case MessageKind::Step: {
          const double max_dt = d.f64();
          d.finish();
          if (!simulation) throw std::logic_error("a step before the solver was made");
          simulation->step(max_dt);
          reply = status();
          break;
        }
        case MessageKind::CaseDiagnostics: {
          const sim::Scene scene = scene::parse_scene(nlohmann::json::parse(d.string()));
          d.finish();
          if (!simulation) throw std::logic_error("case diagnostics before the solver was made");
          kind = MessageKind::Values;
          reply.doubles(simulation->case_diagnostics(scene));
          break;
        }
        case MessageKind::Spectrum: {
          const std::uint64_t points = d.u64();
          d.finish();
          if (!simulation) throw std::logic_error("a spectrum before the solver was made");
          const auto* ranks = dynamic_cast<const analysis::DistributedProducts*>(simulation.get());
          if (!ranks || points < 2 || points > std::numeric_limits<int>::max())
            throw std::invalid_argument("the job's solver does not compute a spectrum on " +
                                        std::to_string(points) + " points per side");
          const analysis::EnergySpectrum spectrum =
              ranks->velocity_spectrum(static_cast<int>(points));
          kind = MessageKind::Values;
          reply.f64(spectrum.delta_k);
          reply.doubles(spectrum.wavenumber);
          reply.doubles(spectrum.energy);
          reply.doubles(spectrum.k2_energy);
          break;
        }
        case MessageKind::ParticleProducts: {
          const analysis::RanksRequest r = decode_ranks_request(d);
          d.finish();
          if (!simulation) throw std::logic_error("particle products before the solver was made");
          const auto* ranks = dynamic_cast<const analysis::DistributedProducts*>(simulation.get());
          if (!ranks)
            throw std::invalid_argument("the job's solver does not compute particle products");
          kind = MessageKind::Values;
          encode(reply, ranks->particle_products(r));
          break;
        }
        case MessageKind::WriteCheckpoint: {
          const std::filesystem::path path = d.string();
          io::CheckpointMetadata metadata;
          metadata.scene_json = d.string();
          metadata.code_version = d.string();
          metadata.packing = d.string();
          const std::uint64_t gzip = d.u64();
          d.finish();
          if (!simulation) throw std::logic_error("a checkpoint before the solver was made");
          const auto* ranks = dynamic_cast<const io::DistributedCheckpoints*>(simulation.get());
          if (!ranks || gzip > 9)
            throw std::invalid_argument(
                "the job's solver does not write checkpoints with gzip "
                "level " +
                std::to_string(gzip));
          ranks->write_checkpoint(path, metadata, {.gzip_level = static_cast<int>(gzip)});
          reply = status();
          break;
        }
        case MessageKind::State:
          if (!simulation) throw std::logic_error("a state before the solver was made");
          kind = MessageKind::SolverState;
          encode(reply, simulation->state());
          break;
        default:
          throw ProtocolError("unexpected request kind " +
                              std::to_string(static_cast<std::uint32_t>(request.kind)));
      }
    } catch (const std::exception& e) {
      kind = MessageKind::Error;
      reply = Encoder{};
      encode_error(reply, e);
    }
    channel.send(kind, reply);
  }
}

}  // namespace sphles::launch
