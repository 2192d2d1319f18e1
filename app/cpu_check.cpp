// SPDX-License-Identifier: GPL-3.0-or-later
// Compiled for the baseline x86-64 instruction set whatever the build's flags (app/CMakeLists.txt),
// since it runs before any code that may use the build's extensions.
#include "app/cpu_check.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>

namespace sphles::app {

std::vector<std::string> missing_cpu_features(std::string_view required,
                                              const std::function<bool(std::string_view)>& has) {
  std::vector<std::string> missing;
  std::size_t at = 0;
  while (at < required.size()) {
    const std::size_t end = std::min(required.find(' ', at), required.size());
    const std::string_view feature = required.substr(at, end - at);
    if (!feature.empty() && !has(feature)) missing.emplace_back(feature);
    at = end + 1;
  }
  return missing;
}

std::string missing_cpu_features_message(const std::vector<std::string>& missing) {
  std::string names;
  for (const std::string& feature : missing) names += (names.empty() ? "" : " ") + feature;
  return "sphles: this processor lacks " + names +
         ", which this build of sphles uses (it was compiled with -march=native on a processor "
         "that has them). Build sphles on this machine (scripts/build.sh), or configure with "
         "-DSPHLES_NATIVE=OFF for a build that runs on any x86-64 processor (README.md).\n";
}

bool cpu_supports(std::string_view feature) {
  __builtin_cpu_init();  // needed before constructors have run (GCC manual)
  // __builtin_cpu_supports takes a string literal, hence one line per name.
#define SPHLES_FEATURE(name) \
  if (feature == name) return __builtin_cpu_supports(name) != 0;
  SPHLES_FEATURE("sse4.2")
  SPHLES_FEATURE("popcnt")
  SPHLES_FEATURE("avx")
  SPHLES_FEATURE("f16c")
  SPHLES_FEATURE("avx2")
  SPHLES_FEATURE("fma")
  SPHLES_FEATURE("bmi")
  SPHLES_FEATURE("bmi2")
  SPHLES_FEATURE("avx512f")
  SPHLES_FEATURE("avx512cd")
  SPHLES_FEATURE("avx512bw")
  SPHLES_FEATURE("avx512dq")
  SPHLES_FEATURE("avx512vl")
  SPHLES_FEATURE("avx512ifma")
  SPHLES_FEATURE("avx512vbmi")
  SPHLES_FEATURE("avx512vbmi2")
  SPHLES_FEATURE("avx512vnni")
  SPHLES_FEATURE("avx512bitalg")
  SPHLES_FEATURE("avx512vpopcntdq")
#undef SPHLES_FEATURE
  return true;
}

namespace {

/// Runs before every other constructor of the program (priority 101, the first one not
/// reserved), so before anything compiled with the build's extensions.
__attribute__((constructor(101))) void check_processor() {
  const std::string_view required = SPHLES_NATIVE_CPU_FEATURES;
  const std::vector<std::string> missing = missing_cpu_features(required, cpu_supports);
  if (missing.empty()) return;
  const std::string message = missing_cpu_features_message(missing);
  if (::write(STDERR_FILENO, message.data(), message.size()) < 0) {
    // Nothing more to do: the exit status says it.
  }
  std::_Exit(1);
}

}  // namespace

}  // namespace sphles::app
