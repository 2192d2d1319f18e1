// SPDX-License-Identifier: GPL-3.0-or-later
// Checkpoint cost (docs/checkpoints.md, "Cost"): write and read time and file size of a TGV 3D
// checkpoint (default 64³), without and with gzip compression, printed as figures.
//
//   build/bench/bench_checkpoint [--per_side=64] [--repeats=3] [--dir=/tmp]
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>

#include "io/checkpoint.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"

namespace scene = sphles::scene;
namespace sim = sphles::sim;
namespace io = sphles::io;

int main(int argc, char** argv) {
  int per_side = 64, repeats = 3;
  std::filesystem::path dir = std::filesystem::temp_directory_path();
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    if (a.rfind("--per_side=", 0) == 0)
      per_side = std::stoi(a.substr(11));
    else if (a.rfind("--repeats=", 0) == 0)
      repeats = std::stoi(a.substr(10));
    else if (a.rfind("--dir=", 0) == 0)
      dir = a.substr(6);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[k]);
      return 2;
    }
  }
  const sim::Scene scene = scene::parse_scene(
      {{"case", "tgv3d"}, {"particles_per_side", per_side}, {"packing", {{"enabled", false}}}});
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  simulation->step();
  const sim::SolverState state = simulation->state();
  const io::CheckpointMetadata meta{scene::scene_to_json(scene).dump(), "bench", "lattice"};
  std::printf("TGV %d^3 (%zu particles), best of %d:\n", per_side, state.particles.size(), repeats);
  std::printf("  %-8s %10s %10s %12s %8s\n", "gzip", "write s", "read s", "size MiB", "ratio");
  double raw_size = 0.0;
  for (const int level : {0, 1, 6}) {
    const auto file = dir / ("sphles_bench_ckpt_" + std::to_string(level) + ".h5");
    double best_write = 1e300, best_read = 1e300;
    for (int r = 0; r < repeats; ++r) {
      auto t0 = std::chrono::steady_clock::now();
      io::write_checkpoint(file, state, meta, {.gzip_level = level});
      auto t1 = std::chrono::steady_clock::now();
      const io::Checkpoint back = io::read_checkpoint(file);
      auto t2 = std::chrono::steady_clock::now();
      best_write = std::min(best_write, std::chrono::duration<double>(t1 - t0).count());
      best_read = std::min(best_read, std::chrono::duration<double>(t2 - t1).count());
    }
    const double size = static_cast<double>(std::filesystem::file_size(file));
    if (level == 0) raw_size = size;
    std::printf("  %-8d %10.3f %10.3f %12.2f %8.3f\n", level, best_write, best_read,
                size / (1024.0 * 1024.0), size / raw_size);
    std::filesystem::remove(file);
  }
  return 0;
}
