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
  std::string host;
  unsigned short port = 0;
  std::string token;
  int threads = 0;
};

WorkerOptions parse_worker_options(const std::vector<std::string>& args) {
  WorkerOptions o;
  for (std::size_t k = 0; k < args.size(); ++k) {
    const std::string& a = args[k];
    if (k + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
    const std::string& v = args[++k];
    if (a == "--connect") {
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
    } else if (a == "--token") {
      o.token = v;
    } else if (a == "--threads") {
      o.threads = std::stoi(v);
      if (o.threads < 1) throw std::invalid_argument("--threads must be at least 1");
    } else {
      throw std::invalid_argument("unknown option '" + a + "'");
    }
  }
  if (o.host.empty() || o.token.empty())
    throw std::invalid_argument("--connect HOST:PORT and --token TOKEN are required");
  return o;
}

}  // namespace

int worker_command(const std::vector<std::string>& args) {
  WorkerOptions options;
  try {
    options = parse_worker_options(args);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles worker: %s\n", e.what());
    return kExitUsage;
  }
  if (options.threads > 0) omp_set_num_threads(options.threads);
  return par::drive_from_rank_zero([&](par::Driver& driver) {
    launch::WorkerSolvers solvers;
    solvers.ranks = driver.ranks();
    solvers.make = [&driver](const sim::Scene& scene, sim::ParticleArrays all) {
      return driver.make(scene, std::move(all));
    };
    solvers.restore = [&driver](const sim::Scene& scene, sim::SolverState state) {
      return driver.restore(scene, std::move(state));
    };
    int rc = kExitOk;
    try {
      launch::serve_job(options.host, options.port, options.token, solvers);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "sphles worker: %s\n", e.what());
      rc = kExitFailure;
    }
    std::fprintf(stderr, "sphles worker: rank 0 of %d done\n", driver.ranks());
    return rc;
  });
}

}  // namespace sphles::app
