// SPDX-License-Identifier: GPL-3.0-or-later
// sphles_stability: the stability sweep (docs/stability.md).
//
//   build/bench/sphles_stability [--quick] [--group NAME[,NAME...]] [--match TEXT]
//                                [--out FILE.csv] [--jobs J] [--check-every STEPS]
//                                [--packing-cache DIR] [--list] [--trace]
//                                [--set dotted.key=value ...] [--cfl C_ac]
//
// Every configuration runs on one OpenMP thread; --jobs runs that many configurations at once.
// Writes one CSV row per configuration (parameters, classification, reason, time reached,
// maximum density deviation, pairing fraction, wall seconds) and prints a line per finished run.
#include <omp.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "bench/stability/sweep.hpp"
#include "scene/document.hpp"
#include "sim/scene.hpp"

namespace {

namespace st = sphles::stability;

int usage(const char* program) {
  std::cerr << "usage: " << program
            << " [--quick] [--group NAME[,NAME...]] [--match TEXT] [--out FILE.csv] [--jobs J]\n"
               "       [--check-every STEPS] [--packing-cache DIR] [--list] [--trace]\n"
               "       [--set dotted.key=value ...] [--cfl C_ac]  (applied to every selected run)\n"
               "groups: mach, p_ref, cfl, kernel, viscosity, forcing, long\n";
  return 2;
}

bool in_list(const std::string& list, const std::string& name) {
  std::stringstream s(list);
  std::string item;
  while (std::getline(s, item, ','))
    if (item == name) return true;
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false, list_only = false;
  std::string groups, match, out_path = "stability.csv";
  int jobs = 1;
  double cfl = 0.0;                    // > 0: acoustic CFL factor of every selected run
  std::vector<std::string> overrides;  // "dotted.key=value", applied to every selected scene
  st::RunOptions options;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) {
        std::cerr << arg << " needs a value\n";
        std::exit(usage(argv[0]));
      }
      return argv[++k];
    };
    if (arg == "--quick") {
      quick = true;
    } else if (arg == "--cfl") {
      cfl = std::atof(value().c_str());
    } else if (arg == "--set") {
      overrides.push_back(value());
    } else if (arg == "--trace") {
      options.trace = true;
    } else if (arg == "--list") {
      list_only = true;
    } else if (arg == "--group") {
      groups = value();
    } else if (arg == "--match") {
      match = value();
    } else if (arg == "--out") {
      out_path = value();
    } else if (arg == "--jobs") {
      jobs = std::atoi(value().c_str());
    } else if (arg == "--check-every") {
      options.check_every = std::atoi(value().c_str());
    } else if (arg == "--packing-cache") {
      options.packing_cache_dir = value();
    } else {
      return usage(argv[0]);
    }
  }
  if (jobs < 1 || options.check_every < 1) return usage(argv[0]);

  std::vector<st::RunSpec> runs;
  for (st::RunSpec& r : st::make_sweep(quick))
    if ((groups.empty() || in_list(groups, r.group)) &&
        (match.empty() || r.label.find(match) != std::string::npos))
      runs.push_back(std::move(r));
  try {
    for (st::RunSpec& r : runs) {
      if (cfl > 0.0) r.cfl = cfl;
      for (const std::string& assignment : overrides)
        sphles::scene::apply_override(r.scene, assignment);
    }
  } catch (const std::exception& e) {
    std::cerr << e.what() << '\n';
    return 2;
  }
  if (list_only) {
    for (const st::RunSpec& r : runs)
      std::cout << r.group << "  " << r.label << "  " << r.scene.dump() << " cfl=" << r.cfl << '\n';
    return 0;
  }
  if (runs.empty()) {
    std::cerr << "no configuration matches\n";
    return 2;
  }

  // Pack every distinct lattice once, serially, so that parallel runs only read the cache.
  for (const st::RunSpec& r : runs) {
    st::RunSpec warm = r;
    warm.scene["time"]["end"] = 1e-9;
    st::run_one(warm, options);
  }

  const auto sweep_start = std::chrono::steady_clock::now();
  std::vector<st::RunResult> results(runs.size());
  std::mutex print_mutex;
  std::size_t done = 0;
  // One thread per configuration: the solver's own parallel loops run serially inside the
  // outer loop (and on one thread when --jobs 1 makes the outer region inactive).
  omp_set_num_threads(1);
  omp_set_max_active_levels(1);
  const auto count = static_cast<std::ptrdiff_t>(runs.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
  for (std::ptrdiff_t k = 0; k < count; ++k) {
    const auto i = static_cast<std::size_t>(k);
    results[i] = st::run_one(runs[i], options);
    const st::RunResult& r = results[i];
    std::lock_guard<std::mutex> lock(print_mutex);
    ++done;
    std::printf("[%zu/%zu] %-9s %-34s %-8s t=%-8.4g %7.1f s  %s\n", done, runs.size(),
                r.spec.group.c_str(), r.spec.label.c_str(),
                std::string(sphles::sim::classification_name(r.classification)).c_str(),
                r.time_reached, r.wall_seconds, r.reason.c_str());
    std::fflush(stdout);
  }

  std::ofstream out(out_path);
  st::write_csv_header(out);
  for (const st::RunResult& r : results) st::write_csv_row(out, r);
  out.close();
  if (!out) {
    std::cerr << "could not write " << out_path << '\n';
    return 1;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - sweep_start).count();
  std::cout << "wrote " << out_path << " (" << results.size() << " configurations, " << seconds
            << " s wall with " << jobs << " job" << (jobs > 1 ? "s" : "") << ")\n";
  return 0;
}
