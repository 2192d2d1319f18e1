// SPDX-License-Identifier: GPL-3.0-or-later
// sphles serve: the HTTP/WebSocket service (server/) over a run manager (control/).
#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/signal_set.hpp>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

#include "app/commands.hpp"
#include "control/resources.hpp"
#include "control/run_manager.hpp"
#include "launch/job.hpp"
#include "scene/document.hpp"
#include "scene/presets.hpp"
#include "server/http_server.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

namespace {

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ServeOptions {
  server::ServerOptions server;
  control::ManagerOptions manager;
  std::string launcher = "mpirun -n {ranks}";  // runs with ranks > 1; empty: none
  std::string job_address = "127.0.0.1";       // where the jobs' rank 0 connects back
  std::string start_run;                       // preset name or scene file; empty: none
  std::vector<std::string> overrides;          // --set, for --start-run
  std::string max_memory;                      // --max-memory as given; empty: the default
  std::string rank_memory;                     // --rank-memory as given; empty: ranks run here
  std::string packing_cache;                   // empty: the default
  std::string log_level;                       // --log-level
};

/// "12G", "512M", "2.5T", "1000000" (bytes; K, M, G, T are binary multiples, an optional "iB"
/// or "B" after them is accepted).
double parse_bytes(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  std::string unit = used > 0 ? text.substr(used) : "";
  for (const char* suffix : {"iB", "B"})
    if (unit.size() > std::strlen(suffix) && unit.ends_with(suffix))
      unit.resize(unit.size() - std::strlen(suffix));
  const std::string units = "KMGT";
  const std::size_t power = unit.size() == 1 ? units.find(unit[0]) : std::string::npos;
  if (used == 0 || !(value > 0.0) || (!unit.empty() && power == std::string::npos))
    throw UsageError(option +
                     " must be a positive size such as 8G, 512M or 1000000 (bytes), got '" + text +
                     "'");
  return unit.empty() ? value : value * std::pow(1024.0, static_cast<double>(power + 1));
}

/// The command line's options (CLI11 checks types and ranges).
void add_serve_options(CLI::App& serve, ServeOptions& o) {
  add_log_level_option(serve, o.log_level);
  serve.add_option("--port", o.server.port, "TCP port; 0 picks a free one (printed)")
      ->capture_default_str();
  serve.add_option("--bind", o.server.address, "address to listen on")->capture_default_str();
  serve
      .add_option("--data", o.manager.data_directory,
                  "data directory: runs live in DIR/runs/ (default sphles-data)")
      ->type_name("DIR");
  serve
      .add_option("--token", o.server.token,
                  "mutating calls need 'Authorization: Bearer TOKEN' (docs/api.md)")
      ->check([](const std::string& v) { return v.empty() ? "must not be empty" : ""; });
  serve
      .add_option("--web", o.server.web_root,
                  "directory of the dashboard's files (default: web/ of the source tree)")
      ->type_name("DIR");
  serve
      .add_option("--reference-dir", o.server.reference_dir,
                  "reference data: the DNS histories and `sphles reference` runs the runs are "
                  "compared with (default: data/reference/ of the source tree)")
      ->type_name("DIR")
      ->check(CLI::ExistingDirectory);
  serve
      .add_option("--scenes", o.server.scenes_dir,
                  "scene files the dashboard's New run form offers beside the presets (default: "
                  "scenes/ of the source tree)")
      ->type_name("DIR")
      ->check(CLI::ExistingDirectory);
  serve.add_option("--max-running", o.manager.max_running, "runs stepping at once")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  serve.add_option("--max-queued", o.manager.max_queued, "runs waiting for a slot")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  serve.add_option("--max-runs", o.manager.max_runs, "runs kept in the data directory")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  serve
      .add_option("--max-memory", o.max_memory,
                  "memory the active runs may use together, e.g. 8G or 512M (default: a share "
                  "of the machine's)")
      ->type_name("SIZE");
  serve
      .add_option("--rank-memory", o.rank_memory,
                  "memory one MPI rank may use where --launcher places it, e.g. 64G: runs with "
                  "ranks are then admitted by their per-rank estimate (a cluster's launcher); "
                  "default: the ranks run on this machine and count against --max-memory")
      ->type_name("SIZE");
  serve
      .add_option("--threads", o.manager.run_options.threads,
                  "OpenMP threads of each run's solver (per MPI rank); 0: the default")
      ->type_name("N")
      ->check(CLI::Range(0, 1024));
  serve
      .add_option("--packing-cache", o.packing_cache,
                  "directory of the packed initial lattices (default ~/.cache/sphles/packing)")
      ->type_name("DIR")
      ->check([](const std::string& v) { return v.empty() ? "must not be empty" : ""; });
  serve
      .add_option("--launcher", o.launcher,
                  "command that starts a run with ranks > 1 as an MPI job ({ranks}: the rank "
                  "count; '' refuses such runs; docs/scaling.md)")
      ->type_name("CMD")
      ->capture_default_str();
  serve
      .add_option("--job-address", o.job_address,
                  "address of this host the MPI jobs' rank 0 connects back to (0.0.0.0: every "
                  "interface, rank 0 is sent this host's name)")
      ->type_name("IP")
      ->capture_default_str();
  serve
      .add_option("--stop-grace", o.manager.run_options.stop_grace_seconds,
                  "seconds a stop waits for a run's next step and checkpoint; an MPI job that "
                  "has not answered by then is ended, and the run stops at its last checkpoint")
      ->type_name("SECONDS")
      ->check(CLI::Range(0.1, 86400.0))
      ->capture_default_str();
  serve.add_option("--max-ranks", o.manager.max_ranks, "MPI ranks one run may ask for")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  serve.add_option("--start-run", o.start_run, "create and start a run at once")
      ->type_name("PRESET|SCENE.json");
  repeatable(serve.add_option("--set", o.overrides, "change a key of the --start-run scene"))
      ->type_name("KEY=VALUE");
}

/// What CLI11 cannot check, and the MPI job launcher.
void finish_serve_options(ServeOptions& o) {
  if (!o.max_memory.empty()) o.manager.max_memory_bytes = parse_bytes("--max-memory", o.max_memory);
  if (!o.rank_memory.empty())
    o.manager.rank_memory_bytes = parse_bytes("--rank-memory", o.rank_memory);
  if (!o.packing_cache.empty()) o.manager.run_options.packing_cache_dir = o.packing_cache;
  if (!o.overrides.empty() && o.start_run.empty()) throw UsageError("--set needs --start-run");
  if (!o.launcher.empty()) {
    launch::LaunchOptions launch;
    launch.launcher = o.launcher;
    std::error_code error;
    launch.executable = std::filesystem::read_symlink("/proc/self/exe", error);
    if (error) throw UsageError("cannot find the sphles program for MPI jobs: " + error.message());
    launch.log_file = "job.log";
    launch.listen_address = o.job_address;
    boost::system::error_code invalid;
    boost::asio::ip::make_address(o.job_address, invalid);
    if (invalid)
      throw UsageError("--job-address must be an IP address of this host, got '" + o.job_address +
                       "'");
    try {
      launch::validate(launch);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--") + e.what());
    }
    // A run created with ranks > 1: its solver in a job of its own, logging to job.log in the
    // run directory, each rank with the --threads of the server's runs.
    o.manager.distribute = [launch](control::RunOptions& run, int ranks,
                                    const std::filesystem::path& directory) {
      launch::LaunchOptions job = launch;
      job.ranks = ranks;
      job.threads = run.threads;
      job.log_file = directory / "job.log";
      launch::JobSolvers solvers = launch::job_solvers(std::move(job));
      run.solvers = std::move(solvers.solvers);
      run.end_solver_job = std::move(solvers.end_job);
    };
  }
}

control::CreateRequest start_request(const std::string& scene_or_preset,
                                     const std::vector<std::string>& overrides) {
  control::CreateRequest request;
  const auto presets = scene::preset_names();
  if (std::filesystem::exists(scene_or_preset))
    request.scene = scene::read_scene_file(scene_or_preset);
  else if (std::find(presets.begin(), presets.end(), scene_or_preset) != presets.end())
    request.preset = scene_or_preset;
  else
    throw UsageError("--start-run: '" + scene_or_preset +
                     "' is neither a scene file nor a preset (see 'sphles presets')");
  request.overrides = overrides;
  request.start = true;
  return request;
}

}  // namespace

