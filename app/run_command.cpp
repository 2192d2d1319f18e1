#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
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
#include "io/checkpoint.hpp"
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
  std::optional<std::string> restart;  // checkpoint file or run directory
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
    } else if (a == "--restart") {
      o.restart = value();
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
  if (o.scene_file.empty() && !o.restart) throw UsageError("missing SCENE.json (or --restart)");
  if (!o.scene_file.empty() && o.restart)
    throw UsageError(
        "give either SCENE.json or --restart, not both (the scene is in the checkpoint)");
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

/// Keeps the rows of an existing timeseries.csv up to `time` (a restart continues it).
void truncate_timeseries_after(const std::filesystem::path& path, double time) {
  std::ifstream in(path);
  if (!in) return;
  std::string text, line;
  if (std::getline(in, line)) text += line + "\n";
  while (std::getline(in, line)) {
    const double t = std::strtod(line.c_str(), nullptr);
    if (t <= time) text += line + "\n";
  }
  in.close();
  write_text_atomically(path, text);
}

/// Index of the last cadence point at or before t (cadence points are k * every, computed the
/// same way in a fresh and in a restarted run, so both take the same steps).
std::uint64_t cadence_count(double t, double every) {
  return every > 0.0 ? static_cast<std::uint64_t>(std::floor(t / every + 1e-9)) : 0;
}

}  // namespace

