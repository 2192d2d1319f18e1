// SPDX-License-Identifier: GPL-3.0-or-later
// Analysis cost (docs/performance.md), printed as figures:
//  1. wall time per snapshot for each product alone and for all together, TGV 3D at the given
//     resolutions (default 48³ and 64³), analysis on 1 thread as in a run;
//  2. solver slowdown: steps/s of a TGV run over [0, T] without analysis and with every product
//     every 0.5 time units on the analysis thread (2 solver threads, default 32³, T = 2);
//  3. what lossless delivery costs: every product at a cadence the analysis cannot keep up with
//     (--dense_every, default 0.05), once with Delivery::Lossless (the solver waits, every
//     snapshot is analysed) and once with Delivery::LatestOnly (snapshots dropped), runs
//     interleaved, medians of --repeats.
//
// --vorticity=mls,particle,grid repeats figure 1 for each vorticity estimate (default: the
// scene default); --costs_only stops after figure 1.
//
//   build/bench/bench_analysis [--sizes=48,64] [--run_size=32] [--run_time=2] [--repeats=2]
//                              [--dense_every=0.05] [--vorticity=NAME,...] [--costs_only]
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "analysis/pipeline.hpp"
#include "analysis/products.hpp"
#include "scene/document.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace an = sphles::analysis;
namespace scene = sphles::scene;
namespace sim = sphles::sim;

