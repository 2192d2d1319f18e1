// SPDX-License-Identifier: GPL-3.0-or-later
// Whether this processor has the instruction-set extensions the build was compiled for: a
// native build (SPHLES_NATIVE, -march=native) lists them (cmake/NativeCpuFeatures.cmake), and
// sphles checks them before anything else runs (cpu_check.cpp), so that a binary moved to an
// older machine stops with a message naming what is missing instead of an illegal instruction.
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace sphles::app {

/// The names of the space-separated list `required` for which `has` says no, in list order.
std::vector<std::string> missing_cpu_features(std::string_view required,
                                              const std::function<bool(std::string_view)>& has);

/// The message for a processor that lacks the build's features `missing`.
std::string missing_cpu_features_message(const std::vector<std::string>& missing);

/// Whether this processor has the feature (a __builtin_cpu_supports name of
/// cmake/NativeCpuFeatures.cmake); true for a name it does not know.
bool cpu_supports(std::string_view feature);

}  // namespace sphles::app