int run_command(const std::vector<std::string>& args) {
  RunOptions options;
  analysis::RunConfig run_config;
  std::optional<io::Checkpoint> checkpoint;
  std::filesystem::path checkpoint_file;
  try {
    options = parse_run_options(args);
    if (options.restart) {
      checkpoint_file = *options.restart;
      if (std::filesystem::is_directory(checkpoint_file)) {
        const std::filesystem::path dir = std::filesystem::exists(checkpoint_file / "checkpoints")
                                              ? checkpoint_file / "checkpoints"
                                              : checkpoint_file;
        std::vector<std::string> rejected;
        checkpoint_file = io::newest_valid_checkpoint(dir, &rejected);
        for (const std::string& r : rejected) std::fprintf(stderr, "skipped: %s\n", r.c_str());
      }
      checkpoint = io::read_checkpoint(checkpoint_file);
      nlohmann::json document = nlohmann::json::parse(checkpoint->metadata.scene_json);
      for (const std::string& assignment : options.overrides)
        sim::apply_override(document, assignment);
      run_config = analysis::parse_run_config(document);
    } else {
      run_config = load_run_config(options.scene_file, options.overrides);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles run: %s\n", e.what());
    return kExitUsage;
  }

  const sim::Scene& scene = run_config.scene;
  const analysis::AnalysisConfig& analysis_config = run_config.analysis;
  try {
    if (options.threads > 0) omp_set_num_threads(options.threads);
    const std::filesystem::path out_dir =
        options.out_dir ? std::filesystem::path(*options.out_dir)
        : checkpoint    ? std::filesystem::absolute(checkpoint_file).parent_path().parent_path()
                        : std::filesystem::path("runs") / scene.name;
    std::filesystem::create_directories(out_dir);
    write_text_atomically(out_dir / "scene.json",
                          analysis::run_config_to_json(run_config).dump(2) + "\n");

    std::fprintf(stderr,
                 "sphles run: %s (%s), %zu particles, kernel %s, D_K/dl = %g, %d threads -> %s\n",
                 scene.name.c_str(), std::string(sim::case_name(scene.case_type)).c_str(),
                 scene.num_particles(), std::string(sim::kernel_name(scene.kernel)).c_str(),
                 scene.kernel_diameter_over_spacing, omp_get_max_threads(), out_dir.c_str());

    std::unique_ptr<sim::Simulation> simulation;
    std::string packing_provenance;
    if (checkpoint) {
      std::fprintf(stderr, "restart: %s at t = %.17g, step %llu\n", checkpoint_file.c_str(),
                   checkpoint->state.time, static_cast<unsigned long long>(checkpoint->state.step));
      packing_provenance = checkpoint->metadata.packing;
      simulation =
          sim::restore_simulation(sim::make_solver_config(scene), std::move(checkpoint->state));
      truncate_timeseries_after(out_dir / "timeseries.csv", simulation->time());
    } else {
      const auto setup_start = std::chrono::steady_clock::now();
      sim::RunSetup setup = sim::setup_run(scene);
      const double setup_seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_start).count();
      {
        char text[512];
        std::snprintf(text, sizeof text,
                      "%s; iterations %d; residual %.6g -> %.6g; from cache %s; cache file %s",
                      scene.packing.enabled ? "Colagrossi packing" : "lattice (packing disabled)",
                      setup.packing.iterations, setup.packing.initial_residual,
                      setup.packing.final_residual, setup.packing.from_cache ? "yes" : "no",
                      setup.packing.cache_file.empty() ? "-" : setup.packing.cache_file.c_str());
        packing_provenance = text;
      }
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

      simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    }
    analysis::TimeSeriesWriter timeseries(
        out_dir / "timeseries.csv", sim::case_diagnostic_names(scene), checkpoint.has_value());
    analysis::DissipationEstimator dissipation(analysis_config.dissipation_window);
    const auto record = [&](const sim::StepDiagnostics& d) {
      timeseries.write(d, dissipation.add(d.time, d.kinetic_energy),
                       sim::case_diagnostics(scene, simulation->particles()));
    };
    if (!checkpoint) record(simulation->diagnostics());

    // Checkpoints: at multiples of checkpoint.every (simulated time) and/or every
    // checkpoint.every_seconds of wall time; the newest checkpoint.keep files are kept.
    const sim::CheckpointConfig& ckpt = scene.checkpoint;
    const std::filesystem::path checkpoint_dir = out_dir / "checkpoints";
    io::CheckpointMetadata metadata{analysis::run_config_to_json(run_config).dump(), SPHLES_VERSION,
                                    packing_provenance};
    auto last_checkpoint_wall = std::chrono::steady_clock::now();
    const auto save_checkpoint = [&] {
      std::filesystem::create_directories(checkpoint_dir);
      io::write_checkpoint(checkpoint_dir / io::checkpoint_file_name(simulation->step_count()),
                           simulation->state(), metadata, {.gzip_level = ckpt.compression});
      const auto files = io::list_checkpoints(checkpoint_dir);
      for (std::size_t k = static_cast<std::size_t>(ckpt.keep); k < files.size(); ++k)
        std::filesystem::remove(files[k]);
      last_checkpoint_wall = std::chrono::steady_clock::now();
    };
    std::uint64_t checkpoint_count = cadence_count(simulation->time(), ckpt.every);
    // Temporaries of a write that a crash interrupted are never valid checkpoints: remove them.
    if (std::filesystem::exists(checkpoint_dir))
      for (const auto& entry : std::filesystem::directory_iterator(checkpoint_dir))
        if (entry.path().filename().string().find(".h5.tmp.") != std::string::npos)
          std::filesystem::remove(entry.path());

    // Snapshot analysis on its own thread, only when the scene asks for products.
    std::unique_ptr<analysis::RunDirectoryWriter> writer;
    std::unique_ptr<analysis::AnalysisPipeline> pipeline;
    if (analysis_config.enabled()) {
      writer = std::make_unique<analysis::RunDirectoryWriter>(
          out_dir, analysis::run_config_to_json(run_config).dump());
      pipeline = std::make_unique<analysis::AnalysisPipeline>(
          analysis_config,
          std::vector<analysis::FrameSink>{
              [w = writer.get()](const analysis::AnalysisFrame& frame) { w->write(frame); }});
      pipeline->publish(analysis::make_snapshot(*simulation));
    }
    std::uint64_t snapshot_count = cadence_count(simulation->time(), analysis_config.every);
    sim::ProgressReporter progress(scene.end_time, scene.output.progress_every_seconds);
    progress.update(simulation->diagnostics());
    const double every = scene.output.timeseries_every;
    std::uint64_t output_count = cadence_count(simulation->time(), every);
    const double end_time = scene.end_time;
    // Stop within a relative 1e-12 of the end so that round-off does not add a tiny last step.
    const double end_tolerance = 1e-12 * end_time;
    while (simulation->time() < end_time - end_tolerance) {
      const double next_output = static_cast<double>(output_count + 1) * every;
      const double next_snapshot = static_cast<double>(snapshot_count + 1) * analysis_config.every;
      const double next_checkpoint = static_cast<double>(checkpoint_count + 1) * ckpt.every;
      double max_dt = end_time - simulation->time();
      if (every > 0.0) max_dt = std::min(max_dt, next_output - simulation->time());
      if (pipeline) max_dt = std::min(max_dt, next_snapshot - simulation->time());
      if (ckpt.every > 0.0) max_dt = std::min(max_dt, next_checkpoint - simulation->time());
      simulation->step(max_dt);
      const sim::StepDiagnostics& d = simulation->diagnostics();
      if (every <= 0.0 || d.time >= next_output - 1e-12 * every) {
        record(d);
        if (every > 0.0) ++output_count;
      }
      if (pipeline && d.time >= next_snapshot - 1e-12 * analysis_config.every) {
        pipeline->publish(analysis::make_snapshot(*simulation));
        ++snapshot_count;
      }
      bool checkpoint_due = false;
      if (ckpt.every > 0.0 && d.time >= next_checkpoint - 1e-12 * ckpt.every) {
        ++checkpoint_count;
        checkpoint_due = true;
      }
      if (ckpt.every_seconds > 0.0 &&
          std::chrono::duration<double>(std::chrono::steady_clock::now() - last_checkpoint_wall)
                  .count() >= ckpt.every_seconds)
        checkpoint_due = true;
      if (checkpoint_due) save_checkpoint();
      if (const std::string line = progress.update(d); !line.empty())
        std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fprintf(stderr, "%s\n", progress.update(simulation->diagnostics(), true).c_str());
    if (ckpt.enabled() && io::list_checkpoints(checkpoint_dir).empty()) save_checkpoint();
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
