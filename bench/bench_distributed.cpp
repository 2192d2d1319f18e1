// SPDX-License-Identifier: GPL-3.0-or-later
// Steps of a distributed run (docs/scaling.md): the 3D TGV of bench_solver (WC4 8Δl,
// lattice displaced at random by 0.05 Δl, packing skipped) over the MPI ranks it is started on,
// each rank with the OpenMP threads OMP_NUM_THREADS gives it. Prints, on rank 0, the median wall
// time per step (the slowest rank's), the share of it the exchange took on the rank where it
// took most (migration, halo builds and refreshes, global reductions, including the wait for
// other ranks), the bytes sent per step and the halo size; then the median time of the energy
// spectrum computed where the particles live (par/spectrum.hpp, M = 2 per_side: the first call,
// then the median of 5 more) and, on one rank, of the one-process analysis (analysis/) of the
// same state (median of 6).
//
//   mpiexec -n 2 build/bench/bench_distributed [--per_side=48] [--steps=40] [--warmup=5]
//   OMP_NUM_THREADS=2 mpiexec -n 1 build/bench/bench_distributed   (the one-rank reference)
#include <mpi.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "analysis/grid.hpp"
#include "analysis/spectrum.hpp"
#include "par/decomposition.hpp"
#include "par/exchange.hpp"
#include "par/spectrum.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace {

using namespace sphles;

struct Options {
  int per_side = 48;
  int steps = 40;
  int warmup = 5;
};

Options parse(int argc, char** argv) {
  Options o;
  for (int k = 1; k < argc; ++k) {
    const auto value = [&](const char* flag) -> const char* {
      const std::size_t n = std::strlen(flag);
      return std::strncmp(argv[k], flag, n) == 0 ? argv[k] + n : nullptr;
    };
    if (const char* v = value("--per_side="))
      o.per_side = std::atoi(v);
    else if (const char* v = value("--steps="))
      o.steps = std::atoi(v);
    else if (const char* v = value("--warmup="))
      o.warmup = std::atoi(v);
    else
      throw std::invalid_argument(std::string("unknown option '") + argv[k] +
                                  "' (--per_side=N, --steps=N, --warmup=N)");
  }
  if (o.per_side < 8 || o.steps < 1 || o.warmup < 0)
    throw std::invalid_argument("--per_side must be >= 8, --steps >= 1, --warmup >= 0");
  return o;
}

/// Resident memory of this process now [bytes] (/proc/self/statm), 0 where it cannot be read.
double resident_bytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0.0;
  unsigned long long size = 0, resident = 0;
  const int read = std::fscanf(f, "%llu %llu", &size, &resident);
  std::fclose(f);
  return read == 2 ? static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE))
                   : 0.0;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

/// The 3D TGV of bench_solver (WC4 8Δl, packing skipped), its lattice displaced at random by
/// 0.05 Δl as bench_solver displaces it.
sim::RunSetup displaced_lattice(int per_side) {
  const sim::Scene scene =
      scene::parse_scene({{"case", "tgv3d"},
                          {"particles_per_side", per_side},
                          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
                          {"packing", {{"enabled", false}}}});
  sim::RunSetup setup = sim::setup_run(scene);
  sim::ParticleArrays& all = setup.particles;
  std::mt19937_64 rng(5);  // the displacement of bench_solver
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int d = 0; d < 3; ++d)
    for (double& x : all.position[d])
      x = sim::wrap_periodic(x + 0.05 * scene.particle_spacing() * u(rng), scene.box_length());
  return setup;
}

/// This rank's particles (every rank made the whole lattice: fine at benchmark sizes); `all` is
/// freed, so that the memory measured after it is the solver's.
sim::ParticleArrays owned_particles(const par::Decomposition& d, sim::ParticleArrays& all) {
  std::vector<std::uint32_t> order, others;  // this rank's particles first
  for (std::size_t i = 0; i < all.size(); ++i)
    (d.owns(all, i) ? order : others).push_back(static_cast<std::uint32_t>(i));
  const std::size_t mine = order.size();
  order.insert(order.end(), others.begin(), others.end());
  sim::ParticleArrays owned = all;
  owned.reorder(order);
  owned.truncate(mine);
  all = sim::ParticleArrays{};
  return owned;
}

/// The timed steps, each the slowest rank's, and the exchange's share of them (the maxima and
/// sums over the ranks on rank 0).
struct StepTimes {
  std::vector<double> step_seconds;
  double wall = 0.0;
  double max_share = 0.0;   // of the wall time in the exchange, on the rank where it took most
  double all_bytes = 0.0;   // sent per step, all ranks
  double max_copies = 0.0;  // halo copies per owned particle
  double builds = 0.0;      // halo builds over the timed steps
};

