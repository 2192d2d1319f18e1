// SPDX-License-Identifier: GPL-3.0-or-later
// sphles worker: one rank of a run's MPI job that the service launched (launch/job.hpp). Not for
// people: the service starts it as `LAUNCHER sphles worker --connect HOST:PORT --token T`.
// Rank 0 connects back to the service and drives the distributed solver (par::Driver) as the
// service asks; the other ranks serve rank 0 (par::serve_commands).
#include <omp.h>

#include <cstdio>
#include <stdexcept>
#include <string>

#include "app/commands.hpp"
#include "launch/job.hpp"
#include "par/driver.hpp"

namespace sphles::app {

namespace {

struct WorkerOptions {
  std::string connect;  // HOST:PORT as given
  std::string host;
  unsigned short port = 0;
  std::string token;
  int threads = 0;
  std::string log_level;
};

/// HOST:PORT of --connect into the options.
void set_connect(WorkerOptions& o, const std::string& v) {
  const std::size_t colon = v.rfind(':');
  int port = 0;
  try {
    port = colon == std::string::npos ? 0 : std::stoi(v.substr(colon + 1));
  } catch (const std::exception&) {
    port = 0;
  }
  if (colon == 0 || port < 1 || port > 65535)
    throw std::invalid_argument("--connect must be HOST:PORT, got '" + v + "'");
  o.host = v.substr(0, colon);
  o.port = static_cast<unsigned short>(port);
}

int worker_command(WorkerOptions options) {
  try {
    set_connect(options, options.connect);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles worker: %s\n", e.what());
    return kExitUsage;
  }
  logging::configure(logging::ConsoleStyle::timestamped, logging::parse_level(options.log_level));
  const auto log = logging::console("worker");
  if (options.threads > 0) omp_set_num_threads(options.threads);
  return par::drive_from_rank_zero([&](par::Driver& driver) {
    const sim::SolverFactories solvers = driver.factories();
    int rc = kExitOk;
    try {
      launch::serve_job(options.host, options.port, options.token, solvers, driver.ranks());
    } catch (const std::exception& e) {
      log->error("{}", e.what());
      rc = kExitFailure;
    }
    log->info("rank 0 of {} done", driver.ranks());
    return rc;
  });
}

}  // namespace

void add_worker_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<WorkerOptions>();
  CLI::App* worker = app.add_subcommand(
      "worker", "a rank of an MPI job the service launched (not for use by hand)");
  worker->group("");  // hidden from the program's help
  worker->add_option("--connect", o->connect, "the service's HOST:PORT")->required();
  worker->add_option("--token", o->token, "the job's token")->required();
  add_threads_option(*worker, o->threads, "OpenMP threads per rank");
  add_log_level_option(*worker, o->log_level);
  worker->callback([o, &exit_code] { exit_code = worker_command(*o); });
}

}  // namespace sphles::app
