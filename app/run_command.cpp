#include <omp.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>

#include "analysis/config.hpp"
#include "analysis/pipeline.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/writer.hpp"
#include "app/commands.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/run_log.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

namespace sphles::app {

namespace {

struct RunOptions {
  std::string scene_file;
  std::vector<std::string> overrides;
  std::optional<std::string> out_dir;
  int threads = 0;
};

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

RunOptions parse_run_options(const std::vector<std::string>& args) {
  RunOptions o;
  for (std::size_t k = 0; k < args.size(); ++k) {
    const std::string& a = args[k];
    const auto value = [&]() -> const std::string& {
      if (k + 1 >= args.size()) throw UsageError(a + " needs a value");
      return args[++k];
    };
    if (a == "--set") {
      o.overrides.push_back(value());
    } else if (a == "--out") {
      o.out_dir = value();
    } else if (a == "--threads") {
      const std::string& v = value();
      std::size_t used = 0;
      int n = 0;
      try {
        n = std::stoi(v, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != v.size() || n < 1 || n > 1024)
        throw UsageError("--threads must be an integer in [1, 1024], got '" + v + "'");
      o.threads = n;
    } else if (!a.empty() && a[0] == '-') {
      throw UsageError("unknown option '" + a + "'");
    } else if (o.scene_file.empty()) {
      o.scene_file = a;
    } else {
      throw UsageError("unexpected argument '" + a + "'");
    }
  }
  if (o.scene_file.empty()) throw UsageError("missing SCENE.json");
  return o;
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << text;
    out.flush();
    if (!out) throw std::runtime_error("cannot write '" + temporary.string() + "'");
  }
  std::filesystem::rename(temporary, path);
}

}  // namespace

int run_command(const std::vector<std::string>& args) {
  RunOptions options;
  analysis::RunConfig run_config;
  try {
    options = parse_run_options(args);
    run_config = load_run_config(options.scene_file, options.overrides);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitUsage;
  }

  const sim::Scene& scene = run_config.scene;
  const analysis::AnalysisConfig& analysis_config = run_config.analysis;
  try {
    if (options.threads > 0) omp_set_num_threads(options.threads);
    const std::filesystem::path out_dir = options.out_dir
                                              ? std::filesystem::path(*options.out_dir)
                                              : std::filesystem::path("runs") / scene.name;
    std::filesystem::create_directories(out_dir);
    write_text_atomically(out_dir / "scene.json",
                          analysis::run_config_to_json(run_config).dump(2) + "\n");

    std::fprintf(stderr,
                 "sphles run: %s (%s), %zu particles, kernel %s, D_K/dl = %g, %d threads -> %s\n",
                 scene.name.c_str(), std::string(sim::case_name(scene.case_type)).c_str(),
                 scene.num_particles(), std::string(sim::kernel_name(scene.kernel)).c_str(),
                 scene.kernel_diameter_over_spacing, omp_get_max_threads(), out_dir.c_str());

    const auto setup_start = std::chrono::steady_clock::now();
    sim::RunSetup setup = sim::setup_run(scene);
    const double setup_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_start).count();
    if (scene.packing.enabled) {
      std::fprintf(stderr, "packing: %s, %d iterations, residual %.3g -> %.3g%s (%.1f s)%s%s\n",
                   setup.packing.from_cache  ? "from cache"
                   : setup.packing.converged ? "converged"
                                             : "NOT converged (max_iterations reached)",
                   setup.packing.iterations, setup.packing.initial_residual,
                   setup.packing.final_residual, "", setup_seconds,
                   setup.packing.cache_file.empty() ? "" : ", cache ",
                   setup.packing.cache_file.c_str());
    }

    auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    analysis::TimeSeriesWriter timeseries(out_dir / "timeseries.csv",
                                          sim::case_diagnostic_names(scene));
    analysis::DissipationEstimator dissipation(analysis_config.dissipation_window);
    const auto record = [&](const sim::StepDiagnostics& d) {
      timeseries.write(d, dissipation.add(d.time, d.kinetic_energy),
                       sim::case_diagnostics(scene, simulation->particles()));
    };
    record(simulation->diagnostics());

    // Snapshot analysis on its own thread, only when the scene asks for products.
    std::unique_ptr<analysis::RunDirectoryWriter> writer;
    std::unique_ptr<analysis::AnalysisPipeline> pipeline;
    if (analysis_config.enabled()) {
      writer = std::make_unique<analysis::RunDirectoryWriter>(out_dir);
      pipeline = std::make_unique<analysis::AnalysisPipeline>(
          analysis_config,
          std::vector<analysis::FrameSink>{
              [w = writer.get()](const analysis::AnalysisFrame& frame) { w->write(frame); }});
      pipeline->publish(analysis::make_snapshot(*simulation));
    }
    double next_snapshot = analysis_config.every;
    sim::ProgressReporter progress(scene.end_time, scene.output.progress_every_seconds);
    progress.update(simulation->diagnostics());
    const double every = scene.output.timeseries_every;
    double next_output = every > 0.0 ? every : 0.0;
    const double end_time = scene.end_time;
    // Stop within a relative 1e-12 of the end so that round-off does not add a tiny last step.
    const double end_tolerance = 1e-12 * end_time;
    while (simulation->time() < end_time - end_tolerance) {
      double max_dt = end_time - simulation->time();
      if (every > 0.0) max_dt = std::min(max_dt, next_output - simulation->time());
      if (pipeline) max_dt = std::min(max_dt, next_snapshot - simulation->time());
      simulation->step(max_dt);
      const sim::StepDiagnostics& d = simulation->diagnostics();
      if (every <= 0.0 || d.time >= next_output - 1e-12 * every) {
        record(d);
        if (every > 0.0) next_output += every;
      }
      if (pipeline && d.time >= next_snapshot - 1e-12 * analysis_config.every) {
        pipeline->publish(analysis::make_snapshot(*simulation));
        next_snapshot += analysis_config.every;
      }
      if (const std::string line = progress.update(d); !line.empty())
        std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fprintf(stderr, "%s\n", progress.update(simulation->diagnostics(), true).c_str());
    if (pipeline) {
      pipeline->close(/*drain=*/true);
      const analysis::PipelineCounters c = pipeline->counters();
      std::fprintf(
          stderr, "analysis: %llu snapshots published, %llu analysed, %llu dropped, %.1f s busy\n",
          static_cast<unsigned long long>(c.published), static_cast<unsigned long long>(c.analysed),
          static_cast<unsigned long long>(c.dropped), c.busy_seconds);
      if (!pipeline->error().empty())
        throw std::runtime_error("analysis failed: " + pipeline->error());
      if (!writer->last_error().empty())
        throw std::runtime_error("writing analysis products failed: " + writer->last_error());
    }
    std::fprintf(stderr, "sphles run: finished, outputs in %s\n", out_dir.c_str());
    return kExitOk;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitFailure;
  }
}

}  // namespace sphles::app
