// SPDX-License-Identifier: GPL-3.0-or-later
// Solver throughput (docs/performance.md): density and force passes in pair interactions per
// second (pairs inside the kernel support, j != i; the passes as the solver runs them: the density
// pass over the Verlet list, recording the pairs inside the support, the force pass over those)
// and wall time per full step, for the 3D Taylor-Green vortex
// at 48³ with Wendland C4, D_K = 8Δl (N_ngb ≈ 250), on 1 and 2 threads.
//
//   build/bench/bench_solver [--benchmark_filter=...] [--per_side=48] [--skin=0.15]
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <random>

#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace scene = sphles::scene;
namespace sim = sphles::sim;

namespace {

int g_per_side = 48;
double g_skin = -1.0;  // < 0: the scene default

struct Fixture {
  sim::Scene scene;
  sim::RunSetup setup;
  std::unique_ptr<sim::VerletNeighbourSearch> search;
  double pairs_inside = 0.0;
};

/// TGV state on a lattice displaced at random by 0.05 Δl (packing skipped to keep set-up short;
/// the neighbour count is that of the packed state).
Fixture& fixture() {
  static std::unique_ptr<Fixture> f;
  if (f) return *f;
  f = std::make_unique<Fixture>();
  f->scene =
      scene::parse_scene({{"case", "tgv3d"},
                          {"particles_per_side", g_per_side},
                          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
                          {"packing", {{"enabled", false}}}});
  f->setup = sim::setup_run(f->scene);
  if (g_skin >= 0.0) f->setup.solver.neighbour_skin = g_skin;
  sim::ParticleArrays& p = f->setup.particles;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int d = 0; d < 3; ++d)
    for (double& x : p.position[d])
      x = sim::wrap_periodic(x + 0.05 * f->scene.particle_spacing() * u(rng),
                             f->scene.box_length());
  const sim::SolverConfig& c = f->setup.solver;
  f->search = std::make_unique<sim::VerletNeighbourSearch>(c.box, c.support_radius,
                                                           c.neighbour_skin * c.support_radius);
  p.reorder(f->search->locality_order(sim::view_positions(p)));
  f->search->build(sim::view_positions(p));
  const double h2 = c.support_radius * c.support_radius;
  const sim::NeighbourList& list = f->search->list();
  std::size_t inside = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (const std::uint32_t j : list.of(i)) {
      double r2 = 0.0;
      for (int d = 0; d < 3; ++d) {
        const double dx = sim::minimum_image(p.position[d][i] - p.position[d][j], c.box.length[d],
                                             0.5 * c.box.length[d]);
        r2 += dx * dx;
      }
      inside += r2 < h2;
    }
  f->pairs_inside = static_cast<double>(inside);
  return *f;
}

