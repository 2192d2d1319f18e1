// SPDX-License-Identifier: GPL-3.0-or-later
// Process CPU time for the timed benchmarks (bench_server, sphles_accuracy).
#pragma once

#include <sys/resource.h>

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

}  // namespace sphles::bench
