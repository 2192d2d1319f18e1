// SPDX-License-Identifier: GPL-3.0-or-later
// Process CPU time and wall time for the timed benchmarks (bench_server, sphles_accuracy,
// sphles_stability).
#pragma once

#include <sys/resource.h>

#include <chrono>

namespace sphles::bench {

/// User + system CPU time of this process, all threads [s].
inline double process_cpu_seconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

/// The wall time since construction [s], read by calling it.
class WallClock {
 public:
  double operator()() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace sphles::bench