StepTimes time_steps(sim::Simulation& simulation, const par::MpiExchange& exchange, int steps) {
  StepTimes t;
  const par::ExchangeStats before = exchange.stats();
  for (int s = 0; s < steps; ++s) {
    MPI_Barrier(MPI_COMM_WORLD);
    const double start = MPI_Wtime();
    simulation.step();
    double seconds = MPI_Wtime() - start, slowest = 0.0;
    MPI_Allreduce(&seconds, &slowest, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    t.step_seconds.push_back(slowest);
    t.wall += slowest;
  }
  const par::ExchangeStats& after = exchange.stats();
  const double exchange_share = (after.seconds() - before.seconds()) / t.wall;
  MPI_Reduce(&exchange_share, &t.max_share, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  const double bytes = static_cast<double>(after.build_bytes + after.refresh_bytes -
                                           before.build_bytes - before.refresh_bytes) /
                       steps;
  MPI_Reduce(&bytes, &t.all_bytes, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  const double copies_per_owned =
      static_cast<double>(after.halo_copies) / static_cast<double>(simulation.owned_count());
  MPI_Reduce(&copies_per_owned, &t.max_copies, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  t.builds = static_cast<double>(after.halo_builds - before.halo_builds);
  return t;
}

/// The energy spectrum's times on M^3 nodes, M = 2 per_side, each the slowest rank's.
struct SpectrumTimes {
  double first_seconds = 0.0;          // the first call, which plans and allocates
  std::vector<double> seconds;         // 5 more calls
  std::vector<double> serial_seconds;  // one rank only: the one-process analysis, 6 calls
};

/// The spectrum of the run's state on M^3 nodes, M = 2 per_side, as the analysis grids it: where
/// the particles live (par/spectrum.hpp), and on one rank the one-process analysis (analysis/) of
/// the same state for comparison.
SpectrumTimes time_spectra(const par::Decomposition& d, const sim::ParticleArrays& state,
                           int per_side, int ranks, double length) {
  SpectrumTimes t;
  // The first call plans the transform and allocates the buffers; later calls reuse them.
  {
    MPI_Barrier(MPI_COMM_WORLD);
    const double start = MPI_Wtime();
    par::DistributedSpectrum spectra(d, 2 * per_side);
    spectra.compute(state);
    const double first = MPI_Wtime() - start;
    MPI_Allreduce(&first, &t.first_seconds, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    for (int k = 0; k < 5; ++k) {
      MPI_Barrier(MPI_COMM_WORLD);
      const double call_start = MPI_Wtime();
      const analysis::EnergySpectrum spectrum = spectra.compute(state);
      double seconds = MPI_Wtime() - call_start, slowest = 0.0;
      MPI_Allreduce(&seconds, &slowest, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
      t.seconds.push_back(slowest);
    }
  }
  if (ranks == 1) {
    analysis::Grid grid;
    grid.dimension = 3;
    grid.points_per_side = 2 * per_side;
    grid.length = length;
    for (int k = 0; k < 6; ++k) {
      const double start = MPI_Wtime();
      const analysis::EnergySpectrum spectrum = analysis::energy_spectrum(
          analysis::sample_velocity(analysis::nearest_particle_map(grid, state), state, true));
      t.serial_seconds.push_back(MPI_Wtime() - start);
    }
  }
  return t;
}

int run(const Options& o) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  sim::RunSetup setup = displaced_lattice(o.per_side);
  const sim::SolverConfig& config = setup.solver;
  const sim::VerletNeighbourSearch search(config.box, config.support_radius,
                                          config.neighbour_skin * config.support_radius);
  const par::Decomposition d(MPI_COMM_WORLD, config.box, search.list_radius(),
                             config.particle_spacing);
  const std::size_t total = setup.particles.size();
  sim::ParticleArrays owned = owned_particles(d, setup.particles);
  // Memory of the solver: resident memory after the warm-up (with its list rebuilds) less that
  // before the solver, with the set-up's lattice freed.
  const double resident_before = resident_bytes();
  const auto exchange = std::make_shared<par::MpiExchange>(d);
  const auto simulation = sim::make_simulation(config, std::move(owned), 0.0, 0, exchange);
  for (int s = 0; s < o.warmup; ++s) simulation->step();
  const double solver_bytes_per_owned =
      (resident_bytes() - resident_before) / static_cast<double>(simulation->owned_count());
  double max_solver_bytes = 0.0;
  MPI_Reduce(&solver_bytes_per_owned, &max_solver_bytes, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);

  const StepTimes steps = time_steps(*simulation, *exchange, o.steps);
  sim::ParticleArrays state = simulation->particles();
  state.truncate(simulation->owned_count());
  const SpectrumTimes spectra = time_spectra(d, state, o.per_side, ranks, config.box.length[0]);
  if (rank == 0) {
    std::printf(
        "particles %zu  ranks %d (%d x %d x %d)  threads per rank %d  steps %d (after %d)\n"
        "median step %.1f ms  mean step %.1f ms  exchange share (max over ranks) %.1f %%\n"
        "bytes sent per step, all ranks: %.2f MB  halo copies per owned particle (max) %.2f  "
        "list rebuilds per step %.2f\nsolver memory per owned particle (max over ranks, "
        "resident growth over the solver's set-up and warm-up) %.0f B\n"
        "energy spectrum on %d^3 nodes where the particles live: first call %.1f ms, then "
        "median %.1f ms\n",
        total, ranks, d.dims()[0], d.dims()[1], d.dims()[2], omp_get_max_threads(), o.steps,
        o.warmup, 1e3 * median(steps.step_seconds), 1e3 * steps.wall / o.steps,
        100.0 * steps.max_share, steps.all_bytes / 1e6, steps.max_copies, steps.builds / o.steps,
        max_solver_bytes, 2 * o.per_side, 1e3 * spectra.first_seconds,
        1e3 * median(spectra.seconds));
    if (!spectra.serial_seconds.empty())
      std::printf("the same state's one-process spectrum (analysis/), 6 calls: median %.1f ms\n",
                  1e3 * median(spectra.serial_seconds));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rc = 0;
  try {
    rc = run(parse(argc, argv));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_distributed: %s\n", e.what());
    MPI_Abort(MPI_COMM_WORLD, 2);  // other ranks may wait in a collective
  }
  MPI_Finalize();
  return rc;
}
