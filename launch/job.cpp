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

#include "launch/channel.hpp"
#include "remote/endpoint.hpp"
#include "remote/proxy.hpp"
#include "sim/initial_conditions.hpp"

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

/// The service gave up on the job (JobSolvers::end_job): it is ended without waiting for it.
class JobAbandoned : public JobEnded {
 public:
  using JobEnded::JobEnded;
};

/// Set by another thread when the service gives up on a job; read by the thread waiting on it.
class Abandonment {
 public:
  void set(const std::string& why) {
    std::lock_guard lock(mutex_);
    if (!set_) why_ = why;
    set_ = true;
  }
  /// Throws JobAbandoned when set.
  void check() const {
    std::lock_guard lock(mutex_);
    if (set_) throw JobAbandoned("the service ended it: " + why_);
  }

 private:
  mutable std::mutex mutex_;
  bool set_ = false;
  std::string why_;
};

/// One launched job: its process (the launcher, in a process group of its own) and the channel
/// to its rank 0, which carries the run's requests to the job's solver. Used by one thread at a
/// time (the run's solver thread).
class Job final : public remote::Transport {
 public:
  Job(LaunchOptions options, std::shared_ptr<const Abandonment> abandonment)
      : o_(std::move(options)), abandonment_(std::move(abandonment)) {
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
            abandonment_->check();
            check_alive("before its rank 0 connected");
            if (std::chrono::duration<double>(Clock::now() - started).count() >
                o_.connect_timeout_seconds)
              throw JobEnded("its rank 0 did not connect within " +
                             std::to_string(o_.connect_timeout_seconds) + " s");
          },
          kPollSeconds);
      const Message hello = channel_.receive(
          [&] {
            abandonment_->check();
            check_alive("before it said hello");
          },
          kPollSeconds);
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

  ~Job() override {
    if (!broken_) {
      try {
        Encoder finish;
        encode(finish, remote::Request{remote::Finish{}});
        channel_.send(MessageKind::Request, finish);
      } catch (const std::exception&) {
      }
    }
    end_process();
  }

  Job(const Job&) = delete;
  Job& operator=(const Job&) = delete;

  /// Sends the request and returns its reply; the job's errors are rethrown as their own type,
  /// a job that ended as a SimulationError saying how. A set-up's `cancelled` is polled while
  /// its reply is awaited: when it says so, the job is ended (a set-up cannot be told to stop
  /// half-way) and sim::SetupCancelled thrown.
  remote::Reply call(remote::Request request) override {
    const std::string what = std::string(remote::what(request)) + " failed";
    if (broken_) throw sim::SimulationError(diagnosis(what, "the job ended earlier"));
    const auto* set_up = std::get_if<remote::SetUp>(&request);
    const std::function<bool()> cancelled = set_up ? set_up->cancelled : nullptr;
    Message reply;
    try {
      Encoder body;
      encode(body, request);
      channel_.send(MessageKind::Request, body);
      reply = channel_.receive(
          [&] {
            abandonment_->check();
            check_alive("while the service waited for it");
            if (cancelled && cancelled())
              throw sim::SetupCancelled(what + ": cancelled, the MPI job ended");
          },
          kPollSeconds);
    } catch (const sim::SetupCancelled&) {
      broken_ = true;
      end_process();
      throw;
    } catch (const JobAbandoned& e) {
      broken_ = true;
      end_process();
      throw sim::SimulationError(diagnosis(what, e.what()));
    } catch (const std::exception& e) {
      broken_ = true;
      wait_for_exit(kExitStatusWaitSeconds);
      end_process();
      throw sim::SimulationError(diagnosis(what, e.what()));
    }
    if (reply.kind == MessageKind::Error) {
      Decoder d(reply.body);
      remote::throw_error(d);
    }
    if (reply.kind != MessageKind::Reply) throw ProtocolError("expected a reply from the job");
    return remote::decode_all<remote::Reply>(reply.body);
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
  std::shared_ptr<const Abandonment> abandonment_;
  std::string command_;
  Channel channel_;
  pid_t pid_ = -1;
  std::string exit_text_;
  bool broken_ = false;
};

/// The job of a run while some solver of it exists; launched by the first solver made.
class JobHolder {
 public:
  explicit JobHolder(LaunchOptions options) : options_(std::move(options)) {}

  /// The run's job, launched if it has none.
  std::shared_ptr<remote::Transport> current_job() {
    std::lock_guard lock(mutex_);
    std::shared_ptr<Job> job = job_.lock();
    if (!job) {
      // A new job starts with a new abandonment: giving up on one job is not giving up on the
      // next (a resume after a stop).
      auto abandonment = std::make_shared<Abandonment>();
      {
        std::lock_guard current(abandonment_mutex_);
        abandonment_ = abandonment;
      }
      job = std::make_shared<Job>(options_, abandonment);
      job_ = job;
    }
    return job;
  }

  /// Gives up on the current job (also while it is being launched, which holds `mutex_`).
  void end_job(const std::string& why) {
    std::lock_guard lock(abandonment_mutex_);
    if (abandonment_) abandonment_->set(why);
  }

 private:
  LaunchOptions options_;
  std::mutex mutex_;
  std::weak_ptr<Job> job_;
  std::mutex abandonment_mutex_;
  std::shared_ptr<Abandonment> abandonment_;
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

JobSolvers job_solvers(LaunchOptions options) {
  validate(options);
  auto holder = std::make_shared<JobHolder>(std::move(options));
  return {remote::remote_solvers([holder] { return holder->current_job(); }),
          [holder](const std::string& why) { holder->end_job(why); }};
}

void serve_job(const std::string& host, unsigned short port, const std::string& token,
               const sim::SolverFactories& solvers, int ranks) {
  Channel channel;
  channel.connect(host, port);
  Encoder hello;
  hello.string(token);
  hello.u64(static_cast<std::uint64_t>(ranks));
  channel.send(MessageKind::Hello, hello);
  remote::Endpoint endpoint(solvers);
  for (;;) {
    Message message;
    try {
      message = channel.receive();
    } catch (const ChannelClosed&) {
      return;  // the service went away: the job ends
    }
    MessageKind kind = MessageKind::Reply;
    Encoder reply;
    try {
      if (message.kind != MessageKind::Request)
        throw ProtocolError("unexpected message kind " +
                            std::to_string(static_cast<std::uint32_t>(message.kind)));
      remote::Request request = remote::decode_all<remote::Request>(message.body);
      if (std::holds_alternative<remote::Finish>(request)) return;
      encode(reply, endpoint.handle(std::move(request)));
    } catch (const std::exception& e) {
      kind = MessageKind::Error;
      reply = Encoder{};
      remote::encode_error(reply, e);
    }
    channel.send(kind, reply);
  }
}

}  // namespace sphles::launch