/// Whether an address to listen on is reachable from this machine only.
bool is_loopback(const std::string& address) {
  boost::system::error_code ec;
  const auto ip = boost::asio::ip::make_address(address, ec);
  return address == "localhost" || (!ec && ip.is_loopback());
}

int serve_command(ServeOptions options) {
  try {
    finish_serve_options(options);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "sphles serve: %s\nRun with --help for more information.\n", e.what());
    return kExitUsage;
  }
  logging::configure(logging::ConsoleStyle::timestamped, logging::parse_level(options.log_level));
  const auto log = logging::console("serve");

  // Signals are handled by the io_context below; block nothing, but install before any thread
  // starts so that every thread sees the same disposition.
  boost::asio::io_context signals_context;
  boost::asio::signal_set signals(signals_context, SIGINT, SIGTERM);

  std::optional<control::RunManager> manager;
  try {
    manager.emplace(options.manager);
  } catch (const std::exception& e) {
    log->error("cannot open the data directory {}: {}", options.manager.data_directory.string(),
               e.what());
    return kExitFailure;
  }
  log->info("sphles {}, data directory {}, {} run(s) found; runs may use {}{}", SPHLES_VERSION,
            options.manager.data_directory.string(), manager->list().size(),
            control::format_bytes(manager->options().max_memory_bytes),
            options.manager.rank_memory_bytes > 0.0
                ? ", each MPI rank " + control::format_bytes(options.manager.rank_memory_bytes)
                : std::string());

  if (!options.start_run.empty()) {
    try {
      const control::CreateRequest request = start_request(options.start_run, options.overrides);
      // The same command again continues the run it started before and that was stopped (Ctrl-C,
      // SIGTERM) from its newest checkpoint, instead of starting the scene again at t = 0.
      if (const auto stopped = manager->find_stopped_like(request)) {
        manager->resume(stopped->id());
        log->info("continuing run {} ({}) from t = {:g}", stopped->id(), options.start_run,
                  stopped->status().time);
      } else {
        const auto run = manager->create(request);
        log->info("started run {} ({})", run->id(), options.start_run);
      }
    } catch (const UsageError& e) {
      std::fprintf(stderr, "sphles serve: %s\n", e.what());
      return kExitUsage;
    } catch (const sim::SceneError& e) {
      std::fprintf(stderr, "sphles serve: --start-run %s: %s\n", options.start_run.c_str(),
                   e.what());
      return kExitUsage;
    } catch (const std::exception& e) {
      log->error("--start-run {}: {}", options.start_run, e.what());
      return kExitFailure;
    }
  }

  server::HttpServer http(*manager, options.server);
  try {
    http.start();
  } catch (const std::exception& e) {
    log->error("{}", e.what());
    manager->shutdown();
    return kExitFailure;
  }
  if (!std::filesystem::is_directory(options.server.web_root))
    log->warn("web root {} does not exist (API only)", options.server.web_root.string());
  if (!options.server.token.empty())
    log->info("mutating calls need 'Authorization: Bearer <token>'");
  else if (!is_loopback(options.server.address))
    log->warn(
        "listening on {} without --token: anyone who can reach it can create, change and stop "
        "runs",
        options.server.address);
  std::printf("sphles serve: listening on %s\n", http.url().c_str());
  std::fflush(stdout);

  int received = 0;
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (!ec) received = signal_number;
  });
  signals_context.run();

  log->info("signal {}: stopping runs (checkpoints) and the server", received);
  http.stop_accepting();
  manager->shutdown();  // every active run writes a checkpoint and is marked stopped
  http.stop();
  manager.reset();
  log->info("stopped");
  return kExitOk;
}

void add_serve_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<ServeOptions>();
  options->server.web_root = SPHLES_WEB_DIR;
  options->manager.data_directory = "sphles-data";
  CLI::App* serve = app.add_subcommand("serve", "the HTTP/WebSocket service and browser dashboard");
  serve->footer(
      "The HTTP/WebSocket service and browser dashboard (docs/api.md, docs/dashboard.md). Runs "
      "live in DIR/runs/ and survive restarts; prints 'sphles serve: listening on URL'. SIGINT "
      "or SIGTERM stops every run with a checkpoint, then the server.");
  add_serve_options(*serve, *options);
  serve->callback([options, &exit_code] { exit_code = serve_command(*options); });
}

}  // namespace sphles::app
