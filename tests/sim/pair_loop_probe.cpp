// SPDX-License-Identifier: GPL-3.0-or-later
// Runs a scene for a number of steps and writes the final positions and velocities (in particle
// id order, as raw doubles) to a file: built twice, against the solver with vectorised pair sums
// and against the solver built with SPHLES_SIMD=OFF, for test PairLoopBuilds.
//
//   pair_loop_probe SCENE_JSON STEPS OUT_FILE
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: pair_loop_probe SCENE_JSON STEPS OUT_FILE\n");
    return 2;
  }
  namespace sim = sphles::sim;
  const sim::Scene scene = sphles::scene::parse_scene(nlohmann::json::parse(argv[1]));
  const int steps = std::atoi(argv[2]);
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  for (int s = 0; s < steps; ++s) simulation->step();
  const sim::ParticleArrays& p = simulation->particles();
  std::vector<double> out(2 * static_cast<std::size_t>(p.dimension) * p.size());
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int d = 0; d < p.dimension; ++d) {
      const std::size_t k = static_cast<std::size_t>(p.id[i]) * 2 * p.dimension;
      out[k + static_cast<std::size_t>(d)] = p.position[d][i];
      out[k + static_cast<std::size_t>(p.dimension + d)] = p.velocity[d][i];
    }
  std::ofstream file(argv[3], std::ios::binary);
  file.write(reinterpret_cast<const char*>(out.data()),
             static_cast<std::streamsize>(out.size() * sizeof(double)));
  std::printf("%s: %d steps, t = %.17g, %s summation\n", scene.name.c_str(), steps,
              simulation->time(), sim::pair_loop_summation());
  return file ? 0 : 1;
}