namespace {

using Clock = std::chrono::steady_clock;

sim::Scene tgv_scene(int per_side) {
  return scene::parse_scene({{"case", "tgv3d"},
                             {"particles_per_side", per_side},
                             {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
                             {"packing", {{"enabled", false}}}});
}

an::AnalysisConfig all_products() {
  an::AnalysisConfig c;
  c.every = 0.5;
  c.products = {an::Product::Spectrum, an::Product::Vorticity, an::Product::Slices,
                an::Product::SubfilterStatistics};
  return c;
}

void per_product_costs(int per_side, int repeats, an::VorticityEstimate estimate) {
  const sim::Scene scene = tgv_scene(per_side);
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  const an::SnapshotPtr snapshot = an::make_snapshot(*simulation);
  omp_set_num_threads(1);
  struct Case {
    std::string name;
    std::set<an::Product> products;
  };
  const std::vector<Case> cases{{"spectrum", {an::Product::Spectrum}},
                                {"vorticity", {an::Product::Vorticity}},
                                {"slices", {an::Product::Slices}},
                                {"sfs_stats", {an::Product::SubfilterStatistics}},
                                {"all", all_products().products}};
  std::printf(
      "\nTGV %d^3 (%zu particles), vorticity estimate %s, analysis on 1 thread, best of "
      "%d:\n",
      per_side, snapshot->size(), std::string(an::vorticity_estimate_name(estimate)).c_str(),
      repeats);
  std::printf("  %-10s %10s   stages\n", "product", "seconds");
  for (const Case& c : cases) {
    an::AnalysisConfig config = all_products();
    config.products = c.products;
    config.gridding.vorticity = estimate;
    double best = 1e300;
    an::AnalysisFrame best_frame;
    for (int r = 0; r < repeats; ++r) {
      an::AnalysisFrame frame = an::analyse(*snapshot, config);
      if (frame.total_seconds < best) {
        best = frame.total_seconds;
        best_frame = frame;
      }
    }
    std::ostringstream stages;
    for (const auto& [stage, seconds] : best_frame.timings)
      stages << stage << "=" << seconds << "s ";
    std::printf("  %-10s %10.3f   %s\n", c.name.c_str(), best, stages.str().c_str());
  }
  omp_set_num_threads(2);
}

enum class Mode { NoAnalysis, AllProducts, SlowConsumerEveryStep, DenseLossless, DenseLatestOnly };

double run_steps_per_second(int per_side, double run_time, Mode mode,
                            an::PipelineCounters* counters, double dense_every = 0.05) {
  const sim::Scene scene = tgv_scene(per_side);
  sim::RunSetup setup = sim::setup_run(scene);
  omp_set_num_threads(2);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  std::unique_ptr<an::AnalysisPipeline> pipeline;
  if (mode == Mode::AllProducts)
    pipeline = std::make_unique<an::AnalysisPipeline>(
        all_products(), std::vector<an::FrameSink>{[](const an::AnalysisFrame&) {}});
  if (mode == Mode::SlowConsumerEveryStep) {
    an::AnalysisConfig spectrum_only = all_products();
    spectrum_only.products = {an::Product::Spectrum};
    // Live viewing's delivery: the solver must not notice the slow consumer.
    pipeline = std::make_unique<an::AnalysisPipeline>(
        spectrum_only, std::vector<an::FrameSink>{[](const an::AnalysisFrame&) {
          std::this_thread::sleep_for(std::chrono::seconds(1));
        }},
        1, an::Delivery::LatestOnly);
  }
  double every = 0.5;
  if (mode == Mode::DenseLossless || mode == Mode::DenseLatestOnly) {
    an::AnalysisConfig dense = all_products();
    dense.every = every = dense_every;
    pipeline = std::make_unique<an::AnalysisPipeline>(
        dense, std::vector<an::FrameSink>{[](const an::AnalysisFrame&) {}}, 1,
        mode == Mode::DenseLossless ? an::Delivery::Lossless : an::Delivery::LatestOnly);
  }
  const bool every_step = mode == Mode::SlowConsumerEveryStep;
  const auto start = Clock::now();
  sim::Cadence snapshots(every, simulation->time());
  while (!sim::reached_end(simulation->time(), run_time)) {
    const double t = simulation->time();
    simulation->step(snapshots.limit_step(t, run_time - t));
    if (every_step) pipeline->publish(an::make_snapshot(*simulation));
    if (snapshots.take(simulation->time()) && !every_step && pipeline)
      pipeline->publish(an::make_snapshot(*simulation));
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  if (pipeline) {
    pipeline->close(true);
    if (counters) *counters = pipeline->counters();
  }
  return static_cast<double>(simulation->step_count()) / seconds;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes{48, 64};
  int run_size = 32, repeats = 2;
  double run_time = 2.0, dense_every = 0.05;
  std::vector<an::VorticityEstimate> estimates{an::GriddingConfig{}.vorticity};
  bool costs_only = false;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    if (a.rfind("--sizes=", 0) == 0) {
      sizes.clear();
      std::stringstream list(a.substr(8));
      for (std::string item; std::getline(list, item, ',');) sizes.push_back(std::stoi(item));
    } else if (a.rfind("--run_size=", 0) == 0) {
      run_size = std::stoi(a.substr(11));
    } else if (a.rfind("--run_time=", 0) == 0) {
      run_time = std::stod(a.substr(11));
    } else if (a.rfind("--dense_every=", 0) == 0) {
      dense_every = std::stod(a.substr(14));
    } else if (a.rfind("--vorticity=", 0) == 0) {
      estimates.clear();
      std::stringstream list(a.substr(12));
      for (std::string item; std::getline(list, item, ',');) {
        const auto parsed = an::parse_run_config(
            {{"analysis", {{"gridding", {{"vorticity", item}}}}}});  // validates the name
        estimates.push_back(parsed.analysis.gridding.vorticity);
      }
    } else if (a == "--costs_only") {
      costs_only = true;
    } else if (a.rfind("--repeats=", 0) == 0) {
      repeats = std::stoi(a.substr(10));
    } else {
      std::fprintf(stderr, "unknown option %s\n", argv[k]);
      return 2;
    }
  }
  for (const int n : sizes)
    for (const an::VorticityEstimate e : estimates) per_product_costs(n, repeats, e);
  if (costs_only) return 0;

  std::printf("\nSolver throughput, TGV %d^3, t in [0, %g], 2 solver threads:\n", run_size,
              run_time);
  double without = 0.0, with = 0.0, slow = 0.0;
  an::PipelineCounters counters, slow_counters;
  for (int r = 0; r < repeats; ++r) {
    without =
        std::max(without, run_steps_per_second(run_size, run_time, Mode::NoAnalysis, nullptr));
    with = std::max(with, run_steps_per_second(run_size, run_time, Mode::AllProducts, &counters));
    slow = std::max(slow, run_steps_per_second(run_size, run_time, Mode::SlowConsumerEveryStep,
                                               &slow_counters));
  }
  std::printf("  without analysis: %.3f steps/s\n", without);
  std::printf(
      "  with all products every 0.5: %.3f steps/s (%llu published, %llu analysed, "
      "%llu dropped, analysis busy %.2f s)\n",
      with, static_cast<unsigned long long>(counters.published),
      static_cast<unsigned long long>(counters.analysed),
      static_cast<unsigned long long>(counters.dropped), counters.busy_seconds);
  std::printf("  throughput ratio with/without: %.3f (slowdown %.1f %%)\n", with / without,
              100.0 * (1.0 - with / without));
  std::printf(
      "  snapshot every step to a consumer sleeping 1 s per frame: %.3f steps/s, ratio "
      "%.3f (%llu published, %llu analysed, %llu dropped)\n",
      slow, slow / without, static_cast<unsigned long long>(slow_counters.published),
      static_cast<unsigned long long>(slow_counters.analysed),
      static_cast<unsigned long long>(slow_counters.dropped));

  // 3. Lossless against latest-only delivery at a cadence analysis cannot keep up with. The
  // solver loop's steps/s is the cost the run sees; the lossless run also drains at the end.
  std::vector<double> lossless, latest, plain;
  an::PipelineCounters lossless_counters, latest_counters;
  for (int r = 0; r < repeats; ++r) {
    plain.push_back(run_steps_per_second(run_size, run_time, Mode::NoAnalysis, nullptr));
    lossless.push_back(run_steps_per_second(run_size, run_time, Mode::DenseLossless,
                                            &lossless_counters, dense_every));
    latest.push_back(run_steps_per_second(run_size, run_time, Mode::DenseLatestOnly,
                                          &latest_counters, dense_every));
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  };
  const double m_plain = median(plain), m_lossless = median(lossless), m_latest = median(latest);
  std::printf(
      "\nAll products every %g (analysis cannot keep up), medians of %d interleaved runs:\n",
      dense_every, repeats);
  std::printf("  without analysis:  %.3f steps/s\n", m_plain);
  const auto report = [&](const char* name, double rate, const an::PipelineCounters& c) {
    std::printf("  %-18s %.3f steps/s, ratio %.3f (%llu published, %llu analysed, %llu dropped)\n",
                name, rate, rate / m_plain, static_cast<unsigned long long>(c.published),
                static_cast<unsigned long long>(c.analysed),
                static_cast<unsigned long long>(c.dropped));
  };
  report("latest-only:", m_latest, latest_counters);
  report("lossless:", m_lossless, lossless_counters);
  std::printf("  lossless / latest-only: %.3f\n", m_lossless / m_latest);
  return 0;
}