void set_counters(benchmark::State& state, const Fixture& f) {
  state.counters["pairs_per_s"] =
      benchmark::Counter(f.pairs_inside, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["N_ngb"] = f.pairs_inside / static_cast<double>(f.setup.particles.size());
  state.counters["list_per_particle"] =
      static_cast<double>(f.search->list().num_entries()) / f.setup.particles.size();
  state.counters["threads"] = omp_get_max_threads();
}

using PassKernel = sim::Kernel<sim::kernel_shape::WendlandC4, 3>;

/// Times `pass(f, c, kernel, interactions)` on the fixture with state.range(0) threads, after an
/// untimed density pass: it records the pairs inside the support that the force pass runs over,
/// and since the solver keeps its interaction list from step to step, its pages are mapped once
/// (a first pass in the timing would add 190 MB of page faults).
template <class Pass>
void bench_pass(benchmark::State& state, Pass pass) {
  omp_set_num_threads(static_cast<int>(state.range(0)));
  Fixture& f = fixture();
  const sim::SolverConfig& c = f.setup.solver;
  const PassKernel kernel(c.support_radius);
  sim::InteractionList interactions;
  sim::density_pass<3>(kernel, c.box, f.search->list(), c.fluid, f.setup.particles, &interactions);
  for (auto _ : state) pass(f, c, kernel, interactions);
  set_counters(state, f);
}

void BM_DensityPass(benchmark::State& state) {
  bench_pass(state, [](Fixture& f, const sim::SolverConfig& c, const PassKernel& kernel,
                       sim::InteractionList& interactions) {
    // As the solver runs it: the density pass also records the pairs inside the support.
    sim::density_pass<3>(kernel, c.box, f.search->list(), c.fluid, f.setup.particles,
                         &interactions);
    benchmark::DoNotOptimize(f.setup.particles.density.data());
  });
}

void BM_ForcePass(benchmark::State& state) {
  bench_pass(state, [](Fixture& f, const sim::SolverConfig& c, const PassKernel& kernel,
                       sim::InteractionList& interactions) {
    // As the solver runs it: over the pairs inside the support the density pass recorded.
    sim::force_pass<3>(kernel, c.box, interactions, c.fluid, sim::view_velocity(f.setup.particles),
                       f.setup.particles);
    benchmark::DoNotOptimize(f.setup.particles.acceleration[0].data());
  });
}

void BM_NeighbourBuild(benchmark::State& state) {
  omp_set_num_threads(static_cast<int>(state.range(0)));
  Fixture& f = fixture();
  for (auto _ : state) f.search->build(sim::view_positions(f.setup.particles));
  set_counters(state, f);
}

/// The same build with the arrays in lattice (id) order rather than cell order, as a set-up's
/// lattice or a gathered snapshot are: the build visits the particles cell by cell anyway.
void BM_NeighbourBuildLatticeOrder(benchmark::State& state) {
  omp_set_num_threads(static_cast<int>(state.range(0)));
  Fixture& f = fixture();
  sim::ParticleArrays lattice = f.setup.particles;
  lattice.reorder(sim::order_by_key(lattice.id));
  const sim::SolverConfig& c = f.setup.solver;
  sim::VerletNeighbourSearch search(c.box, c.support_radius, c.neighbour_skin * c.support_radius);
  for (auto _ : state) search.build(sim::view_positions(lattice));
  set_counters(state, f);
}

/// A full step of the solver (kick, drift, list check/rebuild, density, force, kick,
/// diagnostics), averaged over steps that include list rebuilds at their natural rate.
/// Steps BM_FullStep runs before timing (two list rebuilds at the default skin).
constexpr int kFullStepWarmup = 12;

void BM_FullStep(benchmark::State& state) {
  omp_set_num_threads(static_cast<int>(state.range(0)));
  Fixture& f = fixture();
  auto simulation = sim::make_simulation(f.setup.solver, f.setup.particles);
  // Untimed steps first, past the first list rebuilds: the framework makes a new simulation for
  // each of its runs, and one-time costs (the first touch of the lists' pages, their first
  // growth) would otherwise land in the timed steps of its shortest runs.
  for (int s = 0; s < kFullStepWarmup; ++s) simulation->step();
  const std::size_t builds_before = simulation->diagnostics().neighbour_builds;
  std::uint64_t steps = 0;
  for (auto _ : state) {
    simulation->step();
    ++steps;
  }
  state.counters["rebuilds_per_step"] =
      static_cast<double>(simulation->diagnostics().neighbour_builds - builds_before) / steps;
  state.counters["particles"] = static_cast<double>(f.setup.particles.size());
  state.counters["threads"] = omp_get_max_threads();
}

}  // namespace

BENCHMARK(BM_DensityPass)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ForcePass)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_NeighbourBuild)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_NeighbourBuildLatticeOrder)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_FullStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(5.0);

int main(int argc, char** argv) {
  for (int k = 1; k < argc; ++k)
    if (std::strncmp(argv[k], "--per_side=", 11) == 0)
      g_per_side = std::atoi(argv[k] + 11);
    else if (std::strncmp(argv[k], "--skin=", 7) == 0)
      g_skin = std::atof(argv[k] + 7);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
